"""benchmark/table3.py on a small planted native_hidden map and replication: the declared verdicts, which seeds are
pooled where, what is left out and why, the header's commits and machines, and the picture. The Table 3 rows run
c2f_table3.py; their results made by c2f.py before it held the ablations (method "c2f") count alike."""
import json

import pytest
from conftest import (
    assert_usage_error,
    plant,
    plant_expert,
    plant_run,
    run_in_process,
    run_module,
    set_machine,
)

from benchmark import table3
from benchmark.regimes import runs_dir
from benchmark.results import ResultError, read_result

ENV = "Hopper-v4"


@pytest.fixture
def planted(tmp_path):
    """Map seeds 1-5 and replication seeds 6-10 of C2F (1000 + 10 per seed) and BC-OH (500 + 10 per seed); the
    controls on seeds 1-10 in the map: no-coarse 600 + 10 per seed (below every C2F seed), penultimate 5 above each
    BC-OH seed (a tie); the Table 3 rows on seeds 1-5, each planted to meet or miss its prediction; and files to
    leave out. Commits: the map aaaa, the controls bbbb, the replication cccc. Expert 1000."""
    results, replication, experts = tmp_path / "regimes", tmp_path / "replication", tmp_path / "runs"
    runs, rep = runs_dir("native_hidden", results), runs_dir("native_hidden", replication)
    for seed in range(1, 11):
        folder = runs if seed <= 5 else rep
        plant_run(folder, "c2f", seed, 1000.0 + 10 * (seed - 1))
        plant_run(folder, "bc_oh", seed, 500.0 + 10 * (seed - 1))
        set_machine(plant_run(runs, "c2f_no_coarse", seed, 600.0 + 10 * (seed - 1)), "Test CPU", "AVX2")
        set_machine(plant_run(runs, "c2f_penultimate", seed, 505.0 + 10 * (seed - 1)), "Test CPU", "AVX512")
    rows = {"bc_so": [100.0] * 5,
            "c2f_middle": [1005.0, 995.0, 1015.0, 1025.0, 1035.0],  # among C2F's seeds: no difference, confirmed
            "c2f_early": [2000.0] * 5,  # above every C2F seed: 'no difference' refuted
            "c2f_output": [300.0] * 5,  # reported only
            "c2f_feature": [200.0] * 5,  # below C2F: worse, confirmed
            "c2f_coarse_history": [505.0, 515.0, 525.0, 535.0, 545.0],  # below C2F, among BC-OH: falls to BC-OH, confirmed
            "c2f_coarse_history_policy_current": [50.0] * 5,  # below both: falls to BC-OH or below, confirmed
            "c2f_no_stop_gradient": [3000.0] * 5,  # above C2F: worse, refuted
            "c2f_two_stage": [900.0, 910.0]}  # two seeds: incomplete
    for method, scores in rows.items():
        for seed, score in enumerate(scores, 1):
            plant_run(runs, method, seed, score)
    plant(runs, "bc_oh", "Walker2d-v4", 1, [80.0] * 3, hide_velocities=True)  # valid, but not part of these tests: not listed
    left_out = [
        f"left out {plant_run(runs, 'c2f_two_stage', 3, 5000.0, hide_velocities=False)}: not the native_hidden settings (hide_velocities False != True)",
        f"left out {plant_run(runs, 'c2f', 6, 5000.0, fusion='middle')}: not the native_hidden settings (fusion middle != late)",
        f"left out {plant_run(runs, 'c2f_middle', 7, 5000.0)}: seed 7 is not among the seeds declared for c2f_middle (1–5)",
        f"left out {plant_run(rep, 'bc_so', 6, 5000.0)}: the replication counts only for the capacity test",
        f"left out {plant_run(rep, 'bc_oh', 5, 5000.0)}: seed 5 of bc_oh is in the map too (the map's counts)",
        f"left out {runs / 'c2f_early' / ENV / 'result_seeds6.json'}: unreadable JSON",
    ]
    (runs / "c2f_early" / ENV / "result_seeds6.json").write_text("{not json")
    (runs / "commit.txt").write_text("a" * 40 + "\n")
    for method in ("c2f_no_coarse", "c2f_penultimate"):
        (runs / method / "commit.txt").write_text("b" * 40 + "\n")
    (rep / "commit.txt").write_text("c" * 40 + "\n")
    plant_expert(experts, ENV, 1000.0)
    return results, replication, experts, left_out


def summarise(results, replication, experts):
    return table3.main(["--results-dir", str(results), "--replication-dir", str(replication), "--expert-runs", str(experts)])


