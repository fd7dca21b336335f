"""Summarise the paper's baselines in native_hidden and the two Walker2d capacity controls, as declared.

    python -m benchmark.regime_baselines [--results-dir results/regimes] [--expert-runs results/runs]

Reads <results-dir>/native_hidden/runs/<method>/<env>/result_seeds<S>.json for the map's BC-SO, BC-OH and C2F, the
baselines (fca, keyframe, history_dropout, average_ensemble, dagger) and the no-coarse control (c2f_no_coarse), on
Hopper-v4 and Walker2d-v4, seeds 1-5; and <results-dir>/fs1_noise/runs/{c2f,bc_oh,c2f_no_coarse}/Walker2d-v4 (the
fs1_noise control), seeds 1-5. Writes
- <results-dir>/native_hidden/table2.md: per env every method's mean, its 95% bootstrap interval, its seeds, its share
  of the expert, the paper's Table 2 value beside it (the paper's setting), P(method > BC-OH) and P(method > BC-SO);
  the declared comparisons (each baseline against BC-OH, C2F against each baseline, C2F against the two Walker2d
  controls) with their verdicts by the declared rule; how many of the 22 separate, and the declared reading of that
  count; the command, the commits and the machines of the runs; the files left out and why;
- <results-dir>/native_hidden/table2.png: per env (and Walker2d fs1_noise) each method's seeds, mean and interval.
The rules are those docs/regimes.md declared before the runs (its section "Baselines in `native_hidden`, and two more
capacity controls"): this tool applies them, it does not choose. A comparison whose sides do not both have their 5
declared seeds gives no verdict.
"""
import statistics
import sys
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark import aggregate, fca_compare, regime_summary
from benchmark.paper import METHOD_NAMES
from benchmark.regimes import REGIMES, RESULTS_DIR, existing_runs_dir, runs_dir
from benchmark.results import EXPERT, OneLineParser, UsageError, run_cli, write_text
from benchmark.stats import bootstrap_ci, expert_normalised, probability_of_improvement, probability_of_improvement_ci
from benchmark.table3 import commits_text, comparison, interval_text, machines_text, scores_of, seed_ranges

REGIME, CONTROL_REGIME = "native_hidden", "fs1_noise"
"""where the baselines run (velocities zeroed), and the regime of the second Walker2d control (frame skip 1, noise)"""
ENVS, CONTROL_ENV = ["Hopper-v4", "Walker2d-v4"], "Walker2d-v4"
SEEDS = range(1, 6)
"""the declared seeds of every cell (the Hopper control has 10: seeds 1-5 count here)"""
COMPLETE = len(SEEDS)
BASELINES = ["fca", "keyframe", "history_dropout", "average_ensemble", "dagger"]
"""the paper's anti-copycat baselines, each at its file's defaults"""
CONTROL = "c2f_no_coarse"
METHODS = ["bc_so", "bc_oh", "c2f", *BASELINES, CONTROL]
"""the rows of each env's table in native_hidden"""
CONTROL_METHODS = ["bc_oh", "c2f", CONTROL]
"""what the fs1_noise control needs: C2F against it, and it against BC-OH (reported)"""
KNOWN = [method for method in METHOD_NAMES if method != EXPERT]
"""every method a regime folder may hold (the map's, the controls, the Table 3 rows): valid runs of those not part of
this comparison are passed over silently, as benchmark.table3 passes over the map's Walker2d runs"""
NAMES = {**METHOD_NAMES, "c2f": "C2F", CONTROL: "no-coarse control"}
BEATS, BELOW, TIE = "beats", "falls below", "ties"
"""the declared outcomes of P(A > B): interval above 0.5, below 0.5, holding 0.5"""
RESOURCES = "10,000 resamples, seed 0"


