"""How much a reader has to read: each method file's length and how far it is from bc_oh.py.

    python scripts/file_sizes.py                  # a markdown table
    python scripts/file_sizes.py --page           # also write it into docs/contributing.md
    python scripts/file_sizes.py --budget bc_oh   # where one file's formatted lines go, by part

Lines = the file's lines once formatted by `ruff format --line-length 100` (so long lines cannot
hide size; the method files are kept formatted, `tests/test_style.py`); diff = the lines
`diff -I '^# Copied from' bc_oh.py FILE` marks with < or > (what `diff bc_oh.py FILE` shows a
reader, copy markers aside); c2f_table3.py is compared with c2f.py instead, the file it varies.
In brackets the targets of issue 55; ANCHORS gives the anchors' sizes, for comparison. --page
puts the table between the <!-- sizes --> markers of docs/contributing.md (or of the page named).
"""

import ast
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # tooling may import the repository's benchmark package
from benchmark.aggregate import page_parts  # noqa: E402
from benchmark.results import OneLineParser, UsageError, check_writable, run_cli, write_text  # noqa: E402

PAGE = Path("docs/contributing.md")
"""the page whose <!-- sizes --> block --page writes when it names no page"""
MARKERS = "<!-- sizes -->", "<!-- /sizes -->"
TARGETS = {
    "bc_oh": (380, None),
    "bc_so": (400, 24),
    "history_dropout": (400, 36),
    "c2f": (430, 100),
    "fca": (460, 160),
    "keyframe": (460, 160),
    "average_ensemble": (460, 160),
    "dagger": (500, 200),
    "c2f_table3": (520, None),
    "expert_ppo": (700, None),
}
"""file -> (most formatted lines, most diff lines against bc_oh.py); None: no target. A file that
does not exist (yet) is left out of the table."""
BASES = {"c2f_table3": "c2f"}
"""file -> the file its diff is counted against, where that is not bc_oh (no target: shown only)"""
NO_DIFF = {"bc_oh", "expert_ppo"}
"""files whose row shows no diff: bc_oh itself, and the expert (another algorithm)"""
RUFF = [sys.executable, "-m", "ruff"]
"""ruff through the running interpreter, so it needs no venv bin/ on PATH"""
ANCHORS = (
    "| CleanRL `ppo_continuous_action.py` (for comparison; black, 127 columns) | 353 | — |\n"
    "| CORL `any_percent_bc.py` (black) | 406 | — |\n"
)
"""the two single-file anchors, measured in their own repositories (../shared/STYLE.md)"""

PARTS = {
    "run": ("run", "train_seeds", "start_worker", "train_and_record", "write_result", "member_summary"),
    "errors": ("UsageError",),
    "evaluation": ("evaluate",),
    "env and partial observability": ("velocity_dims", "PartialObservation", "make_env"),
    "data": ("load_demos", "partially_observe", "stack_history"),
}
"""the parts of a method file by its top-level definitions (a name a file lacks counts 0); `Args`
is its own part, and every other definition is the method's (mlp, Normalizer, Policy,
make_policy, train_seed, fit; DAgger's expert); the rest (header, imports, banners, copy markers,
the blank lines between definitions, `__main__`) is counted as such"""


def budget(name: str) -> dict:
    """{part: formatted lines} of a method file, each definition counted from its first line
    (decorators included) to its last; the parts sum to the file's formatted lines."""
    text = formatted(name)
    parts = dict.fromkeys(["Args", "the method", *PARTS, "the rest"], 0)
    for node in ast.parse(text).body:
        if not isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            continue
        part = "the method"
        if node.name == "Args":
            part = "Args"
        for candidate, names in PARTS.items():
            if node.name in names:
                part = candidate
        first = min([node.lineno, *(decorator.lineno for decorator in node.decorator_list)])
        parts[part] += node.end_lineno - first + 1
    parts["the rest"] += len(text.splitlines()) - sum(parts.values())
    return parts


def formatted(name: str) -> str:
    """The file as `ruff format --line-length 100` writes it."""
    path = ROOT / f"{name}.py"
    if not path.exists():
        raise UsageError(f"{path} not found")
    return format_text(path.read_text())


def format_text(source: str) -> str:
    command = [*RUFF, "format", "--line-length", "100", "-"]
    done = subprocess.run(command, input=source, capture_output=True, text=True)
    if done.returncode != 0 and "No module named" in done.stderr:
        message = f"ruff is not installed for {sys.executable}: pip install -r requirements.txt"
        raise UsageError(message + " (it pins ruff), in the active venv")
    if done.returncode != 0:
        first_line = (done.stderr.strip().splitlines() or ["no message"])[0]
        raise UsageError(f"ruff format failed: {first_line}")
    return done.stdout


def diff_lines(name: str, base: str = "bc_oh") -> int:
    """The lines `diff -I '^# Copied from' BASE.py NAME.py` marks with < or >."""
    command = ["diff", "-I", "^# Copied from", str(ROOT / f"{base}.py"), str(ROOT / f"{name}.py")]
    diff = subprocess.run(command, capture_output=True, text=True)
    return len(re.findall(r"^[<>]", diff.stdout, re.M))


def existing() -> list:
    """The names in TARGETS whose file exists."""
    return [name for name in TARGETS if (ROOT / f"{name}.py").exists()]


def target(value, most) -> str:
    if most is None:
        return f"{value}"
    if value > most:
        return f"{value} ({most}, over)"
    return f"{value} ({most})"


def diff_cell(name: str) -> str:
    if name in NO_DIFF:
        return "—"
    if name in BASES:
        return f"{diff_lines(name, BASES[name])} against {BASES[name]}.py"
    return target(diff_lines(name), TARGETS[name][1])


def table() -> str:
    rows = [
        "| file | formatted lines (target) | diff vs bc_oh.py (target) |",
        "|---|---:|---:|",
    ]
    for name in existing():
        lines = len(formatted(name).splitlines())
        rows.append(f"| `{name}.py` | {target(lines, TARGETS[name][0])} | {diff_cell(name)} |")
    return "\n".join(rows) + "\n" + ANCHORS


def main(argv=None):
    parser = OneLineParser(
        prog="python scripts/file_sizes.py", description=__doc__.split("\n\n")[0]
    )
    markers = " and ".join(MARKERS)
    parser.add_argument(
        "--page",
        type=Path,
        nargs="?",
        const=PAGE,
        help=f"also put the table between this page's (alone: {PAGE}) {markers} markers",
    )
    parser.add_argument(
        "--budget",
        choices=list(TARGETS),
        help="print instead where this file's formatted lines go, by part",
    )
    args = parser.parse_args(argv)
    if args.budget and args.page:
        message = "--budget prints one file's parts, not the table that --page writes"
        raise UsageError(f"{message}: leave out --budget or --page")
    if args.budget:
        parts = budget(args.budget)
        shares = "; ".join(f"{part} {n}" for part, n in parts.items())
        print(f"{args.budget}.py, {sum(parts.values())} formatted lines: {shares}")
        return 0
    if args.page:
        page_parts(args.page, *MARKERS)  # check the markers before anything else
        check_writable(args.page, "--page", is_file=True)
    text = table()
    print(text, end="")
    if args.page:
        before, after = page_parts(args.page, *MARKERS)
        write_text(args.page, f"{before}\n{text}{after}")
    return 0


if __name__ == "__main__":
    run_cli(main)
