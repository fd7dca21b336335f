"""Per-run JSON results: their paths, and the checks that tell a valid result from a corrupt or partial one.

A result is the JSON a method script writes (bc_oh.py's run()), `{output_dir}/result_seeds{S}.json`:
    {"env": ..., "method": ..., "args": {...}, "scores": {"<seed>": {"score": s, "evaluations": [[epoch, return], ...]}},
     "mean": ..., "std": ...}
and, for the expert (benchmark/run_grid.py writes it), the same shape with one evaluation per seed.
"""
import argparse
import contextlib
import json
import math
import os
import signal
import statistics
import sys
from pathlib import Path

EXPERT = "expert"
"""the method name of the PPO expert's own evaluation (expert_ppo.py --eval-only)"""


class UsageError(Exception):
    """Bad input from the user: printed as one line on stderr, exit status 2, no traceback."""


class ResultError(Exception):
    """A result file that cannot be counted: unreadable, partial, or not the run it claims to be."""


class OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are UsageErrors: one line on stderr and exit 2, like every other bad input."""

    def error(self, message):
        raise UsageError(f"{message}: see {self.prog} --help")


def run_cli(main):
    """Call main(); turn a UsageError into one line on stderr and exit status 2, and Ctrl-C or `kill` into one line
    and exit status 130 (what main holds in `with` blocks, temporary folders and child processes, is cleaned up)."""
    previous = signal.signal(signal.SIGTERM, signal.default_int_handler)  # `kill PID` stops it as Ctrl-C does
    try:
        status = main()
        # Here, not at exit: a reader that has gone (`| head`) is caught below.
        sys.stdout.flush()
        sys.exit(status)
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    except BrokenPipeError:  # output piped into `head` that stopped reading: end quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # so the exit-time flush cannot fail
        sys.exit(1)
    except OSError as error:  # a path that cannot be read or written: a folder, a file in the way, no right to it
        path = error.filename2 or error.filename or "the output"  # os.replace(tmp, path) names the path second; stdout none
        print(f"error: cannot use {path}: {error.strerror or error}: pass another path", file=sys.stderr)
        sys.exit(2)
    finally:
        signal.signal(signal.SIGTERM, previous)  # a caller in this process (a test) keeps its own


def check_folder(folder: Path, what: str, fix: str):
    """Refuse in one line a folder to read that is not there, or is a file:
    '{what} {folder} not found: {fix}'."""
    if folder.is_dir():
        return
    problem = "is a file, not a folder" if folder.exists() else "not found"
    raise UsageError(f"{what} {folder} {problem}: {fix}")


def check_writable(path: Path, flag: str, is_file: bool = False):
    """Refuse in one line, before any work, an output path (a folder, or with is_file a file) that
    cannot be written: a file in the way of its folder, a folder where the file goes, no right to
    it."""
    path = Path(path)
    reason = unwritable(path.parent if is_file else path)
    if is_file and path.is_dir():
        reason = f"{path} is a folder"
    if reason:
        raise UsageError(f"{flag} {path} cannot be written: {reason}: pass another {flag}")


def unwritable(folder: Path):
    """Why files cannot be written in folder (made with its parents as needed), or None."""
    existing = next(path for path in (folder, *folder.parents) if path.exists())
    if not existing.is_dir():
        return f"{existing} is not a folder"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{existing} is not writable"
    return None


def check_distinct(flag: str, values: list):
    """Refuse a value given twice: the same run (or timing) would be made twice, side by side."""
    repeated = [value for index, value in enumerate(values) if value in values[:index]]
    if repeated:
        raise UsageError(f"{flag} lists {repeated[0]} twice: name each once")


def last_line_of(text: str) -> str:
    """The line of a failed run's output that names its problem: the first inside tyro's error box, else the last."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    tops = [i for i, line in enumerate(lines) if line.startswith("╭")]
    if tops and lines[-1].startswith("╰"):  # tyro's boxed error: its first line inside the box names the problem
        lines = [lines[tops[-1] + 1].strip("│ ")]
    return lines[-1][:200] if lines else "(empty log)"