def test_capacity_test_pools_map_and_replication_and_gives_the_declared_verdicts(planted, capsys):
    results, replication, experts, _ = planted
    assert summarise(results, replication, experts) == 0
    table = (results / "native_hidden" / "table3.md").read_text()
    assert capsys.readouterr().out.startswith(table)
    # every C2F seed 1-10 (1000-1090) above every control seed (600-690): separated above 0.5
    assert "| 1. capacity | P(C2F > no-coarse control) | 1.00 | [1.00, 1.00] | n=10 vs 10 | C2F beats the control |" in table
    # penultimate 505-595 against BC-OH 500-590: seed k beats k of BC-OH's seeds, 55 of 100 pairs
    assert "| 2. ζ at BC-OH's capacity | P(penultimate fusion > BC-OH) | 0.55 |" in table
    assert "| n=10 vs 10 | 0.5 inside the interval: not decided |" in table
    assert "| reported, not a test | P(no-coarse control > BC-OH) | 1.00 | [1.00, 1.00] | n=10 vs 10 | reported, not a test |" in table
    # the sides: C2F's seeds 1-5 from the map and 6-10 from the replication (the replication's seed 5 of BC-OH is left out)
    assert "| C2F (`c2f`) | 1–10 | 10 | 1045 | " in table and ", ".join(str(1000 + 10 * k) for k in range(10)) in table
    assert "| BC-OH (`bc_oh`) | 1–10 | 10 | 545 | " in table


def test_table3_rows_use_seeds_1_to_5_only_and_give_the_declared_verdicts(planted):
    results, replication, experts, _ = planted
    summarise(results, replication, experts)
    part = (results / "native_hidden" / "table3.md").read_text().split("## Table 3 on MuJoCo", 1)[1].split("## Left out")[0]
    rows = {line.split(" | ")[0].strip("| "): line for line in part.splitlines() if line.startswith("| ") and "(`" in line.split(" | ")[0]}
    # not pooled: C2F's row is the map's seeds 1-5 (mean 1020, not 1045), and so are the controls' rows
    assert rows["C2F (late fusion, the paper) (`c2f`)"] == ("| C2F (late fusion, the paper) (`c2f`) | (default) | n=5 | 1020 | [1008, 1032] | 1.02 | — | "
                                                          "1.00 [1.00, 1.00] | 49.3 ± 3.6 | (the paper's model) | — |")
    assert "| `--no-coarse-action` | n=5 | 620 |" in rows["no coarse action (`c2f_no_coarse`)"]
    assert "| `--fusion penultimate` | n=5 | 525 |" in rows["penultimate fusion (`c2f_penultimate`)"]
    verdicts = {name: line.rstrip(" |").rsplit(" | ", 1)[1] for name, line in rows.items()}
    assert verdicts == {
        "C2F (late fusion, the paper) (`c2f`)": "—",
        "middle fusion (`c2f_middle`)": "confirmed",
        "early fusion (`c2f_early`)": "refuted",
        "output fusion (`c2f_output`)": "reported only",
        "penultimate fusion (`c2f_penultimate`)": "refuted",  # 525 on seeds 1-5: below every C2F seed, not 'no difference'
        "feature as ζ (`c2f_feature`)": "confirmed",
        "BC-OH as π_φ and π_θ (`c2f_coarse_history`)": "confirmed",
        "BC-OH as π_φ + BC-SO as π_θ (`c2f_coarse_history_policy_current`)": "confirmed",
        "no stop-gradient (`c2f_no_stop_gradient`)": "refuted",
        "two-stage (`c2f_two_stage`)": "incomplete (n=2 of 5): no verdict",
        "no coarse action (`c2f_no_coarse`)": "reported only",
        "BC-OH (`bc_oh`)": "—",
        "BC-SO (`bc_so`)": "—",
    }
    assert ("| `--coarse-output feature` | n=5 | 200 | [200, 200] | 0.20 | 0.00 [0.00, 0.00] | 0.00 [0.00, 0.00] | 44.8 ± 5.2 | "
            "worse | confirmed |") in rows["feature as ζ (`c2f_feature`)"]
    assert rows["BC-SO (`bc_so`)"] == ("| BC-SO (`bc_so`) | — | n=5 | 100 | [100, 100] | 0.10 | 0.00 [0.00, 0.00] | "
                                       "0.00 [0.00, 0.00] | — | (reference) | — |")
    assert rows["BC-OH (`bc_oh`)"] == "| BC-OH (`bc_oh`) | — | n=5 | 520 | [508, 532] | 0.52 | 0.00 [0.00, 0.00] | — | — | (reference) | — |"
    assert "n=2, incomplete" in rows["two-stage (`c2f_two_stage`)"] and "| 47.3 ± 3.8 | worse, a little |" in rows["two-stage (`c2f_two_stage`)"]


