"""scripts/file_sizes.py: the README's table of file lengths and diffs against bc_oh.py."""
import file_sizes
from conftest import REPO_ROOT, assert_usage_error, run_script


def test_the_table_counts_lines_and_diff_lines(tmp_path):
    rows = {row.split(" | ")[0].strip("| `"): row for row in file_sizes.table().splitlines()[2:]}
    assert set(rows) == {f"{name}.py" for name in file_sizes.TARGETS}
    assert f"| {len((REPO_ROOT / 'bc_oh.py').read_text().splitlines())} (330) |" in rows["bc_oh.py"]
    assert 0 < file_sizes.diff_lines("bc_so") < file_sizes.diff_lines("dagger")
    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- sizes -->\nold\n<!-- /sizes -->\nrest\n")
    file_sizes.main(["--readme", str(readme)])
    assert readme.read_text() == "intro\n<!-- sizes -->\n" + file_sizes.table() + "<!-- /sizes -->\nrest\n"


def test_a_readme_without_markers_is_one_line(tmp_path):
    (tmp_path / "README.md").write_text("no markers\n")
    assert_usage_error(run_script("scripts/file_sizes.py", "--readme", tmp_path / "README.md"), "needs one <!-- sizes --> line")
    assert_usage_error(run_script("scripts/file_sizes.py", "--readme", tmp_path / "missing.md"), "not found")
