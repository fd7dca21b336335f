"""Summarise the capacity test and the paper's Table 3 ablations on MuJoCo (native_hidden, Hopper-v4), as declared.

    python -m benchmark.table3 [--results-dir results/regimes] [--replication-dir results/regimes_replication]
        [--expert-runs results/runs]

Reads the results of the regime map's native_hidden runs (<results-dir>/native_hidden/runs/<method>/Hopper-v4/
result_seeds<S>.json: the map's methods, the capacity controls and the Table 3 rows) and of its replication
(<replication-dir>/native_hidden/runs/: C2F and BC-OH seeds 6-10), and writes
- <results-dir>/native_hidden/table3.md: the capacity test (seeds 1-10 a side, map and replication pooled) with its
  verdict by the rule declared before the runs; one row per Table 3 variant (seeds 1-5, against C2F and BC-OH seeds
  1-5) with the paper's CARLA figure, its prediction and the declared verdict; which commits and machines made the
  runs; the files left out and why;
- <results-dir>/native_hidden/table3.png: the seeds, means and intervals of every row, and of the capacity test.
Corrupt results, and results at settings other than native_hidden's and their variant's (benchmark.regime_summary.
collect checks them), are reported on stderr and in table3.md, and left out. The rules are those the README
declared before the runs (its section on capacity controls and Table 3): this tool applies them, it does not choose.
"""
import json
import statistics
import sys
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark import aggregate, regime_summary
from benchmark.paper import PAPER_TABLE3, as_flags, variant_flags
from benchmark.regimes import REGIMES, RESULTS_DIR, existing_runs_dir, recorded_commit, runs_dir
from benchmark.results import OneLineParser, UsageError, run_cli, write_text
from benchmark.stats import bootstrap_ci, expert_normalised, probability_of_improvement, probability_of_improvement_ci

REGIME, ENV = "native_hidden", "Hopper-v4"
"""where the declared tests run: velocities zeroed, Hopper (the map's C2F gain that the controls question)"""
REPLICATION_DIR = Path("results/regimes_replication")
CAPACITY_SEEDS, ROW_SEEDS = range(1, 11), range(1, 6)
"""the declared seeds: 1-10 a side in the capacity test, 1-5 a Table 3 row (and its C2F and BC-OH)"""
CAPACITY_METHODS = ["c2f", "c2f_no_coarse", "c2f_penultimate", "bc_oh"]
"""the methods of the capacity test: the only ones with seeds 6-10, and the only ones taken from the replication"""
CAPACITY_TESTS = [
    ("1. capacity", "c2f", "c2f_no_coarse", "C2F beats the control", "the control beats C2F"),
    ("2. ζ at BC-OH's capacity", "c2f_penultimate", "bc_oh", "penultimate beats BC-OH", "BC-OH beats penultimate"),
]
"""(test, A, B, verdict when P(A > B)'s interval is above 0.5, verdict when it is below): declared before the runs"""
REPORTED = [("reported, not a test", "c2f_no_coarse", "bc_oh")]
"""read beside test 1 (does the control alone beat BC-OH?), never a verdict of its own"""

