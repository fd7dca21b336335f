"""Helpers shared by all test files (pytest loads this file itself; import it as `conftest`).

    from conftest import REPO_ROOT, run_script, assert_usage_error

    result = run_script("expert_ppo.py", "--env", "Nope-v0", cwd=tmp_path)
    assert_usage_error(result, "cannot make env")

pytest.ini puts the repo root and scripts/ on sys.path, so tests can also `import expert_ppo`,
`import bc_oh` or `import check_copies` directly.
"""
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
"""The repository root: the method scripts, experts/, scripts/ and tests/ live here."""


def run_script(script, *args, cwd=None, timeout=120):
    """Run `python REPO_ROOT/script *args` and return the subprocess.CompletedProcess.

    stdout and stderr are captured as text (result.stdout, result.stderr); the exit code is not
    checked. cwd defaults to a fresh temporary directory, so relative default paths (runs/, experts/)
    never touch the repo; pass cwd=tmp_path to look at what the script wrote there. Warnings are
    silenced (PYTHONWARNINGS=ignore) so stderr holds only what the script itself prints.
    Arguments may be str, int, float or Path.
    """
    env = dict(os.environ, PYTHONWARNINGS="ignore")
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
