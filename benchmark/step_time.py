"""Time the training step of method scripts against an older commit's, side by side in one run.

    python -m benchmark.step_time [--scripts bc_oh c2f fca] [--baseline 8ce2c69] [--epochs 20] [--repeats 2]

Each run is the real script on Hopper-v4 (paper settings but --epochs, one seed, one evaluation of one
episode); its `ms_per_step` is read from its JSON result: the script's own training-loop time per step,
evaluations excluded, first epoch included, on one thread. The baseline's file is `git show
<baseline>:<script>.py`, run from the repository's root. The runs alternate (baseline, new, baseline, new)
so that a change in the machine's load reaches both. Prints the machine and a Markdown table: each run's
figure, and the ratio of the medians (new / baseline; below 1 is faster).
"""

import json
import statistics
import sys
import tempfile
from pathlib import Path

from benchmark.baseline import BEFORE_FUSED_ADAM, REPO_ROOT, machine_line, script_at, timed_run
from benchmark.results import OneLineParser, UsageError, run_cli


def step_time(script_path: Path, epochs: int, out: Path, cuda: bool) -> float:
    """ms per training step of one run of the script."""
    command = [sys.executable, str(script_path), "--env", "Hopper-v4", "--seeds", "1"]
    command += ["--epochs", str(epochs), "--eval-every", str(epochs), "--eval-episodes", "1"]
    command += ["--output-dir", str(out)]
    if cuda:
        command.append("--cuda")
    timed_run(command)
    result = json.loads((out / "result_seeds1.json").read_text())
    return result["scores"]["1"]["ms_per_step"]


def figures(values: list) -> str:
    return ", ".join(f"{value:.3f}" for value in values)


def main(argv=None) -> int:
    parser = OneLineParser(
        prog="python -m benchmark.step_time", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--scripts", nargs="+", default=["bc_oh", "c2f", "fca"])
    parser.add_argument("--baseline", default=BEFORE_FUSED_ADAM, help="the commit to compare with")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=2, help="runs of each version, alternating")
    parser.add_argument("--cuda", action="store_true", help="train both versions on the GPU")
    options = parser.parse_args(argv)
    for script in options.scripts:
        if not (REPO_ROOT / f"{script}.py").is_file():
            raise UsageError(f"unknown script {script}.py: name a method file, e.g. c2f")
    if options.epochs <= 0 or options.repeats <= 0:
        raise UsageError("--epochs and --repeats must be positive")
    versions = [options.baseline, "HEAD"]
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(options.repeats):
            for script in options.scripts:
                for version in versions:
                    path = script_at(version, script, Path(tmp))
                    out = Path(tmp, f"out_{script}_{version}_{repeat}")
                    seconds = step_time(path, options.epochs, out, options.cuda)
                    times.setdefault((script, version), []).append(seconds)
                    print(f"{script} at {version}: {seconds:.3f} ms a step", file=sys.stderr)
    print(f"machine: {machine_line()}; Hopper-v4, {options.epochs} epochs, one thread")
    print(
        f"| script | ms a step at {options.baseline} | ms a step now | now / {options.baseline} |"
    )
    print("|---|---:|---:|---:|")
    for script in options.scripts:
        before = times[script, options.baseline]
        after = times[script, "HEAD"]
        ratio = statistics.median(after) / statistics.median(before)
        print(f"| `{script}.py` | {figures(before)} | {figures(after)} | {ratio:.2f}x |")
    return 0


if __name__ == "__main__":
    run_cli(main)
