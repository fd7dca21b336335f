"""FCA before and after the authors' BatchNorm encoder (issue 33): the Table 2 rows side by side, the rule declared
before the runs ("a seed diverges when any adversary error in its log exceeds 4", docs/regimes.md), and the
adversary's error over training.

    python -m benchmark.fca_compare [--new results/runs] [--old results/fca_before_batchnorm] [--out results]

Reads every `<dir>/fca/<env>/seed<S>.log` with its `result_seeds<S>.json` (a log without its result is a run still
going and is left out), writes `<out>/fca_compare.md` and `<out>/fca_adversary.png`.
"""
import re
import sys
from pathlib import Path

import numpy as np

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.aggregate import save_figure
from benchmark.paper import PAPER_TABLE2
from benchmark.results import OneLineParser, ResultError, UsageError, read_result, run_cli, write_text

DIVERGED_ABOVE = 4.0
"""the largest error an adversary whose predictions stay inside the action bounds [-1, 1] can have (declared)"""
ENVS = ["Hopper-v4", "Ant-v4", "HalfCheetah-v4", "Walker2d-v4"]
PROGRESS = re.compile(r"^seed \d+ \| epoch (\d+)/\d+ \| loss \S+ \| adversary error (\S+)", re.M)


def adversary_curve(log: Path) -> list:
    """[(epoch, the adversary's mean error over that epoch)] from a run's progress lines."""
    return [(int(epoch), float(error)) for epoch, error in PROGRESS.findall(log.read_text(errors="replace"))]


def runs(folder: Path, env: str) -> dict:
    """{seed: (score, adversary curve)} of the finished FCA runs of env under folder."""
    found = {}
    for log in sorted((Path(folder) / "fca" / env).glob("seed*.log")):
        seed = int(log.stem.removeprefix("seed"))
        try:
            result = read_result(log.with_name(f"result_seeds{seed}.json"), "fca", env, [seed])
        except (ResultError, OSError):
            continue  # still running, or not a result: not counted
        found[seed] = (result["scores"][str(seed)]["score"], adversary_curve(log))
    return found


def row(found: dict) -> str:
    if not found:
        return "— | — | —"
    scores = [score for score, _ in found.values()]
    peaks = [max((error for _, error in curve), default=float("nan")) for _, curve in found.values()]
    diverged = sum(peak > DIVERGED_ABOVE for peak in peaks)
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
    new, old = ({env: runs(folder, env) for env in ENVS} for folder in (args.new, args.old))
    command = f"python -m benchmark.fca_compare --new {args.new} --old {args.old} --out {args.out}"
    text = markdown(new, old, command)
    write_text(args.out / "fca_compare.md", text)
    plot(new, old, args.out / "fca_adversary.png")
    print(text, end="")
    return 0


if __name__ == "__main__":
    run_cli(main)
