"""How much a reader has to read: each method file's length and how far it is from bc_oh.py.

    python scripts/file_sizes.py          # a markdown table
    python scripts/file_sizes.py --page   # also put it between the <!-- sizes --> markers of docs/contributing.md

Lines = `wc -l`; diff = the lines `diff -I '^# Copied from' bc_oh.py FILE` marks with < or > (what
`diff bc_oh.py FILE` shows a reader, copy markers aside); in brackets the targets the project set itself (the
teaching-grade issue), for contributors.
"""
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # tooling may import the repository's benchmark package
from benchmark.aggregate import page_parts  # noqa: E402
from benchmark.results import OneLineParser, run_cli, write_text  # noqa: E402

PAGE = Path("docs/contributing.md")
"""the page whose <!-- sizes --> block --page writes when it names no page"""
MARKERS = "<!-- sizes -->", "<!-- /sizes -->"
TARGETS = {"bc_oh": (330, None), "bc_so": (400, 20), "history_dropout": (400, 15), "c2f": (400, 80), "fca": (400, 100),
           "keyframe": (400, 100), "average_ensemble": (400, 100), "dagger": (400, 120)}
"""method file -> (most lines, most diff lines against bc_oh.py)"""


def diff_lines(name: str) -> int:
    diff = subprocess.run(["diff", "-I", "^# Copied from", str(ROOT / "bc_oh.py"), str(ROOT / f"{name}.py")], capture_output=True, text=True)
    return len(re.findall(r"^[<>]", diff.stdout, re.M))


def table() -> str:
    rows = ["| file | lines (target) | diff vs bc_oh.py (target) |", "|---|---:|---:|"]
    for name, (most_lines, most_diff) in TARGETS.items():
        lines = len((ROOT / f"{name}.py").read_text().splitlines())
        diff = "—" if most_diff is None else f"{diff_lines(name)} ({most_diff})"
        rows.append(f"| `{name}.py` | {lines} ({most_lines}) | {diff} |")
    return "\n".join(rows) + "\n"


def main(argv=None):
    parser = OneLineParser(prog="python scripts/file_sizes.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--page", type=Path, nargs="?", const=PAGE, help=f"also put the table between this page's (alone: {PAGE}) {' and '.join(MARKERS)} markers")
    args = parser.parse_args(argv)
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
