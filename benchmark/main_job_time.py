"""Time the main job (three seeds of a method script) against an older commit's, and with each --workers count.

    python -m benchmark.main_job_time [--script c2f] [--epochs 100] [--baseline 8ce2c69] [--workers 2 3] [--repeats 2]

Each run is the whole command `python <script>.py --env Hopper-v4 --seeds 1 2 3 --workers W --epochs N`
(paper settings otherwise: start-up, demos loaded, training, ten evaluations, result files) in a fresh output
folder, from the repository's root. The baseline is `git show <baseline>:<script>.py` with --workers set to
the cores (its default then); the new file runs with each count of --workers. The runs alternate (baseline,
then each count of the new file, then again) so that a change in the machine's load reaches all of them.
Prints the machine and a Markdown table of wall times, each against the baseline's median.
"""

import os
import statistics
import sys
import tempfile
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.baseline import BEFORE_FUSED_ADAM, REPO_ROOT, machine_line, script_at, timed_run
from benchmark.results import OneLineParser, UsageError, run_cli

SEEDS = ["1", "2", "3"]


def job(script_path: Path, epochs: int, workers: int, out: Path) -> list:
    command = [sys.executable, str(script_path), "--env", "Hopper-v4", "--seeds", *SEEDS]
    command += ["--workers", str(workers), "--epochs", str(epochs), "--output-dir", str(out)]
    return command


def main(argv=None) -> int:
    cores = len(os.sched_getaffinity(0))
    parser = OneLineParser(
        prog="python -m benchmark.main_job_time", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--script", default="c2f")
    parser.add_argument("--epochs", type=int, default=100)
    parser.add_argument("--baseline", default=BEFORE_FUSED_ADAM, help="the commit to compare with")
    parser.add_argument("--workers", type=int, nargs="+", default=sorted({cores, len(SEEDS)}))
    parser.add_argument("--repeats", type=int, default=2, help="runs of each setting, alternating")
    options = parser.parse_args(argv)
    if not (REPO_ROOT / f"{options.script}.py").is_file():
        raise UsageError(f"unknown script {options.script}.py: name a method file, e.g. c2f")
    if options.epochs <= 0 or options.repeats <= 0 or min(options.workers) <= 0:
        raise UsageError("--epochs, --repeats and --workers must be positive")
    settings = [(options.baseline, cores)]
    for workers in options.workers:
        settings.append(("HEAD", workers))
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(options.repeats):
            for version, workers in settings:
                path = script_at(version, options.script, Path(tmp))
                out = Path(tmp, f"out_{version}_{workers}_{repeat}")
                seconds = timed_run(job(path, options.epochs, workers, out))
                times.setdefault((version, workers), []).append(seconds)
                print(f"{version}, --workers {workers}: {seconds:.1f} s", file=sys.stderr)
    baseline = statistics.median(times[settings[0]])
    print(f"machine: {machine_line()}")
    print(
        f"{options.script}.py --env Hopper-v4 --seeds {' '.join(SEEDS)} --epochs {options.epochs}"
    )
    print(f"| code | --workers | wall time (s), each run | median | vs {options.baseline} |")
    print("|---|---:|---:|---:|---:|")
    for (version, workers), seconds in times.items():
        runs = ", ".join(f"{value:.1f}" for value in seconds)
        median = statistics.median(seconds)
        code = version
        if version == "HEAD":
            code = "this checkout"
        print(f"| {code} | {workers} | {runs} | {median:.1f} | {median / baseline:.2f}x |")
    return 0


if __name__ == "__main__":
    run_cli(main)
