#!/usr/bin/env python3
"""Count the constructions that make a line of Python slow to read (code golf), per file.

    python scripts/plain_code.py bc_oh.py c2f.py ...                # a table, then each finding
    python scripts/plain_code.py --quiet *.py                       # the table only
    python scripts/plain_code.py --allow packed-assign=3 bc_oh.py   # up to 3 of a kind pass

Each finding is a place where one line does several things a reader must untangle. The cure is
nearly always more lines: a plain `if` block, one assignment a line, a named helper with a `def`.

  packed-assign   `a, b = f(x), g(y)`: one line assigns several unrelated values (a tuple literal
                  of two or more expressions that are not plain names or constants). Unpacking a
                  call's result (`obs, info = env.reset()`) is fine.
  nested-ternary  a conditional expression inside another.
  bool-multiply   a number, string or list multiplied by a comparison or a boolean
                  (`"s" * (n > 1)`, `width * (fusion == "early")`).
  fstring-logic   an f-string field holding a conditional expression, a boolean multiply, or another
                  f-string.
  lambda-assign   a lambda bound to a name (use def).
  side-effect-or  `x or print(...)`, `cond and f()`: a boolean operator used as an if.
  setdefault-rw   `d.setdefault(k, v)` used inside an arithmetic expression (a write hidden in
                  a read).
  noqa            a `# noqa` that silences a linter.
  long-line       a line over --max-length characters (default 100).

Exit status: 0 when no file has a finding beyond what --allow lets pass, 1 otherwise (and when the
output is cut short: `| head` stopped reading), 2 on unreadable input or a bad --allow.
"""

import argparse
import ast
import os
import sys
import tokenize
from collections import Counter
from pathlib import Path

KINDS = [
    "packed-assign",
    "nested-ternary",
    "bool-multiply",
    "fstring-logic",
    "lambda-assign",
    "side-effect-or",
    "setdefault-rw",
    "noqa",
    "long-line",
]


def is_simple(node: ast.AST) -> bool:
    return isinstance(node, (ast.Name, ast.Constant)) or (
        isinstance(node, ast.UnaryOp) and isinstance(node.operand, ast.Constant)
    )


def is_boolish(node: ast.AST) -> bool:
    if isinstance(node, (ast.Compare, ast.BoolOp)):
        return True
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        return True
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "bool"


def has_call(node: ast.AST) -> bool:
    return any(isinstance(n, ast.Call) for n in ast.walk(node))


def findings(path: Path, max_length: int) -> list:
    source = path.read_text()
    tree = ast.parse(source, filename=str(path))
    found = []

    def add(kind, node_or_line):
        line = node_or_line if isinstance(node_or_line, int) else node_or_line.lineno
        found.append((kind, line))

    parents = {}
    for parent in ast.walk(tree):
        for child in ast.iter_child_nodes(parent):
            parents[child] = parent

    for node in ast.walk(tree):
        if isinstance(node, ast.Assign):
            value = node.value
            if (
                any(isinstance(t, (ast.Tuple, ast.List)) for t in node.targets)
                and isinstance(value, ast.Tuple)
                and len(value.elts) >= 2
                and not all(is_simple(e) for e in value.elts)
            ):
                add("packed-assign", node)
            if (
                len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name)
                and isinstance(value, ast.Lambda)
            ):
                add("lambda-assign", node)
        elif isinstance(node, ast.IfExp):
            parent = parents.get(node)
            if not isinstance(parent, ast.IfExp) and any(
                isinstance(n, ast.IfExp) for n in ast.walk(node) if n is not node
            ):
                add("nested-ternary", node)
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
            if is_boolish(node.left) or is_boolish(node.right):
                add("bool-multiply", node)
        elif isinstance(node, ast.JoinedStr):
            if isinstance(parents.get(node), ast.FormattedValue):
                continue  # counted once, at the outer f-string
            for value in node.values:
                if isinstance(value, ast.FormattedValue) and any(
                    isinstance(n, (ast.IfExp, ast.JoinedStr))
                    or (
                        isinstance(n, ast.BinOp)
                        and isinstance(n.op, ast.Mult)
                        and (is_boolish(n.left) or is_boolish(n.right))
                    )
                    for n in ast.walk(value.value)
                ):
                    add("fstring-logic", node)
                    break
        elif (
            isinstance(node, ast.Expr)
            and isinstance(node.value, ast.BoolOp)
            and has_call(node.value)
        ):
            add("side-effect-or", node)
        elif (
            isinstance(node, ast.Lambda)
            and isinstance(node.body, ast.BoolOp)
            and has_call(node.body)
        ):
            add("side-effect-or", node)
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "setdefault"
            and isinstance(parents.get(node), ast.BinOp)
        ):
            add("setdefault-rw", node)

    with path.open("rb") as handle:
        for token in tokenize.tokenize(handle.readline):
            if token.type == tokenize.COMMENT and "noqa" in token.string:
                add("noqa", token.start[0])
    for number, line in enumerate(source.splitlines(), 1):
        if len(line) > max_length:
            add("long-line", number)
    return sorted(found, key=lambda item: (item[1], item[0]))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument(
        "--max-length", type=int, default=100, help="longest line allowed (default 100)"
    )
    parser.add_argument("--quiet", action="store_true", help="the table only")
    parser.add_argument(
        "--allow",
        action="append",
        default=[],
        metavar="KIND=N",
        help="let up to N findings of KIND a file pass (repeatable)",
    )
    args = parser.parse_args(argv)
    allowed = {}
    for item in args.allow:
        kind, _, number = item.partition("=")
        if kind not in KINDS or not number.isdigit():
            print(
                f"error: --allow {item}: use KIND=N with KIND one of {', '.join(KINDS)}",
                file=sys.stderr,
            )
            return 2
        allowed[kind] = int(number)
    rows, total = [], 0
    for path in args.files:
        try:
            found = findings(path, args.max_length)
        except (OSError, SyntaxError, UnicodeDecodeError) as error:
            print(f"error: cannot read {path}: {error}", file=sys.stderr)
            return 2
        counts = Counter(kind for kind, _ in found)
        rows.append((path, counts, found))
        total += sum(max(0, n - allowed.get(kind, 0)) for kind, n in counts.items())
    width = max(len(str(path)) for path, _, _ in rows)
    print(f"{'file':<{width}}  total  " + "  ".join(KINDS))
    for path, counts, _ in rows:
        cells = "  ".join(f"{counts.get(kind, 0):>{len(kind)}}" for kind in KINDS)
        print(f"{str(path):<{width}}  {sum(counts.values()):>5}  {cells}")
    if not args.quiet:
        for path, _, found in rows:
            lines = path.read_text().splitlines()
            for kind, number in found:
                print(f"{path}:{number}: {kind}: {lines[number - 1].strip()[:110]}")
    return 1 if total else 0


if __name__ == "__main__":
    try:
        status = main()
        sys.stdout.flush()  # here, not at exit: a reader gone early is caught below
    except BrokenPipeError:  # piped into `head`, which stopped reading: end quietly, exit 1
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit-time flush passes
        status = 1
    sys.exit(status)
