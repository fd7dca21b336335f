"""scripts/file_sizes.py: the table of file lengths and diffs against bc_oh.py, and the contributors' page it goes into."""
import file_sizes
from conftest import REPO_ROOT, assert_usage_error, run_script


def test_the_table_counts_lines_and_diff_lines(tmp_path):
    rows = {row.split(" | ")[0].strip("| `"): row for row in file_sizes.table().splitlines()[2:]}
    assert set(rows) == {f"{name}.py" for name in file_sizes.TARGETS}
    assert f"| {len((REPO_ROOT / 'bc_oh.py').read_text().splitlines())} (330) |" in rows["bc_oh.py"]
    assert 0 < file_sizes.diff_lines("bc_so") < file_sizes.diff_lines("dagger")
    page = tmp_path / "page.md"
    page.write_text("intro\n<!-- sizes -->\nold\n<!-- /sizes -->\nrest\n")
    file_sizes.main(["--page", str(page)])
    assert page.read_text() == "intro\n<!-- sizes -->\n" + file_sizes.table() + "<!-- /sizes -->\nrest\n"


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
