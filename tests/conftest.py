"""Helpers shared by all test files (pytest loads this file itself; import it as `conftest`).

    from conftest import REPO_ROOT, run_script, assert_usage_error

    result = run_script("expert_ppo.py", "--env", "Nope-v0", cwd=tmp_path)
    assert_usage_error(result, "cannot make env")

Commands: run_script (a file of the repo), run_module (`python -m benchmark.X`), run_in_process; a method file's
tiny run: smoke_run and check_summary, tiny_run (the pinned budget); demo files: make_demos, link_experts, demo_file;
planted results for the benchmark tools: plant, plant_expert, plant_variant, plant_run, set_machine, the regime_map
fixture.

pytest.ini puts the repo root and scripts/ on sys.path, so tests can also `import expert_ppo`,
`import bc_oh` or `import check_copies` directly.
"""
import contextlib
import os
import re
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent
"""The repository root: the method scripts, experts/, scripts/ and tests/ live here."""


def run_command(command, cwd, timeout=120, env=None):
    """Run `command` (a list) in cwd and return the subprocess.CompletedProcess, stdout and stderr captured as text
    (result.stdout, result.stderr); the exit code is not checked. Warnings are silenced (PYTHONWARNINGS=ignore) so
    stderr holds only what the program itself prints; env holds more environment variables for it."""
    env = dict(os.environ, PYTHONWARNINGS="ignore", OMP_NUM_THREADS="1", **(env or {}))
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def run_script(script, *args, cwd=None, timeout=120, env=None):
    """Run `python REPO_ROOT/script *args` and return the subprocess.CompletedProcess (run_command's).

    cwd defaults to a fresh temporary directory, so relative default paths (runs/, experts/) never touch the repo;
    pass cwd=tmp_path to look at what the script wrote there. Arguments may be str, int, float or Path.
    """
    command = [sys.executable, str(REPO_ROOT / script), *map(str, args)]
    if cwd is not None:
        return run_command(command, cwd, timeout, env)
    with tempfile.TemporaryDirectory() as tmp:
        return run_command(command, tmp, timeout, env)


def run_module(module, *args, cwd=REPO_ROOT, timeout=300, env=None):
    """Run `python -m module *args` (e.g. module="benchmark.h3") in cwd, by default the repo root where the benchmark
    package lives, and return the subprocess.CompletedProcess (run_command's). Arguments may be str, int, float or Path."""
    return run_command([sys.executable, "-m", module, *map(str, args)], cwd, timeout, env)


def edited_checkpoint(path, folder, edit) -> Path:
    """A copy of the checkpoint at path, changed in place by edit(checkpoint), saved as folder/edited.pt."""
    import torch

    checkpoint = torch.load(path, weights_only=True)
    edit(checkpoint)
    torch.save(checkpoint, Path(folder) / "edited.pt")
    return Path(folder) / "edited.pt"


def assert_usage_error(result, expected):
    """Assert that a script rejected bad input cleanly: non-zero exit, no traceback, and stderr holding
    exactly one non-empty line that contains `expected`."""
    assert result.returncode != 0, f"expected a failure, got exit 0; stdout:\n{result.stdout}"
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}:\n{result.stderr}"
    assert expected in lines[0], f"{expected!r} not in stderr line {lines[0]!r}"


SMOKE_ARGS = ("--epochs", 2, "--eval-every", 1, "--eval-episodes", 2, "--num-demo-samples", 300, "--seeds", 1)
"""A tiny budget for a smoke run of an imitation method script (seconds); add --output-dir (and --demos)."""


DEMO_CACHE = Path(tempfile.mkdtemp(prefix="copycat-test-demos-"))
"""One folder of demo files for the whole test session: expert_ppo.py --make-demos writes each once (make_demos)."""
DEMOS_TESTS_USE = [("Hopper-v4", n, None) for n in (120, 200, 300, 500, 1000)] + [("Hopper-v4", 120, 1), ("Hopper-v4", 300, 1)]
"""(env, --num-demo-samples, --frame-skip) of the runs the tests make: link_experts provides them all"""


