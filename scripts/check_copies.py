"""Check that code copied between the method files is still identical to its original.

The scripts at the repo root are single-file on purpose, so they duplicate shared code. Each copied
top-level function or class carries a marker on the line directly above it (or above its decorators):

    # Copied from bc_oh.make_env
    # Copied from bc_oh.make_env with Foo->Bar, foo->bar
    # Copied from bc_oh.run..stack_history

The copy must equal the top-level def/class `make_env` of bc_oh.py, after the renames (plain text
replacements, applied in order to the original). A span (`first..last`) covers a run of consecutive
definitions: the text from the marker's definition to the end of `last` must equal bc_oh.py's text from
`run` to the end of `stack_history`, comments and blank lines between them included. A copy may itself be
the original of another copy.

    python scripts/check_copies.py          # report drifted copies, exit 1 if any
    python scripts/check_copies.py --fix    # rewrite drifted copies from their originals
"""
import ast
import os
import re
import stat
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

# The repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.results import OneLineParser, UsageError, check_folder, run_cli

MARKER_PREFIX = "# Copied from"
MARKER = re.compile(r"# Copied from (\w+)\.(\w+)(?:\.\.(\w+))?(?: with (.+?))?\s*$")
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
    last_name: str = ""  # a span's last definition in the original; "" for one definition
    names: tuple = ()  # the definitions the copy covers (a span's as the copy names them: spans take no renames)


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
    blocks = top_level_blocks(source)
    starts = {block.start: block for block in blocks.values()}
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
                renames = parse_renames(match.group(4)) if match.group(4) else []
            except ValueError as error:
                problems.append(f"{file}:{number}: {error}")
                continue
            block, last = starts[number + 1], match.group(3) or ""
            if last:  # a span: from this definition to the end of the copy's `last`
                end = blocks.get(apply_renames(last, renames))
                if end is None or end.end < block.start:
                    problems.append(f"{file}:{number}: span end {last} is not a definition below the marker")
                    continue
                block = Block(block.start, end.end)
            names = tuple(name for name, b in blocks.items() if block.start <= b.start <= block.end) if last else ()
            names = names or (match.group(2),)
            copies.append(Copy(file, number, match.group(1), match.group(2), renames, block, last, names))
    for span in (copy for copy in copies if copy.last_name):  # a marker inside a span would be fixed twice
        for inner in (copy for copy in copies if span.block.start < copy.marker_line < span.block.end):
            problems.append(f"{file}:{inner.marker_line}: marker inside the span of line {span.marker_line}")
    return copies


def write_atomically(path, text):
    """Replace the file at path by text at once: written to a temporary file beside it (a name that
    does not end in .py, so a leftover is never checked), then renamed over it. A write that fails
    (a full disk) leaves the file as it was."""
    path = Path(path)
    mode = stat.S_IMODE(path.stat().st_mode)
    tmp = None
    try:
        handle, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with open(handle, "w") as file:
            file.write(text)
        # mkstemp makes the file for its owner only: keep the copy's own permissions.
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except OSError as error:
        fix = "free disk space or make its folder writable; it is unchanged"
        raise UsageError(f"--fix cannot rewrite {path} ({error.strerror}): {fix}")
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)


def check(root, fix=False):
    """Check (with fix: rewrite drifted) copies in root/*.py. Returns (problems, copies checked, rewritten)."""
    root = Path(root)
    sources, problems, copies, rewritten = {}, [], [], 0
    for path in sorted(root.glob("*.py")):
        try:
            sources[path.name] = path.read_text()
        except (OSError, UnicodeDecodeError) as error:
            reason = getattr(error, "strerror", None) or "not UTF-8 text"
            problems.append(f"{path.name}: cannot read ({reason})")
            continue
        try:
            copies += find_copies(path.name, sources[path.name], problems)
        except SyntaxError as error:
            problems.append(f"{path.name}:{error.lineno}: cannot parse ({error.msg})")
    # Bottom-up, so a fix that changes a block's length leaves the line numbers above it valid.
    for copy in sorted(copies, key=lambda c: (c.file, -c.marker_line)):
        where, name = f"{copy.file}:{copy.marker_line}", copy.orig_name + (f"..{copy.last_name}" if copy.last_name else "")
        orig_file = f"{copy.orig_module}.py"
        try:
            orig_blocks = top_level_blocks(sources[orig_file])
        except (KeyError, SyntaxError):
            orig_blocks = {}
        orig_block, last = orig_blocks.get(copy.orig_name), orig_blocks.get(copy.last_name or copy.orig_name)
        if orig_block is None or last is None or last.end < orig_block.start:
            problems.append(f"{where}: original {copy.orig_module}.{name} not found")
            continue
        orig_block = Block(orig_block.start, last.end)
        expected = apply_renames(block_text(sources[orig_file].splitlines(keepends=True), orig_block), copy.renames)
        lines = sources[copy.file].splitlines(keepends=True)
        if block_text(lines, copy.block) == expected:
            continue
        orig_where = f"{orig_file}:{orig_block.start}"
        if fix and not os.access(root / copy.file, os.W_OK):
            fixing = "make it writable, or fix the copy by hand"
            raise UsageError(f"--fix cannot write {root / copy.file}: {fixing}")
        if fix:
            lines[copy.block.start - 1 : copy.block.end] = [expected]
            sources[copy.file] = "".join(lines)
            write_atomically(root / copy.file, sources[copy.file])
            rewritten += 1
            print(f"{where}: rewrote copy of {copy.orig_module}.{name} from {orig_where}")
        else:
            problems.append(f"{where}: copy of {copy.orig_module}.{name} drifted from its original ({orig_where})")
    return problems, len(copies), rewritten


def main(argv=None):
    description = __doc__.split("\n\n")[0]
    parser = OneLineParser(prog="python scripts/check_copies.py", description=description)
    parser.add_argument("--root", default=str(Path(__file__).resolve().parent.parent), help="directory whose *.py files are checked (default: the repo root)")
    parser.add_argument("--fix", action="store_true", help="rewrite drifted copies from their originals")
    args = parser.parse_args(argv)
    root = Path(args.root)
    fix = "pass the folder holding the method files (default: the repo root)"
    if not args.root:
        raise UsageError(f"--root is empty: {fix}")
    check_folder(root, "--root", fix)
    if not any(root.glob("*.py")):  # nothing to check would read "0 copies checked, all match"
        raise UsageError(f"--root {root} holds no .py files: {fix}")
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
    run_cli(main)
