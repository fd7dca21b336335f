"""Run methods x envs x seeds of the Table 2 benchmark, each combination as its own process.

    python -m benchmark.run_grid --methods bc_so bc_oh c2f expert --envs Hopper-v4 HalfCheetah-v4 Ant-v4 \
        --seeds 1 2 3 --workers 4 [--cuda] [--extra-args "--epochs 2"] [--results-dir results/runs]

A combination runs `python <method>.py --env E --seeds S --output-dir <results-dir>/<method>/<env>` (plus
--extra-args, plus --cuda) from the repository root, logging to <results-dir>/<method>/<env>/seed<S>.log.
Method `expert` evaluates experts/<env>.pt with `expert_ppo.py --eval-only` once per env (the expert is
deterministic and its evaluation episodes are seeded by expert_ppo.py, so it is seed 0) and stores the
result in the same JSON shape, with score = mean return over --expert-episodes episodes.

Before its runs the grid makes the demo files they load (`expert_ppo.py --env E --make-demos`, at the frame skip
and sample count of --extra-args; cheap when a file is already made from the same expert), and after each method
run it adds where the run was made (`machine`, benchmark/machine.py) to its result.

The grid accumulates: a combination whose valid result exists, made with the settings asked for now
(the paper's unless --extra-args changes them), is skipped. A corrupt or partial result, or one made
with other settings, is reported and re-run. A run that fails does not stop the others; failures are
listed at the end and make the exit status 1. `--dry-run` only lists; `--slurm FILE` writes the grid
as a SLURM array job (one array index per combination) instead of running it (with --dry-run, prints
it and writes nothing).
"""
import json
import os
import re
import shlex
import signal
import statistics
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.paper import VARIANTS, as_flags, paper_settings, script_of, setting_differences, variant_flags, variant_settings
from benchmark.results import (EXPERT, OneLineParser, ResultError, UsageError, check_distinct, last_line_of, make_result, read_result, result_path,
                               run_cli, unwritable, write_text)

REPO_ROOT = Path(__file__).resolve().parent.parent
EXPERT_SEED = 0
"""the expert's one evaluation per env is stored as seed 0"""
SET_BY_RUNNER = ("env", "seeds", "output_dir")
"""flags the runner sets per combination: not allowed in --extra-args"""
NOT_SETTINGS = ("cuda", "cuda_graph", "save_model", "workers")
"""flags that do not change a result: a result made with or without them counts as done either way"""


@dataclass(frozen=True)
class Run:
    method: str
    env: str
    seed: int

    def __str__(self):
        return f"{self.method} {self.env} seed {self.seed}"


@dataclass
class Options:
    methods: list
    envs: list
    seeds: list
    workers: int = 1
    cuda: bool = False
    extra_args: list = field(default_factory=list)
    expert_episodes: int = 20
    results_dir: Path = Path("results/runs")
    scripts_dir: Path = REPO_ROOT
    slurm: str = None
    dry_run: bool = False


def parse_options(argv=None) -> Options:
    parser = OneLineParser(prog="python -m benchmark.run_grid", description=__doc__.split("\n\n")[0])
    parser.add_argument("--methods", nargs="+", required=True, help="method file names without .py, their variants ("
                        + ", ".join(f"{name} = {script}.py {' '.join(as_flags(flags))}" for name, (script, flags) in VARIANTS.items())
                        + "), and/or `expert`")
    parser.add_argument("--envs", nargs="+", required=True, help="gymnasium MuJoCo env ids, e.g. Hopper-v4")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3], help="training seeds (default 1 2 3)")
    parser.add_argument("--workers", type=int, default=1, help="runs at the same time (default 1)")
    parser.add_argument("--cuda", action="store_true", help="pass --cuda to every method: all workers share the GPU")
    parser.add_argument("--extra-args", default="", help='more flags for every method script, e.g. "--epochs 2"')
    parser.add_argument("--expert-episodes", type=int, default=20, help="episodes of the expert's evaluation (default 20)")
    parser.add_argument("--results-dir", type=Path, default=Path("results/runs"), help="where results and logs go")
    parser.add_argument("--scripts-dir", type=Path, default=REPO_ROOT, help="folder with the method scripts and experts/ (default: the repository)")
    parser.add_argument("--slurm", metavar="FILE", help="write the grid as a SLURM array job to FILE instead of running it")
    parser.add_argument("--dry-run", action="store_true", help="list what would run, and why, without running it")
    options = Options(**vars(parser.parse_args(argv)))
    try:
        options.extra_args = shlex.split(options.extra_args)
    except ValueError as error:
        raise UsageError(f"--extra-args cannot be split into flags ({error}): quote it as one shell word")
    options.results_dir, options.scripts_dir = options.results_dir.resolve(), options.scripts_dir.resolve()
    check_options(options)
    return options