def gather(results_dir: Path):
    """({(regime, env): records at seeds 1-5}, problems): the valid results of the cells of this comparison (their
    regime's settings, which regime_summary.collect checks), and a line per file of those cells left out, including
    valid seeds outside 1-5 (one line per cell)."""
    cells, problems = {}, []
    for regime, envs, methods in ((REGIME, ENVS, METHODS), (CONTROL_REGIME, [CONTROL_ENV], CONTROL_METHODS)):
        folder = runs_dir(regime, results_dir)
        for env in envs:
            cells[regime, env] = []
        if not folder.is_dir():
            problems.append(f"no {folder}: its cells ({', '.join(methods)} on {', '.join(envs)}) have no runs yet")
            continue
        records, found = regime_summary.collect(regime, results_dir, KNOWN)
        ours = [f"{folder / method / env}/" for method in methods for env in envs]
        problems += [problem for problem in found if any(prefix in problem for prefix in ours)]
        unused = {}
        for record in records:
            if record.method in methods and record.env in envs:
                if record.seed in SEEDS:
                    cells[regime, record.env].append(record)
                else:
                    unused.setdefault((record.method, record.env), []).append(record.seed)
        problems += [f"left out {folder / method / env} seeds {seed_ranges(seeds)}: valid, but seeds {seed_ranges(SEEDS)} "
                     f"count here (declared)" for (method, env), seeds in unused.items()]
    return cells, problems


def outcome(x: list, y: list):
    """The declared rule: BEATS when the 95% interval of P(A > B) lies above 0.5, BELOW when it lies below, TIE when
    it holds 0.5; None while either side has fewer than its 5 declared seeds."""
    if min(len(x), len(y)) < COMPLETE:
        return None
    low, high = probability_of_improvement_ci(x, y)
    return BEATS if low > 0.5 else BELOW if high < 0.5 else TIE


def incomplete_text(sides: dict) -> str:
    """{name: scores} -> 'incomplete (FCA 3 of 5): no verdict', naming every side without its 5 seeds."""
    short = ", ".join(f"{name} {len(scores)} of {COMPLETE}" for name, scores in sides.items() if len(scores) < COMPLETE)
    return f"incomplete ({short}): no verdict"


def verdict(a: str, b: str, x: list, y: list) -> str:
    """The verdict of P(a > b) as a sentence ('FCA beats BC-OH', 'tie: 0.5 inside the interval'), or why none."""
    result = outcome(x, y)
    if result is None:
        return incomplete_text({NAMES[a]: x, NAMES[b]: y})
    return "tie: 0.5 inside the interval" if result == TIE else f"{NAMES[a]} {result} {NAMES[b]}"


def control_reading(c2f: list, control: list, bc_oh: list) -> str:
    """Comparison 3, read as the capacity test was: P(C2F > control) above 0.5, the coarse action helps at equal
    capacity; holding 0.5, capacity is not ruled out, and if P(control > BC-OH) is also above 0.5 (reported, not a
    test) the gain is at least partly the network's."""
    result = outcome(c2f, control)
    if result is None:
        return incomplete_text({"C2F": c2f, "control": control})
    if result == BEATS:
        return "C2F beats the control: at equal capacity the coarse action helps here"
    if result == BELOW:
        return "C2F falls below the control (its interval is below 0.5)"
    reported = outcome(control, bc_oh)
    if reported is None:
        tail = f"P(control > BC-OH) is {incomplete_text({'control': control, 'BC-OH': bc_oh}).removesuffix(': no verdict')}"
    elif reported == BEATS:
        tail = "and the control beats BC-OH (reported): the gain is at least partly the network's"
    else:
        tail = "the control does not beat BC-OH (reported)"
    return f"0.5 inside: capacity is not ruled out; {tail}"


def comparisons() -> list:
    """The 22 declared comparisons: (number, regime, env, A, B), in the declaration's order."""
    first = [(1, REGIME, env, baseline, "bc_oh") for env in ENVS for baseline in BASELINES]
    second = [(2, REGIME, env, "c2f", baseline) for env in ENVS for baseline in BASELINES]
    third = [(3, regime, CONTROL_ENV, "c2f", CONTROL) for regime in (REGIME, CONTROL_REGIME)]
    return first + second + third


