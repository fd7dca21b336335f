"""Helpers shared by all test files (pytest loads this file itself; import it as `conftest`).

    from conftest import REPO_ROOT, run_script, assert_usage_error

    result = run_script("expert_ppo.py", "--env", "Nope-v0", cwd=tmp_path)
    assert_usage_error(result, "cannot make env")

pytest.ini puts the repo root and scripts/ on sys.path, so tests can also `import expert_ppo`,
`import bc_oh` or `import check_copies` directly.
"""
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
"""The repository root: the method scripts, experts/, scripts/ and tests/ live here."""


def run_script(script, *args, cwd=None, timeout=120, env=None):
    """Run `python REPO_ROOT/script *args` and return the subprocess.CompletedProcess.

    stdout and stderr are captured as text (result.stdout, result.stderr); the exit code is not
    checked. cwd defaults to a fresh temporary directory, so relative default paths (runs/, experts/)
    never touch the repo; pass cwd=tmp_path to look at what the script wrote there. Warnings are
    silenced (PYTHONWARNINGS=ignore) so stderr holds only what the script itself prints.
    Arguments may be str, int, float or Path; env holds more environment variables for the script.
    """
    env = dict(os.environ, PYTHONWARNINGS="ignore", OMP_NUM_THREADS="1", **(env or {}))
    command = [sys.executable, str(REPO_ROOT / script), *map(str, args)]
    if cwd is not None:
        return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    with tempfile.TemporaryDirectory() as tmp:
        return subprocess.run(command, cwd=tmp, env=env, capture_output=True, text=True, timeout=timeout)


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


def skip_evaluation(monkeypatch, module, score=0.0):
    """Replace module.evaluate by a constant, for training tests that need no env rollouts."""
    monkeypatch.setattr(module, "evaluate", lambda policy, args, episodes, seed, device: [score] * episodes)


def smoke_run(script, directory, *extra):
    """Run `script` with SMOKE_ARGS (plus `extra`) in `directory` (experts linked there), check that it
    succeeds, ends with the summary line `Hopper-v4 METHOD: score MEAN ± STD (mean ± std over 1 seed), P% of the expert's E` and writes a JSON
    result that agrees with it; return (stdout, the JSON result as a dict)."""
    import json
    import re

    directory = link_experts(directory)
    result = run_script(script, *SMOKE_ARGS, "--output-dir", directory / "out", *extra, cwd=directory)
    assert result.returncode == 0, result.stderr
    method = Path(script).stem
    match = re.fullmatch(rf"Hopper-v4 {method}: score (-?[\d.]+) ± ([\d.]+) \(mean ± std over 1 seed\), \d+% of the expert's \d+", result.stdout.strip().splitlines()[-1])
    assert match, result.stdout
    summary = json.loads((directory / "out" / "result_seeds1.json").read_text())
    assert summary["method"] == method and summary["env"] == "Hopper-v4"
    assert abs(summary["mean"] - float(match.group(1))) <= 0.05 and list(summary["scores"]) == ["1"]
    return result.stdout, summary


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