# ----------------------------------------------------------------------------------------------
# What may run


def method_files(scripts_dir: Path) -> list:
    """The method files' names (no .py): the scripts that declare METHOD = "<their file name>"."""
    names = []
    for path in sorted(scripts_dir.glob("*.py")):
        if re.search(rf'^METHOD = "{re.escape(path.stem)}"', path.read_text(), re.M):
            names.append(path.stem)
    return names


def available_methods(scripts_dir: Path) -> list:
    """The method files, their variants (c2f_output = c2f.py --fusion output...) and the expert."""
    methods = method_files(scripts_dir)
    variants = [name for name in VARIANTS if script_of(name) in methods]
    return methods + variants + ([EXPERT] if (scripts_dir / "expert_ppo.py").is_file() else [])


def check_options(options: Options):
    """Reject unknown methods and envs, and flags the runner owns, before anything runs."""
    if options.slurm is not None:
        check_slurm(options.slurm)
    if not options.scripts_dir.is_dir():
        raise UsageError(f"--scripts-dir {options.scripts_dir} is not a folder: pass a checkout of this repository")
    check_results_dir(options.results_dir)
    known = available_methods(options.scripts_dir)
    if not known:  # "choose from" nothing
        raise UsageError(f"--scripts-dir {options.scripts_dir} holds no method files: "
                         "pass a checkout of this repository")
    for method in options.methods:
        if method not in known:
            raise UsageError(f"unknown method {method!r}: choose from {', '.join(known)}")
    import gymnasium  # here, so that --help and method errors stay fast

    for env in options.envs:
        try:
            spec = gymnasium.spec(env)
        except Exception:
            raise UsageError(f"unknown env {env!r}: use a gymnasium MuJoCo id such as Hopper-v4")
        if "mujoco" not in str(spec.entry_point):  # the advice to train an expert would lead to a refusal
            raise UsageError(f"{env} is not a MuJoCo env: the method files imitate MuJoCo envs, e.g. Hopper-v4")
    needs_expert = EXPERT in options.methods or "demos" not in explicit_settings(options.extra_args)
    for env in options.envs:
        if needs_expert and not (options.scripts_dir / "experts" / f"{env}.pt").is_file():
            raise UsageError(f"no expert checkpoint experts/{env}.pt for {env}: train one with `python expert_ppo.py --env {env}` first")
    if options.workers < 1 or options.expert_episodes < 1:
        raise UsageError(f"--workers and --expert-episodes must be at least 1, got {options.workers} and {options.expert_episodes}")
    check_distinct("--methods", options.methods)
    check_distinct("--envs", options.envs)
    check_distinct("--seeds", options.seeds)
    if min(options.seeds) < 0 or max(options.seeds) >= 2**32:  # as the method files refuse them, before the grid
        raise UsageError(f"--seeds must lie in [0, 2**32), got {' '.join(map(str, options.seeds))}")
    for name in explicit_settings(options.extra_args):
        if name in SET_BY_RUNNER:
            raise UsageError(f"--extra-args sets --{name.replace('_', '-')}, which the runner sets for each combination: leave it out")
    words = options.extra_args
    if words and not words[0].startswith("--"):  # every run would refuse it
        raise UsageError(f"--extra-args starts with {words[0]!r}, not a flag: e.g. \"--epochs 2\"")