def result_path(results_dir, method: str, env: str, seeds) -> Path:
    """Where a method script given --output-dir results_dir/method/env --seeds *seeds writes its result."""
    return Path(results_dir) / method / env / f"result_seeds{'-'.join(map(str, seeds))}.json"


def seed_score(evaluations: list) -> float:
    """The paper's score of one seed: the mean return of its last three evaluations."""
    last = [ret for _, ret in evaluations[-3:]]
    return sum(last) / len(last)


def make_result(env: str, method: str, args: dict, evaluations: dict) -> dict:
    """A result in the scripts' JSON shape from {seed: [[epoch, return], ...]}."""
    scores = {str(seed): {"score": seed_score(runs), "evaluations": runs} for seed, runs in evaluations.items()}
    values = [entry["score"] for entry in scores.values()]
    return {"env": env, "method": method, "args": args, "scores": scores, "mean": statistics.fmean(values), "std": statistics.pstdev(values)}


def finite_number(value) -> bool:
    """Whether value is a finite int or float (a bool is not a number here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def read_result(path, method: str, env: str, seeds=None) -> dict:
    """Load and check a result; raises ResultError(why) unless it is complete and is the run of
    `method` on `env` for exactly `seeds` (by default the seeds its file name says)."""
    path = Path(path)
    if seeds is None:
        try:
            seeds = [int(s) for s in path.stem.removeprefix("result_seeds").split("-")]
        except ValueError:
            raise ResultError("file name is not result_seeds<S>[-<S>...].json")
    try:
        result = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ResultError(f"unreadable JSON ({type(error).__name__}: {error})")
    if not isinstance(result, dict):
        raise ResultError("not a JSON object")
    missing = [key for key in ("env", "method", "args", "scores", "mean", "std") if key not in result]
    if missing:
        raise ResultError(f"missing keys {', '.join(missing)}")
    made_by = [method]
    if method == "c2f_table3":
        # The Table 3 variants ran c2f.py until c2f_table3.py took its ablation flags (issue 55): their
        # results made before name the method "c2f", with the variant's flags in their args.
        made_by.append("c2f")
    if result["method"] not in made_by or result["env"] != env:
        raise ResultError(f"holds {result['method']} on {result['env']}, expected {method} on {env}")
    scores = result["scores"]
    if not isinstance(scores, dict) or sorted(scores) != sorted(map(str, seeds)):
        got = sorted(scores) if isinstance(scores, dict) else type(scores).__name__
        raise ResultError(f"holds seeds {got}, expected {list(seeds)}")
    if not isinstance(result["args"], dict):
        raise ResultError("args is not a JSON object")
    for seed, entry in scores.items():
        evaluations = entry.get("evaluations") if isinstance(entry, dict) else None
        if not evaluations or not all(isinstance(e, list) and len(e) == 2 and all(map(finite_number, e)) for e in evaluations):
            raise ResultError(f"seed {seed} has no valid evaluations (a list of [epoch, return] pairs)")
        if not finite_number(entry.get("score")) or not math.isclose(entry["score"], seed_score(evaluations), rel_tol=1e-6, abs_tol=1e-6):
            raise ResultError(f"seed {seed}: score {entry.get('score')} is not the mean of its last three evaluations")
    if not finite_number(result["mean"]) or not finite_number(result["std"]):
        raise ResultError("mean or std is not a number")
    return result


@contextlib.contextmanager
def written_atomically(path):
    """Yield a temporary path to write to; on success rename it to `path` (no half-written files)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.tmp{os.getpid()}{path.suffix}")  # keep the suffix for savefig
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text(path, text: str):
    with written_atomically(path) as tmp:
        tmp.write_text(text)