def sides(cells: dict, regime: str, env: str, a: str, b: str):
    return scores_of(cells[regime, env], a, SEEDS), scores_of(cells[regime, env], b, SEEDS)


def reading(cells: dict) -> list:
    """The declared multiple-comparison reading: the count of separated comparisons out of the 22, then, of the 20 of
    comparisons 1 and 2, which are a baseline's result (the same comparison separated in the same direction on both
    envs) and which are leads (a separated one without its pair)."""
    results = {key: outcome(*sides(cells, *key[1:])) for key in comparisons()}
    complete = [key for key, result in results.items() if result is not None]
    separated = [key for key in complete if results[key] != TIE]
    tested = [key for key in separated if key[0] in (1, 2)]
    lines = [f"- **Separated: {len(separated)} of the 22** (comparisons 1 and 2: {len(tested)} of 20; comparison 3: "
             f"{len(separated) - len(tested)} of 2). With their 5 seeds a side: {len(complete)} of the 22; the other "
             f"{22 - len(complete)} give no verdict yet" + (", so this reading is not final." if len(complete) < 22 else ".")]
    findings, leads = [], []
    for number in (1, 2):
        for baseline in BASELINES:
            a, b = ("c2f", baseline) if number == 2 else (baseline, "bc_oh")
            by_env = {env: results[number, REGIME, env, a, b] for env in ENVS}
            if by_env[ENVS[0]] == by_env[ENVS[1]] in (BEATS, BELOW):
                findings.append(f"  - {NAMES[baseline]}'s result (comparison {number}): {NAMES[a]} {by_env[ENVS[0]]} {NAMES[b]} "
                                "on both envs.")
                continue
            for env, other in ((ENVS[0], ENVS[1]), (ENVS[1], ENVS[0])):
                if by_env[env] in (BEATS, BELOW):
                    there = "no verdict yet" if by_env[other] is None else f"{NAMES[a]} {by_env[other]} {NAMES[b]}"
                    leads.append(f"  - a lead (comparison {number}, {env}): {NAMES[a]} {by_env[env]} {NAMES[b]}; on {other}: {there}.")
    lines.append("- **Read as declared** (comparisons 1 and 2): a single separated comparison of the 20 is a lead, not a "
                 "finding; two or more in the same direction for the same baseline (both envs) are that baseline's result. Applied "
                 "per comparison: its verdict the same way on both envs is the baseline's result; any other separated one "
                 "is a lead.")
    lines += findings or ["  - no baseline's result: no comparison separated the same way on both envs."]
    lines += leads or ["  - no lead: no other comparison of the 20 separated."]
    return lines


def share(mean: float, experts: dict, env: str) -> str:
    return f"{expert_normalised(mean, experts[env]):.2f}" if env in experts else "—"


def method_table(records: list, methods: list, experts: dict, env: str, paper: bool) -> list:
    """Per method: seeds, mean, its 95% interval, the share of the expert, (the paper's Table 2 cell), P(method > BC-OH)
    and P(method > BC-SO) (reported, each with its 95% interval)."""
    bc_oh, bc_so = scores_of(records, "bc_oh", SEEDS), scores_of(records, "bc_so", SEEDS)
    head = "| method | seeds | mean | 95% interval | / expert |" + (" paper's Table 2 (paper's setting) |" if paper else "")
    lines = [head + " P(method > BC-OH) [95%] |" + (" P(method > BC-SO) [95%] |" if "bc_so" in methods else ""),
             "|---|---|---:|---:|---:|" + ("---:|" if paper else "") + "---:|" + ("---:|" if "bc_so" in methods else "")]
    for method in methods:
        scores = scores_of(records, method, SEEDS)
        seeds = [r.seed for r in records if r.method == method]
        count = f"{seed_ranges(seeds)} (n={len(scores)})" if len(scores) >= COMPLETE else f"incomplete ({len(scores)} of {COMPLETE}): no verdict"
        if scores:
            mean = statistics.fmean(scores)
            cells = [count, f"{mean:.0f}", interval_text(*bootstrap_ci(scores), digits=0), share(mean, experts, env)]
        else:
            cells = [count, "—", "—", "—"]
        if paper:
            cell = aggregate.paper_cell(method, env)
            cells.append(aggregate.format_cell(*cell) if cell else "—")
        cells.append(comparison(scores, bc_oh) if method != "bc_oh" else "—")
        if "bc_so" in methods:
            cells.append(comparison(scores, bc_so) if method != "bc_so" else "—")
        lines.append(f"| {NAMES[method]} (`{method}`) | " + " | ".join(cells) + " |")
    return lines + [""]