NO_DIFFERENCE, WORSE, FALLS, FALLS_OR_BELOW, REPORTED_ONLY = "no difference", "worse", "falls to BC-OH", "falls to BC-OH or below", "reported only"
ROWS = [
    ("c2f", "C2F (late fusion, the paper)", None, "(the paper's model)"),
    ("c2f_middle", "middle fusion", NO_DIFFERENCE, "no difference"),
    ("c2f_early", "early fusion", NO_DIFFERENCE, "no difference"),
    ("c2f_output", "output fusion", REPORTED_ONLY, "(MuJoCo text's reading)"),
    ("c2f_penultimate", "penultimate fusion", NO_DIFFERENCE, "no difference (a fusion stage)"),
    ("c2f_feature", "feature as ζ", WORSE, "worse"),
    ("c2f_coarse_history", "BC-OH as π_φ and π_θ", FALLS, "falls to BC-OH"),
    ("c2f_coarse_history_policy_current", "BC-OH as π_φ + BC-SO as π_θ", FALLS_OR_BELOW, "falls to BC-OH or below"),
    ("c2f_no_stop_gradient", "no stop-gradient", WORSE, "worse"),
    ("c2f_two_stage", "two-stage", WORSE, "worse, a little"),
    ("c2f_no_coarse", "no coarse action", REPORTED_ONLY, "(the capacity control)"),
    ("bc_oh", "BC-OH", None, "(reference)"),
    ("bc_so", "BC-SO", None, "(reference)"),
]
"""(runner variant, Table 3's row name, the declared rule its verdict follows or None, the prediction as declared),
in the declaration's order (the paper lists early fusion before middle), then the two references"""
METHODS = [method for method, *_ in ROWS]
NAMES = {method: name for method, name, *_ in ROWS}
SHORT_NAMES = {"c2f": "C2F", "c2f_no_coarse": "no-coarse control", "c2f_penultimate": "penultimate fusion", "bc_oh": "BC-OH"}
"""the capacity test's names of its four sides"""


def seed_ranges(seeds) -> str:
    """[1, 2, 3, 5, 6, 9] -> "1–3, 5–6, 9": the seeds of a run set in few characters."""
    seeds, parts = sorted(seeds), []
    for seed in seeds:
        if parts and seed == parts[-1][1] + 1:
            parts[-1][1] = seed
        else:
            parts.append([seed, seed])
    return ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in parts) or "none"


def gather(results_dir: Path, replication_dir: Path):
    """(map records, replication records, problems): the valid Hopper results of the two folders at the regime's
    settings (regime_summary.collect checks them), each at a seed declared for its method; a seed that is in both
    folders counts from the map. The map's Walker2d runs are valid but not part of these tests, and are not listed."""
    records, problems = regime_summary.collect(REGIME, results_dir, METHODS)
    replication, replication_problems = regime_summary.collect(REGIME, replication_dir, METHODS)
    problems += replication_problems
    kept = {"map": [], "replication": []}
    for source, found in (("map", records), ("replication", replication)):
        for record in (r for r in found if r.env == ENV):
            declared = CAPACITY_SEEDS if record.method in CAPACITY_METHODS else ROW_SEEDS
            if source == "replication" and record.method not in CAPACITY_METHODS:
                problems.append(f"left out {record.path}: the replication counts only for the capacity test ({', '.join(CAPACITY_METHODS)})")
            elif record.seed not in declared:
                problems.append(f"left out {record.path}: seed {record.seed} is not among the seeds declared for {record.method} "
                                f"({seed_ranges(declared)})")
            elif source == "replication" and any((r.method, r.seed) == (record.method, record.seed) for r in kept["map"]):
                problems.append(f"left out {record.path}: seed {record.seed} of {record.method} is in the map too (the map's counts)")
            else:
                kept[source].append(record)
    return kept["map"], kept["replication"], problems


def scores_of(records: list, method: str, seeds) -> list:
    return [r.score for r in sorted(records, key=lambda r: r.seed) if r.method == method and r.seed in seeds]


def interval_text(low: float, high: float, digits=2) -> str:
    return f"[{low:.{digits}f}, {high:.{digits}f}]"


def capacity_verdict(x: list, y: list, above: str, below: str) -> str:
    """The declared rule of a capacity test on seeds 1-10 a side; no verdict while either side has fewer."""
    if min(len(x), len(y)) < len(CAPACITY_SEEDS):
        return f"incomplete (n={len(x)} vs {len(y)} of {len(CAPACITY_SEEDS)}): no verdict yet"
    low, high = probability_of_improvement_ci(x, y)
    return above if low > 0.5 else below if high < 0.5 else "0.5 inside the interval: not decided"