def make_demos(env="Hopper-v4", num_samples=300, frame_skip=None) -> Path:
    """The demo file `expert_ppo.py --env ENV --make-demos --num-demo-samples N [--frame-skip K]` writes, made in this
    process (the same arrays as the command, in the default numeric mode) into DEMO_CACHE, once a session."""
    import contextlib

    import expert_ppo

    (DEMO_CACHE / "demos").mkdir(exist_ok=True)
    if not (DEMO_CACHE / "experts").exists():
        (DEMO_CACHE / "experts").symlink_to(REPO_ROOT / "experts", target_is_directory=True)
    args = expert_ppo.Args(env=env, make_demos=True, num_demo_samples=num_samples, frame_skip=frame_skip)
    native, rate = expert_ppo.env_frame_skip(env), expert_ppo.env_frame_skip(env, frame_skip)
    suffix = "" if rate == native else f"_fs{rate}"  # where --make-demos writes, and the method files look
    path = DEMO_CACHE / "demos" / f"{env}{suffix}_{num_samples}.npz"
    if not path.exists():
        with contextlib.chdir(DEMO_CACHE), contextlib.redirect_stdout(None):
            expert_ppo.make_demos(args)
    return path


DEMOS_MADE_IN_MODE = {}
"""(environment variables, flags) -> the demos/ folder demos_made_in made with them"""


def demos_made_in(numeric_env: dict, *flags) -> Path:
    """The demos/ folder that `expert_ppo.py --make-demos *flags` writes when it runs with the environment variables
    numeric_env (e.g. MKL_CBWR=COMPATIBLE, which MKL reads when it loads: so in a subprocess, not in this process).
    Made once a test process for each (numeric_env, flags); link it into a run's folder, never write into it."""
    key = (tuple(sorted(numeric_env.items())), tuple(map(str, flags)))
    if key not in DEMOS_MADE_IN_MODE:
        folder = link_experts(tempfile.mkdtemp(prefix="made-in-mode-", dir=DEMO_CACHE), demos=False)
        made = run_script("expert_ppo.py", "--make-demos", *flags, cwd=folder, env=numeric_env)
        assert made.returncode == 0, made.stderr
        DEMOS_MADE_IN_MODE[key] = folder / "demos"
    return DEMOS_MADE_IN_MODE[key]


def link_experts(directory, demos=True):
    """Symlink REPO_ROOT/experts into `directory` (a run's cwd) and, unless demos is False, the session's demo files
    (DEMOS_TESTS_USE, made by make_demos) as its demos/ folder; return the directory."""
    directory = Path(directory)
    (directory / "experts").symlink_to(REPO_ROOT / "experts", target_is_directory=True)
    if demos:
        for env, num_samples, frame_skip in DEMOS_TESTS_USE:
            make_demos(env, num_samples, frame_skip)
        (directory / "demos").symlink_to(DEMO_CACHE / "demos", target_is_directory=True)
    return directory


def fake_demos(n=256, obs_dim=11, act_dim=3, episode_length=50, seed=0):
    """Random demos shaped like Hopper-v4's (obs 11, action 3), episodes of `episode_length` steps:
    a dict as load_demos returns, for fast in-process training tests."""
    import numpy as np

    rng = np.random.default_rng(seed)
    return {"observations": rng.normal(size=(n, obs_dim)), "actions": rng.uniform(-1, 1, (n, act_dim)).astype(np.float32),
            "episode_starts": np.arange(n) % episode_length == 0}


def tiny_args(module, **overrides):
    """module.Args on Hopper-v4 with a budget of a few milliseconds (lr set: run() normally fills it in), its seeds
    trained in this process (workers=1: a pool's processes would not see the test's monkeypatches)."""
    settings = dict(env="Hopper-v4", seeds=[1], workers=1, epochs=2, batch_size=32, hidden=32, eval_every=1, eval_episodes=1, learning_rate=1e-3)
    return module.Args(**{**settings, **overrides})


