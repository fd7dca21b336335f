"""What the speed benchmarks share: a method script as an older commit had it, and one timed run of a command.

    from benchmark.baseline import BEFORE_FUSED_ADAM, script_at, timed_run
    path = script_at("8ce2c69", "c2f", folder)   # folder/8ce2c69/c2f.py, written from `git show`
    seconds = timed_run([sys.executable, str(path), ...])

A method file imports nothing from this repository, so its old text runs as it ran then. It runs from the
repository's root, where it finds demos/ and experts/ as the new one does.
"""

import os
import subprocess
import time
from pathlib import Path

from benchmark.machine import describe, machine
from benchmark.results import UsageError, last_line_of
from benchmark.run_grid import method_files

REPO_ROOT = Path(__file__).resolve().parent.parent
BEFORE_FUSED_ADAM = "8ce2c69"
"""the last commit before issue 56 (fused Adam, sensor envs built once): the benchmarks' default baseline"""


def script_at(commit: str, script: str, folder: Path) -> Path:
    """Write `script`.py as it was at `commit` into folder/<commit>/ and return its path; "HEAD" is
    the working tree's file itself, uncommitted changes included."""
    if commit == "HEAD":
        return REPO_ROOT / f"{script}.py"
    if not commit.strip():  # git would show the staged file (both benchmarks take it as --baseline)
        raise UsageError(f"--baseline needs a commit, e.g. --baseline {BEFORE_FUSED_ADAM}")
    shown = git("show", f"{commit}:{script}.py")
    if shown.returncode != 0:
        raise UsageError(not_shown(commit, script))
    path = folder / commit / f"{script}.py"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(shown.stdout)
    return path


def git(*args: str) -> subprocess.CompletedProcess:
    """`git <args>` in the repository, its output captured; the exit status is not checked."""
    return subprocess.run(["git", *args], cwd=REPO_ROOT, capture_output=True, text=True)


def not_shown(commit: str, script: str) -> str:
    """Why git cannot show `script`.py at `commit`: no such commit, or a commit without the file."""
    if git("rev-parse", "--verify", f"{commit}^{{commit}}").returncode != 0:
        return f"git cannot show {script}.py at {commit!r}: give a commit of this repository"
    added = git("log", "--diff-filter=A", "--format=%h", "-1", "--", f"{script}.py").stdout.strip()
    example = ""
    if added:
        example = f", e.g. {added}, which added it"
    # A version older than the default baseline is refused by both benchmarks: name that one.
    if added and git("merge-base", "--is-ancestor", added, BEFORE_FUSED_ADAM).returncode == 0:
        example = f", e.g. {BEFORE_FUSED_ADAM}"
    return f"commit {commit!r} has no {script}.py: give a later commit{example}"


def check_method_file(flag: str, script: str):
    """Refuse what is not a method file (what the speed benchmarks run and read) before any run."""
    known = method_files(REPO_ROOT)
    if script not in known:
        raise UsageError(f"{flag} {script} is not a method file: choose from {', '.join(known)}")


def timed_run(command: list) -> float:
    """Run the command from the repository's root; the seconds it took. A failed run is refused with its
    error line (results.last_line_of: the line inside tyro's box, else the last line of stderr)."""
    start = time.perf_counter()
    finished = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if finished.returncode != 0:
        shown = " ".join(map(str, command[1:]))
        raise UsageError(f"{shown} failed: {last_line_of(finished.stderr)}")
    return seconds


def machine_line() -> str:
    """The machine a timing was made on, in one line: CPU, its family and model, cores, torch."""
    record = machine()
    cores = len(os.sched_getaffinity(0))
    family = f"CPU family {record['cpu_family']}, model {record['cpu_model']}"
    return f"{describe(record)}, {family}, {cores} cores, torch {record['torch']}"
