"""benchmark/fca_compare.py: the old and new FCA rows, the declared divergence rule (any logged adversary error
above 4), and runs still going left out."""
import json

from conftest import run_in_process

from benchmark import fca_compare
from benchmark.results import make_result


def fake_run(folder, env, seed, errors, score):
    run = folder / "fca" / env
    run.mkdir(parents=True, exist_ok=True)
    lines = [f"seed {seed} | epoch {50 * (k + 1)}/1000 | loss 0.01 | adversary error {error} | last eval 1.0 | 2.00 ms/step"
             for k, error in enumerate(errors)]
    (run / f"seed{seed}.log").write_text("\n".join(lines) + "\n")
    if score is not None:
        result = make_result(env, "fca", {"env": env, "seeds": [seed]}, {seed: [[1000, score]] * 3})
        (run / f"result_seeds{seed}.json").write_text(json.dumps(result))


def test_rows_apply_the_declared_rule_and_leave_out_runs_still_going(tmp_path):
    new, old = tmp_path / "new", tmp_path / "old"
    fake_run(new, "Hopper-v4", 1, [0.05, 0.07], 1000.0)
    fake_run(new, "Hopper-v4", 2, [0.05, 3.9], 1200.0)
    fake_run(new, "Hopper-v4", 3, [0.05, 50.0], None)  # no result yet: still going
    fake_run(old, "Hopper-v4", 1, [0.05, 4000.0], 10.0)
    assert fca_compare.adversary_curve(new / "fca" / "Hopper-v4" / "seed2.log") == [(50, 0.05), (100, 3.9)]
    assert fca_compare.main(["--new", str(new), "--old", str(old), "--out", str(tmp_path)]) == 0
    table = (tmp_path / "fca_compare.md").read_text()
    hopper = next(line for line in table.splitlines() if line.startswith("| Hopper-v4 "))
    assert hopper == "| Hopper-v4 | 831 ± 108 | 1100 ± 100 (n=2) | 0.07–3.9 | 0 of 2 | 10 ± 0 (n=1) | 4e+03–4e+03 | 1 of 1 |"
    assert (tmp_path / "fca_adversary.png").read_bytes()[:4] == b"\x89PNG"


def test_logs_and_results_that_cannot_be_read_are_left_out_and_named(tmp_path, capsys):
    """A log not named seed<S>.log ended in a ValueError traceback; a result cut short was left out without a word; a
    log without an adversary error counted as a seed that never diverged (or made the range nan-nan); a NaN error, an
    adversary whose predictions are no numbers, was not counted as diverged."""
    new, old = tmp_path / "new", tmp_path / "old"
    fake_run(new, "Hopper-v4", 1, [0.05, 0.07], 1000.0)
    fake_run(new, "Hopper-v4", 2, [0.05, "nan"], 1200.0)
    fake_run(new, "Hopper-v4", 3, [], 1400.0)  # a log without a progress line
    fake_run(new, "Hopper-v4", 4, [0.05], 1600.0)
    run = new / "fca" / "Hopper-v4"
    (run / "result_seeds4.json").write_text('{"env": "Hopper-v4", "meth')
    (run / "seed1.old.log").write_text((run / "seed1.log").read_text())
    fake_run(old, "Hopper-v4", 1, [0.05], 10.0)
    assert fca_compare.main(["--new", str(new), "--old", str(old), "--out", str(tmp_path)]) == 0
    assert capsys.readouterr().err.splitlines() == [
        f"left out {run / 'seed1.old.log'}: not a run's log (seed<S>.log)",
        f"left out {run / 'seed3.log'}: no adversary error in its progress lines",
        f"left out {run / 'result_seeds4.json'}: unreadable JSON (JSONDecodeError: Unterminated string starting at: "
        "line 1 column 22 (char 21))"]
    rows = (tmp_path / "fca_compare.md").read_text().splitlines()
    hopper = next(line for line in rows if line.startswith("| Hopper-v4 "))
    assert hopper == "| Hopper-v4 | 831 ± 108 | 1100 ± 100 (n=2) | 0.07–inf | 1 of 2 | 10 ± 0 (n=1) | 0.05–0.05 | 0 of 1 |"


def test_an_out_folder_that_cannot_be_written_is_one_line(tmp_path):
    """It was told as 'cannot use ...: File exists'."""
    for folder in ("new", "old"):
        fake_run(tmp_path / folder, "Hopper-v4", 1, [0.05], 1000.0)
    (tmp_path / "file").write_text("")
    result = run_in_process("benchmark/fca_compare.py", "--new", tmp_path / "new", "--old", tmp_path / "old",
                            "--out", tmp_path / "file")
    message = f"--out {tmp_path / 'file'} cannot be written: {tmp_path / 'file'} is not a folder: pass another --out"
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")
