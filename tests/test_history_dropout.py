"""history_dropout.py: dropout reaches the past frames only, in training only; bad rates; a run."""
import dataclasses
import re

import pytest
import torch

import history_dropout
from conftest import SMOKE_DEMOS, assert_usage_error, load_demos, one_torch_thread, run_in_process, skip_evaluation, smoke_run

OBS, ACT, HISTORY = 11, 3, 3
PAST = (HISTORY - 1) * OBS
"""the entries of the past frames [o_{t-H+1}, ..., o_{t-1}]: the first of the history"""


def small_policy(rate):
    torch.manual_seed(0)
    inputs = torch.randn(100, OBS * HISTORY) * 3 + 1
    return history_dropout.Policy(OBS, ACT, HISTORY, hidden=16, rate=rate, inputs=inputs)


def mlp_inputs(policy, history, draws):
    """What the MLP sees in `draws` forward passes of the same batch."""
    seen = []

    def record(module, args):
        seen.append(args[0].detach().clone())

    handle = policy.net.register_forward_pre_hook(record)
    for _ in range(draws):
        policy(history)
    handle.remove()
    return torch.stack(seen)


def test_current_frame_is_never_dropped_and_past_frames_are_in_training():
    rate = 0.5
    policy = small_policy(rate)
    history = torch.randn(512, OBS * HISTORY)
    normalized = policy.normalize(history).expand(20, -1, -1)
    # 20 draws of 512 samples: 225280 past entries.
    seen = mlp_inputs(policy.train(), history, draws=20)
    assert torch.equal(seen[:, :, PAST:], normalized[:, :, PAST:]), "o_t reaches the MLP untouched"
    dropped = seen[:, :, :PAST] == 0
    assert dropped.float().mean().item() == pytest.approx(rate, abs=0.01)
    # torch's Dropout scales the entries it keeps by 1 / (1 - rate).
    kept = normalized[:, :, :PAST][~dropped]
    assert torch.allclose(seen[:, :, :PAST][~dropped], kept / (1 - rate))


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
    policy = small_policy(0.0).train()
    history = torch.randn(8, OBS * HISTORY)
    assert torch.equal(policy(history), policy.net(policy.normalize(history)))


@pytest.mark.parametrize("rate", [1, 1.5, -0.1])
def test_rate_outside_zero_one_is_rejected(rate):
    result = run_in_process("history_dropout.py", "--history-dropout", rate)
    assert_usage_error(result, "--history-dropout must lie in [0, 1)")


def test_smoke_run_trains_with_the_rate_it_is_given(tmp_path, monkeypatch, capsys):
    """The run's printed losses are those of training at --history-dropout 0.3 (repeated in this process on the same
    demos and args), which differ from those at rate 0: the flag reaches the training."""
    stdout, summary = smoke_run("history_dropout.py", tmp_path, "--history-dropout", 0.3)
    args = history_dropout.Args(**summary["args"])
    demos, _ = load_demos(history_dropout, demos=str(tmp_path / SMOKE_DEMOS))
    skip_evaluation(monkeypatch, history_dropout)  # evaluation draws nothing from torch's generator: training is the same

    def losses(out):
        return re.findall(r"^seed 1 \| epoch \d/2 \| loss (\S+) \|", out, re.MULTILINE)

    def trained_losses(rate):
        with one_torch_thread():
            history_dropout.train_seed(dataclasses.replace(args, history_dropout=rate), demos, 1, torch.device("cpu"))
        return losses(capsys.readouterr().out)

    assert len(losses(stdout)) == 2 and losses(stdout) == trained_losses(0.3) != trained_losses(0.0)
