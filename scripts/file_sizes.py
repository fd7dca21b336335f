"""How much a reader has to read: each method file's length and how far it is from bc_oh.py.

    python scripts/file_sizes.py          # a markdown table
    python scripts/file_sizes.py --page   # also put it between the <!-- sizes --> markers of docs/contributing.md
    python scripts/file_sizes.py --budget bc_oh   # where one file's formatted lines go, by part (method, run, ...)
    python scripts/file_sizes.py --features       # what each feature of the shared part costs every method file

Lines = the file's lines once formatted by `ruff format --line-length 120` (so long lines cannot hide size; the
method files are kept formatted, `tests/test_style.py`), characters likewise; diff = the lines
`diff -I '^# Copied from' bc_oh.py FILE` marks with < or > (what `diff bc_oh.py FILE` shows a reader, copy markers
aside). In brackets the targets of issue 31; CLEANRL_CORL gives the anchors' sizes, for comparison.
"""
import ast
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # tooling may import the repository's benchmark package
from benchmark.aggregate import page_parts  # noqa: E402
from benchmark.results import OneLineParser, UsageError, run_cli, write_text  # noqa: E402

PAGE = Path("docs/contributing.md")
"""the page whose <!-- sizes --> block --page writes when it names no page"""
MARKERS = "<!-- sizes -->", "<!-- /sizes -->"
TARGETS = {"bc_oh": (400, 18_000, None), "bc_so": (440, None, 20), "history_dropout": (440, None, 30),
           "c2f": (480, None, 120), "fca": (440, None, 120), "keyframe": (440, None, 120),
           "average_ensemble": (440, None, 120), "dagger": (480, None, 150)}
"""method file -> (most formatted lines, most characters, most diff lines against bc_oh.py); None: no target"""
ANCHORS = "| CleanRL `ppo_continuous_action.py` (for comparison) | 353 | 14.6k | — |\n| CORL `any_percent_bc.py` | 406 | — | — |\n"
"""the two single-file anchors, measured in their own repositories (../shared/STYLE.md)"""


PARTS = {"run": ("run", "train_and_record", "run_name", "finished_seed", "write_result", "member_summary"),
         "errors": ("UsageError", "require"), "evaluation": ("evaluate",),
         "env and partial observability": ("velocity_dims", "PartialObservation", "make_env"),
         "data": ("load_demos", "partially_observe", "stack_history")}
"""the parts of a method file by its top-level definitions; `Args` is its own part, and every other definition is the
method's (network, loss, training step, train_seed, fit; DAgger's expert); the rest (header, imports, banners, copy
markers, the blank lines between definitions, `__main__`) is counted as such"""

FEATURES = {
    "--velocity-dims": [(r'^    velocity_dims: .*\n    """.*\n', ""), (r"^    if override:\n(?:        .*\n){2}", "")],
    "the demos' copy error": [(r"^    (?:step_error|copy_error|shortcut) = .*\n", ""), (r"; \{shortcut\} \(near 0[^)]*\)", "")],
    "the job's ETA": [(r"^    (?:workers, position|waves_after) = .*\n", ""), (r"^ +eta = .*\n", ""), (r" \| job ETA \{eta:\.1f\} min", "")],
    "the share of the expert's return": [(r'^    if "expert_return" in meta:.*\n(?:        .*\n)+', "")],
    "the hint for transposed demos": [(r"^    turned = .*\n", ""), (r"^    fix = .*\n", '    fix = "use demos of this env"\n')],
    "the kept and waiting seeds' lines": [(r"^    if kept:\n        .*\n", ""), (r"^    if len\(to_train\) > args\.workers:\n(?:        .*\n)+", "")],
    "the usage line of the docstring": [(r'\n\n    python bc_oh\.py --env Hopper-v4\n"""', '"""')],
    "keeping finished seeds on a rerun": [(r"^def finished_seed(?:.*\n)*?(?=^def )", ""), (r"finished_seed\(output_dir, s(?:eed)?, args\)", "None")],
    "a clean interrupt": [(r"^    try:\n((?:        .*\n)+)    except KeyboardInterrupt:.*\n(?:        .*\n)+", lambda m: re.sub("^    ", "", m[1], flags=re.M)),
                          (r"^ +signal\.signal\(.*\n", ""), (r"^import signal\n", "")],
    "run names that keep settings apart": [(r"^def run_name(?:.*\n)*?(?=^def )", ""), (r"run_name\(args\)", "METHOD")],
    "the one-line refusals of bad flags and demos": [  # the require checks, their messages and their loops
        (r'^    for key in (?:"history|\("observations", "actions").*\n(?:        (?:value, flag|require).*\n)+', ""),
        (r'^    for key, values in \(\("observations".*\n(?:        .*\n){2}', ""), (r"^ +require\(.*\n", ""),
        (r"^    (?:seeds|samples, batch|make|where|turned|fix|need|shapes|rows|batch|outside|bounds) \+?= .*\n", ""),
        (r"^    low, high = env\.action_space.*\n", "")],
}
"""a feature of the shared part (the same in every method file) -> the edits of formatted bc_oh.py that take it out,
(regular expression, replacement) each, applied in turn; --features measures what each saves, and all of them"""


