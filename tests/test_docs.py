"""The README and the pages under docs/: every relative link resolves (file and #anchor), every page is linked from
the README, the README stays short and its first screen answers a newcomer, and the capacity test's declaration stays
word for word what was committed before its runs."""
import hashlib
import re
import unicodedata

import pytest
from conftest import REPO_ROOT

README = REPO_ROOT / "README.md"
PAGES = [README, *sorted((REPO_ROOT / "docs").glob("*.md")), REPO_ROOT / "experts" / "README.md"]
MOST_README_LINES = 200
FIRST_SCREEN_LINES = 60
MOST_FIRST_SCREEN_WORDS = 460
"""the README's first 60 lines: about 450 words (counted as `wc -w` does, code blocks and tables included)"""
MOST_PARAGRAPH_WORDS = 85
INSTALL = ("python3 -m venv .venv && . .venv/bin/activate && pip install torch==2.13.0 "
           "--index-url https://download.pytorch.org/whl/cpu\npip install -r requirements.txt\n")

LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
"""[text](target) and ![alt](target); the text may hold one level of [brackets]"""


def prose(text: str) -> str:
    """The text without fenced code blocks and inline code, where brackets and # are not markdown."""
    text = re.sub(r"^```.*?^```[^\n]*$", "", text, flags=re.M | re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: its text lower-cased, without markup and punctuation, spaces as hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "").strip().lower()
    kept = "".join(c for c in text if unicodedata.category(c)[0] in "LMN" or unicodedata.category(c) == "Pc" or c in " -")
    return kept.replace(" ", "-")


def anchors(page) -> set:
    """The anchors of a page's headings (outside code blocks); a repeated heading gets -1, -2, ... as on GitHub."""
    seen, result = {}, set()
    for line in re.sub(r"^```.*?^```[^\n]*$", "", page.read_text(), flags=re.M | re.S).splitlines():
        match = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if match:
            base = slug(match.group(1))
            result.add(base if base not in seen else f"{base}-{seen[base]}")
            seen[base] = seen.get(base, 0) + 1
    return result


def relative_links(page) -> list:
    return [target for target in LINK.findall(prose(page.read_text())) if not re.match(r"[a-z][a-z0-9+.-]*:", target)]


def test_the_slugs_follow_github():
    assert slug("Reproducibility: what \"same seed, same numbers\" means here") == "reproducibility-what-same-seed-same-numbers-means-here"
    assert slug("Seeing the copycat shortcut: `copycat_analysis.py` (paper section 5.4, H3)") == \
        "seeing-the-copycat-shortcut-copycat_analysispy-paper-section-54-h3"
    assert slug("Is the gain the coarse action's, or an extra layer? Capacity controls") == \
        "is-the-gain-the-coarse-actions-or-an-extra-layer-capacity-controls"


def broken_links(page, root=REPO_ROOT) -> list:
    """One line per relative link of page whose file, or heading in a linked .md file, does not exist."""
    broken = []
    for target in relative_links(page):
        path, _, anchor = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        if root.resolve() not in [linked, *linked.parents]:
            broken.append(f"{target}: outside the repository")
        elif not linked.exists():
            broken.append(f"{target}: no file {linked}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no heading #{anchor} in {linked}")
    return broken


def test_a_broken_link_or_anchor_is_found(tmp_path):
    (tmp_path / "other.md").write_text("# A heading\n\n```\n# not a heading\n```\n")
    page = tmp_path / "page.md"
    page.write_text("[ok](other.md#a-heading) [gone](missing.md) [no anchor](other.md#not-a-heading) [web](https://x.org/y)\n"
                    "`[in code](nowhere.md)` ![picture](other.md) [self](#title)\n\n# Title\n")
    assert broken_links(page, tmp_path) == ["missing.md: no file " + str(tmp_path / "missing.md"),
                                            "other.md#not-a-heading: no heading #not-a-heading in " + str(tmp_path / "other.md")]


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(REPO_ROOT)))
def test_every_relative_link_points_to_a_file_and_heading_that_exist(page):
    assert page.is_file()
    assert broken_links(page) == []


def test_the_readme_is_short_and_links_every_page_and_the_license():
    lines = README.read_text().splitlines()
    assert len(lines) <= MOST_README_LINES, f"README.md has {len(lines)} lines: move material into a page under docs/"
    linked = {(REPO_ROOT / target.partition("#")[0]).resolve() for target in relative_links(README)}
    assert set(PAGES[1:]) <= linked, "every page is linked from the README"
    assert (REPO_ROOT / "LICENSE").resolve() in linked and (REPO_ROOT / "LICENSE").read_text().startswith("MIT License")


def test_the_readme_first_screen_answers_a_newcomer():
    """The first 60 lines say how to install, check, run and test, how long each takes, and whether C2F works, in
    about 450 words: the install block alone (it does not start the main job), no paragraph over about 80 words."""
    screen = "\n".join(README.read_text().splitlines()[:FIRST_SCREEN_LINES]) + "\n"
    words = len(screen.split())
    assert words <= MOST_FIRST_SCREEN_WORDS, f"the README's first {FIRST_SCREEN_LINES} lines hold {words} words"
    assert f"```bash\n{INSTALL}```\n" in screen, "the install block, alone, on the first screen"
    for needed in ["## Does C2F work?", "python c2f.py --env Hopper-v4 --seeds 1 --epochs 30\n",
                   "python c2f.py --env Hopper-v4\n", "python -m pytest\n", "| BC-SO", "| BC-OH", "| C2F"]:
        assert needed in screen, f"the first screen lacks {needed!r}"
    assert screen.index("## Does C2F work?") > screen.index("python -m pytest"), "install, check, run and test come first"
    for paragraph in re.sub(r"^```.*?^```[^\n]*$", "", screen, flags=re.M | re.S).split("\n\n"):
        if not paragraph.lstrip().startswith("|"):
            for item in re.split(r"\n(?=- )", paragraph):
                assert len(item.split()) <= MOST_PARAGRAPH_WORDS, f"a paragraph over about 80 words: {item[:60]!r}"


DECLARATIONS = {
    "the capacity test and Table 3 (README of commit 12c0a93)": (
        "### Is the gain the coarse action's, or an extra layer?",
        "core-hours, over more than one working session (the runner resumes; finished runs are skipped).\n",
        "09b01760aa0580daf4083f2a965b37f5beb29ad005661dfd2dc0182c566ea5c6"),
    "the baselines in native_hidden and the Walker2d controls (issue 33)": (
        "### Baselines in `native_hidden`, and two more capacity controls (declared before their runs)",
        '    --seeds 1 2 3 4 5 --workers 2 --results-dir "$OLDPWD/results/regimes"\n```\n',
        "f35f6fcc55a3c6163a0bf02ef93f7cfc05e871b90a46b15c212c2c981342f25e"),
}
"""declaration -> (its first line, its last line, the SHA-256 of the section as committed before any of its runs)"""


@pytest.mark.parametrize("name", list(DECLARATIONS))
def test_a_declaration_is_word_for_word_the_one_committed_before_its_runs(name):
    first, last, sha256 = DECLARATIONS[name]
    text = (REPO_ROOT / "docs" / "regimes.md").read_text()
    assert text.count(first) == 1
    start = text.index(first)
    section = text[start:text.index(last, start) + len(last)]
    assert hashlib.sha256(section.encode()).hexdigest() == sha256, "a pre-registration is not reworded"