def load_demos(module, **overrides):
    """module.load_demos(tiny_args(module, **overrides), Hopper-v4) as run() calls it: at the env's own frame skip
    (4) unless frame_skip is given, as run() resolves it before loading. Returns (demos, meta)."""
    args = tiny_args(module, **{"frame_skip": 4, **overrides})
    return module.load_demos(args, module.make_env(args.env))


@contextlib.contextmanager
def one_torch_thread():
    """torch on one thread inside the block, as a method file trains each seed (train_and_record): the same sums in the
    same order, so a run in this process repeats the printed digits of a run of the command."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def skip_evaluation(monkeypatch, module, score=0.0):
    """Replace module.evaluate by a constant, for training tests that need no env rollouts."""
    monkeypatch.setattr(module, "evaluate", lambda policy, args, episodes, seed, device: [score] * episodes)


SUMMARY = re.compile(r"(?P<env>\S+) (?P<method>\w+): score (?P<mean>-?\d+\.\d) ± (?P<std>\d+\.\d) \(mean ± std over (?P<seeds>\d+) seeds?\)"
                     r"(?:, (?P<share>-?\d+)% of the expert's (?P<expert>\d+))?")
"""the summary line that ends a method file's run: `ENV METHOD: score MEAN ± STD (mean ± std over N seeds), P% of the
expert's E` (the share only where the demos' meta records the expert's return)"""


def demo_file(path) -> tuple:
    """(arrays, meta) of a demo file: {name: array} of its arrays but meta, and its meta as a dict (None without one)."""
    import json

    import numpy as np

    with np.load(path, allow_pickle=False) as data:
        arrays = {key: data[key] for key in data.files if key != "meta"}
        return arrays, json.loads(str(data["meta"])) if "meta" in data.files else None


def table_row(stdout, seed) -> list:
    """The columns of seed's row in the table a method file's run prints (`     1 | 12.3 | 11.0` -> ["12.3", "11.0"])."""
    rows = re.findall(rf"^\s+{seed} \|(.*)$", stdout, re.MULTILINE)
    assert len(rows) == 1, f"expected one table row of seed {seed}:\n{stdout}"
    return [column.strip() for column in rows[0].split("|")]


def check_summary(stdout, cwd, output_dir, method, seeds=(1,), expert=None, env="Hopper-v4") -> dict:
    """Check a method file's run, which ran in cwd with --output-dir output_dir, against the JSON result it wrote there,
    and return that result: the last line is the SUMMARY of `seeds` (the share of the expert's return `expert`, from the
    demos' meta, where given; none printed where None), `result: OUTPUT_DIR/result_seeds<seeds>.json` is printed, each
    seed's table row opens with its score, a seed's score is the mean of its last 3 evaluations, and the mean and std of
    the seeds' scores are the JSON's and the printed ones (to 0.1)."""
    import json

    import numpy as np

    lines = stdout.strip().splitlines()
    match = SUMMARY.fullmatch(lines[-1])
    assert match and (match["env"], match["method"], int(match["seeds"])) == (env, method, len(seeds)), lines[-1]
    printed_path = Path(output_dir, f"result_seeds{'-'.join(map(str, seeds))}.json")
    assert f"result: {printed_path}" in lines, stdout
    result = json.loads((Path(cwd) / printed_path).read_text())
    assert (result["env"], result["method"], list(result["scores"])) == (env, method, list(map(str, seeds)))
    scores = []
    for seed in seeds:
        entry = result["scores"][str(seed)]
        assert entry["score"] == pytest.approx(np.mean([value for _, value in entry["evaluations"][-3:]]))
        assert table_row(stdout, seed)[0] == f"{entry['score']:.1f}", "the seed's row of the table"
        scores.append(entry["score"])
    assert result["mean"] == pytest.approx(np.mean(scores)) and result["std"] == pytest.approx(np.std(scores))
    assert (match["mean"], match["std"]) == (f"{result['mean']:.1f}", f"{result['std']:.1f}")
    if expert is None:
        assert match["share"] is None, lines[-1]
    else:
        assert (match["share"], match["expert"]) == (f"{result['mean'] / expert:.0%}".removesuffix("%"), f"{expert:.0f}")
    return result


