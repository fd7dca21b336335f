"""benchmark/stats.py against hand-computed figures, and benchmark/regime_summary.py on a small synthetic regime map."""
from pathlib import Path

import pytest
from conftest import REPO_ROOT, assert_usage_error, plant, run_in_process, run_module, summarise

from benchmark import aggregate, regime_summary
from benchmark.regimes import runs_dir
from benchmark.stats import bootstrap_ci, expert_normalised, probability_of_improvement, probability_of_improvement_ci

# ----------------------------------------------------------------------------------------------
# Statistics


def test_bootstrap_interval_of_identical_scores_or_one_score_is_a_point():
    assert bootstrap_ci([7.0] * 5) == (7.0, 7.0)
    assert bootstrap_ci([3.3]) == (3.3, 3.3)


def test_bootstrap_interval_holds_the_mean_within_the_scores_and_is_deterministic():
    scores = [1.0, 2.0, 3.0, 10.0, 4.0]
    low, high = bootstrap_ci(scores)
    assert 1.0 <= low < 4.0 < high <= 10.0  # mean 4
    assert bootstrap_ci(scores) == (low, high)  # the same seed draws the same resamples


def test_bootstrap_interval_of_two_scores_by_hand():
    # resampled means of [0, 1]: 0 (1/4), 0.5 (1/2), 1 (1/4): the 2.5% and 97.5% tails land on 0 and 1, the 30% and 70% on 0.5
    assert bootstrap_ci([0.0, 1.0]) == (0.0, 1.0)
    assert bootstrap_ci([0.0, 1.0], confidence=0.4) == (0.5, 0.5)


@pytest.mark.parametrize("x, y, expected", [
    ([1, 2, 3], [2, 2, 2], (0 * 3 + 0.5 * 3 + 1 * 3) / 9),  # 0.5
    ([3, 4], [1, 2, 3], 5.5 / 6),  # 3 beats 1 and 2 and ties 3; 4 beats all three
    ([5, 6], [1, 2], 1.0),
    ([1, 2], [5, 6], 0.0),
    ([2, 2], [2, 2, 2], 0.5),
])
def test_probability_of_improvement_by_hand(x, y, expected):
    assert probability_of_improvement(x, y) == pytest.approx(expected)
    assert probability_of_improvement(y, x) == pytest.approx(1 - expected)


def test_probability_of_improvement_interval_by_hand():
    assert probability_of_improvement_ci([5, 6], [1, 2]) == (1.0, 1.0)  # every resample: every x above every y
    # x resampled from [0, 1] against y = 0.5: P = 0 (1/4), 0.5 (1/2), 1 (1/4)
    assert probability_of_improvement_ci([0, 1], [0.5]) == (0.0, 1.0)
    assert probability_of_improvement_ci([0, 1], [0.5], confidence=0.4) == (0.5, 0.5)
    assert probability_of_improvement_ci([1, 4, 2], [3, 0]) == probability_of_improvement_ci([1, 4, 2], [3, 0])


def test_expert_normalised():
    assert expert_normalised(300.0, 1000.0) == pytest.approx(0.3)


# ----------------------------------------------------------------------------------------------
# The summary CLI


