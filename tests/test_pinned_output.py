"""A default run's numbers are pinned: a refactoring of the method files must not change what a user
measures. The values were printed by bc_oh.py and c2f.py at commit 969e6af (whose default runs repeat
the committed results/runs/*/Hopper-v4/seed1.log bit for bit) on a tiny budget; CPU training and the
MuJoCo rollouts are deterministic, so they hold across machines."""
import json
import re

import pytest
from conftest import link_experts, run_script

BUDGET = ("--env", "Hopper-v4", "--seeds", 1, "--epochs", 3, "--eval-every", 1, "--eval-episodes", 2, "--num-demo-samples", 1000)
PINNED = {
    "bc_oh": (["loss 0.41418 | last eval 5.4", "loss 0.44887 | last eval 5.5", "loss 0.44370 | last eval 5.7"],
              [5.405768547773855, 5.509190086066875, 5.6875229417875905]),
    "c2f": (["loss 0.73090 | last eval 154.8", "loss 0.76120 | last eval 105.6", "loss 0.73444 | last eval 85.8"],
            [154.82275671779175, 105.55874793049816, 85.78130067348546]),
}


@pytest.mark.parametrize("method", sorted(PINNED))
def test_a_default_run_prints_the_pinned_losses_and_evaluations(tmp_path, method):
    link_experts(tmp_path)
    result = run_script(f"{method}.py", *BUDGET, "--output-dir", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    printed = re.findall(r"^seed 1 \| epoch \d/3 \| (loss \S+ \| last eval \S+) \|", result.stdout, re.M)
    lines, returns = PINNED[method]
    assert printed == lines
    evaluations = json.loads((tmp_path / "out" / "result_seeds1.json").read_text())["scores"]["1"]["evaluations"]
    assert [epoch for epoch, _ in evaluations] == [1, 2, 3]
    assert [value for _, value in evaluations] == pytest.approx(returns, rel=1e-9)