def comparison_lines(cells: dict) -> list:
    """The declared comparisons 1 to 3 with their verdicts, and what is reported beside them."""
    lines = ["## The declared comparisons", "",
             "Each is P(A > B), the chance that a seed of A scores above a seed of B (ties count half), with its 95% "
             f"stratified percentile-bootstrap interval ({RESOURCES}). A beats B when the interval lies above 0.5, falls "
             "below B when it lies below 0.5, and ties when it holds 0.5; no verdict while a side has fewer than its "
             f"{COMPLETE} seeds.", ""]
    titles = {1: "### 1. Each baseline against BC-OH (10)", 2: "### 2. C2F against each baseline (10)"}
    for number in (1, 2):
        lines += [titles[number], "", "| env | P(A > B) | value | 95% interval | seeds | verdict |", "|---|---|---:|---:|---|---|"]
        for _, regime, env, a, b in [key for key in comparisons() if key[0] == number]:
            x, y = sides(cells, regime, env, a, b)
            value = [f"{probability_of_improvement(x, y):.2f}", interval_text(*probability_of_improvement_ci(x, y))] if x and y else ["—", "—"]
            lines.append(f"| {env} | P({NAMES[a]} > {NAMES[b]}) | {value[0]} | {value[1]} | n={len(x)} vs {len(y)} | {verdict(a, b, x, y)} |")
        lines.append("")
    lines += ["### 3. The two Walker2d capacity controls (2)", "",
              "Read as the capacity test was: P(C2F > control) above 0.5, at equal capacity the coarse action helps there; "
              "holding 0.5, capacity is not ruled out, and if P(control > BC-OH) is also above 0.5 (reported, not a test), "
              "the gain is at least partly the network's.", "",
              "| regime | P(C2F > control) | 95% interval | seeds | reading | P(control > BC-OH) [95%], reported |",
              "|---|---:|---:|---|---|---:|"]
    for _, regime, env, a, b in [key for key in comparisons() if key[0] == 3]:
        c2f, control = sides(cells, regime, env, a, b)
        bc_oh = scores_of(cells[regime, env], "bc_oh", SEEDS)
        value = [f"{probability_of_improvement(c2f, control):.2f}", interval_text(*probability_of_improvement_ci(c2f, control))] \
            if c2f and control else ["—", "—"]
        lines.append(f"| {env} `{regime}` | {value[0]} | {value[1]} | n={len(c2f)} vs {len(control)} | "
                     f"{control_reading(c2f, control, bc_oh)} | {comparison(control, bc_oh)} (n={len(control)} vs {len(bc_oh)}) |")
    hopper = cells[REGIME, "Hopper-v4"]
    control, bc_oh = scores_of(hopper, CONTROL, SEEDS), scores_of(hopper, "bc_oh", SEEDS)
    lines += ["", "### Reported, not tested", "",
              f"- P(no-coarse control > BC-OH) on Hopper-v4 `{REGIME}`, seeds {seed_ranges(SEEDS)}: {comparison(control, bc_oh)} "
              f"(n={len(control)} vs {len(bc_oh)}).",
              "- P(baseline > BC-SO), the means with their 95% bootstrap intervals and the shares of the expert: the tables above.", ""]
    return lines


