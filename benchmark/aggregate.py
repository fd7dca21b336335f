"""Turn the per-run results of benchmark.run_grid into the Table 2 files, ours beside the paper's.

    python -m benchmark.aggregate [--results-dir results/runs] [--out results] [--allow-nonpaper] [--page [docs/results.md]]

Reads every <results-dir>/<method>/<env>/result_seeds*.json and writes
- <out>/mujoco.csv: env,method,seed,score, score = mean return of the seed's last three evaluations;
- <out>/table2.md: mean ± std over seeds per method and env, the paper's number beside it, seeds per cell;
- <out>/table2.png: the same as bars with error bars, paper beside ours, one panel per env;
- <out>/curves.png: each method's evaluation return against epoch (mean over seeds, min-max band), one panel per env;
- with --page, the table and both pictures between the <!-- table2 --> markers of docs/results.md (or the page named).
Corrupt or partial results, and runs at settings other than the paper's (unless --allow-nonpaper), are
reported on stderr, naming the file, and left out.
"""
import os
import statistics
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.paper import METHOD_NAMES, NATIVE_FRAME_SKIP, PAPER_ENV_ORDER, PAPER_TABLE2, env_family, paper_settings, script_of, setting_differences, variant_settings
from benchmark.results import (EXPERT, OneLineParser, ResultError, UsageError, check_folder, check_writable, read_result, run_cli, seed_score,
                               write_text, written_atomically)


@dataclass
class Record:
    """One seed of one run."""
    method: str
    env: str
    seed: int
    score: float
    path: Path
    episode_std: float = None
    """the expert only: std of its evaluation over episodes"""
    episodes: int = None
    """the expert only: episodes of its evaluation"""
    differences: list = field(default_factory=list)
    """how its settings differ from the paper's (empty at the paper's settings)"""
    evaluations: list = field(default_factory=list)
    """the seed's evaluation curve, [[epoch, mean return], ...] (the expert: one, at epoch 0)"""


@dataclass
class Cell:
    mean: float
    std: float
    count: str
    """'n=3' (seeds), or for the expert '20 ep.' (episodes of its one evaluation; '' where its
    result does not say)"""


def collect(results_dir: Path, allow_nonpaper: bool):
    """The valid records under results_dir, and one line per file left out and why."""
    records, problems = {}, []
    for path in sorted(results_dir.glob("*/*/result_seeds*.json")):
        method, env = path.parent.parent.name, path.parent.name
        try:
            result = read_result(path, script_of(method), env)
        except ResultError as error:
            problems.append(f"left out {path}: {error}")
            continue
        wanted = {**paper_settings(env), **variant_settings(method)}
        differences = [] if method == EXPERT else setting_differences(result["args"], wanted, env)
        if differences and not allow_nonpaper:
            problems.append(f"left out {path}: not the paper's settings ({', '.join(differences)}); --allow-nonpaper includes it")
            continue
        for seed, entry in result["scores"].items():
            record = Record(method, env, int(seed), seed_score(entry["evaluations"]), path, differences=differences,
                            evaluations=entry["evaluations"])
            if method == EXPERT:
                record.episode_std, record.episodes = result["std"], result["args"].get("eval_episodes")
            key = (method, env, record.seed)
            if key in records:  # the same seed in two files (e.g. result_seeds1.json and result_seeds1-2-3.json)
                older, record = sorted([records[key], record], key=lambda r: r.path.stat().st_mtime)
                problems.append(f"left out seed {record.seed} of {older.path}: {record.path} is newer and holds it too")
            records[key] = record
    return list(records.values()), problems


def ordered(names, order) -> list:
    """names in the paper's order first, then the others alphabetically."""
    return sorted(set(names), key=lambda name: (order.index(name) if name in order else len(order), name))


ENV_ORDER = [f"{family}-v4" for family in PAPER_ENV_ORDER]


def summarise(records: list) -> Cell:
    scores = [record.score for record in records]
    if records[0].method == EXPERT:  # one deterministic evaluation: its spread is over episodes
        # A result without eval_episodes showed "(None ep.)": its count is left out.
        count = ""
        if records[0].episodes is not None:
            count = f"{records[0].episodes} ep."
        return Cell(statistics.fmean(scores), statistics.fmean(r.episode_std for r in records), count)
    return Cell(statistics.fmean(scores), statistics.pstdev(scores), f"n={len(scores)}")


