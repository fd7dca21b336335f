"""scripts/file_sizes.py: the table of file lengths and diffs against bc_oh.py, and the contributors' page it goes into."""
import file_sizes
import pytest
from conftest import REPO_ROOT, assert_usage_error, run_script


def test_the_table_has_a_row_per_method_file_and_the_anchors(tmp_path):
    lines = file_sizes.table().splitlines()
    assert lines[:2] == ["| file | formatted lines (target) | characters (target) | diff vs bc_oh.py (target) |", "|---|---:|---:|---:|"]
    rows = {row.split(" | ")[0].strip("| `"): row.split(" | ")[1:] for row in lines[2:]}
    assert set(rows) == {f"{name}.py" for name in file_sizes.TARGETS} | {"CleanRL `ppo_continuous_action.py` (for comparison)",
                                                                       "CORL `any_percent_bc.py"}
    text = file_sizes.formatted("bc_oh")
    over = lambda value, most: ", over" if value > most else ""  # noqa: E731
    assert rows["bc_oh.py"] == [f"{len(text.splitlines())} (400{over(len(text.splitlines()), 400)})",
                                f"{len(text)} (18000{over(len(text), 18_000)})", "— |"]
    diff = file_sizes.diff_lines("dagger")
    assert rows["dagger.py"][2] == f"{diff} (150{over(diff, 150)}) |" and rows["dagger.py"][1].isdigit()  # no character target
    assert 0 < file_sizes.diff_lines("bc_so") < diff
    page = tmp_path / "page.md"
    page.write_text("intro\n<!-- sizes -->\nold\n<!-- /sizes -->\nrest\n")
    file_sizes.main(["--page", str(page)])
    assert page.read_text() == "intro\n<!-- sizes -->\n" + file_sizes.table() + "<!-- /sizes -->\nrest\n"


def test_lines_and_characters_are_counted_formatted_and_copy_markers_are_no_diff(tmp_path, monkeypatch):
    """A long line counts as the lines `ruff format` makes of it; a '# Copied from' marker is not a difference."""
    long = "VALUES = [" + ", ".join(map(str, range(60))) + "]\n"  # 240 columns: ruff puts each entry on its own line
    (tmp_path / "bc_oh.py").write_text("def f():\n    return 1\n" + long)
    (tmp_path / "bc_so.py").write_text("# Copied from bc_oh.f\ndef f():\n    return 2\n" + long)
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    monkeypatch.setattr(file_sizes, "TARGETS", {"bc_oh": (60, 500, None), "bc_so": (100, None, 2)})
    formatted = "def f():\n    return 1\n\n\nVALUES = [\n" + "".join(f"    {n},\n" for n in range(60)) + "]\n"
    assert file_sizes.formatted("bc_oh") == formatted
    rows = file_sizes.table().splitlines()[2:4]
    assert rows == [f"| `bc_oh.py` | 66 (60, over) | {len(formatted)} (500, over) | — |",
                    f"| `bc_so.py` | 67 (100) | {len(formatted) + len('# Copied from bc_oh.f') + 1} | 2 (2) |"]  # return 1 -> return 2: one < and one >


def test_a_bare_page_flag_writes_docs_contributing_md(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "contributing.md").write_text("<!-- sizes -->\n<!-- /sizes -->\n")
    assert str(file_sizes.PAGE) == "docs/contributing.md"
    file_sizes.main(["--page"])
    assert (tmp_path / "docs" / "contributing.md").read_text() == "<!-- sizes -->\n" + file_sizes.table() + "<!-- /sizes -->\n"


def test_docs_contributing_md_holds_the_current_table():
    """The page the script owns carries its block, up to date with the method files (after changing one, run
    `python scripts/file_sizes.py --page`)."""
    before, after = file_sizes.page_parts(REPO_ROOT / file_sizes.PAGE, *file_sizes.MARKERS)
    text = (REPO_ROOT / file_sizes.PAGE).read_text()
    assert text == before + "\n" + file_sizes.table() + after