def row_verdict(rule: str, vs_c2f: tuple, vs_bc_oh: tuple) -> str:
    """The declared verdict of a Table 3 row from the 95% intervals of P(row > C2F) and P(row > BC-OH).
    'no difference' is confirmed by an interval that holds 0.5 and refuted by one that excludes it; the other
    predictions are refuted when the row is separated above C2F, and 'not confirmed' when 5 seeds cannot tell."""
    if rule == REPORTED_ONLY:
        return "reported only"
    below_c2f, above_c2f = vs_c2f[1] < 0.5, vs_c2f[0] > 0.5
    if rule == NO_DIFFERENCE:
        return "refuted" if below_c2f or above_c2f else "confirmed"
    confirmed = {WORSE: below_c2f,
                 FALLS: below_c2f and vs_bc_oh[0] <= 0.5 <= vs_bc_oh[1],
                 FALLS_OR_BELOW: below_c2f and vs_bc_oh[0] <= 0.5}[rule]
    return "confirmed" if confirmed else "refuted" if above_c2f else "not confirmed"


def comparison(x: list, y: list) -> str:
    if not x or not y:
        return "—"
    return f"{probability_of_improvement(x, y):.2f} {interval_text(*probability_of_improvement_ci(x, y))}"


def capacity_lines(pooled: list, expert) -> list:
    """The capacity block: its tests with the declared verdicts, then each side's seeds, mean and interval."""
    lines = ["## The capacity test (declared before its runs; it decides)", "",
             f"Seeds {seed_ranges(CAPACITY_SEEDS)} a side: C2F and BC-OH seeds 1–5 from the map, 6–10 from the replication; "
             "the controls from the map. A verdict when the 95% interval of P(A > B) excludes 0.5 and both sides have "
             f"{len(CAPACITY_SEEDS)} seeds.", "",
             "| test | P(A > B) | value | 95% interval | seeds | verdict |", "|---|---|---:|---:|---|---|"]
    for test, a, b, *verdicts in CAPACITY_TESTS + [(label, a, b, None, None) for label, a, b in REPORTED]:
        x, y = scores_of(pooled, a, CAPACITY_SEEDS), scores_of(pooled, b, CAPACITY_SEEDS)
        name = f"P({SHORT_NAMES[a]} > {SHORT_NAMES[b]})"
        if not x or not y:
            lines.append(f"| {test} | {name} | — | — | n={len(x)} vs {len(y)} | no runs yet |")
            continue
        complete = min(len(x), len(y)) >= len(CAPACITY_SEEDS)
        verdict = capacity_verdict(x, y, *verdicts) if verdicts[0] else "reported, not a test" + ("" if complete else " (incomplete)")
        lines.append(f"| {test} | {name} | {probability_of_improvement(x, y):.2f} | "
                     f"{interval_text(*probability_of_improvement_ci(x, y))} | n={len(x)} vs {len(y)} | {verdict} |")
    lines += ["", "| method | seeds | n | mean | 95% interval | / expert | per seed |", "|---|---|---:|---:|---:|---:|---|"]
    for method in CAPACITY_METHODS:
        cell = [r for r in sorted(pooled, key=lambda r: r.seed) if r.method == method and r.seed in CAPACITY_SEEDS]
        if not cell:
            lines.append(f"| {SHORT_NAMES[method]} (`{method}`) | none | 0 | — | — | — | no runs yet |")
            continue
        scores = [r.score for r in cell]
        mean = statistics.fmean(scores)
        share = f"{expert_normalised(mean, expert):.2f}" if expert else "—"
        lines.append(f"| {SHORT_NAMES[method]} (`{method}`) | {seed_ranges(r.seed for r in cell)} | {len(cell)} | {mean:.0f} | "
                     f"{interval_text(*bootstrap_ci(scores), digits=0)} | {share} | {', '.join(f'{s:.0f}' for s in scores)} |")
    return lines + [""]