SMOKE_DEMOS = "demos/Hopper-v4_300.npz"
"""the demo file a smoke run (SMOKE_ARGS) loads, relative to its folder"""


def smoke_run(script, directory, *extra, seeds=(1,), output_dir="out"):
    """Run `script` with SMOKE_ARGS (plus `extra`: seeds other than 1 are both in extra and in `seeds`) in `directory`
    (experts and the session's demos linked there, unless it has experts/ already) with --output-dir output_dir, check
    that it succeeds and that its summary agrees with its JSON result and with the expert's return in the demos' meta
    (check_summary); return (stdout, the JSON result as a dict)."""
    directory = Path(directory)
    if not (directory / "experts").exists():
        link_experts(directory)
    result = run_script(script, *SMOKE_ARGS, "--output-dir", output_dir, *extra, cwd=directory)
    assert result.returncode == 0, result.stderr
    expert = demo_file(directory / SMOKE_DEMOS)[1]["expert_return"]
    return result.stdout, check_summary(result.stdout, directory, output_dir, Path(script).stem, seeds, expert)


def run_in_process(script, *args):
    """Run REPO_ROOT/script as __main__ inside this process with sys.argv = [script, *args] (no new
    interpreter: ~0.1 s instead of ~2 s, for fast bad-input checks). Returns an object with returncode,
    stdout and stderr like run_script's, so assert_usage_error applies."""
    import contextlib
    import io
    import runpy
    from types import SimpleNamespace

    stdout, stderr, argv, code = io.StringIO(), io.StringIO(), sys.argv, 0
    sys.argv = [str(REPO_ROOT / script), *map(str, args)]
    sigterm = signal.getsignal(signal.SIGTERM)  # the method files' __main__ turns SIGTERM into Ctrl-C
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            runpy.run_path(str(REPO_ROOT / script), run_name="__main__")
    except SystemExit as exit:
        code = exit.code if isinstance(exit.code, int) else 1
    finally:
        sys.argv = argv
        signal.signal(signal.SIGTERM, sigterm)
    return SimpleNamespace(returncode=code, stdout=stdout.getvalue(), stderr=stderr.getvalue())


METHOD_FILES = ["bc_so.py", "bc_oh.py", "c2f.py", "c2f_table3.py", "fca.py", "keyframe.py", "history_dropout.py", "average_ensemble.py",
                "dagger.py"]
"""the method files (those with a `METHOD = "..."` line; test_check_copies checks that this list names them all)"""


# ---- The pinned tiny runs (test_pinned_output, test_parallel_seeds, test_fingerprint) ----
BUDGET = ("--env", "Hopper-v4", "--seeds", 1, "--epochs", 3, "--eval-every", 1, "--eval-episodes", 2, "--num-demo-samples", 1000)
"""the tiny budget of the pinned runs"""
FIXED_MODE = {"MKL_CBWR": "COMPATIBLE"}
"""MKL's conditional numerical reproducibility: the same MKL kernels on every x86-64 CPU"""
PIN_TOLERANCE = 1e-6
"""relative, for the pinned evaluations: the Intel Xeon and the AMD EPYC differ by up to 3.6e-8 in the fixed mode"""