def build_table(records: list):
    """(methods, envs, ours[(method, env)] -> Cell): rows = the paper's methods and any others we ran."""
    envs = ordered([r.env for r in records], ENV_ORDER)
    methods = ordered(list(PAPER_TABLE2) + [r.method for r in records], list(METHOD_NAMES))  # the paper's rows and any we ran
    ours = {}
    for method in methods:
        for env in envs:
            cell_records = [r for r in records if r.method == method and r.env == env]
            if cell_records:
                ours[method, env] = summarise(cell_records)
    return methods, envs, ours


def paper_cell(method: str, env: str):
    return PAPER_TABLE2.get(method, {}).get(env_family(env))


def format_cell(mean, std) -> str:
    return f"{mean:.0f}" if std is None else f"{mean:.0f} ± {std:.0f}"


def settings_text() -> str:
    """The paper's settings; where the envs differ, each value with the envs that take it (frame_skip: each env's own)."""
    per_family = {family: paper_settings(f"{family}-v4") for family in NATIVE_FRAME_SKIP}
    parts = []
    for name in per_family["Hopper"]:
        families_of = {}
        for family, settings in per_family.items():
            families_of.setdefault(settings[name], []).append(family)
        if len(families_of) == 1:
            parts.append(f"{name} {per_family['Hopper'][name]}")
        else:
            parts.append(f"{name} " + " / ".join(f"{value} ({', '.join(families)})" for value, families in families_of.items()))
    return "; ".join(parts)


