"""benchmark/h3.py on planted copycat_analysis.py reports and runs: the figures it tabulates, its means, the reference
at the paper's setting, what it leaves out and why; and that the committed h3.md is what it makes now."""
import json
import shutil

import pytest
from conftest import REPO_ROOT, assert_usage_error, plant_run, run_in_process, run_module

from benchmark import h3
from benchmark.regimes import runs_dir

ENV = "Hopper-v4"


def report(seed, hidden=True, zeta=(0.04, 0.03, 0.02), models=None, scale=1.0):
    """A copycat_analysis.json of seed's models (models: {row: seed} to plant other seeds), its figures scaled by scale."""
    models = {m: seed for m in h3.MODELS if hidden or m != "c2f_no_coarse"} | (models or {})
    row = {"rollout_returns": [100.0 * scale, 200.0 * scale, 300.0 * scale], "history_change_demos": 0.25 * scale,
           "towards_previous_demos": 0.8 * scale, "history_change_rollouts": 0.3 * scale,
           "towards_previous_rollouts": 0.9 * scale, "copycat_score": 0.3 * scale}
    return {"env": ENV, "hide_velocities": hidden,
            "methods": {m: {"model": f"runs/{m}/{ENV}/seed{s}.pt", **row} for m, s in models.items()},
            "zeta": {"relative_demos": list(zeta), "relative_rollouts": [z / 2 for z in zeta]}}


def write(path, content):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    return path


@pytest.fixture
def planted(tmp_path):
    """Reports of seeds 1 and 2 (seed 2's figures twice seed 1's), references at the paper's setting for seeds 1 and 3,
    re-made runs (seed S of method m scores 100 S + its index) and the map's (1000 + that), and files to leave out."""
    analysis, reference, remade, results = tmp_path / "reference" / "hidden", tmp_path / "reference", tmp_path / "h3", tmp_path / "regimes"
    write(analysis / "seed1" / "copycat_analysis.json", report(1))
    write(analysis / "seed2" / "copycat_analysis.json", report(2, zeta=(0.06, 0.05, 0.04), scale=2.0))
    write(reference / "copycat_analysis.json", report(1, hidden=False, zeta=(0.12, 0.11, 0.10)))
    write(reference / "seed3" / "copycat_analysis.json", report(3, hidden=False, zeta=(0.22, 0.09, 0.05)))
    for seed in (1, 2):
        for index, method in enumerate(h3.MODELS):
            if method != "c2f_no_coarse":
                plant_run(runs_dir("native_hidden", remade), method, seed, 100.0 * seed + index)
            plant_run(runs_dir("native_hidden", results), method, seed, 1000.0 + 100.0 * seed + index)
    plant_run(runs_dir("native_hidden", results), "c2f_middle", 1, 5.0)  # another row of the map: not H3's, not listed
    left_out = [
        f"left out {write(analysis / 'seed3' / 'copycat_analysis.json', report(4))}: its models are seed 4's, its folder seed3",
        f"left out {write(analysis / 'seed5' / 'copycat_analysis.json', report(5, models={'bc_oh': 6}))}: its models are not one seed's "
        "(bc_so: seed 5, bc_oh: seed 6, c2f: seed 5, c2f_no_coarse: seed 5)",
        f"left out {write(analysis / 'seed7' / 'copycat_analysis.json', report(7, hidden=False))}: not Hopper-v4 with the velocities hidden",
        f"left out {write(analysis / 'seed8' / 'copycat_analysis.json', '{cut')}: unreadable report (JSONDecodeError",
        f"left out reference {write(reference / 'seed9' / 'copycat_analysis.json', '[]')}",
        f"left out reference {write(reference / 'other' / 'copycat_analysis.json', report(1, hidden=False, zeta=(0.9,) * 3))}: "
        "a second report of seed 1 (the first, by path, is kept)",
        f"left out {plant_run(runs_dir('native_hidden', remade), 'bc_oh', 3, 5.0, hide_velocities=False)}: not the native_hidden settings",
    ]
    return ["--analysis-dir", str(analysis), "--reference", str(reference), "--h3-dir", str(remade), "--results-dir", str(results)], \
        analysis, left_out


def section(text, heading):
    return text.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]