def test_summary_numbers_files_and_left_out_runs(regime_map, capsys):
    results, experts, problems = regime_map
    assert summarise(results, experts) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and all(any(line.startswith(problem) for line in err) for problem in problems), err
    assert (results / "native_noise" / "mujoco.csv").read_text().splitlines() == [
        "env,method,seed,score",
        "Hopper-v4,bc_so,1,100.000", "Hopper-v4,bc_so,2,300.000", "Hopper-v4,bc_oh,1,200.000", "Hopper-v4,bc_oh,2,400.000",
        "Hopper-v4,c2f,1,500.000", "Hopper-v4,c2f,2,700.000", "Hopper-v4,c2f_output,1,600.000", "Walker2d-v4,bc_oh,1,80.000"]
    assert (results / "fs1_noise" / "mujoco.csv").read_text() == "env,method,seed,score\nHopper-v4,bc_oh,1,50.000\n"
    summary = (results / "summary.md").read_text()
    assert summary.index("**native_noise**") < summary.index("**fs1_noise**") and "native_hidden" not in summary
    assert f"runs made by commit (not recorded); others as `{results / 'native_noise' / 'README.md'}` says)." in summary  # its provenance file
    assert "runs made by commit (not recorded))." in summary  # fs1_noise has none
    assert f"--results-dir {results} --expert-runs {experts}` from 9 per-seed results" in summary
    # mean, interval of the resampled means (200, 300 or 400), seeds, mean / expert 1000
    assert "| Hopper-v4 | BC-OH | 300 | [200, 400] | n=2, incomplete | 0.30 |" in summary
    assert "| Hopper-v4 | C2F (output fusion) | 600 | [600, 600] | n=1, incomplete | 0.60 |" in summary
    assert "| Walker2d-v4 | BC-OH | 80 | [80, 80] | n=1, incomplete | 0.20 |" in summary
    assert "| Hopper-v4 | BC-OH | 50 | [50, 50] | n=1, incomplete | 0.05 |" in summary  # fs1_noise
    assert "| Hopper-v4 | P(Coarse-to-fine > BC-OH) | 1.00 | [1.00, 1.00] | n=2 vs 2, incomplete | undecided (fewer than 5 seeds) |" in summary
    assert "| Hopper-v4 | P(C2F (output fusion) > BC-OH) | 1.00 | [1.00, 1.00] | n=1 vs 2, incomplete | undecided (fewer than 5 seeds) |" in summary
    # 200 and 400 against 100 and 300: 3 of 4 pairs; a resample of 200, 200 against 300, 300 (1/16) gives 0, one of 400, 400 gives 1
    assert "| Hopper-v4 | P(BC-OH > BC-SO) | 0.75 | [0.00, 1.00] | n=2 vs 2, incomplete | undecided (fewer than 5 seeds) |" in summary
    # 500 and 700 against 100 and 300: every pair; a comparison added after the runs says so
    assert ("| Hopper-v4 | P(Coarse-to-fine > BC-SO) | 1.00 | [1.00, 1.00] | n=2 vs 2, incomplete | "
            "undecided (fewer than 5 seeds), exploratory (added after the runs) |") in summary
    # over envs: BC-OH (0.30 + 0.20) / 2; the others on Hopper only
    assert ("Expert-normalised mean over envs: BC-SO 0.20 (1 env); BC-OH 0.25 (2 envs); Coarse-to-fine 0.60 (1 env); "
            "C2F (output fusion) 0.60 (1 env).") in summary
    assert (results / "summary.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_summary_goes_into_the_page_between_its_markers(regime_map, tmp_path, capsys):
    results, experts, _ = regime_map
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n<!-- regimes -->\nthe old map\n<!-- /regimes -->\n\nReading.\n")
    assert summarise(results, experts, "--page", page) == 0
    text = page.read_text()
    assert text.startswith("# Title\n\n<!-- regimes -->\nMade by `python -m benchmark.regime_summary --results-dir ")
    assert f"--page {page}` from 9 per-seed results" in text
    assert "the old map" not in text and (results / "summary.md").read_text().split("\n", 2)[2].strip() in text
    assert text.endswith("\n\n![Regime map](results/regimes/summary.png)\n<!-- /regimes -->\n\nReading.\n")


def test_a_bare_page_flag_writes_docs_regimes_md_and_names_it(regime_map, tmp_path, monkeypatch):
    """--page alone is the page the summary owns, docs/regimes.md; the summary's command line names it."""
    results, experts, _ = regime_map
    monkeypatch.chdir(tmp_path)
    page = tmp_path / "docs" / "regimes.md"
    page.parent.mkdir()
    page.write_text("<!-- regimes -->\n<!-- /regimes -->\n")
    assert regime_summary.PAGE == Path("docs/regimes.md")
    assert summarise(results.relative_to(tmp_path), experts.relative_to(tmp_path), "--page") == 0
    text = page.read_text()
    assert "--expert-runs runs --page docs/regimes.md` from 9 per-seed results" in text
    assert text.endswith("\n\n![Regime map](../results/regimes/summary.png)\n<!-- /regimes -->\n")


def test_docs_regimes_md_holds_the_committed_map():
    """The page the summary owns carries its block, and the block is the committed results/regimes/summary.md
    (rerun `python -m benchmark.regime_summary --page` after new runs)."""
    aggregate.page_parts(REPO_ROOT / regime_summary.PAGE, regime_summary.PAGE_START, regime_summary.PAGE_END)
    block = (REPO_ROOT / regime_summary.PAGE).read_text().split("<!-- regimes -->", 1)[1].split("<!-- /regimes -->")[0]
    summary = (REPO_ROOT / "results" / "regimes" / "summary.md").read_text()
    assert summary.split("\n", 2)[2].strip() in block and "--page docs/regimes.md` from" in summary
    assert "![Regime map](../results/regimes/summary.png)" in block


def cli(*args):
    return run_module("benchmark.regime_summary", *args)


def test_bad_input_is_one_line_and_exit_2(regime_map, tmp_path):
    results, experts, _ = regime_map
    page = tmp_path / "page.md"
    page.write_text("# Title without markers\n")
    result = cli("--results-dir", results, "--expert-runs", experts, "--page", page)
    assert_usage_error(result, "needs one <!-- regimes --> line and, after it, one <!-- /regimes --> line")
    assert result.returncode == 2 and not (results / "summary.md").exists(), "nothing is written before the page is checked"
    result = cli("--results-dir", tmp_path / "nowhere")
    assert_usage_error(result, "results folder")
    assert result.returncode == 2
    # A mistyped --expert-runs would leave every expert-normalised mean out with only a warning.
    result = cli("--results-dir", results, "--expert-runs", tmp_path / "nowhere")
    assert_usage_error(result, f"no expert/ folder in {tmp_path / 'nowhere'}: pass --expert-runs")
    assert result.returncode == 2 and not (results / "summary.md").exists()


@pytest.mark.parametrize("score", [0.0, -5.0])
def test_an_expert_score_not_above_0_leaves_the_shares_of_it_out(regime_map, capsys, score):
    """Hopper's expert at 0 ended in a ZeroDivisionError traceback; below 0 it turned every share's sign."""
    import json

    from benchmark.results import make_result, result_path

    results, experts, _ = regime_map
    path = result_path(experts, "expert", "Hopper-v4", [0])
    path.write_text(json.dumps(make_result("Hopper-v4", "expert", {"env": "Hopper-v4", "seeds": [0]}, {0: [[0, score]]})))
    assert summarise(results, experts) == 0
    assert (f"no expert score for Hopper-v4 ({path}: its score {score:g} is not above 0 (a share of it would mean "
            "nothing)): its expert-normalised means are left out") in capsys.readouterr().err.splitlines()
    summary = (results / "summary.md").read_text()
    assert "| Hopper-v4 | BC-OH | 300 | [200, 400] | n=2, incomplete | — |" in summary
    assert "| Walker2d-v4 | BC-OH | 80 | [80, 80] | n=1, incomplete | 0.20 |" in summary


@pytest.mark.parametrize("folder, message", [
    # "no valid regime results under ... (see above)", with nothing above: a regime's own folder passed
    ("results/regimes/native_noise", "no <regime>/runs/ folder under {tmp}/results/regimes/native_noise (native_noise, "
     "fs1_noise, native_hidden, fs1_hidden): pass the folder python -m benchmark.regimes wrote (--results-dir), or run it"),
    # "results folder ... not found", of a file that is there
    ("results/regimes/native_noise/README.md", "results folder {tmp}/results/regimes/native_noise/README.md is a file, "
     "not a folder: run python -m benchmark.regimes first, or pass --results-dir"),
])
def test_a_results_dir_that_is_not_the_maps_is_one_line(regime_map, tmp_path, folder, message):
    _, experts, _ = regime_map
    result = run_in_process("benchmark/regime_summary.py", "--results-dir", tmp_path / folder, "--expert-runs", experts)
    assert (result.returncode, result.stderr) == (2, f"error: {message.format(tmp=tmp_path)}\n")


def test_no_valid_results_is_exit_2(tmp_path):
    wrong = plant(runs_dir("fs1_noise", tmp_path), "bc_oh", "Hopper-v4", 1, [1.0] * 3)  # at the native rate
    (tmp_path / "experts" / "expert").mkdir(parents=True)
    result = cli("--results-dir", tmp_path, "--expert-runs", tmp_path / "experts")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert lines[0] == f"left out {wrong}: not the fs1_noise settings (frame_skip 4 != 1)"
    assert lines[-1].startswith("error: no valid regime results under") and not (tmp_path / "summary.md").exists()


def test_the_verdict_needs_five_seeds_a_cell_and_an_interval_that_excludes_one_half():
    from pathlib import Path

    from benchmark.aggregate import Record

    def records(method, scores):
        return [Record(method, "Hopper-v4", seed, score, Path("x")) for seed, score in enumerate(scores, 1)]

    apart = records("bc_so", [10, 11, 12, 13, 14]) + records("bc_oh", [20, 21, 22, 23, 24]) + records("c2f", [19, 21, 23, 25, 20])
    lines = "\n".join(regime_summary.regime_tables("fs1_noise", apart, {}, ""))
    assert "| Hopper-v4 | P(BC-OH > BC-SO) | 1.00 | [1.00, 1.00] | n=5 vs 5 | separated |" in lines
    # c2f against bc_oh: 19 wins 0, 20 ties once (0.5), 21 wins 1 + tie, 23 wins 3 + tie, 25 wins 5: 10.5 of 25 pairs
    assert "| Hopper-v4 | P(Coarse-to-fine > BC-OH) | 0.42 |" in lines and "n=5 vs 5 | not separated (more seeds) |" in lines
    assert "| Hopper-v4 | P(Coarse-to-fine > BC-SO) | 1.00 | [1.00, 1.00] | n=5 vs 5 | separated, exploratory (added after the runs) |" in lines
