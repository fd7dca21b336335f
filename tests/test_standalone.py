"""Each method file must run on its own when copied alone into a new folder: it imports nothing of this repo."""
import ast
import dataclasses
import importlib
import os
import re
import shutil
import subprocess
import sys

import pytest

from conftest import METHOD_FILES, REPO_ROOT, check_summary, demo_file

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


@pytest.mark.parametrize("script", [script for script in SCRIPTS if script not in METHOD_FILES])
def test_script_runs_alone_in_an_empty_folder(script, tmp_path):
    """The real thing the import check stands for: the file, copied alone into a new folder, starts (--help). The
    method files do more alone: test_a_method_file_trains_alone_in_an_empty_folder_with_its_demo_file."""
    shutil.copy(REPO_ROOT / script, tmp_path / script)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # nothing of this repo on the path
    result = subprocess.run([sys.executable, script, "--help"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    assert "--env" in result.stdout


def in_order(node) -> list:
    """The string constants under node, in source order (an f-string's parts, nested ones included)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    return [text for child in ast.iter_child_nodes(node) for text in in_order(child)]


def usage_messages(tree) -> set:
    """The text of every UsageError message: `raise UsageError(...)` and `require(condition, message)`, and apart, the
    text of each local variable a message interpolates (e.g. a command built up in `make = ...; make += ...`)."""
    messages = set()
    for scope in [tree, *(node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)))]:
        assigned = {}  # a local name -> the strings of its assignments, in source order
        for node in ast.walk(scope) if scope is not tree else []:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AugAssign) else []
            for target in (target for target in targets if isinstance(target, ast.Name)):
                assigned.setdefault(target.id, []).extend(in_order(node.value))
        for node in ast.walk(scope):
            if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and getattr(node.exc.func, "id", "") == "UsageError":
                message = node.exc
            elif isinstance(node, ast.Call) and getattr(node.func, "id", "") == "require" and len(node.args) == 2:
                message = node.args[1]
            else:
                continue
            messages.add(" ".join(in_order(message)))
            names = {name.id for name in ast.walk(message) if isinstance(name, ast.Name)}
            messages |= {" ".join(assigned[name]) for name in names & set(assigned)}
    return messages


COMMAND = re.compile(r"python (\w+)\.py\b([^`),;:]*)")
"""`python SCRIPT.py --flag ...` inside a message: a command of that script, up to a backtick, bracket or punctuation"""


def named_flags(text) -> set:
    return {flag.replace("-", "_").removeprefix("no_") for flag in re.findall(r"--([a-z][a-z0-9-]*)", text)}


def args_fields(script) -> set:
    return {field.name for field in dataclasses.fields(importlib.import_module(script).Args)}


@pytest.mark.parametrize("script", SCRIPTS)
def test_error_messages_name_only_flags_the_script_has(script):
    """A fix that names a flag the script does not take is a lie (e.g. "pass --checkpoint" in a file without
    one): every --flag in a UsageError message is a field of that script's Args, except in a command of another
    script that the message quotes ("run python expert_ppo.py --env E --make-demos"): those are that script's."""
    fields, named, quoted = args_fields(script.removesuffix(".py")), set(), {}
    for text in usage_messages(ast.parse((REPO_ROOT / script).read_text())):
        for command in COMMAND.finditer(text):
            quoted.setdefault(command[1], set()).update(named_flags(command[2]))
        named |= named_flags(COMMAND.sub("", text))
    if script == "copycat_analysis.py":
        # it reads models trained by the method files: its messages name their training flags
        # (--seeds, --save-model, --coarse-output, --frame-skip, --velocity-dims, --batch-size)
        fields |= args_fields("c2f_table3")
    assert named <= fields, f"{script} names flags it does not have: {sorted(named - fields)}"
    for other, flags in quoted.items():
        assert (REPO_ROOT / f"{other}.py").is_file(), f"{script} quotes a command of {other}.py, which is not in the repo"
        assert flags <= args_fields(other), f"{script} quotes {other}.py with flags it does not have: {sorted(flags - args_fields(other))}"


@pytest.mark.parametrize("script", METHOD_FILES)
def test_a_method_file_trains_alone_in_an_empty_folder_with_its_demo_file(script, tmp_path):
    """What a user who copies one file does: the file and the demo file it loads (DAgger also its expert, which it
    queries), nothing else of this repo on the path; a tiny run ends with its summary line and its result."""
    from conftest import make_demos

    shutil.copy(REPO_ROOT / script, tmp_path / script)
    (tmp_path / "demos").mkdir()
    shutil.copy(make_demos("Hopper-v4", 120), tmp_path / "demos" / "Hopper-v4_120.npz")
    if script == "dagger.py":
        (tmp_path / "experts").mkdir()
        shutil.copy(REPO_ROOT / "experts" / "Hopper-v4.pt", tmp_path / "experts" / "Hopper-v4.pt")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    budget = ["--seeds", "1", "--epochs", "1", "--eval-every", "1", "--eval-episodes", "1", "--num-demo-samples", "120",
              "--batch-size", "32", *(["--dagger-samples", "20", "--dagger-rounds", "1", "--dagger-epochs", "1"] if script == "dagger.py" else [])]
    result = subprocess.run([sys.executable, script, *budget], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    (result_file,) = tmp_path.glob("runs/Hopper-v4__*__*/result_seeds1.json")
    # the summary line (the mean as printed, the share of the expert's return in the demos' meta) agrees with the JSON
    expert = demo_file(tmp_path / "demos" / "Hopper-v4_120.npz")[1]["expert_return"]
    check_summary(result.stdout, tmp_path, result_file.parent.relative_to(tmp_path), script.removesuffix(".py"), expert=expert)
    assert set(os.listdir(tmp_path)) == {script, "demos", "runs", *(["experts"] if script == "dagger.py" else [])}
