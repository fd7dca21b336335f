"""H3 on positions-only Hopper: what the history and the coarse action do in the native_hidden models, seed by seed.

    python -m benchmark.h3 [--analysis-dir analysis/Hopper-v4/native_hidden] [--h3-dir results/h3]
        [--results-dir results/regimes] [--reference analysis/Hopper-v4]

Reads copycat_analysis.py's report of each seed, <analysis-dir>/seed<S>/copycat_analysis.json: BC-SO, BC-OH and C2F
re-made into <h3-dir> with --save-model, and the no-coarse control's model from the map (<results-dir>). Also reads
the scores of those runs and of the map's runs of the same seeds, which were made on another CPU. As the reference,
it reads the reports at the paper's setting (every other copycat_analysis.json under <reference>). It writes
<analysis-dir>/h3.md with these parts:
- per seed, each run's score beside the map's;
- per seed and model, the rollout return and the intervention on the history (held-out demos and the policy's own
  rollouts), the copycat score, and the means over seeds;
- C2F's relative weight on each coarse-action dim, here and at the paper's setting.
A report that is unreadable, or whose models are not its seed's, is left out. So is a score that does not read.
Each is reported with its reason, on stderr and in h3.md.
"""
import json
import statistics
import sys
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark import regime_summary
from benchmark.regimes import RESULTS_DIR, existing_runs_dir
from benchmark.results import OneLineParser, UsageError, check_folder, finite_number, run_cli, write_text

REGIME, ENV = "native_hidden", "Hopper-v4"
ANALYSIS_DIR, H3_DIR, REFERENCE_DIR = Path("analysis/Hopper-v4/native_hidden"), Path("results/h3"), Path("analysis/Hopper-v4")
MODELS = {"bc_so": "BC-SO", "bc_oh": "BC-OH", "c2f": "C2F", "c2f_no_coarse": "no-coarse control"}
"""copycat_analysis.py's rows (c2f_no_coarse: the model given as --control) and their names here"""
REMADE = ["bc_so", "bc_oh", "c2f"]
"""the models re-made into <h3-dir>; the control's model is the map's own run"""


FIGURES = ["history_change_demos", "towards_previous_demos", "history_change_rollouts", "towards_previous_rollouts", "copycat_score"]
"""copycat_analysis.py's figures per model that h3.md tabulates (and rollout_returns)"""


def numbers(values, length=None) -> bool:
    """Whether values is a list of finite numbers (of `length` entries, if given)."""
    return isinstance(values, list) and bool(values) and (length is None or len(values) == length) and all(map(finite_number, values))


def seed_of(report: dict, model: str):
    """The seed of a model in a report, from its file name (seed<S>.pt), or None."""
    name = Path(report["methods"][model]["model"]).name
    return int(name[4:-3]) if name.startswith("seed") and name.endswith(".pt") and name[4:-3].isdigit() else None


def read_report(path: Path, models, hidden: bool) -> tuple:
    """(seed, report) of a copycat_analysis.json whose models are all one seed's, of ENV, with the velocities hidden
    or not; raises ValueError(why) otherwise."""
    try:
        report = json.loads(path.read_text())
        if report["env"] != ENV or bool(report.get("hide_velocities")) != hidden:
            raise ValueError(f"not {ENV} with the velocities {'hidden' if hidden else 'noisy'}")
        seeds = {model: seed_of(report, model) for model in models}
        rows, zeta = [report["methods"][model] for model in models], report["zeta"]
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"unreadable report ({type(error).__name__}: {error})")
    if not all(isinstance(row, dict) and numbers(row.get("rollout_returns")) and numbers([row.get(k) for k in FIGURES])
               for row in rows) or not (isinstance(zeta, dict) and numbers(zeta.get("relative_demos"))
                                        and numbers(zeta.get("relative_rollouts"), len(zeta["relative_demos"]))):
        raise ValueError("a figure is missing or not a number (not a report of this copycat_analysis.py)")
    if len(set(seeds.values())) != 1 or None in seeds.values():
        raise ValueError(f"its models are not one seed's ({', '.join(f'{m}: seed {s}' for m, s in seeds.items())})")
    return seeds["c2f"], report