def check_results_dir(folder: Path):
    """Refuse a --results-dir that cannot be made or written in before the grid starts (a dry run
    too: it lists what the grid would do); makes nothing."""
    reason = unwritable(folder)
    if reason:
        problem = f"--results-dir {folder} cannot hold results: {reason}"
        raise UsageError(f"{problem}: pass another --results-dir")


def check_slurm(name: str):
    """Refuse a --slurm FILE that cannot be written before anything is made or run."""
    example = "e.g. --slurm grid.sh"
    if not name.strip():
        raise UsageError(f"--slurm needs the name of the file to write, {example}")
    path = Path(name).absolute()
    if path.is_dir():
        raise UsageError(f"--slurm {name} is a folder: name the file to write, {example}")
    reason = unwritable(path.parent)  # write_text makes the missing folders
    if reason:
        raise UsageError(f"--slurm {name} cannot be written: {reason}: pass another --slurm")


def combinations(options: Options) -> list:
    """Every combination once, seeds outermost (an interrupted grid covers every cell evenly);
    the expert once per env."""
    runs = [Run(EXPERT, env, EXPERT_SEED) for env in options.envs if EXPERT in options.methods]
    return runs + [Run(method, env, seed) for seed in options.seeds for env in options.envs for method in options.methods if method != EXPERT]


def parse_value(words: list):
    """Flag values as the scripts will read them: numbers, None, strings; several words give a list."""
    def one(word):
        for kind in (int, float):
            try:
                return kind(word)
            except ValueError:
                pass
        return None if word == "None" else word
    values = [one(word) for word in words]
    return values[0] if len(values) == 1 else values


def explicit_settings(extra_args: list) -> dict:
    """{field: value} of the flags in --extra-args: '--eval-every 1' -> eval_every 1, '--cuda' -> cuda True,
    '--no-cuda' -> cuda False, '--velocity-dims 5 6' -> velocity_dims [5, 6]."""
    words, name = {}, None
    for word in extra_args:
        if word.startswith("--"):
            name, equals, value = word[2:].partition("=")
            name = name.replace("-", "_")
            words[name] = [value] if equals else []
        elif name is not None:
            words[name].append(word)
    settings = {}
    for name, values in words.items():
        if values:
            settings[name] = parse_value(values)
        elif name.startswith("no_"):
            settings[name[3:]] = False
        else:
            settings[name] = True
    return settings


def wanted_settings(run: Run, options: Options) -> dict:
    """The settings this run's result must have been made with: the paper's, changed by --extra-args."""
    if run.method == EXPERT:
        return {"eval_episodes": options.expert_episodes}
    explicit = {name: value for name, value in explicit_settings(options.extra_args).items() if name not in NOT_SETTINGS}
    return {**paper_settings(run.env), **variant_settings(run.method), **explicit}


# ----------------------------------------------------------------------------------------------
# One combination


def output_dir(run: Run, options: Options) -> Path:
    return options.results_dir / run.method / run.env


def log_path(run: Run, options: Options) -> Path:
    return output_dir(run, options) / f"seed{run.seed}.log"


def command(run: Run, options: Options) -> list:
    """The process of one combination, run with the scripts folder as working directory."""
    if run.method == EXPERT:
        return [sys.executable, "expert_ppo.py", "--eval-only", "--env", run.env, "--checkpoint", f"experts/{run.env}.pt",
                "--eval-episodes", str(options.expert_episodes)]
    return [sys.executable, f"{script_of(run.method)}.py", "--env", run.env, "--seeds", str(run.seed), "--output-dir", str(output_dir(run, options)),
            *as_flags(variant_flags(run.method)), *options.extra_args, *(["--cuda"] if options.cuda else [])]


