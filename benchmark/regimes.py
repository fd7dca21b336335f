"""The copycat regime map: where does copying the previous action become a shortcut, and does C2F help there?

    python -m benchmark.regimes --regimes fs1_noise native_hidden --seeds 1 2 3 4 5 --workers 2 \
        [--scripts-dir PATH] [--dry-run]

Each regime is a setting of the shared flags of the method files (control rate, kind of partial
observability); everything else is the paper's protocol (benchmark.paper.paper_settings). For every regime
asked for, this runs benchmark.run_grid over METHODS x ENVS x --seeds into results/regimes/<regime>/runs/
(finished runs are skipped, so an interrupted map resumes), and records in <regime>/runs/<method>/commit.txt
the commit of the scripts that made the runs: a method's runs in a regime must be made by one code version.
(The map's first methods share <regime>/runs/commit.txt.)
"""
import shlex
import subprocess
import sys
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark import run_grid
from benchmark.results import OneLineParser, UsageError, check_distinct, run_cli, write_text

REGIMES = {
    "native_noise": ([], "native control rate, N(0, 0.2^2) noise on the velocities: the paper's setting (Table 2)"),
    "fs1_noise": (["--frame-skip", "1"], "frame skip 1 (the control rate of the FCA authors' MuJoCo code), N(0, 0.2^2) noise on the velocities"),
    "native_hidden": (["--hide-velocities"], "native control rate, velocities zeroed (positions only)"),
    "fs1_hidden": (["--frame-skip", "1", "--hide-velocities"],
                   "frame skip 1, velocities zeroed: the control rate and partial observability of the FCA authors' MuJoCo "
                   "code, not their whole setting (theirs: gym's -v2 envs; 500 native steps an episode, 2000 at frame skip 1, "
                   "where ours are 1000 and 4000; for Hopper 20000 windows drawn at random from a 50000-step expert rollout, "
                   "where ours are the first 20000 steps, 5 episodes at frame skip 1; one scalar mean and std normalising "
                   "every input, where ours are per entry; 100 evaluation episodes, where ours are 10 at each of the last "
                   "three evaluations)"),
}
"""regime name -> (the flags every method file gets, what it is)"""
METHODS = ["bc_so", "bc_oh", "c2f", "c2f_output"]
ENVS = ["Hopper-v4", "Walker2d-v4"]
RESULTS_DIR = Path("results/regimes")


def runs_dir(regime: str, results_dir: Path = RESULTS_DIR) -> Path:
    return Path(results_dir) / regime / "runs"


def existing_runs_dir(regime: str, results_dir: Path = RESULTS_DIR, flag="--results-dir", runs="") -> Path:
    """runs_dir(regime, results_dir), refused in one line when the regime has not been run there
    (flag: the option that named results_dir; runs: the runner's flags that make what the folder holds)."""
    folder = runs_dir(regime, results_dir)
    if not folder.is_dir():
        run = f"python -m benchmark.regimes --regimes {regime}"
        if runs:
            run += f" {runs}"
        if Path(results_dir) != RESULTS_DIR:  # the runner writes into RESULTS_DIR unless told
            run += f" --results-dir {shlex.quote(str(results_dir))}"
        raise UsageError(f"no {folder}: run {run} first, or pass {flag}")
    return folder


def scripts_commit(scripts_dir: Path) -> str:
    """The commit of the scripts folder, refused when its tracked files have changes (not reproducible)."""
    def git(*words):
        return subprocess.run(["git", "-C", str(scripts_dir), *words], capture_output=True, text=True)
    head = git("rev-parse", "HEAD")
    if head.returncode != 0:
        raise UsageError(f"{scripts_dir} is not a git checkout: run the map from a checkout (e.g. a git worktree) of a commit")
    if git("status", "--porcelain", "--untracked-files=no").stdout.strip():
        raise UsageError(f"{scripts_dir} has uncommitted changes: commit them, or run from a git worktree of a fixed commit")
    return head.stdout.strip()


def recorded_commit(folder: Path, method: str):
    """The commit.txt that says which commit made the method's runs in a regime's runs folder, or None.
    A method folder without its own commit.txt was made by the commit of the regime's commit.txt (the map's
    first runs); a method added later (a control, a Table 3 row) records its own."""
    own, regime = Path(folder) / method / "commit.txt", Path(folder) / "commit.txt"
    return own if own.is_file() else regime if regime.is_file() and (Path(folder) / method).is_dir() else None


def record_commit(folder: Path, commit: str, method: str):
    """Write <method>/commit.txt, or check that the method's runs already there were made by the same commit
    (recorded_commit says which file holds it)."""
    own, recorded = folder / method / "commit.txt", recorded_commit(folder, method)
    if recorded is not None and recorded.read_text().strip() != commit:
        raise UsageError(f"{folder / method} holds runs made by commit {recorded.read_text().strip()[:12]}, not {commit[:12]}: "
                         "run from a worktree of that commit (git worktree add ../map <commit>)")
    if recorded is None:
        write_text(own, commit + "\n")


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.regimes", description=__doc__.split("\n\n")[0])
    parser.add_argument("--regimes", nargs="+", required=True, choices=list(REGIMES), help="regimes to run, in this order")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3, 4, 5], help="training seeds (default 1 2 3 4 5)")
    parser.add_argument("--methods", nargs="+", default=METHODS, help=f"default: {' '.join(METHODS)}")
    parser.add_argument("--envs", nargs="+", default=ENVS, help=f"default: {' '.join(ENVS)}")
    parser.add_argument("--workers", type=int, default=2, help="runs at the same time (default 2)")
    parser.add_argument("--results-dir", type=Path, default=RESULTS_DIR, help=f"default: {RESULTS_DIR}")
    parser.add_argument("--scripts-dir", type=Path, default=run_grid.REPO_ROOT, help="checkout whose scripts run (default: this one)")
    parser.add_argument("--save-model", action="store_true", help="save each run's model beside its result (for copycat_analysis.py)")
    parser.add_argument("--dry-run", action="store_true", help="list what would run")
    args = parser.parse_args(argv)
    check_distinct("--regimes", args.regimes)  # else its grid would run twice
    commit = scripts_commit(args.scripts_dir)
    status = 0
    for regime in args.regimes:
        folder = runs_dir(regime, args.results_dir).resolve()
        grid = ["--methods", *args.methods, "--envs", *args.envs, "--seeds", *map(str, args.seeds), "--workers", str(args.workers),
                "--results-dir", str(folder), "--scripts-dir", str(args.scripts_dir), *(["--dry-run"] if args.dry_run else [])]
        flags = REGIMES[regime][0] + (["--save-model"] if args.save_model else [])
        grid += [f"--extra-args={' '.join(flags)}"] if flags else []  # one word: argparse takes "--x" for a flag
        run_grid.parse_options(grid)  # bad methods, envs or sizes stop here, before a commit is recorded
        if not args.dry_run:
            for method in args.methods:
                record_commit(folder, commit, method)
        print(f"== {regime}: {REGIMES[regime][1]}", flush=True)
        status = max(status, run_grid.main(grid))
    return status


if __name__ == "__main__":
    run_cli(main)
