"""Each method file must run on its own when copied alone into a new folder: it imports nothing of this repo."""
import ast

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


def test_every_method_file_is_checked():
    assert {"expert_ppo.py", "bc_so.py", "bc_oh.py", "c2f.py", "fca.py", "keyframe.py", "history_dropout.py",
            "average_ensemble.py", "dagger.py", "copycat_analysis.py"} <= set(SCRIPTS)


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_imports_nothing_of_this_repo(script):
    own = imported_modules(REPO_ROOT / script) & (OWN_MODULES | {"."})
    assert not own, f"{script} imports {own}: copy the code in with a '# Copied from' marker instead"


def test_the_check_catches_a_repo_import(tmp_path):
    planted = tmp_path / "planted.py"
    planted.write_text("import numpy\nfrom bc_oh import stack_history\n")
    assert imported_modules(planted) & OWN_MODULES == {"bc_oh"}