def libm_as_pinned() -> bool:
    """Whether the C library's maths runs the code it ran where the pins were recorded (FMA and AVX2 in the CPU's
    flags, not hidden by GLIBC_TUNABLES)."""
    from benchmark.machine import LIBM_FMA_FLAGS, cpu_flags

    return LIBM_FMA_FLAGS <= cpu_flags() and not re.search(r"-(FMA|AVX2)\b", os.environ.get("GLIBC_TUNABLES", ""))


LIBM_AS_PINNED = libm_as_pinned()

PINNED = {
    "bc_oh": ("bc_oh", [],
        ["epoch 1/3 | loss 0.41194 | last eval 5.5", "epoch 2/3 | loss 0.44837 | last eval 5.6", "epoch 3/3 | loss 0.44358 | last eval 5.8"],
        [5.4815068817504535, 5.575409521185545, 5.763501822598074]),
    "c2f": ("c2f", [],
        ["epoch 1/3 | loss 0.72757 | last eval 212.0", "epoch 2/3 | loss 0.75569 | last eval 185.4", "epoch 3/3 | loss 0.73433 | last eval 90.9"],
        [212.02897605363432, 185.3938132281013, 90.92470548581613]),
    "bc_oh_hidden": ("bc_oh", ["--hide-velocities"],
        ["epoch 1/3 | loss 0.38415 | last eval 21.6", "epoch 2/3 | loss 0.40119 | last eval 24.5", "epoch 3/3 | loss 0.40038 | last eval 25.7"],
        [21.550929660282875, 24.45770858222134, 25.65288286955353]),
    "c2f_output_fs1": ("c2f_table3", ["--fusion", "output", "--frame-skip", 1],
        ["epoch 1/3 | loss 0.76668 | last eval 8.0", "epoch 2/3 | loss 0.99929 | last eval 8.2", "epoch 3/3 | loss 0.95021 | last eval 8.2"],
        [7.991499033650937, 8.186719769456332, 8.248357499633197]),
    "c2f_two_stage": ("c2f_table3", ["--two-stage"],
        ["epoch 1/3 | loss 0.36140 | last eval n/a", "epoch 2/3 | loss 0.37972 | last eval n/a", "epoch 3/3 | loss 0.35987 | last eval n/a", "epoch 1/3 | loss 0.36602 | last eval 172.0", "epoch 2/3 | loss 0.37594 | last eval 107.5", "epoch 3/3 | loss 0.37445 | last eval 95.1"],
        [172.028436385825, 107.52890692211584, 95.09800132539624]),
    "c2f_middle": ("c2f_table3", ["--fusion", "middle", "--hide-velocities"],
        ["epoch 1/3 | loss 0.74418 | last eval 38.2", "epoch 2/3 | loss 0.78286 | last eval 39.8", "epoch 3/3 | loss 0.76615 | last eval 40.4"],
        [38.24394388018163, 39.80276037808818, 40.415561311654315]),
    "c2f_early": ("c2f_table3", ["--fusion", "early", "--hide-velocities"],
        ["epoch 1/3 | loss 0.75365 | last eval 29.2", "epoch 2/3 | loss 0.79096 | last eval 29.9", "epoch 3/3 | loss 0.77317 | last eval 30.5"],
        [29.24531594528206, 29.908453227011474, 30.450676126880527]),
    "c2f_penultimate": ("c2f_table3", ["--fusion", "penultimate", "--hide-velocities"],
        ["epoch 1/3 | loss 0.72177 | last eval 38.4", "epoch 2/3 | loss 0.75806 | last eval 39.4", "epoch 3/3 | loss 0.74964 | last eval 38.8"],
        [38.41211822741548, 39.421972744133, 38.800783510151874]),
    "c2f_feature": ("c2f_table3", ["--coarse-output", "feature", "--hide-velocities"],
        ["epoch 1/3 | loss 0.75064 | last eval 156.0", "epoch 2/3 | loss 0.78470 | last eval 157.6", "epoch 3/3 | loss 0.77423 | last eval 159.0"],
        [156.00988980135807, 157.6043177951157, 159.01969620898598]),
    "c2f_coarse_history": ("c2f_table3", ["--coarse-input", "history", "--hide-velocities"],
        ["epoch 1/3 | loss 0.74170 | last eval 23.6", "epoch 2/3 | loss 0.78158 | last eval 24.2", "epoch 3/3 | loss 0.78142 | last eval 24.0"],
        [23.593138878221154, 24.23418149507276, 24.045231792978868]),
    "c2f_coarse_history_policy_current": ("c2f_table3", ["--coarse-input", "history", "--policy-input", "current", "--hide-velocities"],
        ["epoch 1/3 | loss 0.75807 | last eval 43.9", "epoch 2/3 | loss 0.78946 | last eval 42.9", "epoch 3/3 | loss 0.78553 | last eval 41.7"],
        [43.94360807700998, 42.88653840056776, 41.6819182109557]),
    "c2f_no_stop_gradient": ("c2f_table3", ["--no-stop-gradient", "--hide-velocities"],
        ["epoch 1/3 | loss 0.73226 | last eval 42.8", "epoch 2/3 | loss 0.77278 | last eval 42.7", "epoch 3/3 | loss 0.75966 | last eval 41.5"],
        [42.82993632108068, 42.65389087179977, 41.498526055818715]),
    "c2f_no_coarse": ("c2f_table3", ["--no-coarse-action", "--hide-velocities"],
        ["epoch 1/3 | loss 0.36717 | last eval 41.6", "epoch 2/3 | loss 0.38409 | last eval 41.6", "epoch 3/3 | loss 0.38078 | last eval 40.6"],
        [41.57438442574792, 41.6010724343859, 40.57713859635703]),
    "fca": ("fca", [],  # re-recorded for the authors' BatchNorm encoder (issue 33), on an AMD EPYC (Zen 4)
        ["epoch 1/3 | loss 0.30386 | adversary error 0.46081 | last eval 69.7", "epoch 2/3 | loss 0.29206 | adversary error 0.49950 | last eval 19.4", "epoch 3/3 | loss 0.32860 | adversary error 0.49926 | last eval 16.5"],
        [69.69024529272632, 19.365407348352953, 16.464570842696123]),
    "keyframe": ("keyframe", [],
        ["epoch 1/3 | loss 0.49967 | last eval 11.0", "epoch 2/3 | loss 0.80457 | last eval 11.0", "epoch 3/3 | loss 0.60385 | last eval 11.1"],
        [11.009662459420957, 11.044730610712293, 11.082395003864645]),
    "average_ensemble": ("average_ensemble", [],
        ["epoch 1/3 | loss bc_so 0.36140, bc_oh 0.41194 | last eval 11.3, bc_so 11.1, bc_oh 5.5", "epoch 2/3 | loss bc_so 0.37972, bc_oh 0.44837 | last eval 11.9, bc_so 11.1, bc_oh 5.6", "epoch 3/3 | loss bc_so 0.35987, bc_oh 0.44358 | last eval 12.1, bc_so 11.1, bc_oh 5.8"],
        [11.298109274798296, 11.947105784097985, 12.140947939616558]),
    "dagger": ("dagger", ["--dagger-samples", 100, "--dagger-rounds", 2, "--dagger-epochs", 2],
        ["round 0 | epoch 1/7 | loss 0.41194 | last eval 5.5", "round 0 | epoch 2/7 | loss 0.44837 | last eval 5.6", "round 0 | epoch 3/7 | loss 0.44358 | last eval 5.8", "round 1 | epoch 4/7 | loss 0.44464 | last eval 5.4", "round 1 | epoch 5/7 | loss 0.45146 | last eval 5.6", "round 2 | epoch 6/7 | loss 0.43738 | last eval 4.8", "round 2 | epoch 7/7 | loss 0.55145 | last eval 5.0"],
        [5.4815068817504535, 5.575409521185545, 5.763501822598074, 5.407443089138905, 5.572266032743634, 4.837532344524785, 5.018537675348245, 4.897645361876352, 5.0024600446467336]),
}
"""case -> (script, its flags beyond BUDGET, the printed epoch lines (timings left out), the evaluations in the JSON), in
FIXED_MODE (where and how they were recorded: test_pinned_output's docstring)"""


