"""What a user measures is pinned: a refactoring of the method files must not change it. Every value was
printed by the method files at commit 104a18a, before the training loop became fit() (their numbers equal those
of commit 969e6af, which made the regime map, and its default runs repeat the committed
results/runs/*/Hopper-v4/seed1.log bit for bit), on a tiny budget: the defaults of each method and the
settings the regime map and Table 3 use. CPU training and the MuJoCo rollouts are deterministic, so the
values hold across machines."""
import json
import re

import pytest
from conftest import link_experts, run_script

BUDGET = ("--env", "Hopper-v4", "--seeds", 1, "--epochs", 3, "--eval-every", 1, "--eval-episodes", 2, "--num-demo-samples", 1000)
PINNED = {
    "bc_oh": ("bc_oh", [],
        ["epoch 1/3 | loss 0.41418 | last eval 5.4", "epoch 2/3 | loss 0.44887 | last eval 5.5", "epoch 3/3 | loss 0.44370 | last eval 5.7"],
        [5.405768547773855, 5.509190086066875, 5.6875229417875905]),
    "c2f": ("c2f", [],
        ["epoch 1/3 | loss 0.73090 | last eval 154.8", "epoch 2/3 | loss 0.76120 | last eval 105.6", "epoch 3/3 | loss 0.73444 | last eval 85.8"],
        [154.82275671779175, 105.55874793049816, 85.78130067348546]),
    "bc_oh_hidden": ("bc_oh", ["--hide-velocities"],
        ["epoch 1/3 | loss 0.38540 | last eval 21.4", "epoch 2/3 | loss 0.40203 | last eval 24.3", "epoch 3/3 | loss 0.40120 | last eval 25.5"],
        [21.424021901801524, 24.30675046763295, 25.453603774487576]),
    "c2f_output_fs1": ("c2f", ["--fusion", "output", "--frame-skip", 1],
        ["epoch 1/3 | loss 0.76668 | last eval 8.0", "epoch 2/3 | loss 0.99929 | last eval 8.2", "epoch 3/3 | loss 0.95021 | last eval 8.2"],
        [7.991499008846071, 8.186719722233063, 8.248357475075778]),
    "c2f_two_stage": ("c2f", ["--two-stage"],
        ["epoch 1/3 | loss 0.36352 | last eval n/a", "epoch 2/3 | loss 0.38246 | last eval n/a", "epoch 3/3 | loss 0.36103 | last eval n/a", "epoch 1/3 | loss 0.36723 | last eval 87.1", "epoch 2/3 | loss 0.37870 | last eval 96.8", "epoch 3/3 | loss 0.37340 | last eval 89.0"],
        [87.14669220643478, 96.81743348798318, 88.99424987857316]),
    "fca": ("fca", [],
        ["epoch 1/3 | loss 0.38707 | adversary error 0.35874 | last eval 268.1", "epoch 2/3 | loss 0.40489 | adversary error 0.34233 | last eval 225.8", "epoch 3/3 | loss 0.39931 | adversary error 0.33372 | last eval 211.1"],
        [268.06498601567307, 225.84267668272122, 211.08063884145668]),
    "keyframe": ("keyframe", [],
        ["epoch 1/3 | loss 0.53263 | last eval 11.0", "epoch 2/3 | loss 0.82834 | last eval 10.9", "epoch 3/3 | loss 0.55146 | last eval 11.0"],
        [10.959352282164517, 10.931489273066262, 10.973369384903815]),
    "average_ensemble": ("average_ensemble", [],
        ["epoch 1/3 | loss bc_so 0.36352, bc_oh 0.41418 | last eval 11.3, bc_so 11.1, bc_oh 5.4", "epoch 2/3 | loss bc_so 0.38246, bc_oh 0.44887 | last eval 11.9, bc_so 11.1, bc_oh 5.5", "epoch 3/3 | loss bc_so 0.36103, bc_oh 0.44370 | last eval 12.1, bc_so 11.1, bc_oh 5.7"],
        [11.255131086577382, 11.904644921395168, 12.107171850188806]),
    "dagger": ("dagger", ["--dagger-samples", 100, "--dagger-rounds", 2, "--dagger-epochs", 2],
        ["round 0 | epoch 1/7 | loss 0.41418 | last eval 5.4", "round 0 | epoch 2/7 | loss 0.44887 | last eval 5.5", "round 0 | epoch 3/7 | loss 0.44370 | last eval 5.7", "round 1 | epoch 4/7 | loss 0.43127 | last eval 5.3", "round 1 | epoch 5/7 | loss 0.45659 | last eval 5.5", "round 2 | epoch 6/7 | loss 0.43238 | last eval 4.7", "round 2 | epoch 7/7 | loss 0.55668 | last eval 5.4"],
        [5.405768547773855, 5.509190086066875, 5.6875229417875905, 5.343152764879655, 5.507030371892469, 4.741901965233796, 4.861809005719982, 4.754168838213433, 5.359705400513073]),
}
"""case -> (script, its flags beyond BUDGET, the printed epoch lines (timings left out), the evaluations in the JSON)"""


@pytest.mark.parametrize("case", list(PINNED))
def test_a_run_prints_the_pinned_losses_and_evaluations(tmp_path, case):
    script, flags, lines, returns = PINNED[case]
    link_experts(tmp_path)
    result = run_script(f"{script}.py", *BUDGET, *flags, "--output-dir", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert re.findall(r"^seed 1 \| (.*last eval \S+(?:, \w+ \S+)*) \| [\d.]+ ms/step", result.stdout, re.M) == lines
    evaluations = json.loads((tmp_path / "out" / "result_seeds1.json").read_text())["scores"]["1"]["evaluations"]
    assert [value for _, value in evaluations] == pytest.approx(returns, rel=1e-9)
