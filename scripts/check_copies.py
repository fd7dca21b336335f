"""Check that code copied between the method files is still identical to its original.

The scripts at the repo root are single-file on purpose, so they duplicate shared code. Each copied
top-level function or class carries a marker on the line directly above it (or above its decorators):

    # Copied from bc_oh.make_env
    # Copied from bc_oh.make_env with Foo->Bar, foo->bar

The copy must equal the top-level def/class `make_env` of bc_oh.py, after the renames (plain text
replacements, applied in order to the original). A copy may itself be the original of another copy.

    python scripts/check_copies.py          # report drifted copies, exit 1 if any
    python scripts/check_copies.py --fix    # rewrite drifted copies from their originals
"""
import argparse
import ast
import re
import sys
from dataclasses import dataclass
from pathlib import Path

MARKER_PREFIX = "# Copied from"
MARKER = re.compile(r"# Copied from (\w+)\.(\w+)(?: with (.+?))?\s*$")
DEFINITIONS = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)
MAX_FIX_PASSES = 10


@dataclass
class Block:
    """A top-level def/class: lines start..end (1-based, inclusive, decorators included)."""

    start: int
    end: int


@dataclass
class Copy:
    file: str  # file name relative to the root, e.g. "gail.py"
    marker_line: int
    orig_module: str
    orig_name: str
    renames: list  # [(old, new), ...]
    block: Block


def parse_renames(text):
    """'Foo->Bar, foo->bar' -> [('Foo', 'Bar'), ('foo', 'bar')]; ValueError if malformed."""
    renames = []
    for part in text.split(","):
        old, arrow, new = part.strip().partition("->")
        if not arrow or not old:
            raise ValueError(f"bad rename {part.strip()!r} (expected Old->New)")
        renames.append((old, new))
    return renames


def apply_renames(text, renames):
    for old, new in renames:
        text = text.replace(old, new)
    return text


def top_level_blocks(source):
    """{name: Block} of the module's top-level functions and classes."""
    blocks = {}
    for node in ast.parse(source).body:
        if isinstance(node, DEFINITIONS):
            start = min([node.lineno] + [d.lineno for d in node.decorator_list])
            blocks[node.name] = Block(start, node.end_lineno)
    return blocks


def block_text(lines, block):
    text = "".join(lines[block.start - 1 : block.end])
    return text if text.endswith("\n") else text + "\n"  # the last block of a file may lack it


def find_copies(file, source, problems):
    """The copies marked in one file; malformed or misplaced markers are added to problems."""
    starts = {block.start: block for block in top_level_blocks(source).values()}
    copies = []
    for number, line in enumerate(source.splitlines(), start=1):
        if not line.startswith(MARKER_PREFIX):
            continue
        match = MARKER.match(line)
        if not match:
            problems.append(f"{file}:{number}: malformed marker (expected '# Copied from FILE.NAME [with Old->New, ...]')")
        elif number + 1 not in starts:
            problems.append(f"{file}:{number}: marker is not directly above a top-level def or class")
        else:
            try:
                renames = parse_renames(match.group(3)) if match.group(3) else []
            except ValueError as error:
                problems.append(f"{file}:{number}: {error}")
                continue
            copies.append(Copy(file, number, match.group(1), match.group(2), renames, starts[number + 1]))
    return copies


def check(root, fix=False):
    """Check (with fix: rewrite drifted) copies in root/*.py. Returns (problems, copies checked, rewritten)."""
    root = Path(root)
    sources, problems, copies, rewritten = {}, [], [], 0
    for path in sorted(root.glob("*.py")):
        sources[path.name] = path.read_text()
        try:
            copies += find_copies(path.name, sources[path.name], problems)
        except SyntaxError as error:
            problems.append(f"{path.name}:{error.lineno}: cannot parse ({error.msg})")
    # Bottom-up, so a fix that changes a block's length leaves the line numbers above it valid.
    for copy in sorted(copies, key=lambda c: (c.file, -c.marker_line)):
        where = f"{copy.file}:{copy.marker_line}"
        orig_file = f"{copy.orig_module}.py"
        try:
            orig_block = top_level_blocks(sources[orig_file]).get(copy.orig_name)
        except (KeyError, SyntaxError):
            orig_block = None
        if orig_block is None:
            problems.append(f"{where}: original {copy.orig_module}.{copy.orig_name} not found")
            continue
        expected = apply_renames(block_text(sources[orig_file].splitlines(keepends=True), orig_block), copy.renames)
        lines = sources[copy.file].splitlines(keepends=True)
        if block_text(lines, copy.block) == expected:
            continue
        orig_where = f"{orig_file}:{orig_block.start}"
        if fix:
            lines[copy.block.start - 1 : copy.block.end] = [expected]
            sources[copy.file] = "".join(lines)
            (root / copy.file).write_text(sources[copy.file])
            rewritten += 1
            print(f"{where}: rewrote copy of {copy.orig_module}.{copy.orig_name} from {orig_where}")
        else:
            problems.append(f"{where}: copy of {copy.orig_module}.{copy.orig_name} drifted from its original ({orig_where})")
    return problems, len(copies), rewritten


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", default=str(Path(__file__).resolve().parent.parent), help="directory whose *.py files are checked (default: the repo root)")
    parser.add_argument("--fix", action="store_true", help="rewrite drifted copies from their originals")
    args = parser.parse_args(argv)
    if not Path(args.root).is_dir():
        print(f"error: --root {args.root} is not a directory", file=sys.stderr)
        return 2
    if args.fix:  # a rewritten copy may be the original of another copy: repeat while anything changes
        for _ in range(MAX_FIX_PASSES):
            if not check(args.root, fix=True)[2]:
                break
    problems, count, _ = check(args.root)
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        return 1
    print(f"{count} copies checked, all match")
    return 0


if __name__ == "__main__":
    sys.exit(main())
