"""keyframe.py: the weights have the requested fraction and factor, keyframes land on planted
changepoints, previous actions follow the episode structure, bad input, and a smoke run."""
import re

import numpy as np
import pytest
import torch

import keyframe
from conftest import SMOKE_DEMOS, assert_usage_error, fake_demos, load_demos, one_torch_thread, run_in_process, skip_evaluation, smoke_run, tiny_args


def piecewise_constant_actions(n=1200, act_dim=2, episode_length=300, seed=0):
    """Actions that hold a random level for 15-40 steps, then jump; episodes of `episode_length`.
    Returns (actions, episode_starts, planted changepoints: jumps inside an episode)."""
    rng = np.random.default_rng(seed)
    actions, changes, t = np.zeros((n, act_dim), np.float32), np.zeros(n, bool), 0
    while t < n:
        length = int(rng.integers(15, 41))
        actions[t : t + length] = rng.uniform(-1, 1, act_dim)
        changes[t] = True
        t += length
    starts = np.arange(n) % episode_length == 0
    return actions, starts, changes & ~starts


@pytest.mark.parametrize("fraction, weight", [(0.1, 5.0), (0.25, 3.0), (1.0, 2.0), (0.1, 0.5)])
def test_weights_have_the_requested_fraction_and_factor(fraction, weight):
    ape = torch.rand(1000, generator=torch.Generator().manual_seed(0))
    weights = keyframe.keyframe_weights(ape, fraction, weight)
    keyframes = keyframe.keyframes(ape, fraction)
    assert keyframes.sum().item() == round(fraction * 1000)
    assert (weights[keyframes] == weight).all() and (weights[~keyframes] == 1).all()
    if fraction < 1:
        assert ape[keyframes].min() > ape[~keyframes].max(), "the keyframes are the samples of highest APE"


def test_softmax_weights_average_one_and_grow_with_the_error():
    ape = torch.tensor([0.0, 0.5, 1.0, 3.0])
    weights = keyframe.softmax_weights(ape, temperature=1.0)
    assert weights.mean().item() == pytest.approx(1.0)
    assert torch.all(weights[1:] > weights[:-1])
    assert weights[-1] / weights[0] == pytest.approx(np.exp(3.0), rel=1e-5)
    flatter = keyframe.softmax_weights(ape, temperature=10.0)
    assert flatter[-1] / flatter[0] == pytest.approx(np.exp(0.3), rel=1e-5)


def test_previous_actions_fill_the_episode_start_with_its_earliest_action():
    actions = np.arange(10, dtype=np.float32)[:, None]  # a_t = t
    starts = np.zeros(10, bool)
    starts[[0, 5]] = True
    rows = keyframe.previous_actions(actions, starts, k=2, spacing=2)  # [a_{t-4}, a_{t-2}]
    assert rows.tolist() == [[0, 0], [0, 0], [0, 0], [0, 1], [0, 2], [5, 5], [5, 5], [5, 5], [5, 6], [5, 7]]
    assert keyframe.previous_actions(actions, starts, k=1, spacing=1)[:, 0].tolist() == [0, 0, 1, 2, 3, 5, 5, 6, 7, 8]


def test_changepoints_are_the_largest_action_jumps_within_episodes():
    actions, starts, planted = piecewise_constant_actions()
    found = keyframe.changepoints(actions, starts, fraction=planted.sum() / len(actions))
    assert np.array_equal(found, planted), "a jump at an episode start is no changepoint"


def test_keyframes_sit_at_planted_changepoints():
    actions, starts, planted = piecewise_constant_actions()
    torch.manual_seed(0)
    ape = keyframe.action_prediction_errors(actions, starts, k=4, spacing=1, epochs=10, batch_size=64, device="cpu")
    assert ape.shape == (len(actions),)
    weights = keyframe.keyframe_weights(ape, 0.1, 5.0).numpy()
    assert planted.sum() < 0.1 * len(actions)  # so there is room for every changepoint among the keyframes
    assert (weights[planted] == 5).mean() >= 0.9
    assert weights[planted].mean() > 2 * weights[~planted].mean()
    assert ape[torch.as_tensor(planted)].mean() > 10 * ape[torch.as_tensor(~planted)].mean()


@pytest.mark.parametrize("fraction", [0, -0.1, 1.5])
def test_keyframe_fraction_outside_zero_one_is_rejected(fraction):
    assert_usage_error(run_in_process("keyframe.py", "--keyframe-fraction", fraction), "--keyframe-fraction must lie in (0, 1]")


@pytest.mark.parametrize("flag", ["--keyframe-k", "--keyframe-spacing", "--keyframe-weight", "--keyframe-temperature", "--keyframe-model-epochs"])
def test_other_method_parameters_must_be_positive(flag):
    assert_usage_error(run_in_process("keyframe.py", flag, 0), f"{flag} must be positive")


def test_softmax_weighting_weighs_each_batch_by_its_own_errors(monkeypatch, capsys):
    calls, softmax_weights = [], keyframe.softmax_weights

    def recording_softmax(ape, temperature):
        calls.append((ape, temperature))
        return softmax_weights(ape, temperature)

    monkeypatch.setattr(keyframe, "softmax_weights", recording_softmax)
    skip_evaluation(monkeypatch, keyframe)
    args = tiny_args(keyframe, weighting="softmax", keyframe_temperature=0.5, keyframe_model_epochs=1)
    keyframe.train_seed(args, fake_demos(), seed=1, device=torch.device("cpu"))
    assert len(calls) == args.epochs * (256 // args.batch_size), "one softmax per training batch"
    assert all(ape.shape == (args.batch_size,) and temperature == 0.5 for ape, temperature in calls)
    assert "keyframes (top 10% of APE): 26 of 256 samples" in capsys.readouterr().out


def test_smoke_run_reports_keyframes_and_changepoints(tmp_path):
    stdout, summary = smoke_run("keyframe.py", tmp_path)
    pattern = r"seed 1 \| keyframes \(top 10% of APE\): (\d+) of (\d+) samples, (\d+) of them at action changepoints \(top 10% of \|\|a_t - a_\{t-1\}\|\|; (\d+) in all\)"
    report = [match.groups() for match in re.finditer(pattern, stdout)]
    assert len(report) == 1, stdout
    assert summary["args"]["weighting"] == "threshold" and summary["args"]["keyframe_weight"] == 5.0
    # The counts are those keyframe.py's functions give on the run's demos, with the seed's torch state (train_seed's
    # manual_seed(1), then nothing random before the action-prediction model) and its one thread.
    demos, _ = load_demos(keyframe, demos=str(tmp_path / SMOKE_DEMOS))
    actions, starts = demos["actions"], demos["episode_starts"]
    with one_torch_thread():
        torch.manual_seed(1)
        ape = keyframe.action_prediction_errors(actions, starts, k=4, spacing=1, epochs=20, batch_size=64, device="cpu")
    is_key, at_change = keyframe.keyframes(ape, 0.1).numpy(), keyframe.changepoints(actions, starts)
    overlap = (is_key & at_change).sum()
    assert tuple(map(int, report[0])) == (is_key.sum(), len(actions), overlap, at_change.sum())
    assert is_key.sum() == at_change.sum() == 30
    assert overlap > 2 * 30 * 30 / 300, "keyframes sit at changepoints far more often than 30 random samples would"
