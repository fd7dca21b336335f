"""scripts/file_sizes.py: the table of file lengths and diffs against bc_oh.py, and the
contributors' page it goes into."""

import os
import sys
from pathlib import Path
from types import SimpleNamespace

import file_sizes
import pytest
from conftest import REPO_ROOT, assert_usage_error, run_script


def run_in_process(capsys, argv):
    """Run file_sizes as its command does (run_cli): (exit status, stdout, stderr) as a result
    for assert_usage_error."""
    with pytest.raises(SystemExit) as exit:
        file_sizes.run_cli(lambda: file_sizes.main(argv))
    captured = capsys.readouterr()
    return SimpleNamespace(returncode=exit.value.code, stdout=captured.out, stderr=captured.err)


HEADER = [
    "| file | formatted lines (target) | diff vs bc_oh.py (target) |",
    "|---|---:|---:|",
]


def over(value, most):
    if value > most:
        return ", over"
    return ""


def test_the_table_has_a_row_per_existing_file_and_the_anchors(tmp_path):
    lines = file_sizes.table().splitlines()
    assert lines[:2] == HEADER
    rows = {row.split(" | ")[0].strip("| `"): row.split(" | ")[1:] for row in lines[2:]}
    files = {f"{name}.py" for name in file_sizes.TARGETS if (REPO_ROOT / f"{name}.py").exists()}
    assert {"bc_oh.py", "c2f.py", "dagger.py", "expert_ppo.py"} <= files
    anchors = {
        "CleanRL `ppo_continuous_action.py` (for comparison; black, 127 columns)",
        "CORL `any_percent_bc.py` (black)",
    }
    assert set(rows) == files | anchors
    lines = len(file_sizes.formatted("bc_oh").splitlines())
    assert rows["bc_oh.py"] == [f"{lines} (380{over(lines, 380)})", "— |"]
    diff = file_sizes.diff_lines("dagger")
    assert rows["dagger.py"][1] == f"{diff} (200{over(diff, 200)}) |"
    assert rows["expert_ppo.py"][1] == "— |"
    assert 0 < file_sizes.diff_lines("bc_so") < diff
    page = tmp_path / "page.md"
    page.write_text("intro\n<!-- sizes -->\nold\n<!-- /sizes -->\nrest\n")
    file_sizes.main(["--page", str(page)])
    expected = "intro\n<!-- sizes -->\n" + file_sizes.table() + "<!-- /sizes -->\nrest\n"
    assert page.read_text() == expected


def test_lines_are_counted_formatted_and_copy_markers_are_no_diff(tmp_path, monkeypatch):
    """A long line counts as the lines `ruff format` makes of it at 100 columns; a '# Copied from'
    marker is not a difference; a file that does not exist has no row."""
    long = "VALUES = [" + ", ".join(map(str, range(30))) + "]\n"  # 120 columns: one entry a line
    (tmp_path / "bc_oh.py").write_text("def f():\n    return 1\n" + long)
    (tmp_path / "bc_so.py").write_text("# Copied from bc_oh.f\ndef f():\n    return 2\n" + long)
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    targets = {"bc_oh": (30, None), "bc_so": (100, 2), "fca": (460, 160)}
    monkeypatch.setattr(file_sizes, "TARGETS", targets)
    entries = "".join(f"    {n},\n" for n in range(30))
    formatted = "def f():\n    return 1\n\n\nVALUES = [\n" + entries + "]\n"
    assert file_sizes.formatted("bc_oh") == formatted
    assert file_sizes.table().splitlines()[2:] == [
        "| `bc_oh.py` | 36 (30, over) | — |",
        "| `bc_so.py` | 37 (100) | 2 (2) |",  # return 1 -> return 2: one < and one >
        *file_sizes.ANCHORS.splitlines(),
    ]


def test_a_line_of_100_columns_stays_one_line(tmp_path, monkeypatch):
    line = "VALUES = [" + ", ".join(["1234"] * 14) + ", 12345]\n"
    assert len(line) == 101  # 100 columns and the newline
    (tmp_path / "bc_oh.py").write_text(line)
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    assert file_sizes.formatted("bc_oh") == line
    (tmp_path / "bc_oh.py").write_text(line.replace("12345]", "123456]"))
    assert len(file_sizes.formatted("bc_oh").splitlines()) > 1


def test_c2f_table3_is_compared_with_c2f_when_it_exists(tmp_path, monkeypatch):
    (tmp_path / "bc_oh.py").write_text("x = 1\n")
    (tmp_path / "c2f.py").write_text("x = 1\ny = 2\n")
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    monkeypatch.setattr(
        file_sizes, "TARGETS", {name: file_sizes.TARGETS[name] for name in ["c2f", "c2f_table3"]}
    )
    assert [row.split(" | ")[0] for row in file_sizes.table().splitlines()[2:4]] == [
        "| `c2f.py`",
        "| CleanRL `ppo_continuous_action.py` (for comparison; black, 127 columns)",
    ]
    (tmp_path / "c2f_table3.py").write_text("x = 1\ny = 3\nz = 4\n")
    rows = file_sizes.table().splitlines()[2:4]
    assert rows == [
        "| `c2f.py` | 2 (430) | 1 (100) |",
        "| `c2f_table3.py` | 3 (520) | 3 against c2f.py |",
    ]


