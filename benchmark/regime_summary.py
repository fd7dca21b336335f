"""Summarise the regime map (benchmark.regimes): per regime, env and method, how good and how sure.

    python -m benchmark.regime_summary [--results-dir results/regimes] [--expert-runs results/runs] [--page [docs/regimes.md]]

Reads <results-dir>/<regime>/runs/<method>/<env>/result_seeds<S>.json for every regime folder there and writes
- <results-dir>/<regime>/mujoco.csv: env,method,seed,score (score = mean return of the seed's last three evaluations);
- <results-dir>/<regime>/curves.png: evaluation return against epoch per env and method (aggregate.plot_curves);
- <results-dir>/summary.md: per regime, env and method the mean over seeds, its 95% bootstrap interval, the seeds
  and the expert-normalised mean; the probability that C2F beats BC-OH and BC-OH beats BC-SO, with intervals;
- <results-dir>/summary.png: the means with their intervals and the seeds, one panel per env;
- with --page, the summary and its picture between the <!-- regimes --> markers of docs/regimes.md (or the page named).
Corrupt or partial results, and runs at settings other than their regime's, are reported on stderr and left out.
"""
import json
import statistics
import sys
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark import aggregate, run_grid
from benchmark.paper import METHOD_NAMES, setting_differences
from benchmark.regimes import ENVS, METHODS, REGIMES, RESULTS_DIR, runs_dir
from benchmark.results import EXPERT, OneLineParser, ResultError, UsageError, check_folder, read_result, run_cli, write_text, written_atomically
from benchmark.stats import bootstrap_ci, expert_normalised, probability_of_improvement, probability_of_improvement_ci

COMPLETE = 5
"""seeds a cell needs before its interval means much; cells with fewer are marked incomplete"""
COMPARISONS = [("c2f", "bc_oh"), ("c2f_output", "bc_oh"), ("bc_oh", "bc_so")]
"""(A, B): report P(a seed of A beats a seed of B); the comparisons of the protocol, fixed before the runs"""
ADDED_COMPARISONS = [("c2f", "bc_so")]
"""comparisons added after seeing runs (does C2F beat the history-free baseline?): reported as exploratory"""
PAGE = Path("docs/regimes.md")
"""the page whose <!-- regimes --> block --page writes when it names no page"""
PAGE_START, PAGE_END = "<!-- regimes -->", "<!-- /regimes -->"


def collect(regime: str, results_dir: Path, methods=METHODS):
    """aggregate.collect for one regime: its valid records, checked against the paper's settings changed by the
    regime's flags (as benchmark.run_grid asks for them), and one line per file left out. methods: the methods
    kept (by default the map's; benchmark.table3 asks for the controls and Table 3 rows too), in their order."""
    records, problems = aggregate.collect(runs_dir(regime, results_dir), allow_nonpaper=True)
    options = run_grid.Options(methods=methods, envs=ENVS, seeds=[], extra_args=REGIMES[regime][0])
    kept = []
    for record in records:
        if record.method not in methods:
            continue  # another summary's runs (benchmark.regime_baselines reads the baselines' in the same folder)
        if record.env not in ENVS:
            problems.append(f"left out {record.path}: {record.method} on {record.env} is not in the regime map")
            continue
        wanted = run_grid.wanted_settings(run_grid.Run(record.method, record.env, record.seed), options)
        differences = setting_differences(json.loads(record.path.read_text())["args"], wanted, record.env)
        if differences:
            problems.append(f"left out {record.path}: not the {regime} settings ({', '.join(differences)})")
            continue
        kept.append(record)
    return sorted(kept, key=lambda r: (ENVS.index(r.env), methods.index(r.method), r.seed)), problems


def expert_scores(expert_runs: Path, envs=ENVS):
    """{env: the PPO expert's score} for the envs (by default the map's) whose expert result reads, and a line per
    env without one."""
    if not (expert_runs / EXPERT).is_dir():
        # A mistyped folder would leave every expert-normalised mean out, with only a warning.
        raise UsageError(f"no {EXPERT}/ folder in {expert_runs}: pass --expert-runs, the folder that holds {EXPERT}/<env>/result_seeds0.json")
    scores, problems = {}, []
    for env in envs:
        path = expert_runs / EXPERT / env / "result_seeds0.json"
        try:
            result = read_result(path, EXPERT, env)
            score = statistics.fmean(entry["score"] for entry in result["scores"].values())
            if score <= 0:  # a share of it would divide by 0, or flip its sign
                reason = f"its score {score:g} is not above 0 (a share of it would mean nothing)"
                raise ResultError(reason)
            scores[env] = score
        except ResultError as error:
            problems.append(f"no expert score for {env} ({path}: {error}): its expert-normalised means are left out")
    return scores, problems