def markdown(cells: dict, experts: dict, problems: list, command: str, results_dir: Path,
             adversary: dict) -> str:
    """table2.md: how it was made, the per-env tables, the declared comparisons, the count and its reading, left out."""
    everything = [record for records in cells.values() for record in records]
    folders = {regime: (runs_dir(regime, results_dir), [r for (g, _), records in cells.items() if g == regime for r in records])
               for regime in (REGIME, CONTROL_REGIME)}
    machines = [f"{env} `{regime}`: {machines_text(records)}" for (regime, env), records in cells.items() if records]
    lines = [
        f"# The paper's baselines where the history is needed ({REGIME}), and two Walker2d capacity controls", "",
        f"Made by `{command}` from {len(everything)} per-seed results of `python -m benchmark.regimes`, by the rules "
        "declared before the runs (docs/regimes.md, \"Baselines in `native_hidden`, and two more capacity controls\").", "",
        f"- Settings: the paper's protocol with `{' '.join(REGIMES[REGIME][0])}` ({REGIMES[REGIME][1]}); the second control "
        f"with `{' '.join(REGIMES[CONTROL_REGIME][0])}` ({REGIMES[CONTROL_REGIME][1]}). Seeds {seed_ranges(SEEDS)} a cell.",
        f"- Commits of the runs: {commits_text(folders)}.",
        f"- Machines (cpu, cpu_capability of each result): {'; '.join(machines) or 'none'}.",
        "- Unpaired comparisons, as declared: the map's runs were made on another CPU, so a seed does not share its demos "
        "across machines; P(A > B) compares every seed of A with every seed of B.",
        "- Each score is one seed's: the mean return of its last three evaluations. Mean over seeds with its 95% percentile "
        f"bootstrap interval ({RESOURCES}); / expert: the mean as a share of the PPO expert's score ("
        + (", ".join(f"{env} {experts[env]:.0f}" for env in ENVS if env in experts) or "not found") + "). The paper's "
        "Table 2 cell (mean ± std, 3 seeds) is at the paper's setting (`native_noise`), not this regime; the paper has no "
        "Walker2d.", "",
    ]
    about = ["P(method > BC-OH) and P(method > BC-SO): reported, not tests (the declared comparisons are below), with their "
             f"95% intervals. A cell with fewer than its {COMPLETE} declared seeds reads incomplete.", ""]
    for env in ENVS:
        lines += [f"## {env}, `{REGIME}`", ""] + about + method_table(cells[REGIME, env], METHODS, experts, env, paper=True)
    lines += [f"## {CONTROL_ENV}, `{CONTROL_REGIME}` (the second control)", ""]
    lines += method_table(cells[CONTROL_REGIME, CONTROL_ENV], CONTROL_METHODS, experts, CONTROL_ENV, paper=False)
    lines += comparison_lines(cells)
    lines += ["## How many separated, and what that means", ""] + reading(cells) + [""]
    lines += adversary_lines(adversary)
    lines += ["## Left out", ""] + ([f"- {problem}" for problem in problems] or ["none"]) + [""]
    return "\n".join(lines)


def adversary_runs(results_dir: Path) -> tuple:
    """({env: {seed: (score, adversary curve)}} of FCA's finished seeds 1-5 in native_hidden, and
    a line per seed of those left out (fca_compare.runs)."""
    found = {}
    problems = []
    for env in ENVS:
        found[env], more = fca_compare.runs(runs_dir(REGIME, results_dir), env, SEEDS)
        problems += more
    return found, problems


def adversary_lines(adversary: dict) -> list:
    """FCA's adversary over training in native_hidden (reported, not a test): per env, from the logs of its finished
    seeds 1-5, the range of each seed's largest adversary error and how many seeds exceed the bound that FCA's Table 2
    cells declared for divergence (fca_compare.DIVERGED_ABOVE: predictions outside the action bounds)."""
    lines = ["## FCA's adversary (reported, not a test)", "",
             f"Each seed's largest logged adversary error (D's mean error over an epoch); a seed diverges above "
             f"{fca_compare.DIVERGED_ABOVE:g}, the rule FCA's Table 2 cells declared (docs/regimes.md).", "",
             f"| env | FCA mean ± std (seeds) | largest adversary error, range over seeds | seeds above "
             f"{fca_compare.DIVERGED_ABOVE:g} |", "|---|---:|---:|---:|"]
    for env in ENVS:
        lines.append(f"| {env} | {fca_compare.row(adversary[env])} |")
    return lines + [""]