def test_a_bare_page_flag_writes_docs_contributing_md(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "contributing.md").write_text("<!-- sizes -->\n<!-- /sizes -->\n")
    assert str(file_sizes.PAGE) == "docs/contributing.md"
    file_sizes.main(["--page"])
    expected = "<!-- sizes -->\n" + file_sizes.table() + "<!-- /sizes -->\n"
    assert (tmp_path / "docs" / "contributing.md").read_text() == expected


def test_docs_contributing_md_holds_the_current_table():
    """The page the script owns carries its block, up to date with the method files (after
    changing one, run `python scripts/file_sizes.py --page`)."""
    before, after = file_sizes.page_parts(REPO_ROOT / file_sizes.PAGE, *file_sizes.MARKERS)
    text = (REPO_ROOT / file_sizes.PAGE).read_text()
    assert text == before + "\n" + file_sizes.table() + after


def test_a_page_without_markers_is_one_line(tmp_path):
    (tmp_path / "page.md").write_text("no markers\n")
    result = run_script("scripts/file_sizes.py", "--page", tmp_path / "page.md")
    assert_usage_error(result, "needs one <!-- sizes --> line")
    result = run_script("scripts/file_sizes.py", "--page", tmp_path / "missing.md")
    assert_usage_error(result, "not found")


def test_the_budget_gives_each_definitions_lines_to_its_part_and_sums_to_the_file(
    tmp_path, monkeypatch
):
    source = (
        '"""doc"""\nimport os\n\n\nclass Args:\n    x = 1\n\n\ndef mlp():\n    return 1\n\n\n'
        "@staticmethod\ndef run():\n    return 2\n\n\ndef load_demos():\n    return 3\n"
    )
    (tmp_path / "bc_oh.py").write_text(source)
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    assert file_sizes.budget("bc_oh") == {
        "Args": 2,
        "the method": 2,
        "run": 3,
        "errors": 0,
        "evaluation": 0,
        "env and partial observability": 0,
        "data": 2,
        "the rest": 11,
    }
    # ruff puts a blank line after the docstring
    assert len(file_sizes.formatted("bc_oh").splitlines()) == 20


def test_the_budget_of_a_real_file_sums_to_its_formatted_lines_and_is_printed_in_one_line(capsys):
    parts = file_sizes.budget("c2f")
    assert sum(parts.values()) == len(file_sizes.formatted("c2f").splitlines())
    assert parts["the method"] > parts["evaluation"] > 0
    assert file_sizes.main(["--budget", "c2f"]) == 0
    shares = "; ".join(f"{p} {n}" for p, n in parts.items())
    expected = f"c2f.py, {sum(parts.values())} formatted lines: {shares}\n"
    assert capsys.readouterr().out == expected


def test_the_budget_of_a_missing_file_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    result = run_in_process(capsys, ["--budget", "c2f_table3"])
    assert_usage_error(result, f"{tmp_path / 'c2f_table3.py'} not found")


def test_ruff_runs_through_the_running_interpreter_without_bin_on_path():
    """`.venv/bin/python scripts/file_sizes.py` works with no venv bin/ on PATH."""
    assert file_sizes.RUFF == [sys.executable, "-m", "ruff"]
    result = run_script("scripts/file_sizes.py", "--budget", "bc_oh", env={"PATH": ""})
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("bc_oh.py, ")


def test_without_ruff_it_says_so_in_one_line(monkeypatch, capsys):
    """Where the running Python has no ruff module (simulated by a module that does not exist)."""
    monkeypatch.setattr(file_sizes, "RUFF", [sys.executable, "-m", "ruff_is_not_installed"])
    result = run_in_process(capsys, [])
    assert_usage_error(
        result, f"ruff is not installed for {sys.executable}: pip install -r requirements.txt"
    )
    assert result.returncode == 2 and result.stdout == ""


def test_budget_and_page_together_are_refused(tmp_path, capsys):
    """--budget printed its line and left the page alone, though --page asked to write it."""
    page = tmp_path / "page.md"
    page.write_text("<!-- sizes -->\n<!-- /sizes -->\n")
    result = run_in_process(capsys, ["--budget", "bc_oh", "--page", str(page)])
    message = "--budget prints one file's parts, not the table that --page writes"
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"error: {message}: leave out --budget or --page\n"


def test_a_page_that_cannot_be_written_is_refused_before_the_table(tmp_path, monkeypatch, capsys):
    """A read-only folder (chmod does not stop root: os.access, which the check asks, plays it)
    was found only when writing, after the table was measured and printed."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    page = folder / "page.md"
    page.write_text("<!-- sizes -->\n<!-- /sizes -->\n")
    real_access = os.access

    def access(path, mode, **kwargs):
        return real_access(path, mode, **kwargs) and Path(path) != folder

    def no_table():
        raise AssertionError("the table was measured before the page was checked")

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(file_sizes, "table", no_table)
    result = run_in_process(capsys, ["--page", str(page)])
    reason = f"{folder} is not writable"
    expected = f"error: --page {page} cannot be written: {reason}: pass another --page\n"
    assert (result.returncode, result.stdout, result.stderr) == (2, "", expected)
