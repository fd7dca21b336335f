"""Tests of scripts/check_copies.py, the "# Copied from" checker, on tiny files in a temp dir."""
import os
import re
import resource
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from check_copies import apply_renames, check, find_copies, parse_renames, top_level_blocks
from conftest import METHOD_FILES, REPO_ROOT, run_in_process, run_script

ORIGINAL = '''\
import functools


def helper(x):
    """Doubles x."""
    return 2 * x


@functools.lru_cache
class Foo:
    size = 3

    def grow(self):
        return helper(self.size)
'''
# exact copies of both definitions, each under its marker
COPY = ORIGINAL.replace("def helper", "# Copied from orig.helper\ndef helper").replace("@functools", "# Copied from orig.Foo\n@functools")


def write(directory, name, text):
    (directory / name).write_text(textwrap.dedent(text))


def check_copies(root, *args):
    return run_script("scripts/check_copies.py", "--root", root, *args)


@pytest.fixture
def root(tmp_path):
    """A directory with orig.py and copy.py (COPY)."""
    write(tmp_path, "orig.py", ORIGINAL)
    write(tmp_path, "copy.py", COPY)
    return tmp_path


def test_matching_copies_pass(root):
    result = check_copies(root)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "2 copies checked, all match"


def test_drift_fails_naming_copy_and_original(root):
    copy = root / "copy.py"
    copy.write_text(copy.read_text().replace("size = 3", "size = 4"))
    result = check_copies(root)
    assert result.returncode == 1
    assert result.stderr.strip() == "copy.py:10: copy of orig.Foo drifted from its original (orig.py:9)"


def test_drift_in_a_decorator_is_found(root):
    copy = root / "copy.py"
    copy.write_text(copy.read_text().replace("@functools.lru_cache", "@functools.cache"))
    assert check(root)[0] == ["copy.py:10: copy of orig.Foo drifted from its original (orig.py:9)"]


def test_renames_apply_to_the_original(tmp_path):
    write(tmp_path, "orig.py", ORIGINAL)
    write(tmp_path, "renamed.py", '''\
        # Copied from orig.helper with helper->triple, 2->3, Doubles->Triples
        def triple(x):
            """Triples x."""
            return 3 * x
        ''')
    assert check_copies(tmp_path).returncode == 0
    (tmp_path / "renamed.py").write_text((tmp_path / "renamed.py").read_text().replace("3 * x", "2 * x"))
    result = check_copies(tmp_path)
    assert result.returncode == 1
    assert "renamed.py:1: copy of orig.helper drifted from its original (orig.py:4)" in result.stderr


def test_parse_and_apply_renames():
    renames = parse_renames("Foo->Bar, foo->bar")
    assert renames == [("Foo", "Bar"), ("foo", "bar")]
    assert apply_renames("Foo.foo(food)", renames) == "Bar.bar(bard)"
    with pytest.raises(ValueError, match="bad rename"):
        parse_renames("Foo=>Bar")


@pytest.mark.parametrize(
    "copy_text, message",
    [
        ("# Copied from orig.nothing\ndef nothing():\n    pass\n", "copy.py:1: original orig.nothing not found"),
        ("# Copied from absent.helper\ndef helper(x):\n    pass\n", "copy.py:1: original absent.helper not found"),
        ("# Copied from orig.helper\n\ndef helper(x):\n    pass\n", "copy.py:1: marker is not directly above a top-level def or class"),
        ("# Copied from orig.helper\nx = 1\n", "copy.py:1: marker is not directly above a top-level def or class"),
        ("# Copied from orig\ndef helper(x):\n    pass\n", "copy.py:1: malformed marker"),
        ("# Copied from orig.helper with helper\ndef helper(x):\n    pass\n", "copy.py:1: bad rename 'helper'"),
    ],
)
def test_bad_markers_fail(tmp_path, copy_text, message):
    write(tmp_path, "orig.py", ORIGINAL)
    write(tmp_path, "copy.py", copy_text)
    result = check_copies(tmp_path)
    assert result.returncode == 1
    assert result.stderr.startswith(message), result.stderr
    assert check_copies(tmp_path, "--fix").returncode == 1  # nothing --fix can repair