def feature_costs() -> dict:
    """{feature: (formatted lines, characters)} that taking it out of bc_oh.py saves (so every method file: the shared
    part is the same in each), and {"all of them": ...}; a UsageError if an edit no longer finds its text."""
    text, costs = formatted("bc_oh"), {}
    every = text
    for feature, edits in FEATURES.items():
        cut = text
        for pattern, replacement in edits:
            cut, found = re.subn(pattern, replacement, cut, flags=re.M)
            every = re.sub(pattern, replacement, every, flags=re.M)
            if not found:
                raise UsageError(f"the edit {pattern!r} of {feature!r} finds nothing in bc_oh.py: update FEATURES")
        costs[feature] = size(text, cut, feature)
    costs["all of them"] = size(text, every, "all of them")
    return costs


def size(text: str, cut: str, feature: str) -> tuple:  # (formatted lines, characters) cut, formatted, has fewer
    try:
        ast.parse(cut)  # a cut that broke the file would measure nothing
    except SyntaxError as error:
        raise UsageError(f"the edits of {feature!r} leave bc_oh.py unparsable (line {error.lineno}): update FEATURES")
    cut = format_text(cut)
    return len(text.splitlines()) - len(cut.splitlines()), len(text) - len(cut)


def budget(name: str) -> dict:
    """{part: formatted lines} of a method file, each definition counted from its first line (decorators included)
    to its last; the parts sum to the file's formatted lines."""
    text = formatted(name)
    parts = dict.fromkeys(["Args", "the method", *PARTS, "the rest"], 0)
    for node in ast.parse(text).body:
        if not isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            continue
        part = next((part for part, names in PARTS.items() if node.name in names), None)
        part = part or ("Args" if node.name == "Args" else "the method")
        first = min([node.lineno, *(decorator.lineno for decorator in node.decorator_list)])
        parts[part] += node.end_lineno - first + 1
    parts["the rest"] += len(text.splitlines()) - sum(parts.values())
    return parts


def formatted(name: str) -> str:
    """The file as `ruff format --line-length 120` writes it."""
    return format_text((ROOT / f"{name}.py").read_text())


def format_text(source: str) -> str:
    try:
        done = subprocess.run(["ruff", "format", "--line-length", "120", "-"], input=source, capture_output=True, text=True, check=True)
    except FileNotFoundError:
        raise UsageError("ruff is not on PATH: pip install -r requirements.txt (it pins ruff), in the active venv")
    return done.stdout


def diff_lines(name: str) -> int:
    diff = subprocess.run(["diff", "-I", "^# Copied from", str(ROOT / "bc_oh.py"), str(ROOT / f"{name}.py")], capture_output=True, text=True)
    return len(re.findall(r"^[<>]", diff.stdout, re.M))


def target(value, most) -> str:
    return f"{value}" if most is None else f"{value} ({most}{'' if value <= most else ', over'})"


def table() -> str:
    rows = ["| file | formatted lines (target) | characters (target) | diff vs bc_oh.py (target) |", "|---|---:|---:|---:|"]
    for name, (most_lines, most_chars, most_diff) in TARGETS.items():
        text = formatted(name)
        diff = "—" if most_diff is None else target(diff_lines(name), most_diff)
        rows.append(f"| `{name}.py` | {target(len(text.splitlines()), most_lines)} | {target(len(text), most_chars)} | {diff} |")
    return "\n".join(rows) + "\n" + ANCHORS


def main(argv=None):
    parser = OneLineParser(prog="python scripts/file_sizes.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--page", type=Path, nargs="?", const=PAGE, help=f"also put the table between this page's (alone: {PAGE}) {' and '.join(MARKERS)} markers")
    parser.add_argument("--budget", choices=list(TARGETS), help="print instead where this file's formatted lines go, by part")
    parser.add_argument("--features", action="store_true", help="print instead what each feature of the shared part costs")
    args = parser.parse_args(argv)
    if args.features:
        for feature, (lines, characters) in feature_costs().items():
            print(f"{feature}: {lines} formatted lines, {characters} characters")
        return 0
    if args.budget:
        parts = budget(args.budget)
        print(f"{args.budget}.py, {sum(parts.values())} formatted lines: " + "; ".join(f"{part} {n}" for part, n in parts.items()))
        return 0
    if args.page:
        page_parts(args.page, *MARKERS)  # check the markers before anything else
    text = table()
    print(text, end="")
    if args.page:
        before, after = page_parts(args.page, *MARKERS)
        write_text(args.page, f"{before}\n{text}{after}")
    return 0


if __name__ == "__main__":
    run_cli(main)