def row_lines(records: list, expert) -> list:
    """The Table 3 block: one line per row, seeds 1-5, against C2F and BC-OH seeds 1-5 (the map's)."""
    c2f, bc_oh = scores_of(records, "c2f", ROW_SEEDS), scores_of(records, "bc_oh", ROW_SEEDS)
    lines = ["## Table 3 on MuJoCo (declared before its runs)", "",
             f"Seeds {seed_ranges(ROW_SEEDS)} a row, each against C2F and BC-OH seeds {seed_ranges(ROW_SEEDS)} (the map's runs; "
             "the replication is not pooled here). Flags: what the runner adds to `c2f_table3.py` for the row (C2F's row is "
             "`c2f.py`, BC-OH and BC-SO are their own files). CARLA: the paper's Table 3, %success (mean ± std). Verdicts, as declared: 'no difference' is "
             "confirmed if the interval of P(row > C2F) holds 0.5 and refuted if it excludes it; 'worse' is confirmed if it is "
             "below 0.5, refuted if above, otherwise not confirmed; 'falls to BC-OH' needs it below 0.5 and 0.5 inside the "
             "interval of P(row > BC-OH); 'falls to BC-OH or below' needs it below 0.5 and P(row > BC-OH) not above 0.5. "
             f"A row, C2F or BC-OH with fewer than {regime_summary.COMPLETE} seeds gives no verdict.", "",
             "| row (runner variant) | flags | n | mean | 95% interval | / expert | P(row > C2F) [95%] | P(row > BC-OH) [95%] "
             "| CARLA %success | prediction | verdict |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---|---|"]
    for method, name, rule, prediction in ROWS:
        scores = scores_of(records, method, ROW_SEEDS)
        flags = " ".join(as_flags(variant_flags(method))) if method.startswith("c2f_") else "(default)" if method == "c2f" else "—"
        carla = "{:.1f} ± {:.1f}".format(*PAPER_TABLE3[method]) if method in PAPER_TABLE3 else "—"
        head = f"| {name} (`{method}`) | {f'`{flags}`' if flags.startswith('--') else flags} |"
        if not scores:
            lines.append(f"{head} no runs yet | — | — | — | — | — | {carla} | {prediction} | no runs yet |")
            continue
        mean = statistics.fmean(scores)
        share = f"{expert_normalised(mean, expert):.2f}" if expert else "—"
        vs_c2f, vs_bc_oh = (comparison(scores, c2f) if method != "c2f" else "—"), (comparison(scores, bc_oh) if method != "bc_oh" else "—")
        if rule is None:
            verdict = "—"
        elif min(len(scores), len(c2f), len(bc_oh)) < regime_summary.COMPLETE:
            verdict = f"incomplete (n={len(scores)} of {regime_summary.COMPLETE}): no verdict" if len(scores) < regime_summary.COMPLETE \
                else "no verdict (C2F or BC-OH incomplete)"
        else:
            verdict = row_verdict(rule, probability_of_improvement_ci(scores, c2f), probability_of_improvement_ci(scores, bc_oh))
        lines.append(f"{head} {regime_summary.seeds_text(len(scores))} | {mean:.0f} | {interval_text(*bootstrap_ci(scores), digits=0)} | "
                     f"{share} | {vs_c2f} | {vs_bc_oh} | {carla} | {prediction} | {verdict} |")
    return lines + [""]


def commits_text(folders: dict) -> str:
    """Which commit made which methods' runs in each folder, as benchmark.regimes recorded them (recorded_commit: a
    method's own commit.txt, or the regime's runs/commit.txt for the map's first methods)."""
    parts = []
    for source, (folder, records) in folders.items():
        by_commit = {}
        for method in dict.fromkeys(r.method for r in records):
            path = recorded_commit(folder, method)
            where = "runs/commit.txt" if path == folder / "commit.txt" else "runs/<method>/commit.txt"
            commit = f"`{path.read_text().strip()[:12]}` ({where})" if path else "not recorded"
            by_commit.setdefault(commit, []).append(method)
        if by_commit:
            parts.append(f"{source} (`{folder}`): " + "; ".join(f"{commit}: {', '.join(methods)}" for commit, methods in by_commit.items()))
    return ". ".join(parts) or "none"