def gather(analysis_dir: Path) -> tuple:
    """({seed: report} here, lines on what was left out)."""
    reports = {}
    problems = []
    for path in sorted(analysis_dir.glob("seed*/copycat_analysis.json")):
        try:
            seed, report = read_report(path, MODELS, hidden=True)
            if path.parent.name != f"seed{seed}":
                raise ValueError(f"its models are seed {seed}'s, its folder {path.parent.name}")
            reports[seed] = report
        except ValueError as error:
            problems.append(f"left out {path}: {error}")
    return reports, problems


def gather_references(analysis_dir: Path, reference_dir: Path) -> tuple:
    """({seed: report} at the paper's setting, lines on what was left out): the reports under
    reference_dir but those of analysis_dir."""
    references = {}
    problems = []
    for path in sorted(reference_dir.glob("**/copycat_analysis.json")):
        if analysis_dir.resolve() in path.resolve().parents:
            continue  # the reports here, not the reference
        try:
            found = json.loads(path.read_text())
            if not isinstance(found, dict):
                raise ValueError("not a JSON object (not a report of copycat_analysis.py)")
            if not found.get("hide_velocities"):
                seed, report = read_report(path, REMADE, hidden=False)
                if seed in references:
                    raise ValueError(f"a second report of seed {seed} (the first, by path, is kept)")
                references[seed] = report
        except (ValueError, OSError) as error:  # JSONDecodeError, UnicodeDecodeError: ValueErrors
            problems.append(f"left out reference {path}: {error}")
    if not references:  # a folder without them leaves the paper's setting out of the ζ table
        where = f"under {reference_dir}"
        problems.append(f"no report at the paper's setting {where}: its column shows —")
    return references, problems


def run_scores(h3_dir: Path, results_dir: Path) -> tuple:
    """({(model, seed): score} of the re-made runs and the control, {(model, seed): score} of the map, problems)."""
    remade, problems = regime_summary.collect(REGIME, h3_dir, methods=REMADE)
    mapped, more = regime_summary.collect(REGIME, results_dir, methods=list(MODELS))
    ours = {(r.method, r.seed): r.score for r in remade + [r for r in mapped if r.method == "c2f_no_coarse"] if r.env == ENV}
    ours_problems = [p for p in problems + more if any(f"/runs/{m}/{ENV}/" in p for m in MODELS)]  # not the other rows'
    return ours, {(r.method, r.seed): r.score for r in mapped if r.env == ENV}, ours_problems