def plot(cells: dict, path: Path):
    """One panel per env of native_hidden and one for Walker2d fs1_noise: per method its seeds as dots and its mean
    with the 95% interval; BC-OH's and C2F's means as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(REGIME, env, METHODS) for env in ENVS] + [(CONTROL_REGIME, CONTROL_ENV, CONTROL_METHODS)]
    figure, axes = plt.subplots(1, len(panels), figsize=(17, 5.6))
    for axis, (regime, env, methods) in zip(axes, panels):
        records = cells[regime, env]
        for y, method in enumerate(methods):
            scores = scores_of(records, method, SEEDS)
            if scores:
                mean, (low, high) = statistics.fmean(scores), bootstrap_ci(scores)
                axis.scatter(scores, [y + 0.18] * len(scores), s=12, color="0.35", zorder=3)
                axis.errorbar([mean], [y], xerr=[[mean - low], [high - mean]], fmt="D", color="C0", capsize=3, markersize=5)
            else:
                axis.text(0.02, y, "no runs yet", transform=axis.get_yaxis_transform(), va="center", fontsize=8, color="0.4")
        for method, color, style in (("c2f", "C3", "--"), ("bc_oh", "C2", ":")):
            scores = scores_of(records, method, SEEDS)
            if scores:
                axis.axvline(statistics.fmean(scores), color=color, linestyle=style, label=f"{NAMES[method]} mean")
        labels = [f"{NAMES[m]} (n={len(scores_of(records, m, SEEDS))})" for m in methods]
        axis.set_yticks(range(len(methods)), labels, fontsize=8)
        axis.set_ylim(len(methods) - 0.5, -0.6)
        axis.set_xlabel("return (mean of last three evaluations)", fontsize=8)
        axis.set_title(f"{env}, {regime}", fontsize=10)
        axis.grid(axis="x", alpha=0.3)
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=7, loc="best")
    figure.suptitle(f"Baselines in {REGIME} and the Walker2d capacity controls: seeds {seed_ranges(SEEDS)} (dots), mean and 95% interval")
    figure.tight_layout()
    aggregate.save_figure(figure, path)


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.regime_baselines", description=__doc__.split("\n\n")[0])
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR, help=f"the regime map, with the baselines and controls (default {RESULTS_DIR})")
    parser.add_argument("--expert-runs", type=Path, default=Path("results/runs"), help="holds expert/<env>/result_seeds0.json (default results/runs)")
    args = parser.parse_args(argv)
    existing_runs_dir(REGIME, args.results_dir)
    cells, problems = gather(args.results_dir)
    adversary, adversary_problems = adversary_runs(args.results_dir)
    # a result that gather left out too is listed once
    problems += [problem for problem in adversary_problems if problem not in problems]
    experts, expert_problems = regime_summary.expert_scores(args.expert_runs, ENVS)
    problems += expert_problems
    for problem in problems:
        print(problem, file=sys.stderr)
    if not any(cells.values()):
        if any(problem.startswith("left out ") for problem in problems):
            raise UsageError(f"no valid results of this comparison under {args.results_dir} (see above)")
        folder = args.results_dir
        raise UsageError(f"no results of this comparison under {folder}: pass --results-dir, the "
                         "folder python -m benchmark.regimes wrote them into")
    command = " ".join(["python -m benchmark.regime_baselines", *(argv if argv is not None else sys.argv[1:])])
    table = markdown(cells, experts, problems, command, args.results_dir, adversary)
    out = args.results_dir / REGIME
    write_text(out / "table2.md", table)
    plot(cells, out / "table2.png")
    print(table)
    print(f"wrote {out / 'table2.md'}, {out / 'table2.png'}" + (f"; left out {len(problems)} (listed above)" if problems else ""))
    return 0


if __name__ == "__main__":
    run_cli(main)
