"""Training time per seed as the committed runs measured it, by run and by the machine each ran on.

    python -m benchmark.seed_times [--results-dir results] [--out results/seed_times.md]

Reads every result JSON under --results-dir that carries a machine record (the grid runners add one), and each
seed's `ms_per_step`: the script's own training-loop time per step, evaluations excluded. The grid runners train two
seeds at once on a 2-core machine, one core each, as the main job does with its default --workers. A seed's training
time at the paper's protocol on Hopper is that times its steps: 1000 epochs of 20000 // 64 = 312 steps, and for
DAgger 468,100 (then four rounds of 100 epochs on the growing aggregate). Results without a machine record (made
before the runners wrote one) are counted, not used: the machine they ran on is unknown. Each row also names the commit
of the scripts that made its runs (the nearest commit.txt above them, which the grid's runs keep): the scripts' speed
changed over time (fused Adam, 654be24, made a step about 0.73x as long).
A result that does not read, or whose ms_per_step is not a positive number, is named on stderr
and left out.
"""
import json
import sys
from collections import defaultdict
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.results import OneLineParser, UsageError, check_writable, finite_number, run_cli, write_text

HOPPER_STEPS = {"dagger": 468_100}
"""training steps of a paper-protocol Hopper seed, where a run differs from 1000 epochs of 312 steps"""
DEFAULT_STEPS = 312_000


def machine_name(record: dict) -> str:
    """The CPU as a result records it: vendor, model name and the kernels torch picked (e.g. 'AuthenticAMD AMD EPYC,
    AVX512'); older records lack the vendor."""
    cpu = " ".join(part for part in (record.get("cpu_vendor"), record.get("cpu")) if part) or "unknown CPU"
    return f"{cpu}, {record['cpu_capability']}" if record.get("cpu_capability") else cpu


def commit_of(path: Path, results_dir: Path) -> str:
    """The short commit in the nearest commit.txt above path, up to results_dir; "unknown" where there is none."""
    for folder in path.parents:
        if (folder / "commit.txt").is_file():
            words = (folder / "commit.txt").read_text().split()
            return words[0][:7] if words else "unknown"
        if folder == results_dir:
            break
    return "unknown"


def collect(results_dir) -> tuple:
    """({(run, machine, commit): [ms per step of each seed]}, results without a machine record,
    a line per result left out: one that does not read, or whose ms_per_step is not a positive
    number). A run is the folder above the env's (e.g. `c2f`, `c2f_no_coarse`): the method with
    the flags its grid gave it, prefixed by the result's method where the folder does not start
    with it."""
    times, unknown = defaultdict(list), 0
    problems = []
    for path in sorted(Path(results_dir).rglob("result_seeds*.json")):
        try:
            result = json.loads(path.read_text())
        except (OSError, ValueError) as error:  # JSONDecodeError, UnicodeDecodeError: ValueErrors
            problems.append(f"left out {path}: unreadable JSON ({type(error).__name__}: {error})")
            continue
        scores = result.get("scores") if isinstance(result, dict) else None
        if not isinstance(scores, dict):
            problems.append(f"left out {path}: not a result (no scores object)")
            continue
        entries = list(scores.values())
        if len(entries) != 1:
            continue  # a summary of several seeds: its seeds have files of their own
        if not isinstance(entries[0], dict) or "ms_per_step" not in entries[0]:
            continue  # no training loop of its own (the expert's evaluation)
        ms = entries[0]["ms_per_step"]
        if not finite_number(ms) or ms <= 0:
            problems.append(f"left out {path}: ms_per_step {ms!r} is not a positive number")
            continue
        if not isinstance(result.get("machine"), dict):
            unknown += 1
            continue
        run, method = path.parent.parent.name, str(result.get("method", ""))
        run = run if run.startswith(method) else f"{method}/{run}"  # e.g. ensemble_twins/bc_so: its members' kind
        times[run, machine_name(result["machine"]), commit_of(path, Path(results_dir))].append(ms)
    return dict(times), unknown, problems


def table(times: dict, unknown: int, command: str) -> str:
    lines = [
        "# Training time per seed, as the committed runs measured it",
        "",
        f"Made by `{command}`. Each seed's own ms per training step (evaluations excluded), two seeds at once on a "
        "2-core machine, one core each; the minutes are the training of a paper-protocol Hopper seed at those step "
        f"times (312,000 steps; DAgger 468,100). {unknown} results without a machine record are left out.",
        "",
        "| run | machine | commit | seeds | ms per step | Hopper seed, training |",
        "|---|---|---|---:|---:|---:|",
    ]
    for (run, machine, commit), values in sorted(times.items()):
        steps = HOPPER_STEPS.get(run, DEFAULT_STEPS)
        low, high = min(values), max(values)
        ms = f"{low:.2f}" if round(low, 2) == round(high, 2) else f"{low:.2f}–{high:.2f}"
        minutes = [value * steps / 60_000 for value in (low, high)]
        span = f"{minutes[0]:.1f}" if round(minutes[0], 1) == round(minutes[1], 1) else f"{minutes[0]:.1f}–{minutes[1]:.1f}"
        lines.append(f"| `{run}` | {machine} | {commit} | {len(values)} | {ms} | {span} min |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.seed_times", description=__doc__.splitlines()[0])
    parser.add_argument("--results-dir", default="results")
    parser.add_argument("--out", default="results/seed_times.md")
    options = parser.parse_args(argv)
    if not Path(options.results_dir).is_dir():
        raise UsageError(f"--results-dir {options.results_dir} is not a folder: pass the folder of the committed runs")
    check_writable(options.out, "--out", is_file=True)
    times, unknown, problems = collect(options.results_dir)
    for problem in problems:
        print(problem, file=sys.stderr)
    if not times:
        raise UsageError(f"no result under {options.results_dir} has a machine record: run the grid runner first")
    command = "python -m benchmark.seed_times" + (
        "" if (options.results_dir, options.out) == ("results", "results/seed_times.md")
        else f" --results-dir {options.results_dir} --out {options.out}")
    text = table(times, unknown, command)
    write_text(options.out, text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    run_cli(main)