def test_fix_restores_the_original_text(root):
    copy = root / "copy.py"
    good = copy.read_text()
    drifted = good.replace('    """Doubles x."""\n', "").replace("size = 3", "size = 3\n    extra = 1")
    copy.write_text(drifted)
    assert check(root)[0] and len(check(root)[0]) == 2

    result = check_copies(root, "--fix")
    assert result.returncode == 0, result.stderr
    assert copy.read_text() == good
    assert (root / "orig.py").read_text() == ORIGINAL
    assert result.stdout.splitlines()[-1] == "2 copies checked, all match"


def limit_file_size():
    """In the child: files may not grow past 64 bytes (a full disk, in effect), and the write fails with EFBIG
    instead of the process being killed by SIGXFSZ."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (64, 64))


def test_fix_replaces_a_copy_at_once_and_a_failed_write_leaves_it_as_it_was(root):
    """--fix rewrote a copy in place: a write that failed midway (a full disk) left the copy cut short, its end lost.
    It now writes a temporary file beside the copy and renames it over the copy: no temporary file is left either way,
    and the copy keeps its permissions."""
    copy = root / "copy.py"
    drifted = copy.read_text().replace("size = 3", "size = 4")
    copy.write_text(drifted)
    copy.chmod(0o754)
    command = [sys.executable, str(REPO_ROOT / "scripts/check_copies.py"), "--root", str(root), "--fix"]
    failed = subprocess.run(command, check=False, capture_output=True, text=True, timeout=60, preexec_fn=limit_file_size)
    assert failed.returncode == 2 and "Traceback" not in failed.stderr, failed.stderr
    fix = "free disk space or make its folder writable; it is unchanged"
    assert failed.stderr == f"error: --fix cannot rewrite {copy} (File too large): {fix}\n"
    assert copy.read_text() == drifted
    assert sorted(path.name for path in root.iterdir()) == ["copy.py", "orig.py"]
    fixed = check_copies(root, "--fix")
    assert fixed.returncode == 0, fixed.stderr
    assert copy.read_text() == COPY and (copy.stat().st_mode & 0o777) == 0o754
    assert sorted(path.name for path in root.iterdir()) == ["copy.py", "orig.py"]


def test_copies_of_copies_compare_with_their_immediate_original(root):
    write(root, "a_second.py", "# Copied from copy.helper with 2->4\ndef helper(x):\n    \"\"\"Doubles x.\"\"\"\n    return 4 * x\n")
    assert check(root)[0] == []
    copy = root / "copy.py"
    copy.write_text(copy.read_text().replace("return 2 * x", "return 2 * x + 0"))
    # a_second.py is checked first, against the drifted copy.py; --fix repairs both in order
    assert [p.split(":")[0] for p in check(root)[0]] == ["a_second.py", "copy.py"]
    assert check_copies(root, "--fix").returncode == 0
    assert "return 4 * x\n" in (root / "a_second.py").read_text()


def test_real_repo_copies_match():
    result = run_script("scripts/check_copies.py")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("all match")


# The method files whose own version of a shared block differs from bc_oh's, on purpose: (file, name): why.
OWN_VERSIONS = {
    ("dagger.py", "run"): "its seeds are DAgger rounds: it checks the DAgger flags and records each seed's bc_oh round 0 and rounds",
    ("average_ensemble.py", "run"): "it also scores and reports each ensemble member by the same rule",
    ("average_ensemble.py", "fit"): "it evaluates each member beside the ensemble and logs both losses",
    ("fca.py", "fit"): "it decays the adversary's learning rate too and logs the adversary's mean error",
    ("dagger.py", "train_and_record"): "a seed's entry also holds its bc_oh round 0 score and its rounds",
    ("average_ensemble.py", "train_and_record"): "a seed's entry also scores each ensemble member, and its result sums them up",
    ("dagger.py", "fit"): "it trains through every round: the rounds share one minibatch generator and one epoch count (the evaluation seeds)",
    ("average_ensemble.py", "write_result"): "its result also sums up each ensemble member's scores",
    ("c2f_table3.py", "fit"): "--two-stage trains the coarse model first, without evaluations",
    ("keyframe.py", "run"): "it also checks KeyFrame's own flags",
}
SHARED_BEFORE_THE_BANNER = {"UsageError", "fit"}
"""bc_oh's error type and training loop sit above its evaluation section (the method's section holds the loop), and
every method file copies them too."""


def shared_plumbing():
    """{name: original module} of bc_oh.py's blocks from its "# ---- Evaluation" banner on (evaluation, env, demos,
    seeds and main), plus UsageError and fit: bc_oh for its own, the module it copies from for any it copies itself."""
    source = (REPO_ROOT / "bc_oh.py").read_text()
    banner = next(number for number, line in enumerate(source.splitlines(), 1) if line.startswith("# ---- Evaluation"))
    names = {name for name, block in top_level_blocks(source).items() if block.start > banner} | SHARED_BEFORE_THE_BANNER
    copied_by_bc_oh = {name: copy.orig_module for copy in find_copies("bc_oh.py", source, []) for name in copy.names}
    return {name: copied_by_bc_oh.get(name, "bc_oh") for name in names}


def test_every_method_file_is_checked():
    """Every method file carries checked copies of all of bc_oh's shared plumbing, so that the checker covers
    it: a block rewritten by hand in one file (no marker, or a marker lost) fails here."""
    plumbing = shared_plumbing()
    assert {"run", "make_env", "load_demos", "train_and_record", "evaluate", "fit"} <= set(plumbing)
    # the method files only load demos, and the harness records the machine: none of them carries these any more
    gone = {"load_or_generate_demos", "generate_demos", "demo_meta", "load_expert", "ExpertPolicy", "CudaGraphStep",
            "make_adam", "set_learning_rate", "machine", "write_atomically", "run_name", "finished_seed",
            "require"}
    assert not gone & set(plumbing), gone & set(plumbing)
    method_files = sorted(path.name for path in REPO_ROOT.glob("*.py") if re.search(r'^METHOD = "\w+"', path.read_text(), re.M))
    assert method_files == sorted(METHOD_FILES), "conftest.METHOD_FILES names every method file"
    missing, problems = [], []
    for file in method_files:
        if file == "bc_oh.py":
            continue
        source = (REPO_ROOT / file).read_text()
        copied = {(copy.orig_module, name) for copy in find_copies(file, source, problems) for name in copy.names}
        defined = top_level_blocks(source)
        for name, module in sorted(plumbing.items()):
            if (file, name) in OWN_VERSIONS:
                assert name in defined and (module, name) not in copied, f"{file}: {name} is a copy of {module}.{name} again: drop it from OWN_VERSIONS"
            elif (module, name) not in copied:
                missing.append(f"{file}: no '# Copied from {module}.{name}'" + (" (an unchecked version of its own)" if name in defined else ""))
    assert not problems, problems
    assert not missing, "\n".join(missing)


def test_dagger_alone_queries_the_expert():
    """DAgger's method asks the expert for labels: it keeps checked copies of expert_ppo's ExpertPolicy and
    load_expert; the other method files no longer define them (they load demos that expert_ppo.py made)."""
    method_files = sorted(path.name for path in REPO_ROOT.glob("*.py") if re.search(r'^METHOD = "\w+"', path.read_text(), re.M))
    for file in method_files:
        source = (REPO_ROOT / file).read_text()
        copied = {(copy.orig_module, name) for copy in find_copies(file, source, []) for name in copy.names}
        defined = {"ExpertPolicy", "load_expert"} & set(top_level_blocks(source))
        if file == "dagger.py":
            assert {("expert_ppo", "ExpertPolicy"), ("expert_ppo", "load_expert")} <= copied
        else:
            assert not defined, f"{file} defines {sorted(defined)}"


SPAN = ORIGINAL.replace("def helper", "# Copied from orig.helper..Foo\ndef helper")


def test_a_span_covers_its_definitions_and_what_lies_between(tmp_path):
    """`# Copied from orig.first..last` checks the whole run of definitions, the blank lines and comments between
    them included, and --fix rewrites it from the original."""
    write(tmp_path, "orig.py", ORIGINAL)
    write(tmp_path, "span.py", SPAN)
    problems, count, _ = check(tmp_path)
    assert (problems, count) == ([], 1)
    (copy,) = find_copies("span.py", (tmp_path / "span.py").read_text(), [])
    assert copy.names == ("helper", "Foo")
    for drift in ("size = 3", "\n\n@functools"):  # inside a definition, and between two of them
        (tmp_path / "span.py").write_text(SPAN.replace(drift, drift.replace("3", "4").replace("\n\n@", "\n# new\n@")))
        assert check(tmp_path)[0] == ["span.py:4: copy of orig.helper..Foo drifted from its original (orig.py:4)"]
        assert check(tmp_path, fix=True)[2] == 1 and (tmp_path / "span.py").read_text() == SPAN


def test_a_span_must_end_below_its_marker_and_hold_no_marker(tmp_path):
    write(tmp_path, "orig.py", ORIGINAL)
    write(tmp_path, "late.py", ORIGINAL.replace("def helper", "# Copied from orig.helper..nothing\ndef helper"))
    write(tmp_path, "nested.py", SPAN.replace("@functools", "# Copied from orig.Foo\n@functools"))
    problems = check(tmp_path)[0]
    assert "late.py:4: span end nothing is not a definition below the marker" in problems
    assert "nested.py:10: marker inside the span of line 4" in problems


ROOT_FIX = "pass the folder holding the method files (default: the repo root)"


@pytest.mark.parametrize("args, message", [
    (["--bogus"], "unrecognized arguments: --bogus: see python scripts/check_copies.py --help"),
    (["--root", "afile"], f"--root {{tmp}}/afile is a file, not a folder: {ROOT_FIX}"),
    (["--root", "missing"], f"--root {{tmp}}/missing not found: {ROOT_FIX}"),
    (["--root", ""], f"--root is empty: {ROOT_FIX}"),
    # a folder with nothing to check read "0 copies checked, all match", exit 0
    (["--root", "empty"], f"--root {{tmp}}/empty holds no .py files: {ROOT_FIX}"),
], ids=["unknown flag", "a file", "missing", "empty", "no .py files"])
def test_a_bad_command_line_is_one_line(tmp_path, args, message):
    """argparse's errors were two lines (usage, then the error); --root named no fix."""
    (tmp_path / "afile").write_text("")
    (tmp_path / "empty").mkdir()
    args = [str(tmp_path / arg) if arg in ("afile", "missing", "empty") else arg for arg in args]
    result = run_in_process("scripts/check_copies.py", *args)
    expected = "error: " + message.format(tmp=tmp_path) + "\n"
    assert (result.returncode, result.stdout, result.stderr) == (2, "", expected)


