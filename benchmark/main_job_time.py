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
import re
import statistics
import sys
import tempfile
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.baseline import (
    BEFORE_FUSED_ADAM,
    check_method_file,
    machine_line,
    script_at,
    timed_run,
)
from benchmark.results import OneLineParser, UsageError, check_distinct, run_cli

SEEDS = ["1", "2", "3"]


def job(script_path: Path, epochs: int, workers: int, out: Path) -> list:
    command = [sys.executable, str(script_path), "--env", "Hopper-v4", "--seeds", *SEEDS]
    command += ["--workers", str(workers), "--epochs", str(epochs), "--output-dir", str(out)]
    return command


def job_script(commit: str, script: str, folder: Path) -> Path:
    """script_at's file, refused when that version takes no --workers (a commit older than the
    seeds' parallel processes, f23377c)."""
    path = script_at(commit, script, folder)
    if not re.search(r"^    workers: ", path.read_text(), re.M):
        advice = f"give a later --baseline, e.g. {BEFORE_FUSED_ADAM}"
        raise UsageError(f"{script}.py at {commit} takes no --workers: {advice}")
    return path


def main(argv=None) -> int:
    cores = len(os.sched_getaffinity(0))
    parser = OneLineParser(
        prog="python -m benchmark.main_job_time", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--script", default="c2f", help="a method file, without .py")
    parser.add_argument("--epochs", type=int, default=100)
    parser.add_argument("--baseline", default=BEFORE_FUSED_ADAM, help="the commit to compare with")
    parser.add_argument("--workers", type=int, nargs="+", default=sorted({cores, len(SEEDS)}))
    parser.add_argument("--repeats", type=int, default=2, help="runs of each setting, alternating")
    options = parser.parse_args(argv)
    check_method_file("--script", options.script)
    if options.epochs <= 0 or options.repeats <= 0 or min(options.workers) <= 0:
        raise UsageError("--epochs, --repeats and --workers must be positive")
    check_distinct("--workers", options.workers)
    settings = [(options.baseline, cores)]
    for workers in options.workers:
        settings.append(("HEAD", workers))
    # By setting, not by (version, workers): with --baseline HEAD the first is one of the others.
    times = [[] for _ in settings]
    with tempfile.TemporaryDirectory() as tmp:
        paths = {}  # every version found (or refused) before the first run
        for version in (options.baseline, "HEAD"):
            paths[version] = job_script(version, options.script, Path(tmp))
        for repeat in range(options.repeats):
            for index, (version, workers) in enumerate(settings):
                out = Path(tmp, f"out_{index}_{repeat}")
                seconds = timed_run(job(paths[version], options.epochs, workers, out))
                times[index].append(seconds)
                print(f"{version}, --workers {workers}: {seconds:.1f} s", file=sys.stderr)
    baseline = statistics.median(times[0])
    print(f"machine: {machine_line()}")
    print(
        f"{options.script}.py --env Hopper-v4 --seeds {' '.join(SEEDS)} --epochs {options.epochs}"
    )
    print(f"| code | --workers | wall time (s), each run | median | vs {options.baseline} |")
    print("|---|---:|---:|---:|---:|")
    for (version, workers), seconds in zip(settings, times):
        runs = ", ".join(f"{value:.1f}" for value in seconds)
        median = statistics.median(seconds)
        code = version
        if version == "HEAD":
            code = "this checkout"
        print(f"| {code} | {workers} | {runs} | {median:.1f} | {median / baseline:.2f}x |")
    return 0


if __name__ == "__main__":
    run_cli(main)
