"""FCA before and after the authors' BatchNorm encoder (issue 33): the Table 2 rows side by side, the rule declared
before the runs ("a seed diverges when any adversary error in its log exceeds 4", docs/regimes.md), and the
adversary's error over training.

    python -m benchmark.fca_compare [--new results/runs] [--old results/fca_before_batchnorm] [--out results]

Reads every `<dir>/fca/<env>/seed<S>.log` with its `result_seeds<S>.json` (a log without its result is a run still
going and is left out), writes `<out>/fca_compare.md` and `<out>/fca_adversary.png`.
A result that does not read, and a log without an adversary error, are left out and named on
stderr. A NaN adversary error counts as above the bound (its predictions are not numbers, so not
inside the action bounds).
"""
import math
import re
import sys
from pathlib import Path

import numpy as np

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.aggregate import save_figure
from benchmark.paper import PAPER_TABLE2
from benchmark.results import OneLineParser, ResultError, UsageError, check_writable, read_result, run_cli, write_text

DIVERGED_ABOVE = 4.0
"""the largest error an adversary whose predictions stay inside the action bounds [-1, 1] can have (declared)"""
ENVS = ["Hopper-v4", "Ant-v4", "HalfCheetah-v4", "Walker2d-v4"]
PROGRESS = re.compile(r"^seed \d+ \| epoch (\d+)/\d+ \| loss \S+ \| adversary error (\S+)", re.M)


def adversary_curve(log: Path) -> list:
    """[(epoch, the adversary's mean error over that epoch)] from a run's progress lines."""
    return [(int(epoch), float(error)) for epoch, error in PROGRESS.findall(log.read_text(errors="replace"))]


def runs(folder: Path, env: str, seeds=None) -> tuple:
    """({seed: (score, adversary curve)} of the finished FCA runs of env under folder (of `seeds`,
    if given), and a line per seed left out: a log not named seed<S>.log, a result that does not
    read, a log without an adversary error. A log without its result is a run still going: left
    out, not listed."""
    found = {}
    problems = []
    for log in sorted((Path(folder) / "fca" / env).glob("seed*.log")):
        name = log.stem.removeprefix("seed")
        if not name.isdecimal():  # seed1.old.log: not a run's log
            problems.append(f"left out {log}: not a run's log (seed<S>.log)")
            continue
        seed = int(name)
        path = log.with_name(f"result_seeds{seed}.json")
        if (seeds is not None and seed not in seeds) or not path.exists():
            continue  # not asked for, or still running
        try:
            result = read_result(path, "fca", env, [seed])
        except ResultError as error:
            problems.append(f"left out {path}: {error}")
            continue
        curve = adversary_curve(log)
        if not curve:  # fca.py's progress lines carry it: a log cut short, or of another script
            problems.append(f"left out {log}: no adversary error in its progress lines")
            continue
        found[seed] = (result["scores"][str(seed)]["score"], curve)
    return found, problems


def peak(curve: list) -> float:
    """A curve's largest adversary error; a NaN error counts as infinite (above any bound)."""
    return max(math.inf if math.isnan(error) else error for _, error in curve)


def row(found: dict) -> str:
    if not found:
        return "— | — | —"
    scores = [score for score, _ in found.values()]
    peaks = [peak(curve) for _, curve in found.values()]
    diverged = sum(value > DIVERGED_ABOVE for value in peaks)
    return (f"{np.mean(scores):.0f} ± {np.std(scores):.0f} (n={len(scores)}) | {min(peaks):.3g}–{max(peaks):.3g} | "
            f"{diverged} of {len(scores)}")


def markdown(new: dict, old: dict, command: str) -> str:
    lines = [f"Made by `{command}`. Mean ± std over seeds of each seed's score (the mean of its last three evaluations);",
             f"the adversary's largest logged error (epoch means); a seed diverges when that exceeds {DIVERGED_ABOVE:g} (the rule",
             "declared before the runs in docs/regimes.md). The new runs: `fca.py` with the authors' BatchNorm encoder, init,",
             "learning-rate ratio and w (commit in `fca/commit.txt`); the old: the encoder without BatchNorm, w = 1, D at 2e-4.", "",
             "| env | paper | FCA as authored | largest adversary error | diverged | old FCA | largest adversary error | diverged |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for env in ENVS:
        paper = PAPER_TABLE2.get("fca", {}).get(env.split("-")[0])
        lines.append(f"| {env} | {f'{paper[0]} ± {paper[1]}' if paper else '—'} | {row(new[env])} | {row(old[env])} |")
    return "\n".join(lines) + "\n"


def plot(new: dict, old: dict, path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(ENVS), figsize=(4 * len(ENVS), 3.2), squeeze=False)
    for axis, env in zip(axes[0], ENVS):
        for found, style, label in ((new[env], "-", "as authored"), (old[env], ":", "old")):
            for k, (seed, (_, curve)) in enumerate(sorted(found.items())):
                if curve:
                    epochs, errors = zip(*curve)
                    axis.plot(epochs, errors, style, color=f"C{seed % 10}", label=f"{label}, seed {seed}" if k < 3 else None)
        axis.axhline(DIVERGED_ABOVE, color="black", linewidth=0.8, linestyle="--")
        axis.set(title=env, xlabel="epoch", yscale="log")
    axes[0][0].set_ylabel("adversary error (epoch mean)")
    labelled = [axis for axis in axes[0] if axis.get_legend_handles_labels()[1]]
    if labelled:  # the seeds' legend once, where there are lines
        labelled[-1].legend(fontsize=6)
    save_figure(figure, path)


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.fca_compare", description=__doc__.split("\n\n")[0])
    parser.add_argument("--new", type=Path, default=Path("results/runs"), help="the new FCA runs (default results/runs)")
    parser.add_argument("--old", type=Path, default=Path("results/fca_before_batchnorm"), help="the old FCA runs")
    parser.add_argument("--out", type=Path, default=Path("results"), help="where fca_compare.md and fca_adversary.png go")
    args = parser.parse_args(argv)
    for folder in (args.new, args.old):
        if not (folder / "fca").is_dir():
            raise UsageError(f"no fca/ folder in {folder}: pass the results folder that holds fca/<env>/ runs")
    check_writable(args.out, "--out")
    new = {}
    old = {}
    problems = []
    for folder, found in ((args.new, new), (args.old, old)):
        for env in ENVS:
            found[env], more = runs(folder, env)
            problems += more
    for problem in problems:
        print(problem, file=sys.stderr)
    command = f"python -m benchmark.fca_compare --new {args.new} --old {args.old} --out {args.out}"
    text = markdown(new, old, command)
    write_text(args.out / "fca_compare.md", text)
    plot(new, old, args.out / "fca_adversary.png")
    print(text, end="")
    return 0


if __name__ == "__main__":
    run_cli(main)