def figure(value, digits=3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def markdown(reports: dict, references: dict, ours: dict, mapped: dict, problems: list, command: str) -> str:
    seeds = sorted(reports)
    lines = [f"# H3 on positions-only Hopper ({REGIME}, {ENV}): what the history and the coarse action do", "",
             f"Made by `{command}` from `copycat_analysis.py`'s reports of seeds {', '.join(map(str, seeds)) or 'none'} "
             "(its commands are in docs/regimes.md). Held-out demos: a fresh expert rollout, velocities zeroed; "
             "rollouts: each policy's own, in the same env.", "",
             "## The runs: each model's score, and the map's run of the same seed", "",
             "The score of a seed is the mean return of its last three evaluations. BC-SO, BC-OH and C2F were re-made "
             "with `--save-model` on the controls' CPU. The map's runs were made on another CPU, whose MKL kernels "
             "give the same seed other demos. The control's run is the map's own.", "",
             "| seed | " + " | ".join(MODELS.values()) + " |", "|---|" + "---:|" * len(MODELS)]
    for seed in seeds:
        cells = [figure(ours.get((m, seed)), 0) + ("" if m == "c2f_no_coarse" else f" (map {figure(mapped.get((m, seed)), 0)})")
                 for m in MODELS]
        lines.append(f"| {seed} | " + " | ".join(cells) + " |")
    lines += ["", "## do(o_hist): how far the history moves each action, and towards what", "",
              "History change: the mean |change| of the action, in demo-action stds, when the history is replaced by "
              "copies of o_t. Towards a_{t−1}: how often the real history pulls the action towards the previous action. "
              "Copycat score: at action changepoints (top decile of |a_t − a_{t−1}|), how often the prediction is "
              "closer to a_{t−1} than to a_t. BC-SO reads only o_t, so its history figures are 0.", "",
              "| seed | model | return (3 rollouts) | history change, demos | towards a_{t−1}, demos "
              "| history change, rollouts | towards a_{t−1}, rollouts | copycat score |", "|---|---|" + "---:|" * 6]
    for model, name in MODELS.items():
        rows = [(seed, reports[seed]["methods"][model]) for seed in seeds]
        mean = {k: statistics.fmean(row[k] for _, row in rows) for k in FIGURES}
        mean["rollout_returns"] = [x for _, row in rows for x in row["rollout_returns"]]  # the mean of every rollout
        for seed, row in rows + [("mean", mean)]:
            shares = " | ".join(figure(row[k], 3 if k.startswith("history") else 2) for k in FIGURES)
            lines.append(f"| {seed} | {name} | {statistics.fmean(row['rollout_returns']):.0f} | {shares} |")
    weights = [w for report in references.values() for w in report["zeta"]["relative_demos"]]
    lines += ["", "## do(ζ): C2F's weight on the coarse action, here and at the paper's setting", "",
              "CE/(hi − lo) per action dim: 1 when C2F's action follows ζ fully, 0 when it ignores it (lo, hi: the "
              "demo actions' quantiles of `--zeta-quantile`). The paper's setting is the native rate with noise on the "
              "velocities (the Table 2 grid's models, `analysis/Hopper-v4/`)"
              + (f"; there, the same figure was {min(weights):.2f}–{max(weights):.2f}." if weights else "."), "",
              "| seed | here, demos | here, rollouts | paper's setting, demos |", "|---|---:|---:|---:|"]

    def dims(values):
        return ", ".join(f"{v:.2f}" for v in values)
    for seed in sorted(set(seeds) | set(references)):
        here = reports[seed]["zeta"] if seed in reports else None
        there = references[seed]["zeta"]["relative_demos"] if seed in references else None
        lines.append(f"| {seed} | {dims(here['relative_demos']) if here else '—'} | {dims(here['relative_rollouts']) if here else '—'} "
                     f"| {dims(there) if there else '—'} |")
    lines += ["", "## Left out", "", *(f"- {p}" for p in problems)] if problems else ["", "## Left out", "", "none"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.h3", description=__doc__.split("\n\n")[0])
    parser.add_argument("--analysis-dir", type=Path, default=ANALYSIS_DIR, help=f"holds seed<S>/copycat_analysis.json (default {ANALYSIS_DIR})")
    parser.add_argument("--h3-dir", type=Path, default=H3_DIR, help=f"the re-made BC-SO, BC-OH and C2F runs (default {H3_DIR})")
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR, help=f"the regime map, with the control (default {RESULTS_DIR})")
    parser.add_argument("--reference", type=Path, default=REFERENCE_DIR, help=f"the reports at the paper's setting (default {REFERENCE_DIR})")
    args = parser.parse_args(argv)
    fix = "pass --reference, the folder of the reports at the paper's setting"
    check_folder(args.reference, "reference folder", fix)
    # Mistyped run folders would show every score as —, with only a warning per seed.
    existing_runs_dir(REGIME, args.h3_dir, "--h3-dir", "--methods bc_so bc_oh c2f --envs Hopper-v4 --seeds 1 2 3 --save-model")
    existing_runs_dir(REGIME, args.results_dir)
    reports, problems = gather(args.analysis_dir)
    if not reports:
        for problem in problems:  # why each report found was left out
            print(problem, file=sys.stderr)
        left_out = " (see above)" if problems else ""
        wanted = f"{args.analysis_dir}/seed<S>/copycat_analysis.json"
        fix = "run copycat_analysis.py as docs/regimes.md shows"
        raise UsageError(f"no valid {wanted}{left_out}: {fix}")
    references, more = gather_references(args.analysis_dir, args.reference)
    problems += more
    ours, mapped, more = run_scores(args.h3_dir, args.results_dir)
    problems += more
    for seed in sorted(reports):
        problems += [f"no valid result of {m} seed {seed} under {args.h3_dir if m in REMADE else args.results_dir}: its score shows —"
                     for m in MODELS if (m, seed) not in ours]
        problems += [f"no valid result of {m} seed {seed} in the map ({args.results_dir}): its map score shows —"
                     for m in REMADE if (m, seed) not in mapped]
    for problem in problems:
        print(problem, file=sys.stderr)
    command = " ".join(["python -m benchmark.h3", *(argv if argv is not None else sys.argv[1:])])
    text = markdown(reports, references, ours, mapped, problems, command)
    write_text(args.analysis_dir / "h3.md", text)
    print(text + f"wrote {args.analysis_dir / 'h3.md'}")
    return 0


if __name__ == "__main__":
    run_cli(main)