def machines_text(records: list) -> str:
    """The machines the runs were made on (the `machine` key of a result: cpu and cpu_capability), with the seeds of
    each method there; results made before the key existed are 'not recorded'."""
    by_machine = {}
    for record in records:
        machine = json.loads(record.path.read_text()).get("machine")
        where = f"{machine.get('cpu')}, {machine.get('cpu_capability')}" if isinstance(machine, dict) else "not recorded"
        by_machine.setdefault(where, {}).setdefault(record.method, []).append(record.seed)
    return "; ".join(f"{where}: " + ", ".join(f"{method} {seed_ranges(seeds)}" for method, seeds in methods.items())
                     for where, methods in sorted(by_machine.items(), key=lambda item: item[0] == "not recorded"))


def markdown(records: list, replication: list, folders: dict, expert, problems: list, command: str) -> str:
    """table3.md: how it was made (command, commits, machines, unpaired), the capacity test, Table 3, what was left out."""
    everything = records + replication
    lines = [
        f"# Table 3 on MuJoCo and the capacity test ({REGIME}, {ENV})", "",
        f"Made by `{command}` from {len(everything)} per-seed results of `python -m benchmark.regimes`.", "",
        f"- Settings: the paper's protocol with `{' '.join(REGIMES[REGIME][0])}` ({REGIMES[REGIME][1]}), and each row's flags; "
        f"{ENV} only (the map's Walker2d runs are not part of these tests).",
        f"- Commits of the runs: {commits_text(folders)}.",
        f"- Machines (cpu, cpu_capability of each result): {machines_text(everything) or 'none'}.",
        "- Unpaired comparisons, as declared: the map's runs and the controls were made on different CPUs, whose MKL "
        "kernels give the same seed different demos, so seeds are not paired; P(A > B) compares every seed of A with "
        "every seed of B.",
        "- Each score is one seed's: the mean return of its last three evaluations. Mean over seeds with its 95% "
        "percentile bootstrap interval; / expert: the mean as a share of the PPO expert's score on Hopper-v4 ("
        + (f"{expert:.0f}" if expert else "not found") + "). P(A > B): the probability that a seed of A scores above "
        "a seed of B (ties 1/2; 0.5 = no difference), with a stratified bootstrap 95% interval.", "",
    ]
    lines += capacity_lines(everything, expert) + row_lines(records, expert)
    lines += ["## Left out", ""] + ([f"- {problem}" for problem in problems] or ["none"]) + [""]
    return "\n".join(lines)