def test_a_file_that_is_not_utf8_is_a_problem_not_a_traceback(root):
    (root / "binary.py").write_bytes(b"\xff\xfe x = 1\n")
    result = run_in_process("scripts/check_copies.py", "--root", root)
    assert (result.returncode, result.stderr) == (1, "binary.py: cannot read (not UTF-8 text)\n")


def test_fix_refuses_a_file_it_cannot_write(root, monkeypatch):
    """A read-only copy (chmod does not stop root: os.access, which --fix asks, plays it) was
    rewritten anyway, or raised a traceback for a user who could not write it."""
    copy = root / "copy.py"
    drifted = copy.read_text().replace("size = 3", "size = 4")
    copy.write_text(drifted)
    real_access = os.access

    def access(path, mode, **kwargs):
        return real_access(path, mode, **kwargs) and Path(path) != copy

    monkeypatch.setattr(os, "access", access)
    result = run_in_process("scripts/check_copies.py", "--root", root, "--fix")
    expected = f"error: --fix cannot write {copy}: make it writable, or fix the copy by hand\n"
    assert (result.returncode, result.stderr) == (2, expected)
    assert copy.read_text() == drifted


def test_output_into_a_closed_pipe_ends_quietly(root):
    """`check_copies.py | head` where the reader has gone: a BrokenPipeError traceback (stdout
    unbuffered, as PYTHONUNBUFFERED=1 sets it, so the line is written inside main)."""
    read, write = os.pipe()
    os.close(read)
    command = [sys.executable, str(REPO_ROOT / "scripts/check_copies.py"), "--root", str(root)]
    environment = dict(os.environ, PYTHONUNBUFFERED="1")
    try:
        done = subprocess.run(command, stdout=write, stderr=subprocess.PIPE,
                              text=True, env=environment, timeout=60)
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (1, "")
