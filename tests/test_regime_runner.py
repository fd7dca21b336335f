"""benchmark.regimes and the runner's method variants (c2f_output = c2f_table3.py --fusion output): which
command runs, which settings a finished run must have, and the one-commit rule of a map."""
import json
import platform
import subprocess

import pytest
from conftest import REPO_ROOT, run_in_process

from benchmark import aggregate, machine, regimes, run_grid
from benchmark.paper import VARIANTS, as_flags, paper_settings, setting_differences
from benchmark.results import UsageError, make_result, write_text


def options(**overrides):
    settings = dict(methods=["c2f_output"], envs=["Hopper-v4"], seeds=[1], extra_args=["--frame-skip", "1"], scripts_dir=REPO_ROOT)
    return run_grid.Options(**{**settings, **overrides})


def test_a_variant_runs_its_script_with_its_flags():
    run = run_grid.Run("c2f_output", "Hopper-v4", 1)
    command = run_grid.command(run, options())
    assert command[1] == "c2f_table3.py"
    assert command[command.index("--fusion") + 1] == "output" and command[-2:] == ["--frame-skip", "1"]
    wanted = run_grid.wanted_settings(run, options())
    assert (wanted["fusion"], wanted["frame_skip"], wanted["epochs"]) == ("output", 1, 1000)
    assert "c2f_output" in run_grid.available_methods(REPO_ROOT)


def test_as_flags():
    assert as_flags({"fusion": "output", "stop_gradient": False, "hide_velocities": True}) == [
        "--fusion", "output", "--no-stop-gradient", "--hide-velocities"]


def test_runs_made_before_the_new_flags_count_as_native_and_visible():
    old = {name: value for name, value in paper_settings("Hopper-v4").items() if name not in ("frame_skip", "hide_velocities")}
    assert setting_differences(old, paper_settings("Hopper-v4"), "Hopper-v4") == []
    assert setting_differences({**old, "frame_skip": None}, {"frame_skip": 4}, "Hopper-v4") == []
    assert setting_differences({**old, "frame_skip": 1}, paper_settings("Hopper-v4"), "Hopper-v4") == ["frame_skip 1 != 4"]
    assert setting_differences(old, {"hide_velocities": True}, "Hopper-v4") == ["hide_velocities False != True"]


@pytest.mark.parametrize("fusion, done", [("output", True), ("late", False)])
def test_a_variant_result_is_the_scripts_result_with_the_variant_settings(tmp_path, fusion, done):
    run = run_grid.Run("c2f_output", "Hopper-v4", 1)
    args = {"env": "Hopper-v4", "seeds": [1], **paper_settings("Hopper-v4"), "frame_skip": 1, "fusion": fusion}
    result = make_result("Hopper-v4", "c2f", args, {1: [[1, 5.0], [2, 6.0], [3, 7.0]]})  # c2f.py names itself c2f
    write_text(tmp_path / "c2f_output" / "Hopper-v4" / "result_seeds1.json", json.dumps(result))
    reason = run_grid.why_not_done(run, options(results_dir=tmp_path))
    assert (reason is None) == done
    if not done:
        assert "fusion late != output" in reason


def git(folder, *words):
    subprocess.run(["git", "-C", str(folder), *words], check=True, capture_output=True)


@pytest.fixture
def checkout(tmp_path):
    """A git checkout with a stand-in method file bc_so.py and an expert for Hopper-v4."""
    folder = tmp_path / "checkout"
    (folder / "experts").mkdir(parents=True)
    (folder / "bc_so.py").write_text('METHOD = "bc_so"\n')
    (folder / "experts" / "Hopper-v4.pt").write_bytes(b"")
    git(folder, "init", "-q")
    git(folder, "add", ".")
    git(folder, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "one")
    return folder


def test_a_map_is_made_by_one_commit(checkout, tmp_path):
    commit = regimes.scripts_commit(checkout)
    assert len(commit) == 40
    folder = tmp_path / "runs"
    regimes.record_commit(folder, commit, "bc_so")
    regimes.record_commit(folder, commit, "bc_so")  # the same commit again: fine
    assert (folder / "bc_so" / "commit.txt").read_text().strip() == commit
    with pytest.raises(UsageError, match="run from a worktree of that commit"):
        regimes.record_commit(folder, "f" * 40, "bc_so")
    regimes.record_commit(folder, "f" * 40, "c2f_no_coarse")  # a method added later records its own commit
    assert (folder / "c2f_no_coarse" / "commit.txt").read_text().strip() == "f" * 40
    (checkout / "bc_so.py").write_text('METHOD = "bc_so"\nchanged = 1\n')
    with pytest.raises(UsageError, match="uncommitted changes"):
        regimes.scripts_commit(checkout)


def test_the_maps_first_methods_share_the_regimes_commit(tmp_path):
    folder = tmp_path / "runs"
    write_text(folder / "commit.txt", "a" * 40 + "\n")
    (folder / "bc_oh").mkdir()
    regimes.record_commit(folder, "a" * 40, "bc_oh")
    assert not (folder / "bc_oh" / "commit.txt").exists()
    with pytest.raises(UsageError, match=f"{folder / 'bc_oh'} holds runs made by commit aaaaaaaaaaaa"):
        regimes.record_commit(folder, "b" * 40, "bc_oh")