def test_scores_history_figures_and_means_are_those_planted(planted, capsys):
    argv, analysis, _ = planted
    assert h3.main(argv) == 0
    text = (analysis / "h3.md").read_text()
    runs = section(text, "The runs")
    assert "| 1 | 100 (map 1100) | 101 (map 1101) | 102 (map 1102) | 1103 |" in runs  # the control's run is the map's own
    assert "| 2 | 200 (map 1200) | 201 (map 1201) | 202 (map 1202) | 1203 |" in runs
    history = section(text, "do(o_hist)")
    assert "| 1 | BC-OH | 200 | 0.250 | 0.80 | 0.300 | 0.90 | 0.30 |" in history
    assert "| 2 | BC-OH | 400 | 0.500 | 1.60 | 0.600 | 1.80 | 0.60 |" in history
    assert "| mean | BC-OH | 300 | 0.375 | 1.20 | 0.450 | 1.35 | 0.45 |" in history  # over seeds, returns over all rollouts
    assert "| mean | no-coarse control | 300 |" in history
    assert "Made by `python -m benchmark.h3 --analysis-dir" in text and "reports of seeds 1, 2 " in text
    assert capsys.readouterr().out.endswith(f"wrote {analysis / 'h3.md'}\n")


def test_zeta_weights_here_beside_the_paper_setting_by_seed(planted):
    argv, analysis, _ = planted
    h3.main(argv)
    zeta = section((analysis / "h3.md").read_text(), "do(ζ)")
    assert "there, the same figure was 0.05–0.22." in zeta  # the range of the references' weights
    assert "| 1 | 0.04, 0.03, 0.02 | 0.02, 0.01, 0.01 | 0.12, 0.11, 0.10 |" in zeta
    assert "| 2 | 0.06, 0.05, 0.04 | 0.03, 0.03, 0.02 | — |" in zeta
    assert "| 3 | — | — | 0.22, 0.09, 0.05 |" in zeta


def test_reports_and_runs_that_do_not_fit_are_left_out_with_their_reason(planted, capsys):
    argv, analysis, left_out = planted
    h3.main(argv)
    part, err = section((analysis / "h3.md").read_text(), "Left out"), capsys.readouterr().err
    for line in left_out:
        assert line in part and line in err
    assert part.count("- left out") == len(left_out)  # the map's other rows are not H3's: not listed
    assert "| 4 |" not in (analysis / "h3.md").read_text().split("## Left out")[0]


def test_no_report_is_one_line_and_exit_2(tmp_path):
    result = run_module("benchmark.h3", "--analysis-dir", tmp_path)
    assert_usage_error(result, "run copycat_analysis.py as docs/regimes.md shows")
    assert result.returncode == 2


def test_a_mistyped_reference_folder_is_one_line_and_exit_2(planted, tmp_path):
    """It would otherwise leave the reference column out, silently."""
    argv, analysis, _ = planted
    argv = [*argv]
    argv[argv.index("--reference") + 1] = str(tmp_path / "nowhere")
    result = run_module("benchmark.h3", *argv)
    assert_usage_error(result, f"reference folder {tmp_path / 'nowhere'} not found: pass --reference")
    assert result.returncode == 2 and not (analysis / "h3.md").exists()


@pytest.mark.parametrize("flag", ["--h3-dir", "--results-dir"])
def test_a_mistyped_run_folder_is_one_line_and_exit_2(planted, tmp_path, flag):
    """It showed every score of those runs as —, with a warning per seed, and exit status 0."""
    argv, analysis, _ = planted
    argv = [*argv]
    argv[argv.index(flag) + 1] = str(tmp_path / "nowhere")
    result = run_in_process("benchmark/h3.py", *argv)
    # The re-made runs need the runner's flags that made them; the map is the runner's default grid.
    runs = ""
    if flag == "--h3-dir":
        runs = " --methods bc_so bc_oh c2f --envs Hopper-v4 --seeds 1 2 3 --save-model"
    message = (f"no {tmp_path / 'nowhere' / 'native_hidden' / 'runs'}: run python -m benchmark.regimes --regimes "
               f"native_hidden{runs} --results-dir {tmp_path / 'nowhere'} first, or pass {flag}")
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")
    assert not (analysis / "h3.md").exists()


def test_a_reference_that_is_a_file_is_one_line_that_says_so(planted, tmp_path):
    """It said 'not found', of a file that is there."""
    argv, _, _ = planted
    argv = [*argv]
    argv[argv.index("--reference") + 1] = str(write(tmp_path / "reference.json", "{}"))
    result = run_in_process("benchmark/h3.py", *argv)
    message = (f"reference folder {tmp_path / 'reference.json'} is a file, not a folder: pass --reference, the folder "
               "of the reports at the paper's setting")
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")