def tiny_run(folder, script: str, flags=(), env=FIXED_MODE, seeds=(1,)):
    """Run `script`.py (no .py) on BUDGET with `seeds`, then `flags`, in `folder` (made, experts linked) with the
    environment variables `env` (a numeric mode), on the demos that expert_ppo.py --make-demos makes in that mode at
    the run's --frame-skip (once a test process: demos_made_in). Returns a namespace: lines {seed: its printed epoch
    lines without timings}, evaluations {seed: [[epoch, return], ...] of its own JSON}, returns {seed: those returns},
    result (the JSON of all the seeds), stdout, and demos (the demo file's arrays)."""
    import json
    from types import SimpleNamespace

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    link_experts(folder, demos=False)
    flags = list(flags)
    rate = flags[flags.index("--frame-skip"):][:2] if "--frame-skip" in flags else []
    (folder / "demos").symlink_to(demos_made_in(env, *BUDGET[:2], *BUDGET[-2:], *rate), target_is_directory=True)
    budget = list(BUDGET)
    budget[budget.index("--seeds") + 1:budget.index("--seeds") + 2] = seeds
    result = run_script(f"{script}.py", *budget, *flags, "--output-dir", folder / "out", cwd=folder, env=env)
    assert result.returncode == 0, result.stderr
    lines = {seed: re.findall(rf"^seed {seed} \| (.*last eval \S+(?:, \w+ \S+)*) \| [\d.]+ ms/step", result.stdout, re.MULTILINE) for seed in seeds}
    evaluations = {seed: json.loads((folder / "out" / f"result_seeds{seed}.json").read_text())["scores"][str(seed)]["evaluations"]
                   for seed in seeds}
    (demos,) = (folder / "demos").glob("*.npz")  # the one demo file expert_ppo.py --make-demos made
    return SimpleNamespace(lines=lines, evaluations=evaluations, returns={seed: [value for _, value in evaluations[seed]] for seed in seeds},
                           result=json.loads((folder / "out" / f"result_seeds{'-'.join(map(str, seeds))}.json").read_text()),
                           stdout=result.stdout, demos=demo_file(demos)[0])