def test_the_regime_flags_reach_every_run(checkout, tmp_path, capsys):
    status = regimes.main(["--regimes", "fs1_hidden", "--methods", "bc_so", "--envs", "Hopper-v4", "--seeds", "1", "2",
                           "--scripts-dir", str(checkout), "--results-dir", str(tmp_path / "map"), "--dry-run"])
    out = capsys.readouterr().out
    assert status == 0
    runs = [line for line in out.splitlines() if line.startswith("run ")]
    assert len(runs) == 2 and all(line.endswith("--frame-skip 1 --hide-velocities)") for line in runs)
    assert str(tmp_path / "map" / "fs1_hidden" / "runs" / "bc_so" / "Hopper-v4") in runs[0]


def test_bad_flags_stop_the_regimes_before_a_commit_is_recorded(checkout, tmp_path):
    """A commit.txt left by a refused run made the next run, from another commit, be refused as a mix of commits."""
    with pytest.raises(UsageError, match="unknown method 'nope'"):
        regimes.main(["--regimes", "fs1_hidden", "--methods", "nope", "--envs", "Hopper-v4", "--seeds", "1",
                      "--scripts-dir", str(checkout), "--results-dir", str(tmp_path / "map")])
    assert not list((tmp_path / "map").rglob("commit.txt"))


def test_a_regime_named_twice_is_one_line(tmp_path):
    """Its grid ran twice, one after the other (run_grid refuses a method, env or seed named twice)."""
    result = run_in_process("benchmark/regimes.py", "--regimes", "fs1_noise", "native_hidden", "fs1_noise",
                            "--results-dir", tmp_path, "--dry-run")
    assert (result.returncode, result.stderr, result.stdout) == (2, "error: --regimes lists fs1_noise twice: name each once\n", "")


TABLE3 = ["c2f_output", "c2f_middle", "c2f_early", "c2f_penultimate", "c2f_feature", "c2f_coarse_history",
          "c2f_coarse_history_policy_current", "c2f_no_stop_gradient", "c2f_two_stage", "c2f_no_coarse"]


@pytest.mark.parametrize("variant", TABLE3)
def test_every_table3_row_is_a_named_variant_whose_command_c2f_accepts(variant):
    assert variant in run_grid.available_methods(REPO_ROOT)
    command = run_grid.command(run_grid.Run(variant, "Hopper-v4", 1), options(methods=[variant]))
    flags = command[command.index("--output-dir") + 2:-2]  # the variant's own flags, before --extra-args
    assert flags == as_flags(VARIANTS[variant][1]) and flags
    import c2f_table3, tyro

    parsed = tyro.cli(c2f_table3.Args, args=flags)
    assert {name: getattr(parsed, name) for name in VARIANTS[variant][1]} == VARIANTS[variant][1]


def plant_c2f(results_dir, folder, **flags):
    args = {"env": "Hopper-v4", "seeds": [1], **paper_settings("Hopper-v4"), **flags}
    write_text(results_dir / folder / "Hopper-v4" / "result_seeds1.json",
               json.dumps(make_result("Hopper-v4", "c2f", args, {1: [[1, 5.0], [2, 6.0], [3, 700.0]]})))


@pytest.mark.parametrize("variant", TABLE3)
def test_an_ablation_result_where_the_defaults_is_expected_is_neither_skipped_over_nor_aggregated(tmp_path, variant):
    plant_c2f(tmp_path, "c2f", **VARIANTS[variant][1])  # e.g. c2f.py --fusion early --output-dir <runs>/c2f/Hopper-v4
    run = run_grid.Run("c2f", "Hopper-v4", 1)
    reason = run_grid.why_not_done(run, options(methods=["c2f"], extra_args=[], results_dir=tmp_path))
    assert reason is not None and "was made with other settings" in reason
    records, problems = aggregate.collect(tmp_path, allow_nonpaper=False)
    assert records == [] and "not the paper's settings" in problems[0]


def test_a_default_result_made_before_the_method_flags_existed_is_the_default(tmp_path):
    plant_c2f(tmp_path, "c2f")  # no fusion, coarse_action, ... in its args
    assert run_grid.why_not_done(run_grid.Run("c2f", "Hopper-v4", 1), options(methods=["c2f"], extra_args=[], results_dir=tmp_path)) is None
    assert [r.method for r in aggregate.collect(tmp_path, allow_nonpaper=False)[0]] == ["c2f"]


def test_a_grid_log_names_no_machine_path_and_records_the_machine(tmp_path):
    checkout = tmp_path / "checkout"
    (checkout / ".git").mkdir(parents=True)
    results = checkout / "results" / "x" / "c2f" / "Hopper-v4"
    shown = run_grid.shown_command(["/usr/bin/python3", "c2f.py", "--output-dir", str(results), "--demos", str(tmp_path / "d.npz")])
    assert shown == ["c2f.py", "--output-dir", "results/x/c2f/Hopper-v4", "--demos", str(tmp_path / "d.npz")]
    record = run_grid.machine()  # benchmark.machine's record: the method files no longer write one
    assert set(record) == {"cpu", "cpu_vendor", "cpu_family", "cpu_model", "cpu_capability", "MKL_CBWR", "MKL_ENABLE_INSTRUCTIONS", "fma_avx2", "GLIBC_TUNABLES", "libc", "os", "python",
                           "torch", "numpy", "mujoco", "gymnasium"}
    assert record["torch"] == __import__("torch").__version__ and record["python"] == platform.python_version()
    assert (record["cpu_family"], record["cpu_model"]) == (machine.cpuinfo_field("cpu family"), machine.cpuinfo_field("model"))
    zen5 = "vendor_id\t: AuthenticAMD\ncpu family\t: 26\nmodel\t\t: 2\nmodel name\t: AMD EPYC\n"  # one model name, two kinds
    assert [machine.cpuinfo_field(key, zen5) for key in ("cpu family", "model", "model name")] == ["26", "2", "AMD EPYC"]