def test_rows_without_runs_say_so_and_an_incomplete_capacity_test_gives_no_verdict(planted):
    results, replication, experts, _ = planted
    runs = runs_dir("native_hidden", results)
    for seed in range(2, 11):
        (runs / "c2f_no_coarse" / ENV / f"result_seeds{seed}.json").unlink()
    for seed in range(1, 6):
        (runs / "c2f_middle" / ENV / f"result_seeds{seed}.json").unlink()
    summarise(results, replication, experts)
    table = (results / "native_hidden" / "table3.md").read_text()
    assert "| 1. capacity | P(C2F > no-coarse control) | 1.00 | [1.00, 1.00] | n=10 vs 1 | incomplete (n=10 vs 1 of 10): no verdict yet |" in table
    assert "| n=1 vs 10 | reported, not a test (incomplete) |" in table
    assert "| no-coarse control (`c2f_no_coarse`) | 1 | 1 | 600 | [600, 600] | 0.60 | 600 |" in table
    assert ("| middle fusion (`c2f_middle`) | `--fusion middle` | no runs yet | — | — | — | — | — | 49.6 ± 1.7 | no difference | "
            "no runs yet |") in table
    assert "| `--no-coarse-action` | n=1, incomplete | 600 |" in table and "incomplete (n=1 of 5): no verdict" in table


def test_variant_results_made_by_c2f_py_before_c2f_table3_count_alike(planted):
    """The committed Table 3 runs were made by c2f.py with the variant's flags: their JSON names the method "c2f"."""
    results, replication, experts, _ = planted
    summarise(results, replication, experts)
    table = (results / "native_hidden" / "table3.md").read_text()
    made_by_c2f = 0
    for path in sorted(runs_dir("native_hidden", results).glob("c2f_*/*/result_seeds*.json")):
        try:
            result = json.loads(path.read_text())
        except json.JSONDecodeError:
            continue
        assert result["method"] == "c2f_table3"
        result["method"] = "c2f"
        path.write_text(json.dumps(result))
        made_by_c2f += 1
    assert made_by_c2f > 50
    summarise(results, replication, experts)
    assert (results / "native_hidden" / "table3.md").read_text() == table


def test_a_c2f_table3_result_may_name_c2f_but_not_the_other_way(tmp_path):
    made_by_c2f = plant(tmp_path, "c2f", ENV, 1, [5.0] * 3, fusion="middle")
    assert read_result(made_by_c2f, "c2f_table3", ENV)["method"] == "c2f"
    made_by_table3 = plant(tmp_path, "c2f_table3", ENV, 1, [5.0] * 3)
    with pytest.raises(ResultError, match="holds c2f_table3 on Hopper-v4, expected c2f on Hopper-v4"):
        read_result(made_by_table3, "c2f", ENV)


def test_results_at_other_settings_or_seeds_are_left_out_with_their_reason(planted, capsys):
    results, replication, experts, left_out = planted
    summarise(results, replication, experts)
    err = capsys.readouterr().err.splitlines()
    assert len(err) == len(left_out) and all(any(line.startswith(reason) for line in err) for reason in left_out), err
    table = (results / "native_hidden" / "table3.md").read_text()
    listed = table.split("## Left out\n\n", 1)[1].splitlines()
    assert [line.removeprefix("- ") for line in listed if line] == err  # the same lines, in table3.md too
    assert "Walker2d" not in "\n".join(err)  # valid runs of another env are not part of these tests, nor errors


def test_header_names_the_command_commits_machines_and_that_comparisons_are_unpaired(planted):
    results, replication, experts, _ = planted
    summarise(results, replication, experts)
    table = (results / "native_hidden" / "table3.md").read_text()
    header = table.split("## The capacity test", 1)[0]
    assert f"Made by `python -m benchmark.table3 --results-dir {results} --replication-dir {replication} --expert-runs {experts}`" in header
    assert f"map (`{runs_dir('native_hidden', results)}`): `aaaaaaaaaaaa` (runs/commit.txt): c2f, c2f_middle," in header
    assert "`bbbbbbbbbbbb` (runs/<method>/commit.txt): c2f_penultimate, c2f_no_coarse." in header
    assert f"replication (`{runs_dir('native_hidden', replication)}`): `cccccccccccc` (runs/commit.txt): c2f, bc_oh." in header
    assert "Test CPU, AVX2: c2f_no_coarse 1–10" in header and "Test CPU, AVX512: c2f_penultimate 1–10" in header
    assert "not recorded: c2f 1–10, c2f_middle 1–5," in header and "bc_oh 1–10" in header
    assert "Unpaired comparisons, as declared" in header and "`--hide-velocities`" in header


