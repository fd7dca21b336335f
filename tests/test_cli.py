"""A bad command line ends in tyro's own error message (the ecosystem's convention): exit 2, no traceback,
and a message that names the flag at fault."""
import re

import pytest

from conftest import METHOD_FILES, REPO_ROOT, run_in_process

SCRIPTS = sorted(path.name for path in REPO_ROOT.glob("*.py"))

COMMON_CASES = {
    "missing value": (["--env"], "Missing value for argument '--env'"),
    "unknown flag": (["--no-such-flag", 1], "Unrecognized options: --no-such-flag"),
    "misspelled flag": (["--envv", "Hopper-v4"], "Perhaps you meant: --env STR"),
}


def assert_tyro_error(result, message):
    assert result.returncode == 2 and result.stdout == "" and "Traceback" not in result.stderr, result.stderr
    unboxed = re.sub(r"\+-+|-+\+|-{3,}|[│╭╮╰╯─|]", " ", result.stderr)  # tyro's box, in UTF-8 or ASCII
    text = " ".join(unboxed.split())  # its words, unwrapped
    assert message in text, text


@pytest.mark.parametrize("case", COMMON_CASES)
@pytest.mark.parametrize("script", SCRIPTS)
def test_a_bad_command_line_exits_2_naming_the_flag(script, case):
    args, message = COMMON_CASES[case]
    assert_tyro_error(run_in_process(script, *args), message)


@pytest.mark.parametrize("args, message", [
    (["--epochs", "abc"], "--epochs"),
    (["--fusion", "sideways"], "invalid choice 'sideways' for argument '--fusion'. Expected one of ('late', 'output', 'middle', 'early', 'penultimate')"),
    (["--seeds", "1", "two"], "--seeds"),
])
def test_a_bad_flag_value_names_the_flag(args, message):
    assert_tyro_error(run_in_process("c2f_table3.py", *args), message)


@pytest.mark.parametrize("script", ["c2f.py", "expert_ppo.py"])
def test_help_still_prints_and_exits_0(script):
    result = run_in_process(script, "--help")
    assert result.returncode == 0 and result.stderr == ""
    assert "--env STR" in result.stdout


@pytest.mark.parametrize("script", METHOD_FILES)
def test_help_opens_with_a_line_saying_what_the_script_does(script):
    """tyro prints the Args docstring under the usage line: the method's name and what it does."""
    import importlib

    lines = [line for line in run_in_process(script, "--help").stdout.splitlines() if line.strip()]
    assert lines[0].startswith("usage: ") and script in lines[0]
    summary = importlib.import_module(script.removesuffix(".py")).Args.__doc__.strip()
    assert lines[1] == summary and ": " in summary, lines[1]


@pytest.mark.parametrize("script", METHOD_FILES)
def test_an_env_id_without_a_version_is_refused_before_anything_else(script, tmp_path, monkeypatch):
    """gymnasium would make Hopper-v5 of "Hopper", and the demo file of it would not be found: refused first."""
    from conftest import assert_usage_error

    monkeypatch.chdir(tmp_path)
    result = run_in_process(script, "--env", "Hopper")
    assert_usage_error(result, "env 'Hopper' has no version: use Hopper-v4 or Hopper-v5")
    assert result.returncode == 2