def plot(records: list, replication: list, path: Path):
    """Left: per Table 3 row its seeds 1-5 as dots and its mean with the 95% interval, C2F's and BC-OH's means as
    lines. Right: the capacity test's four sides on seeds 1-10."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (rows_axis, capacity_axis) = plt.subplots(1, 2, figsize=(13, 6.4), gridspec_kw={"width_ratios": [2.6, 1]})

    def panel(axis, cells, title):
        for y, (label, scores) in enumerate(cells):
            if scores:
                mean, (low, high) = statistics.fmean(scores), bootstrap_ci(scores)
                axis.scatter(scores, [y + 0.18] * len(scores), s=12, color="0.35", zorder=3)
                axis.errorbar([mean], [y], xerr=[[mean - low], [high - mean]], fmt="D", color="C0", capsize=3, markersize=5)
            else:
                axis.text(0.02, y, "no runs yet", transform=axis.get_yaxis_transform(), va="center", fontsize=8, color="0.4")
        axis.set_yticks(range(len(cells)), [label for label, _ in cells], fontsize=8)
        axis.set_ylim(len(cells) - 0.5, -0.6)
        axis.set_xlabel("return (mean of last three evaluations)")
        axis.set_title(title, fontsize=10)
        axis.grid(axis="x", alpha=0.3)

    cells = [(f"{name} (n={len(scores_of(records, method, ROW_SEEDS))})", scores_of(records, method, ROW_SEEDS)) for method, name, *_ in ROWS]
    panel(rows_axis, cells, f"Table 3 rows, seeds {seed_ranges(ROW_SEEDS)}: seeds (dots), mean and 95% interval")
    for method, style in (("c2f", "--"), ("bc_oh", ":")):
        scores = scores_of(records, method, ROW_SEEDS)
        if scores:
            rows_axis.axvline(statistics.fmean(scores), color="C3" if method == "c2f" else "C2", linestyle=style, label=f"{NAMES[method]} mean")
    if rows_axis.get_legend_handles_labels()[0]:
        rows_axis.legend(fontsize=8, loc="lower right")
    pooled = records + replication
    cells = [(f"{SHORT_NAMES[m]} (n={len(scores_of(pooled, m, CAPACITY_SEEDS))})", scores_of(pooled, m, CAPACITY_SEEDS)) for m in CAPACITY_METHODS]
    panel(capacity_axis, cells, f"Capacity test, seeds {seed_ranges(CAPACITY_SEEDS)}")
    tests = [(a, b, scores_of(pooled, a, CAPACITY_SEEDS), scores_of(pooled, b, CAPACITY_SEEDS)) for _, a, b, *_ in CAPACITY_TESTS]
    capacity_axis.set_xlabel("return\n" + "\n".join(f"P({SHORT_NAMES[a]} > {SHORT_NAMES[b]}) = {comparison(x, y)}" for a, b, x, y in tests), fontsize=8)
    figure.suptitle(f"{REGIME}, {ENV}: Table 3 ablations and the capacity test")
    figure.tight_layout()
    aggregate.save_figure(figure, path)


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.table3", description=__doc__.split("\n\n")[0])
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR, help=f"the regime map, with the controls and rows (default {RESULTS_DIR})")
    parser.add_argument("--replication-dir", type=Path, default=REPLICATION_DIR, help=f"C2F and BC-OH seeds 6-10 (default {REPLICATION_DIR})")
    parser.add_argument("--expert-runs", type=Path, default=Path("results/runs"), help="holds expert/<env>/result_seeds0.json (default results/runs)")
    args = parser.parse_args(argv)
    existing_runs_dir(REGIME, args.results_dir)
    # A mistyped folder would leave the capacity test at the map's seeds, with only a warning.
    existing_runs_dir(REGIME, args.replication_dir, "--replication-dir", "--methods bc_oh c2f --envs Hopper-v4 --seeds 6 7 8 9 10")
    records, replication, problems = gather(args.results_dir, args.replication_dir)
    experts, expert_problems = regime_summary.expert_scores(args.expert_runs, [ENV])
    problems += expert_problems
    for problem in problems:
        print(problem, file=sys.stderr)
    if not records and not replication:
        where = f"{args.results_dir} or {args.replication_dir}"
        if any(problem.startswith("left out ") for problem in problems):
            raise UsageError(f"no valid {REGIME} {ENV} results under {where} (see above)")
        raise UsageError(f"no {REGIME} {ENV} results under {where}: pass --results-dir, the folder "
                         "python -m benchmark.regimes wrote them into")
    folders = {"map": (runs_dir(REGIME, args.results_dir), records), "replication": (runs_dir(REGIME, args.replication_dir), replication)}
    command = " ".join(["python -m benchmark.table3", *(argv if argv is not None else sys.argv[1:])])
    table, out = markdown(records, replication, folders, experts.get(ENV), problems, command), args.results_dir / REGIME
    write_text(out / "table3.md", table)
    plot(records, replication, out / "table3.png")
    print(table)
    print(f"wrote {out / 'table3.md'}, {out / 'table3.png'}" + (f"; left out {len(problems)} (listed above)" if problems else ""))
    return 0


if __name__ == "__main__":
    run_cli(main)
