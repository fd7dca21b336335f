"""benchmark/fca_compare.py: the old and new FCA rows, the declared divergence rule (any logged adversary error
above 4), and runs still going left out."""
import json

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
