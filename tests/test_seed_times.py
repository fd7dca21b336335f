"""benchmark/seed_times.py: each committed run's training time per step, beside the machine that measured it."""
import json

import pytest
from conftest import run_in_process

from benchmark import seed_times
from benchmark.results import UsageError

AMD = {"cpu": "AMD EPYC", "cpu_vendor": "AuthenticAMD", "cpu_capability": "AVX512"}
XEON = {"cpu": "Intel(R) Xeon(R) Processor", "cpu_capability": "AVX512"}  # an older record: no vendor


def write(folder, seed, ms, machine=None, seeds=None, method=None):
    folder.mkdir(parents=True, exist_ok=True)
    scores = {str(s): {"score": 1.0, "evaluations": [[1, 1.0]], "ms_per_step": ms} for s in (seeds or [seed])}
    result = {"env": "Hopper-v4", "method": method or folder.parent.name, "args": {}, "scores": scores, "mean": 1.0, "std": 0.0}
    if machine:
        result["machine"] = machine
    (folder / f"result_seeds{'-'.join(map(str, seeds or [seed]))}.json").write_text(json.dumps(result))


def test_times_are_grouped_by_run_and_machine_and_priced_at_a_hopper_seeds_steps(tmp_path):
    write(tmp_path / "runs/c2f/Hopper-v4", 1, 2.0, AMD)
    write(tmp_path / "runs/c2f/Hopper-v4", 2, 4.0, AMD)
    write(tmp_path / "runs/c2f/Walker2d-v4", 1, 1.0, XEON)
    write(tmp_path / "runs/c2f/Walker2d-v4", 9, 1.0, XEON, seeds=[1, 9])  # a summary of two seeds: not counted again
    write(tmp_path / "regimes/x/runs/dagger/Hopper-v4", 1, 1.0, AMD)
    write(tmp_path / "twins/runs/bc_so/Hopper-v4", 1, 3.0, AMD, method="ensemble_twins")  # named by method and folder
    write(tmp_path / "runs/bc_oh/Hopper-v4", 1, 1.0)  # no machine record: counted, left out
    write(tmp_path / "runs/bc_so/Hopper-v4", 1, "fast", AMD)  # not a number: left out, not a traceback
    (tmp_path / "runs/bc_so/Hopper-v4/result_seeds2.json").write_text("{half")  # half written: left out
    (tmp_path / "regimes/x/runs/commit.txt").write_text("969e6af8096e106a197193ab36c155e852d00d86\n")
    (tmp_path / "regimes/x/runs/dagger/commit.txt").write_text("310975f (runs started 2026-12-06)\n")  # the nearest wins
    write(tmp_path / "regimes/x/runs/c2f/Hopper-v4", 1, 5.0, AMD)
    times, unknown, problems = seed_times.collect(tmp_path)
    assert problems == [f"left out {tmp_path / 'runs/bc_so/Hopper-v4/result_seeds1.json'}: ms_per_step 'fast' is not a positive number",
                        f"left out {tmp_path / 'runs/bc_so/Hopper-v4/result_seeds2.json'}: unreadable JSON "
                        "(JSONDecodeError: Expecting property name enclosed in double quotes: line 1 column 2 (char 1))"]
    assert times == {("c2f", "AuthenticAMD AMD EPYC, AVX512", "unknown"): [2.0, 4.0], ("c2f", "Intel(R) Xeon(R) Processor, AVX512", "unknown"): [1.0],
                     ("c2f", "AuthenticAMD AMD EPYC, AVX512", "969e6af"): [5.0], ("dagger", "AuthenticAMD AMD EPYC, AVX512", "310975f"): [1.0],
                     ("ensemble_twins/bc_so", "AuthenticAMD AMD EPYC, AVX512", "unknown"): [3.0]}
    assert unknown == 1
    rows = seed_times.table(times, unknown, "cmd").splitlines()
    assert "| `c2f` | AuthenticAMD AMD EPYC, AVX512 | unknown | 2 | 2.00–4.00 | 10.4–20.8 min |" in rows  # 312,000 steps
    assert "| `c2f` | Intel(R) Xeon(R) Processor, AVX512 | unknown | 1 | 1.00 | 5.2 min |" in rows
    assert "| `dagger` | AuthenticAMD AMD EPYC, AVX512 | 310975f | 1 | 1.00 | 7.8 min |" in rows  # 468,100 steps
    assert "1 results without a machine record are left out" in rows[2]


def test_no_timed_result_is_one_line(tmp_path):
    write(tmp_path / "runs/bc_oh/Hopper-v4", 1, 1.0)
    with pytest.raises(UsageError, match="has a machine record"):
        seed_times.main(["--results-dir", str(tmp_path), "--out", str(tmp_path / "t.md")])
    with pytest.raises(UsageError, match="is not a folder"):
        seed_times.main(["--results-dir", str(tmp_path / "none")])



def test_results_that_are_no_timing_are_left_out_and_named(tmp_path, capsys):
    """A result that is a JSON list ended in a TypeError traceback; a nan, 0 or negative ms per step was tabulated."""
    write(tmp_path / "runs/c2f/Hopper-v4", 1, 2.0, AMD)
    for seed, ms in ((2, float("nan")), (3, 0), (4, -2.0)):
        write(tmp_path / "runs/c2f/Hopper-v4", seed, ms, AMD)
    (tmp_path / "runs/c2f/Hopper-v4/result_seeds5.json").write_text("[1, 2]")
    assert seed_times.main(["--results-dir", str(tmp_path), "--out", str(tmp_path / "t.md")]) == 0
    folder = tmp_path / "runs/c2f/Hopper-v4"
    assert capsys.readouterr().err.splitlines() == [
        f"left out {folder / 'result_seeds2.json'}: ms_per_step nan is not a positive number",
        f"left out {folder / 'result_seeds3.json'}: ms_per_step 0 is not a positive number",
        f"left out {folder / 'result_seeds4.json'}: ms_per_step -2.0 is not a positive number",
        f"left out {folder / 'result_seeds5.json'}: not a result (no scores object)"]
    assert "| `c2f` | AuthenticAMD AMD EPYC, AVX512 | unknown | 1 | 2.00 | 10.4 min |" in (tmp_path / "t.md").read_text()


def test_an_out_file_that_cannot_be_written_is_one_line(tmp_path):
    """It was told as 'cannot use ...: File exists'."""
    write(tmp_path / "runs/c2f/Hopper-v4", 1, 2.0, AMD)
    (tmp_path / "file").write_text("")
    result = run_in_process("benchmark/seed_times.py", "--results-dir", tmp_path / "runs", "--out", tmp_path / "file/t.md")
    message = f"--out {tmp_path / 'file/t.md'} cannot be written: {tmp_path / 'file'} is not a folder: pass another --out"
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")