def test_the_picture_is_written(planted):
    results, replication, experts, _ = planted
    summarise(results, replication, experts)
    assert (results / "native_hidden" / "table3.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list((results / "native_hidden").glob("*.tmp*")), "atomic writes leave no temporary file"


@pytest.mark.parametrize("rule, vs_c2f, vs_bc_oh, verdict", [
    (table3.NO_DIFFERENCE, (0.3, 0.7), (0.9, 1.0), "confirmed"),
    (table3.NO_DIFFERENCE, (0.5, 0.9), (0.9, 1.0), "confirmed"),  # a bound at 0.5 still holds it
    (table3.NO_DIFFERENCE, (0.0, 0.4), (0.4, 0.6), "refuted"),
    (table3.NO_DIFFERENCE, (0.6, 1.0), (0.9, 1.0), "refuted"),
    (table3.WORSE, (0.0, 0.4), (0.4, 0.6), "confirmed"),
    (table3.WORSE, (0.2, 0.7), (0.4, 0.6), "not confirmed"),
    (table3.WORSE, (0.6, 1.0), (0.9, 1.0), "refuted"),
    (table3.FALLS, (0.0, 0.4), (0.3, 0.7), "confirmed"),
    (table3.FALLS, (0.0, 0.4), (0.0, 0.2), "not confirmed"),  # below BC-OH too: not 'falls to BC-OH'
    (table3.FALLS, (0.0, 0.4), (0.6, 1.0), "not confirmed"),
    (table3.FALLS, (0.6, 1.0), (0.9, 1.0), "refuted"),
    (table3.FALLS_OR_BELOW, (0.0, 0.4), (0.0, 0.2), "confirmed"),
    (table3.FALLS_OR_BELOW, (0.0, 0.4), (0.3, 0.7), "confirmed"),
    (table3.FALLS_OR_BELOW, (0.0, 0.4), (0.6, 1.0), "not confirmed"),
    (table3.FALLS_OR_BELOW, (0.3, 0.7), (0.0, 0.2), "not confirmed"),
    (table3.REPORTED_ONLY, (0.0, 0.1), (0.0, 0.1), "reported only"),
])
def test_row_verdicts_follow_the_declared_rules(rule, vs_c2f, vs_bc_oh, verdict):
    assert table3.row_verdict(rule, vs_c2f, vs_bc_oh) == verdict


def test_capacity_verdicts_follow_the_declared_rule():
    above, below = "C2F beats the control", "the control beats C2F"
    apart, tie = [float(s) for s in range(100, 110)], [float(s) + 0.5 for s in range(10)]
    assert table3.capacity_verdict(apart, tie, above, below) == above
    assert table3.capacity_verdict(tie, apart, above, below) == below
    assert table3.capacity_verdict(tie, [s + 0.25 for s in tie], above, below) == "0.5 inside the interval: not decided"
    assert table3.capacity_verdict(apart, apart[:9], above, below) == "incomplete (n=10 vs 9 of 10): no verdict yet"


def test_seed_ranges():
    assert table3.seed_ranges([3, 1, 2, 5, 6, 9]) == "1–3, 5–6, 9" and table3.seed_ranges([]) == "none"


def test_no_map_folder_is_one_line_and_exit_2(tmp_path):
    result = run_module("benchmark.table3", "--results-dir", tmp_path / "nowhere")
    # The runner's own --results-dir, where the refusal looked: the command it names then fills that folder.
    assert_usage_error(result, f"run python -m benchmark.regimes --regimes native_hidden --results-dir {tmp_path / 'nowhere'} first")
    assert result.returncode == 2


def test_a_mistyped_replication_folder_is_one_line_and_exit_2(planted, tmp_path):
    """It left the capacity test at the map's seeds 1-5, with a warning, and exit status 0."""
    results, _, experts, _ = planted
    result = run_in_process("benchmark/table3.py", "--results-dir", results, "--replication-dir", tmp_path / "nowhere",
                            "--expert-runs", experts)
    message = (f"no {tmp_path / 'nowhere' / 'native_hidden' / 'runs'}: run python -m benchmark.regimes --regimes native_hidden "
               f"--methods bc_oh c2f --envs Hopper-v4 --seeds 6 7 8 9 10 --results-dir {tmp_path / 'nowhere'} first, or pass "
               "--replication-dir")
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")
    assert not (results / "native_hidden" / "table3.md").exists()


def test_folders_without_runs_are_one_line_that_says_so(tmp_path):
    """It said '(see above)', with nothing above."""
    for folder in ("map", "replication"):
        runs_dir("native_hidden", tmp_path / folder).mkdir(parents=True)
    plant_expert(tmp_path / "runs", ENV, 1000.0)
    result = run_in_process("benchmark/table3.py", "--results-dir", tmp_path / "map", "--replication-dir",
                            tmp_path / "replication", "--expert-runs", tmp_path / "runs")
    message = (f"no native_hidden Hopper-v4 results under {tmp_path / 'map'} or {tmp_path / 'replication'}: pass "
               "--results-dir, the folder python -m benchmark.regimes wrote them into")
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")