# ---- Planted results for the benchmark tools (test_benchmark, test_regime_summary, test_table3, test_h3, ...) ----
def plant(results, method, env, seed, returns, **settings):
    """Write a valid result of `method` on `env` for `seed` whose evaluations return `returns`; return its path."""
    import json

    from benchmark.paper import paper_settings
    from benchmark.results import make_result, result_path

    args = {"env": env, "seeds": [seed], **paper_settings(env), "learning_rate": None, **settings}
    result = make_result(env, method, args, {seed: [[epoch, value] for epoch, value in enumerate(returns, 1)]})
    path = result_path(results, method, env, [seed])
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result))
    return path


def plant_expert(runs, env, score):
    """Write the expert's result on env (expert_ppo.py's evaluation) returning `score`."""
    import json

    from benchmark.results import make_result, result_path

    path = result_path(runs, "expert", env, [0])
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(make_result(env, "expert", {"env": env, "seeds": [0], "eval_episodes": 20}, {0: [[0, score]]})))


def plant_variant(runs, method, script, env, seed, returns, **settings):
    """plant() for a method variant: its script's result (method "c2f") in the variant's folder (c2f_output)."""
    from benchmark.results import result_path

    path = result_path(runs, method, env, [seed])
    path.parent.mkdir(parents=True, exist_ok=True)
    return plant(runs.parent / "staging", script, env, seed, returns, **settings).replace(path)


