"""history_dropout.py: dropout reaches the past frames only, only in training; bad input; a smoke run."""

import pytest
import torch

import history_dropout
from conftest import assert_usage_error, run_in_process, smoke_run

OBS, ACT, HISTORY = 11, 3, 3


def small_policy(rate):
    torch.manual_seed(0)
    return history_dropout.Policy(
        OBS, ACT, HISTORY, hidden=16, rate=rate, inputs=torch.randn(100, OBS * HISTORY) * 3 + 1
    )


def mlp_inputs(policy, history, draws):
    """What the MLP sees in `draws` forward passes of the same batch."""
    seen = []
    handle = policy.net.register_forward_pre_hook(
        lambda module, args: seen.append(args[0].detach().clone())
    )
    for _ in range(draws):
        policy(history)
    handle.remove()
    return torch.stack(seen)


def test_current_frame_is_never_dropped_and_past_frames_are_in_training():
    rate, policy = 0.5, small_policy(0.5)
    history = torch.randn(512, OBS * HISTORY)
    normalized = policy.normalize(history)
    seen = mlp_inputs(policy.train(), history, draws=20)  # 10240 samples, 225280 past entries
    past = (HISTORY - 1) * OBS
    assert torch.equal(seen[:, :, past:], normalized[:, past:].expand(20, -1, -1)), (
        "o_t must reach the MLP untouched"
    )
    dropped = seen[:, :, :past] == 0
    assert dropped.float().mean().item() == pytest.approx(rate, abs=0.01)
    kept = normalized[:, :past].expand(20, -1, -1)[~dropped]
    assert torch.allclose(seen[:, :, :past][~dropped], kept / (1 - rate)), (
        "kept past entries are scaled by 1 / (1 - rate)"
    )


def test_evaluation_is_deterministic_and_drops_nothing():
    policy = small_policy(0.5)
    history = torch.randn(64, OBS * HISTORY)
    policy.eval()
    seen = mlp_inputs(policy, history, draws=20)
    assert torch.equal(seen, policy.normalize(history).expand(20, -1, -1))
    assert torch.equal(policy(history), policy(history))
    assert torch.equal(policy(history), policy.net(policy.normalize(history)))
    policy.train()
    assert not torch.equal(policy(history), policy(history)), "training draws fresh masks"


def test_rate_zero_is_bc_oh():
    policy, history = small_policy(0.0).train(), torch.randn(8, OBS * HISTORY)
    assert torch.equal(policy(history), policy.net(policy.normalize(history)))


@pytest.mark.parametrize("rate", [1, 1.5, -0.1])
def test_rate_outside_zero_one_is_rejected(rate):
    assert_usage_error(
        run_in_process("history_dropout.py", "--history-dropout", rate),
        "--history-dropout must lie in [0, 1)",
    )


def test_smoke_run(tmp_path):
    _, summary = smoke_run("history_dropout.py", tmp_path, "--history-dropout", 0.3)
    assert summary["args"]["history_dropout"] == 0.3