def test_when_no_report_reads_each_is_named_before_the_one_line(tmp_path):
    """It said only that none was valid, as if there were none."""
    analysis = tmp_path / "analysis"
    cut = write(analysis / "seed1" / "copycat_analysis.json", "{cut")
    for folder in ("h3", "regimes"):
        runs_dir("native_hidden", tmp_path / folder).mkdir(parents=True)
    result = run_in_process("benchmark/h3.py", "--analysis-dir", analysis, "--reference", tmp_path, "--h3-dir",
                            tmp_path / "h3", "--results-dir", tmp_path / "regimes")
    assert result.returncode == 2 and result.stderr.splitlines() == [
        f"left out {cut}: unreadable report (JSONDecodeError: Expecting property name enclosed in double quotes: line 1 "
        "column 2 (char 1))",
        f"error: no valid {analysis}/seed<S>/copycat_analysis.json (see above): run copycat_analysis.py as "
        "docs/regimes.md shows"]


def test_a_reference_folder_without_a_report_says_so(planted, tmp_path, capsys):
    """A folder holding no report at the paper's setting left its column out without a word; a report that is a JSON
    list was told as "'list' object has no attribute 'get'"."""
    argv, analysis, _ = planted
    argv = [*argv]
    listed = write(tmp_path / "elsewhere" / "copycat_analysis.json", "[]")
    argv[argv.index("--reference") + 1] = str(tmp_path / "elsewhere")
    assert h3.main(argv) == 0
    err = capsys.readouterr().err.splitlines()
    assert f"left out reference {listed}: not a JSON object (not a report of copycat_analysis.py)" in err
    assert f"no report at the paper's setting under {tmp_path / 'elsewhere'}: its column shows —" in err
    assert f"- no report at the paper's setting under {tmp_path / 'elsewhere'}: its column shows —" in (analysis / "h3.md").read_text()


def test_the_committed_h3_page_is_what_the_tool_makes_from_the_committed_reports(tmp_path):
    committed = REPO_ROOT / h3.ANALYSIS_DIR
    copy = shutil.copytree(committed, tmp_path / "native_hidden")
    run = run_module("benchmark.h3", "--analysis-dir", copy)
    assert run.returncode == 0, run.stderr
    made = (copy / "h3.md").read_text().replace(f" --analysis-dir {copy}", "")
    assert made == (committed / "h3.md").read_text(), "analysis h3.md is stale: run python -m benchmark.h3"


def test_a_report_with_a_missing_or_bad_figure_is_left_out(planted, capsys):
    argv, analysis, _ = planted
    broken = report(6)
    broken["methods"]["bc_oh"]["copycat_score"] = None
    write(analysis / "seed6" / "copycat_analysis.json", broken)
    no_zeta = report(10)
    del no_zeta["zeta"]
    write(analysis / "seed10" / "copycat_analysis.json", no_zeta)
    assert h3.main(argv) == 0
    err = capsys.readouterr().err
    assert f"left out {analysis / 'seed6' / 'copycat_analysis.json'}: a figure is missing or not a number" in err
    assert f"left out {analysis / 'seed10' / 'copycat_analysis.json'}: unreadable report (KeyError" in err
    assert "| 6 |" not in (analysis / "h3.md").read_text().split("## Left out")[0]


def test_a_missing_score_or_a_malformed_zeta_is_named_not_a_traceback(planted, capsys):
    argv, analysis, _ = planted
    odd = report(11)
    odd["zeta"] = 3
    write(analysis / "seed11" / "copycat_analysis.json", odd)
    (analysis.parent.parent / "h3" / "native_hidden" / "runs" / "c2f" / ENV / "result_seeds2.json").unlink()
    assert h3.main(argv) == 0
    err = capsys.readouterr().err
    assert f"left out {analysis / 'seed11' / 'copycat_analysis.json'}: a figure is missing or not a number" in err
    assert f"no valid result of c2f seed 2 under {analysis.parent.parent / 'h3'}: its score shows —" in err
    assert "| 2 | 200 (map 1200) | 201 (map 1201) | — (map 1202) | 1203 |" in (analysis / "h3.md").read_text()