def seeds_text(*counts) -> str:
    return "n=" + " vs ".join(map(str, counts)) + (", incomplete" if min(counts) < COMPLETE else "")


def regime_tables(regime: str, records: list, experts: dict, commit: str, provenance: str = "") -> list:
    """The markdown lines of one regime: means per env and method, comparisons, and the normalised means over envs.
    provenance: a file that says where runs not made by `commit` come from (the regime folder's README.md)."""
    scores = {(env, method): [r.score for r in records if (r.env, r.method) == (env, method)] for env in ENVS for method in METHODS}
    flags = " ".join(REGIMES[regime][0]) or "none"
    made_by = f"runs made by commit {commit[:12] or '(not recorded)'}" + (f"; others as `{provenance}` says" if provenance else "")
    lines = [f"**{regime}**: {REGIMES[regime][1]} (flags: `{flags}`; {made_by}).", "",
             "| env | method | mean | 95% interval | seeds | / expert |", "|---|---|---:|---:|---|---:|"]
    normalised = {method: [] for method in METHODS}
    for (env, method), cell in scores.items():
        if cell:
            mean, (low, high) = statistics.fmean(cell), bootstrap_ci(cell)
            if env in experts:
                normalised[method].append(expert_normalised(mean, experts[env]))
            share = f"{normalised[method][-1]:.2f}" if env in experts else "—"
            lines.append(f"| {env} | {METHOD_NAMES[method]} | {mean:.0f} | [{low:.0f}, {high:.0f}] | {seeds_text(len(cell))} | {share} |")
    lines += ["", "| env | P(A beats B) | value | 95% interval | seeds | verdict |", "|---|---|---:|---:|---|---|"]
    for env in ENVS:
        for a, b in COMPARISONS + ADDED_COMPARISONS:
            x, y = scores[env, a], scores[env, b]
            if x and y:
                low, high = probability_of_improvement_ci(x, y)
                if min(len(x), len(y)) < COMPLETE:  # the protocol's 5 seeds a cell: fewer decide nothing
                    verdict = f"undecided (fewer than {COMPLETE} seeds)"
                else:
                    verdict = "separated" if low > 0.5 or high < 0.5 else "not separated (more seeds)"
                verdict += ", exploratory (added after the runs)" if (a, b) in ADDED_COMPARISONS else ""
                lines.append(f"| {env} | P({METHOD_NAMES[a]} > {METHOD_NAMES[b]}) | {probability_of_improvement(x, y):.2f} | "
                             f"[{low:.2f}, {high:.2f}] | {seeds_text(len(x), len(y))} | {verdict} |")
    over_envs = [f"{METHOD_NAMES[m]} {statistics.fmean(v):.2f} ({len(v)} env{'s' * (len(v) > 1)})" for m, v in normalised.items() if v]
    return lines + ["", "Expert-normalised mean over envs: " + ("; ".join(over_envs) or "no expert scores") + ".", ""]


def markdown(tables: dict, empty: list, experts: dict, command: str) -> str:
    """summary.md: a header saying how it was made and what its figures mean, then one part per regime."""
    count = sum(len(records) for records, *_ in tables.values())
    lines = [
        "# The regime map: where copying the previous action becomes a shortcut, and does C2F help there?", "",
        f"Made by `{command}` from {count} per-seed results of `python -m benchmark.regimes`.", "",
        "Each score is one seed's: the mean return of its last three evaluations. Per env and method: the mean over seeds, "
        "its 95% percentile bootstrap interval (seeds drawn again with replacement, 10000 times), the seeds (n; "
        f"'incomplete' under {COMPLETE}: such intervals are too narrow to trust), and the mean as a share of the PPO "
        "expert's score on that env (" + (", ".join(f"{env} {score:.0f}" for env, score in experts.items()) or "none found")
        + "; the expert at the native rate, clean observations). P(A beats B): the probability that a seed of A scores above "
        "a seed of B (ties count 1/2; 0.5 = no difference), with a stratified bootstrap 95% interval; 'separated' when the "
        f"interval excludes 0.5 and both cells have {COMPLETE} seeds (the protocol fixed before the runs).", "",
    ] + ([f"No valid results yet: {', '.join(empty)}.", ""] if empty else [])
    for regime, (records, commit, provenance) in tables.items():
        lines += regime_tables(regime, records, experts, commit, provenance)
    return "\n".join(lines)