def markdown(records: list, results_dir: Path, out: Path, allow_nonpaper: bool, page=None) -> str:
    methods, envs, ours = build_table(records)
    lines = [
        "# Table 2: imitation on MuJoCo with noisy velocities, ours beside the paper's",
        "",
        f"Made by `python -m benchmark.aggregate --results-dir {results_dir} --out {out}"
        + (" --allow-nonpaper" if allow_nonpaper else "") + (f" --page {page}" if page else "") + f"` from {len(records)} per-seed results, made by "
        "`python -m benchmark.run_grid` (the log beside each result starts with the command that made it).",
        "",
        "Ours: mean ± std over seeds (population std), n = seeds in the cell; a seed's score is the mean return of "
        "its last three evaluations, as the paper reports, except DAgger's: three evaluations of its final learner, which "
        "trains for 50% (Hopper) to 60% (10000 demo steps) more gradient steps than BC-OH. Paper: its Table 2, mean ± std over three seeds (as "
        "transcribed from the paper). The expert is deterministic and evaluated once per env (as seed 0): its ± is the std over the "
        "evaluation episodes (ep.), on the clean env; the paper gives no std for it.",
        "",
        f"Settings (the paper's): {settings_text()}.",
        "",
    ]
    nonpaper = Counter(", ".join(r.differences) for r in records if r.differences)
    if nonpaper:
        lines += ["**Not at the paper's settings** (included by --allow-nonpaper): "
                  + "; ".join(f"{count} seed runs with {difference}" for difference, count in nonpaper.items()) + ".", ""]
    lines += ["| method | " + " | ".join(f"{env} ours | {env_family(env)} paper" for env in envs) + " |",
              "|---|" + "---:|---:|" * len(envs)]
    for method in methods:
        cells = []
        for env in envs:
            cell, paper = ours.get((method, env)), paper_cell(method, env)
            if cell is None:
                cells.append("—")
            elif cell.count:
                cells.append(f"{format_cell(cell.mean, cell.std)} ({cell.count})")
            else:
                cells.append(format_cell(cell.mean, cell.std))
            cells.append(format_cell(*paper) if paper else "—")
        lines.append(f"| {METHOD_NAMES.get(method, method)} (`{method}`) | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(records: list, path: Path):
    """One panel per env: for each method a bar of ours and one of the paper's, std as error bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods, envs, ours = build_table(records)
    figure, axes = plt.subplots(1, len(envs), figsize=(4.8 * len(envs), 4.6), squeeze=False)
    for axis, env in zip(axes[0], envs):
        shown = [m for m in methods if (m, env) in ours or paper_cell(m, env)]
        for offset, label, color, value in (
            (-0.2, "ours", "tab:blue", lambda m: (ours[m, env].mean, ours[m, env].std) if (m, env) in ours else None),
            (0.2, "paper", "0.75", lambda m: paper_cell(m, env)),
        ):
            bars = [(i, *value(m)) for i, m in enumerate(shown) if value(m)]
            if bars:
                x, means, stds = zip(*bars)
                axis.bar([i + offset for i in x], means, 0.4, yerr=[s or 0 for s in stds], capsize=3, color=color, label=label)
        axis.set_xticks(range(len(shown)), [METHOD_NAMES.get(m, m) for m in shown], rotation=45, ha="right")
        axis.set_title(env)
        axis.set_ylabel("return")
    axes[0][0].legend()
    figure.suptitle("Table 2: ours (mean ± std over seeds) beside the paper's")
    figure.tight_layout()
    save_figure(figure, path)


def save_figure(figure, path: Path):
    """Write a matplotlib figure to path atomically as PNG, and free it."""
    import matplotlib.pyplot as plt

    with written_atomically(path) as tmp:
        figure.savefig(tmp, dpi=120)
    plt.close(figure)


class Curve(NamedTuple):
    """One method's learning curve on one env: at each epoch the mean, lowest and highest evaluation return over seeds."""
    epochs: list
    mean: list
    low: list
    high: list


def curves(records: list) -> dict:
    """{env: {method: Curve}} for every env and method with records, the expert left out (it has one evaluation, no
    curve); envs and methods in the paper's order."""
    cells = {}
    for record in records:
        if record.method != EXPERT:
            cells.setdefault(record.env, {}).setdefault(record.method, []).append(dict(record.evaluations))
    result = {}
    for env in ordered(cells, ENV_ORDER):
        for method in ordered(cells[env], list(METHOD_NAMES)):
            seeds = cells[env][method]
            # Seeds evaluated at other epochs than the rest of the cell (another --epochs or evaluation interval) are
            # grouped by epoch: only the epochs present in every seed of the cell are averaged, the others are left out.
            epochs = sorted(set.intersection(*map(set, seeds)))
            if epochs:
                returns = [[seed[epoch] for seed in seeds] for epoch in epochs]
                result.setdefault(env, {})[method] = Curve(epochs, *(list(map(f, returns)) for f in (statistics.fmean, min, max)))
    return result


def expert_scores(records: list) -> dict:
    """{env: the expert's score} for the envs whose expert record is among records."""
    scores = {}
    for record in records:
        if record.method == EXPERT:
            scores.setdefault(record.env, []).append(record.score)
    return {env: statistics.fmean(values) for env, values in scores.items()}


def plot_curves(records: list, path: Path, experts=None, title="Learning curves") -> bool:
    """One panel per env: each method's evaluation return against epoch, the mean over seeds as a line and the
    lowest to highest seed as a band, one colour per method; the expert's score (experts {env: score}, by default the
    expert records among records) as a dashed line. False, and nothing written, when no record has a curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    data = curves(records)
    experts = expert_scores(records) if experts is None else experts
    if not data:
        return False
    methods = ordered([method for cell in data.values() for method in cell], list(METHOD_NAMES))
    columns = min(len(data), 2)
    rows = -(-len(data) // columns)
    legend_height = 0.8  # inches below the panels for the legend (two rows of it)
    figure, axes = plt.subplots(rows, columns, figsize=(6.4 * columns, 4.2 * rows + legend_height), squeeze=False)
    for axis, (env, cell) in zip(axes.flat, data.items()):
        for method, curve in cell.items():
            color = f"C{methods.index(method) % 10}"
            axis.plot(curve.epochs, curve.mean, color=color, linewidth=1.6)
            axis.fill_between(curve.epochs, curve.low, curve.high, color=color, alpha=0.15, linewidth=0)
        if env in experts:
            axis.axhline(experts[env], color="black", linestyle="--", linewidth=1.2)
        axis.set_title(env)
        axis.set_xlabel("epoch")
        axis.set_ylabel("evaluation return")
        axis.grid(alpha=0.3)
    for axis in axes.flat[len(data):]:
        axis.set_visible(False)
    legend = [Line2D([], [], color=f"C{i % 10}", linewidth=1.6, label=METHOD_NAMES.get(m, m)) for i, m in enumerate(methods)]
    if set(experts) & set(data):
        legend.append(Line2D([], [], color="black", linestyle="--", linewidth=1.2, label=METHOD_NAMES[EXPERT]))
    figure.legend(handles=legend, loc="lower center", ncol=min(len(legend), 5))
    figure.suptitle(f"{title}: mean over seeds (line), lowest to highest seed (band)"
                    + (", expert's score (dashed)" if len(legend) > len(methods) else ""))
    figure.tight_layout(rect=(0, legend_height / figure.get_figheight(), 1, 1))
    save_figure(figure, path)
    return True


PAGE = Path("docs/results.md")
"""the page whose <!-- table2 --> block --page writes when it names no page"""
PAGE_START, PAGE_END = "<!-- table2 -->", "<!-- /table2 -->"


def page_parts(page: Path, start=PAGE_START, end=PAGE_END) -> tuple:
    """The page's text up to its start marker, and from its end marker on."""
    if page.is_dir():
        raise UsageError(f"page {page} is a folder: pass the markdown page itself to --page")
    if not page.is_file():
        raise UsageError(f"page {page} not found: check the --page path")
    try:
        text = page.read_text()
    except UnicodeDecodeError:
        raise UsageError(f"page {page} is not text (not UTF-8): pass the markdown page to --page")
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise UsageError(f"{page} needs one {start} line and, after it, one {end} line: add them where the table goes")
    return text[:text.index(start) + len(start)], text[text.index(end):]


def update_page(page: Path, table: str, image: Path, start=PAGE_START, end=PAGE_END, title="Table 2", more_images=()):
    """Put the table (without its title) and the plot between the page's markers, then more_images ((title, path)
    pairs) under it, linked relative to the page; keep the rest."""
    before, after = page_parts(page, start, end)
    body = table.split("\n", 2)[2].strip()  # below the "# ..." title and its blank line
    links = "\n\n".join(f"![{name}]({os.path.relpath(path, page.parent)})" for name, path in [(title, image), *more_images])
    write_text(page, f"{before}\n{body}\n\n{links}\n{after}")


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.aggregate", description=__doc__.split("\n\n")[0])
    parser.add_argument("--results-dir", type=Path, default=Path("results/runs"), help="where benchmark.run_grid wrote the runs")
    parser.add_argument("--out", type=Path, default=Path("results"), help="where mujoco.csv, table2.md and table2.png go")
    parser.add_argument("--allow-nonpaper", action="store_true", help="include runs at settings other than the paper's")
    parser.add_argument("--page", type=Path, nargs="?", const=PAGE,
                        help=f"also put the table and pictures into this page (alone: {PAGE}), between {PAGE_START} and {PAGE_END}")
    args = parser.parse_args(argv)
    if args.page:
        page_parts(args.page)  # check the markers before anything is written
    fix = "run python -m benchmark.run_grid first, or pass --results-dir"
    check_folder(args.results_dir, "results folder", fix)
    check_writable(args.out, "--out")
    records, problems = collect(args.results_dir, args.allow_nonpaper)
    for problem in problems:
        print(problem, file=sys.stderr)
    if not problems and not records:  # not one result file: not the folder run_grid wrote
        folder = args.results_dir
        raise UsageError(f"no <method>/<env>/result_seeds*.json under {folder}: pass the folder "
                         "python -m benchmark.run_grid wrote (--results-dir), or run it")
    if not records:
        raise UsageError(f"no valid results to aggregate under {args.results_dir} (see above): run python -m benchmark.run_grid")
    methods, envs, _ = build_table(records)
    rows = sorted(records, key=lambda r: (envs.index(r.env), methods.index(r.method), r.seed))
    write_text(args.out / "mujoco.csv", "env,method,seed,score\n" + "".join(f"{r.env},{r.method},{r.seed},{r.score:.3f}\n" for r in rows))
    table = markdown(records, args.results_dir, args.out, args.allow_nonpaper, args.page)
    write_text(args.out / "table2.md", table)
    plot(records, args.out / "table2.png")
    curves_image = [("Learning curves", args.out / "curves.png")] if plot_curves(records, args.out / "curves.png") else []
    if args.page:
        update_page(args.page, table, args.out / "table2.png", more_images=curves_image)
    print(table)
    print(f"wrote {args.out / 'mujoco.csv'} ({len(rows)} rows), {args.out / 'table2.md'}, {args.out / 'table2.png'}"
          + "".join(f", {image}" for _, image in curves_image)
          + (f", and the table into {args.page}" if args.page else "")
          + (f"; left out {len(problems)} (listed above)" if problems else ""))
    return 0


if __name__ == "__main__":
    run_cli(main)