def test_a_page_without_markers_is_one_line(tmp_path):
    (tmp_path / "page.md").write_text("no markers\n")
    assert_usage_error(run_script("scripts/file_sizes.py", "--page", tmp_path / "page.md"), "needs one <!-- sizes --> line")
    assert_usage_error(run_script("scripts/file_sizes.py", "--page", tmp_path / "missing.md"), "not found")


def test_the_budget_gives_each_definitions_lines_to_its_part_and_sums_to_the_file(tmp_path, monkeypatch):
    source = ('"""doc"""\nimport os\n\n\nclass Args:\n    x = 1\n\n\ndef mlp():\n    return 1\n\n\n@staticmethod\ndef run():\n'
              "    return 2\n\n\ndef load_demos():\n    return 3\n")
    (tmp_path / "bc_oh.py").write_text(source)
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    assert file_sizes.budget("bc_oh") == {"Args": 2, "the method": 2, "run": 3, "errors": 0, "evaluation": 0,
                                          "env and partial observability": 0, "data": 2, "the rest": 11}
    assert len(file_sizes.formatted("bc_oh").splitlines()) == 20  # ruff puts a blank line after the docstring


def test_the_budget_of_a_real_file_sums_to_its_formatted_lines_and_is_printed_in_one_line(capsys):
    parts = file_sizes.budget("c2f")
    assert sum(parts.values()) == len(file_sizes.formatted("c2f").splitlines()) and parts["the method"] > parts["evaluation"] > 0
    assert file_sizes.main(["--budget", "c2f"]) == 0
    assert capsys.readouterr().out == f"c2f.py, {sum(parts.values())} formatted lines: " + "; ".join(f"{p} {n}" for p, n in parts.items()) + "\n"


def test_without_ruff_it_says_so_in_one_line():
    result = run_script("scripts/file_sizes.py", env={"PATH": ""})
    assert_usage_error(result, "ruff is not on PATH: pip install -r requirements.txt")
    assert result.returncode == 2


def test_each_feature_of_the_shared_part_has_a_cost_and_all_cost_the_most(capsys):
    """--features: taking each feature out of bc_oh.py (so out of every method file) saves lines and characters."""
    costs = file_sizes.feature_costs()
    assert list(costs) == [*file_sizes.FEATURES, "all of them"]
    assert all(lines > 0 and characters > 0 for lines, characters in costs.values())
    every = costs.pop("all of them")
    assert max(lines for lines, _ in costs.values()) < every[0] <= sum(lines for lines, _ in costs.values())
    assert file_sizes.main(["--features"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0] == f"--velocity-dims: {costs['--velocity-dims'][0]} formatted lines, {costs['--velocity-dims'][1]} characters"
    assert len(printed) == len(file_sizes.FEATURES) + 1 and printed[-1].startswith(f"all of them: {every[0]} formatted lines")


def test_a_feature_cost_counts_the_formatted_lines_its_edits_take_out(tmp_path, monkeypatch):
    (tmp_path / "bc_oh.py").write_text("def f():\n    x = 1\n    y = 2  # a feature\n    return x\n")
    monkeypatch.setattr(file_sizes, "ROOT", tmp_path)
    monkeypatch.setattr(file_sizes, "FEATURES", {"y": [(r"^    y = .*\n", "")], "x": [(r"^    x = 1\n", ""), (r"return x", "return 1")]})
    assert file_sizes.feature_costs() == {"y": (1, 23), "x": (1, 10), "all of them": (2, 33)}
    monkeypatch.setattr(file_sizes, "FEATURES", {"gone": [(r"^    z = .*\n", "")]})
    with pytest.raises(file_sizes.UsageError, match="the edit .* of 'gone' finds nothing in bc_oh.py: update FEATURES"):
        file_sizes.feature_costs()
    monkeypatch.setattr(file_sizes, "FEATURES", {"broken": [(r"^    return x\n", "    return (\n")]})
    with pytest.raises(file_sizes.UsageError, match="the edits of 'broken' leave bc_oh.py unparsable"):
        file_sizes.feature_costs()
