"""Time a whole three-seed job of a method script with each --workers count (seeds in parallel processes).

    python -m benchmark.main_job_time [--script c2f] [--epochs N] [--workers 1 2 3]

Each count runs `python <script>.py --env Hopper-v4 --seeds 1 2 3 --workers W --epochs N` (paper settings
otherwise) in a fresh output folder, demos generated once beforehand so that no run pays for them, and
prints a Markdown table of wall times (the whole command: start-up, training, evaluations) with the machine.
"""
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmark.machine import cpuinfo_field
from benchmark.results import OneLineParser, UsageError, run_cli

REPO_ROOT = Path(__file__).resolve().parent.parent
SEEDS = ["1", "2", "3"]


def job(script: str, epochs: int, workers: int, workdir: Path) -> list:
    return [sys.executable, str(REPO_ROOT / f"{script}.py"), "--env", "Hopper-v4", "--seeds", *SEEDS, "--workers", str(workers),
            "--epochs", str(epochs), "--output-dir", str(workdir / f"out_{workers}")]


def wall_time(command: list) -> float:
    start = time.time()
    finished = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True)
    if finished.returncode != 0:
        raise UsageError(f"{' '.join(command[1:])} failed: {finished.stderr.strip().splitlines()[-1:]}")
    return time.time() - start


def cpu_name() -> str:
    return cpuinfo_field("model name") or platform.processor() or platform.machine()


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.main_job_time", description=__doc__.splitlines()[0])
    parser.add_argument("--script", default="c2f")
    parser.add_argument("--epochs", type=int, default=1000)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 3])
    options = parser.parse_args(argv)
    if not (REPO_ROOT / f"{options.script}.py").is_file():
        raise UsageError(f"unknown script {options.script}.py")
    if options.epochs <= 0 or min(options.workers) <= 0:
        raise UsageError("--epochs and --workers must be positive")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    with tempfile.TemporaryDirectory() as tmp:
        # one short seed first: it caches the demos under demos/ (as any run does), so no timed run generates them
        wall_time([*job(options.script, 1, 1, Path(tmp))[:5], "1", "--epochs", "1", "--output-dir", str(Path(tmp) / "warm-up")])
        times = {workers: wall_time(job(options.script, options.epochs, workers, Path(tmp))) for workers in options.workers}
    print(f"machine: {cpu_name()}, {cores} cores; {options.script}.py, Hopper-v4, "
          f"seeds {' '.join(SEEDS)}, {options.epochs} epochs")
    print("| --workers | wall time (s) | vs --workers 1 |" if 1 in times else "| --workers | wall time (s) |")
    print("|---|---|---|" if 1 in times else "|---|---|")
    for workers, seconds in times.items():
        print(f"| {workers} | {seconds:.1f} |" + (f" {times[1] / seconds:.2f}x |" if 1 in times else ""))
    return 0


if __name__ == "__main__":
    run_cli(main)