def shown_command(cmd: list) -> list:
    """The command as a log shows it: a path inside a git checkout relative to that checkout's root (the results
    may live in another checkout than the scripts, e.g. a worktree), so a committed log names no machine."""
    def shown(word: str) -> str:
        path = Path(word)
        root = next((folder for folder in path.parents if (folder / ".git").exists()), None) if path.is_absolute() else None
        return str(path.relative_to(root)) if root else word
    return [shown(word) for word in cmd[1:]]


def machine() -> dict:
    """Where a run was made (benchmark.machine): the second line of its log, and a field of its result."""
    from benchmark.machine import machine as record  # here: importing torch and gymnasium is slow

    return record()


def demo_commands(runs: list, options: Options) -> list:
    """The `expert_ppo.py --make-demos` commands that make the demo files the grid's method runs load (each is cheap when
    its file is already made from the same expert): one per env, at the --frame-skip and --num-demo-samples asked for."""
    settings = explicit_settings(options.extra_args)
    if settings.get("demos") is not None:  # the grid's own demo file: nothing to make
        return []
    wanted = [word for name in ("frame_skip", "num_demo_samples") if settings.get(name) is not None
              for word in (f"--{name.replace('_', '-')}", str(settings[name]))]
    envs = sorted({run.env for run in runs if run.method != EXPERT})
    return [[sys.executable, "expert_ppo.py", "--env", env, "--make-demos", *wanted] for env in envs]


def make_demos(runs: list, options: Options):
    """Make the demos the grid needs before any run starts, in the scripts folder (one clear line if that fails)."""
    for cmd in demo_commands(runs, options):
        made = subprocess.run(cmd, cwd=options.scripts_dir, capture_output=True, text=True)
        if made.returncode != 0:
            raise UsageError(f"could not make the demos ({shlex.join(shown_command(cmd))}): {last_line_of(made.stderr or made.stdout)}")
        print(last_line_of(made.stdout), flush=True)


def add_machine(run: Run, options: Options):
    """Record in a method run's result where it was made (the method files leave that to the harness)."""
    path = result_path(options.results_dir, run.method, run.env, [run.seed])
    result = json.loads(path.read_text())
    result["machine"] = machine()
    write_text(path, json.dumps(result, indent=1))


def why_not_done(run: Run, options: Options):
    """None when a valid result made with the wanted settings exists; otherwise why the run is needed."""
    path = result_path(options.results_dir, run.method, run.env, [run.seed])
    if not path.exists():
        return "no result yet"
    try:
        result = read_result(path, script_of(run.method), run.env, [run.seed])
    except ResultError as error:
        return f"corrupt result {path}: {error}"
    differences = setting_differences(result["args"], wanted_settings(run, options), run.env)
    if differences:
        return f"{path} was made with other settings ({', '.join(differences)})"
    return None


def write_expert_result(run: Run, options: Options, output: str):
    """Turn the output of expert_ppo.py --eval-only into a result JSON of the shape of the methods'."""
    returns = [float(value) for value in re.findall(r"^episode \d+: return (\S+)$", output, re.M)]
    summary = re.search(rf"^{re.escape(run.env)} expert: \S+ ± \S+ over (\d+) episodes$", output, re.M)
    if not summary or len(returns) != int(summary[1]) or len(returns) != options.expert_episodes:
        raise ResultError(f"expert_ppo.py printed no '{run.env} expert: MEAN ± STD over {options.expert_episodes} episodes' line with its episode returns")
    args = {"env": run.env, "seeds": [run.seed], "checkpoint": f"experts/{run.env}.pt", "eval_episodes": len(returns)}
    result = make_result(run.env, EXPERT, args, {run.seed: [[0, statistics.fmean(returns)]]})
    result.update(std=statistics.pstdev(returns), returns=returns)  # the expert's spread is over episodes
    write_text(result_path(options.results_dir, run.method, run.env, [run.seed]), json.dumps(result, indent=1))