def plot(tables: dict, path: Path):
    """One panel per env: a group per regime, a bar per method (mean, bootstrap interval as error bar), seeds as dots."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    figure, axes = plt.subplots(1, len(ENVS), figsize=(2 + 2.4 * len(tables) * len(ENVS), 4.8), squeeze=False)
    width = 0.8 / len(METHODS)
    for axis, env in zip(axes[0], ENVS):
        for m, method in enumerate(METHODS):
            for g, (records, *_) in enumerate(tables.values()):
                cell = [r.score for r in records if (r.env, r.method) == (env, method)]
                if cell:
                    x, mean, (low, high) = g + (m - (len(METHODS) - 1) / 2) * width, statistics.fmean(cell), bootstrap_ci(cell)
                    axis.bar(x, mean, width, yerr=[[mean - low], [high - mean]], capsize=3, color=f"C{m}")
                    axis.scatter([x + width / 4] * len(cell), cell, s=9, color="0.25", zorder=3)
        axis.set_xticks(range(len(tables)), list(tables), rotation=20, ha="right")
        axis.set_title(env)
    axes[0][0].set_ylabel("return (mean of last three evaluations)")
    legend = [Patch(color=f"C{m}", label=METHOD_NAMES[method]) for m, method in enumerate(METHODS)]
    figure.legend(handles=legend, loc="lower center", ncol=len(METHODS))
    figure.suptitle("Regime map: mean over seeds, 95% bootstrap interval, seeds as dots")
    figure.tight_layout(rect=(0, 0.07, 1, 1))
    with written_atomically(path) as tmp:
        figure.savefig(tmp, dpi=120)
    plt.close(figure)


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.regime_summary", description=__doc__.split("\n\n")[0])
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR, help=f"where benchmark.regimes wrote the map (default {RESULTS_DIR})")
    parser.add_argument("--expert-runs", type=Path, default=Path("results/runs"), help="holds expert/<env>/result_seeds0.json (default results/runs)")
    parser.add_argument("--page", type=Path, nargs="?", const=PAGE,
                        help=f"also put the summary and plot into this page (alone: {PAGE}), between {PAGE_START} and {PAGE_END}")
    args = parser.parse_args(argv)
    fix = "run python -m benchmark.regimes first, or pass --results-dir"
    check_folder(args.results_dir, "results folder", fix)
    if args.page:
        aggregate.page_parts(args.page, PAGE_START, PAGE_END)  # check the markers before anything is written
    regimes = [regime for regime in REGIMES if runs_dir(regime, args.results_dir).is_dir()]
    if not regimes:  # not the folder benchmark.regimes wrote: a regime's own, results/runs, ...
        names = ", ".join(REGIMES)
        raise UsageError(f"no <regime>/runs/ folder under {args.results_dir} ({names}): pass the "
                         "folder python -m benchmark.regimes wrote (--results-dir), or run it")
    tables, empty, problems = {}, [], []
    for regime in regimes:
        records, regime_problems = collect(regime, args.results_dir)
        problems += regime_problems
        if records:
            commit, provenance = runs_dir(regime, args.results_dir) / "commit.txt", runs_dir(regime, args.results_dir).parent / "README.md"
            tables[regime] = records, commit.read_text().strip() if commit.is_file() else "", str(provenance) if provenance.is_file() else ""
        else:
            empty.append(regime)
    experts, expert_problems = expert_scores(args.expert_runs)
    for problem in problems + expert_problems:
        print(problem, file=sys.stderr)
    if not tables:
        raise UsageError(f"no valid regime results under {args.results_dir} (see above): run python -m benchmark.regimes")
    for regime, (records, *_) in tables.items():
        rows = "".join(f"{r.env},{r.method},{r.seed},{r.score:.3f}\n" for r in records)
        write_text(args.results_dir / regime / "mujoco.csv", "env,method,seed,score\n" + rows)
        aggregate.plot_curves(records, args.results_dir / regime / "curves.png", experts, title=f"Learning curves, {regime}")
    words = list(argv if argv is not None else sys.argv[1:])
    if args.page == PAGE and "--page" in words and str(PAGE) not in words:  # a bare --page: name the page it wrote
        words.insert(words.index("--page") + 1, str(PAGE))
    command = " ".join(["python -m benchmark.regime_summary", *map(str, words)])
    summary, image = markdown(tables, empty, experts, command), args.results_dir / "summary.png"
    write_text(args.results_dir / "summary.md", summary)
    plot(tables, image)
    if args.page:
        aggregate.update_page(args.page, summary, image, PAGE_START, PAGE_END, "Regime map")
    print(summary)
    print(f"wrote {', '.join(f'{args.results_dir / r}/mujoco.csv, {args.results_dir / r}/curves.png' for r in tables)}, {args.results_dir / 'summary.md'}, {image}"
          + (f", and the summary into {args.page}" if args.page else "") + (f"; left out {len(problems)} (listed above)" if problems else ""))
    return 0


if __name__ == "__main__":
    run_cli(main)
