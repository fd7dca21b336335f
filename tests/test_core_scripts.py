"""bc_so.py, bc_oh.py, c2f.py and c2f_table3.py as commands: a tiny-budget run of each prints the per-seed table and the
summary line and writes the JSON result (and with --save-model a checkpoint that rebuilds the model), on the demos
expert_ppo.py --make-demos made (conftest.link_experts links them); every bad input gives one line on stderr, exit
status 2 and no traceback."""
import re
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import c2f_table3
from conftest import REPO_ROOT, SMOKE_DEMOS, assert_usage_error, demo_file, fake_demos, link_experts, run_in_process, smoke_run, table_row


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A cwd with experts/ and the session's demos/ (the tiny Hopper demos of 300 steps among them)."""
    return link_experts(tmp_path_factory.mktemp("core_scripts"))


def smoke(script, workdir, *extra, seeds=(1,)):
    """conftest.smoke_run into out/METHOD (the summary, table rows and JSON agree, with the paper's scoring and the
    share of the expert's return in the demos' meta), and more: the JSON holds no more than the method file writes
    (the machine is recorded by run_grid.py), the paper's Hopper lr filled in, and each seed's table row is its score
    alone. Returns (stdout, the JSON result)."""
    method = script.removesuffix(".py")
    stdout, summary = smoke_run(script, workdir, *extra, seeds=seeds, output_dir=f"out/{method}")
    assert set(summary) == {"env", "method", "args", "scores", "mean", "std"}, "the machine is recorded by run_grid.py"
    assert summary["args"]["epochs"] == 2 and summary["args"]["learning_rate"] == 1e-5, "the paper's Hopper lr is filled in"
    for seed in seeds:
        epochs, returns = zip(*summary["scores"][str(seed)]["evaluations"])
        assert epochs == (1, 2) and all(ret > 0 for ret in returns)
        assert table_row(stdout, seed) == [f"{summary['scores'][str(seed)]['score']:.1f}"]
    return stdout, summary


def test_bc_oh_smoke_run_loads_the_made_demos_and_reports(tmp_path):
    workdir = link_experts(tmp_path)
    made = (workdir / "demos" / "Hopper-v4_300.npz").stat().st_mtime_ns
    stdout, _ = smoke("bc_oh.py", workdir)
    assert stdout.startswith("demos: 300 steps from demos/Hopper-v4_300.npz\ndemos: copy error MSE(a_{t-1}, a_t)/Var(a) = ")
    assert (workdir / "demos" / "Hopper-v4_300.npz").stat().st_mtime_ns == made, "it only loads the file, never rewrites it"
    assert "seed 1 | training" in stdout.splitlines()
    assert re.search(r"^seed 1 \| epoch 2/2 \| loss \d+\.\d+ \| last eval \d+\.\d \| \d+\.\d+ ms/step \| \d+\.\d min left$", stdout, re.M)


def test_bc_so_smoke_run_with_two_seeds(workdir):
    _, summary = smoke("bc_so.py", workdir, "--seeds", 1, 2, seeds=(1, 2))
    assert summary["scores"]["1"]["score"] != summary["scores"]["2"]["score"]


def test_c2f_table3_smoke_run_with_ablations_saves_a_rebuildable_model(workdir):
    stdout, summary = smoke("c2f_table3.py", workdir, "--two-stage", "--fusion", "middle", "--coarse-output", "feature", "--save-model")
    assert "seed 1 | stage 1: the coarse model alone" in stdout and "seed 1 | stage 2: the coarse model frozen" in stdout
    assert (summary["args"]["fusion"], summary["args"]["coarse_output"], summary["args"]["two_stage"]) == ("middle", "feature", True)
    checkpoint = torch.load(workdir / "out" / "c2f_table3" / "seed1.pt", weights_only=False)
    assert (checkpoint["method"], checkpoint["env_id"], checkpoint["obs_dim"], checkpoint["act_dim"]) == ("c2f_table3", "Hopper-v4", 11, 3)
    args = SimpleNamespace(**checkpoint["args"])
    policy = c2f_table3.make_policy(args, 11, 3, torch.zeros(2, 11 * args.history))
    policy.load_state_dict(checkpoint["state_dict"])  # strict: the args rebuild exactly the saved model
    demos, _ = demo_file(workdir / SMOKE_DEMOS)  # the normalisation came with the weights
    noisy = c2f_table3.partially_observe(demos["observations"], list(range(5, 11)), 0.2, False, seed=1)
    inputs = c2f_table3.stack_history(noisy, demos["episode_starts"], args.history)
    assert torch.allclose(policy.normalize.mean, torch.as_tensor(inputs.mean(0), dtype=torch.float32), atol=1e-5)
    assert policy(torch.as_tensor(inputs[:5], dtype=torch.float32)).shape == (5, 3)


BAD_INPUTS = {
    "unknown env": (["--env", "Nope-v0"], "cannot make env 'Nope-v0'"),
    "no version": (["--env", "Hopper"], "env 'Hopper' has no version: use Hopper-v4 or Hopper-v5"),
    "history 0": (["--history", 0], "--history must be positive and finite, got 0"),
    # At frame skip 10000 a Hopper episode would have round(1000 * 4 / 10000) = 0 steps: gymnasium raised.
    "frame skip over an episode": (["--frame-skip", 10000], "--frame-skip 10000 outlasts an episode: pass a smaller one"),
    "negative noise": (["--obs-noise-std", -0.1], "--obs-noise-std must be >= 0 and finite, got -0.1"),
    # NaN passes a `<= 0` check, and an infinite rate or noise trains on NaN: both are refused.
    "nan learning rate": (["--learning-rate", "nan"], "--learning-rate must be positive and finite, got nan"),
    "infinite noise": (["--obs-noise-std", "inf"], "--obs-noise-std must be >= 0 and finite, got inf"),
    # Run from another folder: the shipped file lies beside the script, so the fix is the folder to run from.
    "no demos": ([], "demo file demos/Hopper-v4_20000.npz not found in {cwd}: run from {root}"),
    "missing demos": (["--demos", "missing.npz"], "demo file missing.npz not found in {cwd}: check --demos"),
    "corrupt demos": (["--demos", "corrupt.npz"], "corrupt.npz is not a readable demo file ("),
    "wrong observation size": (["--demos", "obs5.npz"], "obs5.npz holds observations (200, 5) and actions (200, 3), but Hopper-v4 needs (N, 11) and (N, 3): "),
    "wrong action size": (["--demos", "act2.npz"], "act2.npz holds observations (200, 11) and actions (200, 2), but Hopper-v4 needs (N, 11) and (N, 3): "),
}


@pytest.mark.parametrize("script", ["bc_so.py", "bc_oh.py", "c2f.py"])
@pytest.mark.parametrize("case", BAD_INPUTS)
def test_bad_input_gives_one_line_and_exit_2(case, script, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no experts/ or demos/ here
    np.savez(tmp_path / "obs5.npz", **fake_demos(200, obs_dim=5))
    (tmp_path / "corrupt.npz").write_bytes((tmp_path / "obs5.npz").read_bytes()[:3000])  # a cut-off download
    np.savez(tmp_path / "act2.npz", **fake_demos(200, act_dim=2))
    args, message = BAD_INPUTS[case]
    message = message.format(cwd=tmp_path, root=REPO_ROOT)
    result = run_in_process(script, *args, "--epochs", 1, "--eval-episodes", 1, "--seeds", 1)  # short, should it train
    assert_usage_error(result, message)
    assert result.returncode == 2 and result.stdout == "", "rejected before anything else happens"
