"""Time the training step of method scripts against an older commit's, side by side in one run.

    python -m benchmark.step_time [--scripts bc_oh c2f fca] [--baseline 8ce2c69] [--epochs 20] [--repeats 3]
    python -m benchmark.step_time --scripts bc_oh c2f --baseline HEAD --env-now MKL_CBWR=COMPATIBLE

Each run is the real script on Hopper-v4 (paper settings but --epochs, one seed, one evaluation of one
episode); its `ms_per_step` is read from its JSON result: the script's own training-loop time per step,
evaluations excluded, first epoch included, on one thread. The baseline's file is `git show
<baseline>:<script>.py`, run from the repository's root. The two versions of a script run at the same
time, one process each, so that whatever else loads the machine reaches both alike (on a shared cloud
machine the step time drifts by a third within minutes); each such pair gives a ratio. Prints the
machine and a Markdown table: each run's figure, and the median of the pairs' ratios (new / baseline;
below 1 is faster). --env-now sets environment variables for the runs of today's scripts only: with --baseline
HEAD, the same script under two settings side by side (the second line above: MKL's fixed numeric mode against
the default).
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.baseline import (
    BEFORE_FUSED_ADAM,
    REPO_ROOT,
    check_method_file,
    machine_line,
    script_at,
)
from benchmark.results import OneLineParser, UsageError, check_distinct, last_line_of, run_cli


def start(script_path: Path, epochs: int, out: Path, cuda: bool, env: dict) -> subprocess.Popen:
    """Start one run of the script, with env added to this process's environment; its result goes to
    out/result_seeds1.json."""
    command = [sys.executable, str(script_path), "--env", "Hopper-v4", "--seeds", "1"]
    command += ["--epochs", str(epochs), "--eval-every", str(epochs), "--eval-episodes", "1"]
    command += ["--output-dir", str(out)]
    if cuda:
        command.append("--cuda")
    pipes = {"stdout": subprocess.DEVNULL, "stderr": subprocess.PIPE}
    return subprocess.Popen(command, cwd=REPO_ROOT, env=dict(os.environ, **env), text=True, **pipes)


def ms_per_step(run: subprocess.Popen, out: Path) -> float:
    """Wait for the run; its ms per training step."""
    _, stderr = run.communicate()
    if run.returncode != 0:
        raise UsageError(f"{' '.join(run.args[1:])} failed: {last_line_of(stderr)}")
    result = json.loads((out / "result_seeds1.json").read_text())
    return result["scores"]["1"]["ms_per_step"]


def timed_script(commit: str, script: str, folder: Path) -> Path:
    """script_at's file, refused when that version records no ms_per_step (a commit older than
    the scripts' timing of their training loop)."""
    path = script_at(commit, script, folder)
    if "ms_per_step" not in path.read_text():
        advice = f"give a later --baseline, e.g. {BEFORE_FUSED_ADAM}"
        raise UsageError(f"{script}.py at {commit} records no ms_per_step: {advice}")
    return path


def figures(values: list) -> str:
    return ", ".join(f"{value:.3f}" for value in values)


def main(argv=None) -> int:
    parser = OneLineParser(
        prog="python -m benchmark.step_time", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "--scripts", nargs="+", default=["bc_oh", "c2f", "fca"], help="method files, without .py"
    )
    parser.add_argument("--baseline", default=BEFORE_FUSED_ADAM, help="the commit to compare with")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3, help="pairs of runs of each script")
    parser.add_argument("--cuda", action="store_true", help="train both versions on the GPU")
    parser.add_argument(
        "--env-now",
        action="append",
        default=[],
        metavar="VAR=VALUE",
        help="an environment variable for the runs of today's scripts only (repeatable)",
    )
    options = parser.parse_args(argv)
    env_now = {}
    for setting in options.env_now:
        name, equals, value = setting.partition("=")
        if not name or not equals:
            raise UsageError(f"--env-now {setting!r} is not VAR=VALUE: e.g. MKL_CBWR=COMPATIBLE")
        env_now[name] = value
    for script in options.scripts:
        check_method_file("--scripts", script)
    check_distinct("--scripts", options.scripts)
    if options.epochs <= 0 or options.repeats <= 0:
        raise UsageError("--epochs and --repeats must be positive")
    before = {script: [] for script in options.scripts}
    after = {script: [] for script in options.scripts}
    with tempfile.TemporaryDirectory() as tmp:
        versions = {}  # every version found (or refused) before the first run
        for script in options.scripts:
            old_path = timed_script(options.baseline, script, Path(tmp))
            versions[script] = old_path, timed_script("HEAD", script, Path(tmp))
        for repeat in range(options.repeats):
            for script in options.scripts:
                old_path, new_path = versions[script]
                old_out = Path(tmp, f"{script}_baseline_{repeat}")
                new_out = Path(tmp, f"{script}_new_{repeat}")
                old_run = start(old_path, options.epochs, old_out, options.cuda, {})
                new_run = start(new_path, options.epochs, new_out, options.cuda, env_now)
                before[script].append(ms_per_step(old_run, old_out))
                after[script].append(ms_per_step(new_run, new_out))
                pair = f"{before[script][-1]:.3f} and {after[script][-1]:.3f} ms a step"
                print(f"{script}, pair {repeat + 1}: {pair}", file=sys.stderr)
    print(f"machine: {machine_line()}")
    print(f"Hopper-v4, {options.epochs} epochs, one thread a run, the two versions at once")
    now = "now"
    if env_now:
        now = "now with " + " ".join(options.env_now)
    print(
        f"| script | ms a step at {options.baseline} | ms a step {now} | {now} / {options.baseline} |"
    )
    print("|---|---:|---:|---:|")
    for script in options.scripts:
        ratios = [new / old for old, new in zip(before[script], after[script])]
        ratio = statistics.median(ratios)
        row = f"| `{script}.py` | {figures(before[script])} | {figures(after[script])} |"
        print(f"{row} {ratio:.2f}x |")
    return 0


if __name__ == "__main__":
    run_cli(main)