def last_line(path: Path) -> str:
    return last_line_of(path.read_text(errors="replace"))


class Processes:
    """The running child processes, so that an interrupted grid can stop them."""

    def __init__(self):
        self.lock, self.running, self.stopping = threading.Lock(), set(), False

    def run(self, cmd: list, cwd: Path, log, env: dict) -> int:
        with self.lock:
            if self.stopping:
                return -2
            process = subprocess.Popen(cmd, cwd=cwd, stdout=log, stderr=subprocess.STDOUT, env=env)
            self.running.add(process)
        try:
            return process.wait()
        finally:
            with self.lock:
                self.running.discard(process)

    def stop(self):
        with self.lock:
            self.stopping = True
            for process in self.running:
                process.terminate()


def child_env(options: Options) -> dict:
    """Split the CPU cores between the workers (torch would give every process all of them)."""
    threads = str(max(1, len(os.sched_getaffinity(0)) // options.workers))
    return {"OMP_NUM_THREADS": threads, "MKL_NUM_THREADS": threads, **os.environ, "PYTHONUNBUFFERED": "1"}


def execute(run: Run, options: Options, processes: Processes):
    """Run one combination; None when it left a valid result, otherwise why it failed."""
    log = log_path(run, options)
    log.parent.mkdir(parents=True, exist_ok=True)
    cmd = command(run, options)
    with open(log, "w") as file:
        file.write(f"$ python {shlex.join(shown_command(cmd))}\n# machine: {json.dumps(machine())}\n")
        file.flush()
        returncode = processes.run(cmd, options.scripts_dir, file, child_env(options))
    if returncode != 0:
        return f"exit {returncode}: {last_line(log)} (log: {log})"
    try:
        if run.method == EXPERT:
            write_expert_result(run, options, log.read_text())
        reason = why_not_done(run, options)
        if reason is None and run.method != EXPERT:
            add_machine(run, options)  # to a valid result only
    except (ResultError, OSError, ValueError) as error:
        return f"{error} (log: {log})"
    return None if reason is None else f"exited 0 but left no valid result: {reason} (log: {log})"


# ----------------------------------------------------------------------------------------------
# The grid


def slurm_script(runs: list, options: Options) -> str:
    """An array job whose task i runs combination i through this runner (which skips it when done)."""
    common = ["--workers", "1", "--results-dir", str(options.results_dir), "--scripts-dir", str(options.scripts_dir),
              "--expert-episodes", str(options.expert_episodes), *(["--cuda"] if options.cuda else [])]
    if options.extra_args:
        common += ["--extra-args", shlex.join(options.extra_args)]
    lines = [
        "#!/bin/bash",
        "# The Table 2 grid as a SLURM array job, written by python -m benchmark.run_grid --slurm.",
        "# Submit with `sbatch <this file>` (add --time, --partition, --mem as your cluster needs). Task i runs",
        "# combination i through the runner, which skips it when its valid result exists, checks the result",
        f"# and logs to {options.results_dir}/<method>/<env>/seed<S>.log. {len(runs)} combinations.",
        "#SBATCH --job-name=copycat-table2",
        f"#SBATCH --array=0-{len(runs) - 1}%{options.workers}",
        "#SBATCH --cpus-per-task=1",
        *(["#SBATCH --gres=gpu:1"] if options.cuda else []),
        f"#SBATCH --output={options.results_dir}/slurm-%A_%a.out",
        "set -euo pipefail",
        f"cd {shlex.quote(str(REPO_ROOT))}",
        f"PYTHON=${{PYTHON:-{shlex.quote(sys.executable)}}}",
        f'one() {{ "$PYTHON" -m benchmark.run_grid {shlex.join(common)} --methods "$1" --envs "$2" --seeds "$3"; }}',
        'case "$SLURM_ARRAY_TASK_ID" in',
        *(f"  {index}) one {run.method} {run.env} {run.seed} ;;" for index, run in enumerate(runs)),
        '  *) echo "no combination for array index $SLURM_ARRAY_TASK_ID" >&2; exit 2 ;;',
        "esac",
    ]
    return "\n".join(lines) + "\n"


def stop_on_sigterm(signum, frame):
    raise KeyboardInterrupt


def run_all(todo: list, options: Options) -> list:
    """Run the combinations on a pool of workers; returns [(run, why it failed)]."""
    failures, processes, start = [], Processes(), time.time()
    pool = ThreadPoolExecutor(options.workers)
    previous_handler = signal.signal(signal.SIGTERM, stop_on_sigterm)  # a killed grid (scancel, kill) stops its runs too
    try:
        futures = {pool.submit(execute, run, options, processes): run for run in todo}
        for done, future in enumerate(as_completed(futures), 1):
            run = futures[future]
            try:
                failure = future.result()
            except Exception as error:  # a bug or an OS error in one run must not stop the grid
                failure = f"{type(error).__name__}: {error}"
            if failure:
                failures.append((run, failure))
            elapsed = (time.time() - start) / 60
            print(f"[{done}/{len(todo)}, {elapsed:.1f} min] {'FAILED' if failure else 'done'} {run}" + (f": {failure}" if failure else ""), flush=True)
    except KeyboardInterrupt:
        processes.stop()
        pool.shutdown(wait=True, cancel_futures=True)
        print("interrupted: finished results are kept; the same command continues the grid", file=sys.stderr)
        raise SystemExit(130)
    finally:
        signal.signal(signal.SIGTERM, previous_handler)
    pool.shutdown()
    return failures


def main(argv=None) -> int:
    options = parse_options(argv)
    runs = combinations(options)
    # A dry run writes nothing: it shows the file instead.
    if options.slurm is not None and options.dry_run:
        print(slurm_script(runs, options), end="")
        job = f"a SLURM array job of {len(runs)} combinations"
        # A comment line: the output redirected to a file is still a job script.
        print(f"# dry run: would write {options.slurm}: {job}; nothing written")
        return 0
    if options.slurm is not None:
        options.results_dir.mkdir(parents=True, exist_ok=True)  # SLURM does not create the --output folder
        write_text(options.slurm, slurm_script(runs, options))
        print(f"wrote {options.slurm}: a SLURM array job of {len(runs)} combinations; submit with `sbatch {options.slurm}`")
        return 0
    todo = []
    for run in runs:
        reason = why_not_done(run, options)
        if reason is None:
            if options.dry_run:
                print(f"skip {run}: valid result exists")
            continue
        todo.append(run)
        if reason != "no result yet":
            print(f"re-run {run}: {reason}", flush=True)
        if options.dry_run:
            print(f"run  {run}: (cd {options.scripts_dir} && python {shlex.join(command(run, options)[1:])})")
    if options.dry_run:  # what runs first: the demos of the runs to do
        for cmd in demo_commands(todo, options):
            print(f"demos {cmd[3]}: (cd {options.scripts_dir} && python {shlex.join(cmd[1:])})")
    print(f"grid: {len(runs)} combinations, {len(runs) - len(todo)} done, {len(todo)} to run"
          + ("" if options.dry_run else f" on {options.workers} workers"), flush=True)
    if options.dry_run or not todo:
        return 0
    make_demos(todo, options)
    failures = run_all(todo, options)
    if failures:
        print(f"\n{len(failures)} of {len(todo)} runs failed:")
        for run, failure in failures:
            print(f"  {run}: {failure}")
        return 1
    print(f"all {len(todo)} runs done: results in {options.results_dir}")
    return 0


if __name__ == "__main__":
    run_cli(main)