REGIME_FLAGS = {"native_hidden": {"hide_velocities": True}, "fs1_noise": {"frame_skip": 1}}
"""the method flags that make a run one of the regime (benchmark/regimes.py)"""


def plant_run(runs, method, seed, score, env="Hopper-v4", regime="native_hidden", script=None, **settings):
    """A valid result of method in the regime scoring `score` at each of 3 evaluations: a plain method file's, or a
    variant's (benchmark.paper.VARIANTS: its flags, made by `script`, by default the variant's own, c2f_table3); settings
    change it (e.g. hide_velocities=False)."""
    from benchmark.paper import VARIANTS, script_of, variant_flags

    settings = {**REGIME_FLAGS[regime], **variant_flags(method), **settings}
    if method in VARIANTS:
        return plant_variant(runs, method, script or script_of(method), env, seed, [score] * 3, **settings)
    return plant(runs, method, env, seed, [score] * 3, **settings)


def set_machine(path, cpu, capability):
    """Record a made-up machine in the result at path (as the grid runner records the real one)."""
    import json

    result = json.loads(path.read_text())
    result["machine"] = {"cpu": cpu, "cpu_capability": capability, "torch": "2.13.0+cpu"}
    path.write_text(json.dumps(result))


def summarise(results, experts, *args):
    """benchmark.regime_summary's main on the regime map in results, the experts' results in experts; its exit status."""
    from benchmark import regime_summary

    return regime_summary.main(["--results-dir", str(results), "--expert-runs", str(experts), *map(str, args)])


@pytest.fixture
def regime_map(tmp_path):
    """native_noise: Hopper BC-SO 100, 300; BC-OH 200, 400; C2F 500, 700; C2F output 600 (and seed 2 without
    --fusion output); Walker2d BC-OH 80. fs1_noise: Hopper BC-OH 50 (and seed 2 at the native rate, and a corrupt
    seed 3 of BC-SO). Experts: Hopper 1000, Walker2d 400. native_noise has a README.md that says where its runs come
    from. Returns (the results folder, the experts' folder, the lines regime_summary prints on what it leaves out)."""
    from benchmark.regimes import runs_dir
    from benchmark.results import result_path

    results, experts = tmp_path / "results" / "regimes", tmp_path / "runs"
    native, fs1 = runs_dir("native_noise", results), runs_dir("fs1_noise", results)
    for method, scores in (("bc_so", (100, 300)), ("bc_oh", (200, 400)), ("c2f", (500, 700))):
        for seed, score in enumerate(scores, 1):
            plant(native, method, "Hopper-v4", seed, [0.0, score - 10.0, score, score + 10.0])  # the first evaluation drops out
    plant_variant(native, "c2f_output", "c2f", "Hopper-v4", 1, [600.0] * 3, fusion="output")
    plant(native, "bc_oh", "Walker2d-v4", 1, [80.0] * 3)
    plant(fs1, "bc_oh", "Hopper-v4", 1, [50.0] * 3, frame_skip=1)
    problems = [
        f"left out {plant_variant(native, 'c2f_output', 'c2f', 'Hopper-v4', 2, [9.0] * 3)}: not the native_noise settings (fusion late != output)",
        f"left out {plant(fs1, 'bc_oh', 'Hopper-v4', 2, [9.0] * 3)}: not the fs1_noise settings (frame_skip 4 != 1)",
        f"left out {result_path(fs1, 'bc_so', 'Hopper-v4', [3])}: unreadable JSON",
    ]
    result_path(fs1, "bc_so", "Hopper-v4", [3]).parent.mkdir(parents=True)
    result_path(fs1, "bc_so", "Hopper-v4", [3]).write_text("{not json")
    plant_expert(experts, "Hopper-v4", 1000.0)
    plant_expert(experts, "Walker2d-v4", 400.0)
    (results / "native_noise" / "README.md").write_text("where these runs come from\n")
    return results, experts, problems
