"""Every top-level script turns tyro's multi-line parse-error box into one line on stderr, exit 2."""
import pytest

from conftest import REPO_ROOT, assert_usage_error, run_in_process

SCRIPTS = sorted(path.name for path in REPO_ROOT.glob("*.py"))

COMMON_CASES = {
    "missing value": (["--env"], "Missing value for argument '--env'"),
    "unknown flag": (["--no-such-flag", 1], "Unrecognized options: --no-such-flag, 1: see --help"),
    "misspelled flag": (["--envv", "Hopper-v4"], "Unrecognized options: --envv, Hopper-v4 (perhaps you meant --env STR): see --help"),
}


@pytest.mark.parametrize("case", COMMON_CASES)
@pytest.mark.parametrize("script", SCRIPTS)
def test_a_bad_command_line_is_one_line_and_exit_2(script, case):
    args, message = COMMON_CASES[case]
    result = run_in_process(script, *args)
    assert_usage_error(result, message)
    assert result.returncode == 2 and result.stdout == ""


@pytest.mark.parametrize("args, message", [
    (["--epochs", "abc"], "Error parsing --epochs: invalid literal for int() with base 10: 'abc': see --help"),
    (["--fusion", "sideways"], "invalid choice 'sideways' for argument '--fusion'. Expected one of ('late', 'output', 'middle', 'early'): see"),
    (["--seeds", "1", "two"], "Error parsing --seeds: "),
])
def test_a_bad_flag_value_names_the_flag(args, message):
    result = run_in_process("c2f.py", *args)
    assert_usage_error(result, message)


@pytest.mark.parametrize("script", ["c2f.py", "expert_ppo.py"])
def test_help_still_prints_and_exits_0(script):
    result = run_in_process(script, "--help")
    assert result.returncode == 0 and result.stderr == ""
    assert "--env STR" in result.stdout


@pytest.mark.parametrize("stdout_encoding", ["utf-8", "ascii"])
def test_both_box_styles_are_read(stdout_encoding, monkeypatch):
    """tyro draws its box in UTF-8 or plain ASCII depending on stdout's encoding; both reduce to one line."""
    import io

    import c2f

    monkeypatch.setattr("sys.argv", ["c2f.py", "--envv", "Ant-v4"])
    monkeypatch.setattr("sys.stdout", io.TextIOWrapper(io.BytesIO(), encoding=stdout_encoding))
    with pytest.raises(c2f.UsageError) as error:
        c2f.parse_args()
    assert str(error.value) == "Unrecognized options: --envv, Ant-v4 (perhaps you meant --env STR): see --help for every flag and its values"
