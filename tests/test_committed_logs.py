"""Committed results name no machine: the command on a log's first line uses paths relative to the repository."""
import re

from conftest import REPO_ROOT


def test_no_committed_log_names_an_absolute_path():
    logs = sorted((REPO_ROOT / "results").rglob("*.log"))
    assert len(logs) > 200, "the committed grid logs are where this test looks"
    absolute = [f"{log.relative_to(REPO_ROOT)}: {line}" for log in logs
                for line in [log.read_text(errors="replace").partition("\n")[0]] if re.search(r"(^|\s)/\S", line.removeprefix("$ "))]
    assert absolute == [], "\n".join(absolute[:5])
