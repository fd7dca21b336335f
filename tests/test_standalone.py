"""Each method file must run on its own when copied alone into a new folder: it imports nothing of this repo."""
import ast
import os
import shutil
import subprocess
import sys

import pytest

from conftest import REPO_ROOT

SCRIPTS = sorted(path.name for path in REPO_ROOT.glob("*.py"))
OWN_MODULES = {path.stem for path in REPO_ROOT.glob("*.py")} | {"benchmark", "scripts", "tests", "conftest", "check_copies"}


def imported_modules(path) -> set:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            names.add("." if node.level else node.module.split(".")[0])
    return names


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_imports_nothing_of_this_repo(script):
    own = imported_modules(REPO_ROOT / script) & (OWN_MODULES | {"."})
    assert not own, f"{script} imports {own}: copy the code in with a '# Copied from' marker instead"


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_runs_alone_in_an_empty_folder(script, tmp_path):
    """The real thing the import check stands for: the file, copied alone into a new folder, starts (--help)."""
    shutil.copy(REPO_ROOT / script, tmp_path / script)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # nothing of this repo on the path
    result = subprocess.run([sys.executable, script, "--help"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    assert "--env" in result.stdout


@pytest.mark.parametrize("script", SCRIPTS)
def test_error_messages_name_only_flags_the_script_has(script):
    """A fix that names a flag the script does not take is a lie (e.g. "pass --checkpoint" in a file without
    one): every --flag in a UsageError message is a field of that script's Args."""
    import dataclasses
    import importlib
    import re

    module = importlib.import_module(script.removesuffix(".py"))
    fields = {field.name for field in dataclasses.fields(module.Args)}
    named = set()
    for node in ast.walk(ast.parse((REPO_ROOT / script).read_text())):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and getattr(node.exc.func, "id", "") == "UsageError":
            text = " ".join(part.value for part in ast.walk(node.exc) if isinstance(part, ast.Constant) and isinstance(part.value, str))
            named |= {flag.replace("-", "_").removeprefix("no_") for flag in re.findall(r"--([a-z][a-z0-9-]*)", text)}
    if script == "copycat_analysis.py":
        # it reads models trained by the method files: its messages name their training flags
        # (--seeds, --save-model, --coarse-output, --frame-skip, --velocity-dims, --batch-size)
        fields |= {field.name for field in dataclasses.fields(importlib.import_module("c2f").Args)}
    assert named <= fields, f"{script} names flags it does not have: {sorted(named - fields)}"
