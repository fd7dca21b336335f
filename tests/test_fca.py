"""fca.py: the adversary is conditioned on a_t, the alternating updates push its loss in opposite
directions, previous actions follow the episode structure, each learning rate decays from its own
start, bad input, and a smoke run."""
import re

import numpy as np
import pytest
import torch

import fca
from conftest import SMOKE_DEMOS, assert_usage_error, demo_file, run_in_process, smoke_run

OBS, ACT, HISTORY, EMBEDDING = 11, 3, 2, 8


def small_policy(seed=0):
    torch.manual_seed(seed)
    return fca.Policy(OBS, ACT, HISTORY, hidden=16, embedding_dim=EMBEDDING, inputs=torch.randn(100, OBS * HISTORY))


def batch(seed=0, n=64):
    generator = torch.Generator().manual_seed(seed)
    return [torch.randn(n, dim, generator=generator) for dim in (OBS * HISTORY, ACT, ACT)]  # history, a_t, a_{t-1}


def optimizers(policy, lr=1e-3):
    """As train_seed builds them: G and F together, D apart, both Adam with betas (0.5, 0.999)."""
    policy_optimizer = torch.optim.Adam([*policy.encoder.parameters(), *policy.head.parameters()], lr=lr, betas=(0.5, 0.999))
    return policy_optimizer, torch.optim.Adam(policy.adversary.parameters(), lr=lr, betas=(0.5, 0.999))


def adversary_loss(policy, history, action, previous):
    with torch.no_grad():
        return ((policy.predict_previous_action(policy.embed(history), action) - previous) ** 2).mean().item()


def snapshot(module):
    return [p.detach().clone() for p in module.parameters()]


def unchanged(module, before):
    return all(torch.equal(p, q) for p, q in zip(module.parameters(), before))


def test_adversary_input_is_the_embedding_and_the_true_current_action():
    policy = small_policy()
    assert policy.adversary[1].in_features == EMBEDDING + ACT
    embedding, action = torch.randn(5, EMBEDDING), torch.randn(5, ACT)
    prediction = policy.predict_previous_action(embedding, action)
    assert prediction.shape == (5, ACT)
    assert torch.equal(prediction, policy.adversary(torch.cat([embedding, action], dim=1)))
    assert not torch.allclose(policy.predict_previous_action(embedding, action + 1.0), prediction), "a_t must reach D"
    assert not torch.allclose(policy.predict_previous_action(embedding + 1.0, action), prediction), "e must reach D"


def test_policy_acts_through_encoder_and_head_only():
    policy = small_policy()
    history = batch()[0]
    assert torch.equal(policy(history), policy.head(policy.encoder(policy.normalize(history))))
    assert policy(history).shape == (64, ACT)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_encoder_step_raises_the_adversary_loss_and_adversary_step_lowers_it(seed):
    """w = 2 (the authors' Hopper value): at w = 1 the BC part of the gradient outweighs the adversarial
    part for about 1 random initialisation in 40; at w = 2 for none of 100 we tried."""
    policy = small_policy(seed)
    history, action, previous = batch(seed)
    policy_optimizer, adversary_optimizer = optimizers(policy)
    before = adversary_loss(policy, history, action, previous)

    adversary_weights = snapshot(policy.adversary)
    bc, adversary = fca.encoder_head_step(policy, policy_optimizer, policy.embed(history), action, previous, weight=2.0)
    assert adversary.item() == pytest.approx(before), "the returned adversary loss is the one before the step"
    assert unchanged(policy.adversary, adversary_weights), "the encoder+policy step must not move D"
    after_encoder = adversary_loss(policy, history, action, previous)
    assert after_encoder > before

    encoder_weights, head_weights = snapshot(policy.encoder), snapshot(policy.head)
    returned = fca.adversary_step(policy, adversary_optimizer, policy.embed(history), action, previous)
    assert returned.item() == pytest.approx(after_encoder)
    assert unchanged(policy.encoder, encoder_weights) and unchanged(policy.head, head_weights), "the D step must move D only"
    assert adversary_loss(policy, history, action, previous) < after_encoder


def test_adversary_weight_zero_is_plain_bc_on_the_fca_network():
    """With w = 0 the encoder+policy step is one BC step: it lowers the BC loss on the batch."""
    policy = small_policy()
    history, action, previous = batch()
    policy_optimizer, _ = optimizers(policy)
    bc_before, _ = fca.encoder_head_step(policy, policy_optimizer, policy.embed(history), action, previous, weight=0.0)
    with torch.no_grad():
        assert ((policy(history) - action) ** 2).mean() < bc_before


def test_previous_action_at_an_episode_start_is_the_current_action():
    actions = np.arange(12, dtype=np.float32).reshape(6, 2)  # a_t = (2t, 2t + 1)
    starts = np.array([True, False, False, True, False, False])
    previous = fca.previous_actions(actions, starts)
    assert previous[:, 0].tolist() == [0, 0, 2, 6, 6, 8]  # 2 * [0, 0, 1, 3, 3, 4]
    assert np.array_equal(previous[starts], actions[starts])
    assert np.array_equal(previous[~starts], actions[np.flatnonzero(~starts) - 1])


def test_the_encoder_is_the_authors_batchnorm_mlp_with_their_init():
    """gan_mlp.Generator: 3 x [Linear (the first without bias) -> BatchNorm1d -> LeakyReLU(0.2)] -> Linear; weights_init:
    Xavier-uniform Linear weights, zero biases, BatchNorm scales near 1."""
    policy = small_policy()
    kinds = [type(layer).__name__ for layer in policy.encoder]
    assert kinds == ["Linear", "BatchNorm1d", "LeakyReLU"] * 3 + ["Linear"]
    linears = [layer for layer in policy.modules() if isinstance(layer, torch.nn.Linear)]
    assert policy.encoder[0].bias is None and all(layer.bias is not None and not layer.bias.any() for layer in linears[1:])
    for layer in linears:  # Xavier-uniform: |w| <= sqrt(6 / (fan_in + fan_out)), and it fills most of that range
        bound = (6 / (layer.in_features + layer.out_features)) ** 0.5
        assert layer.weight.abs().max() <= bound and layer.weight.abs().max() > 0.9 * bound
    scales = torch.cat([layer.weight for layer in policy.encoder if isinstance(layer, torch.nn.BatchNorm1d)])
    assert (scales - 1).abs().max() < 0.1 and scales.std() > 0.005


def test_batchnorm_is_frozen_at_evaluation_and_a_reloaded_model_acts_the_same():
    """Training moves BatchNorm's running statistics, evaluation (eval mode) leaves them, and a model rebuilt from
    its saved state_dict (as scripts/evaluate.py does, on zero inputs) gives the same actions."""
    args = fca.Args(hidden=16, embedding_dim=EMBEDDING, eval_episodes=2)
    policy = fca.make_policy(args, OBS, ACT, torch.randn(100, OBS * HISTORY))

    def stats():
        return [buffer.clone() for name, buffer in policy.named_buffers() if "running" in name]

    before = stats()
    policy_optimizer, adversary_optimizer = optimizers(policy)
    for seed in range(3):
        history, action, previous = batch(seed)
        fca.encoder_head_step(policy, policy_optimizer, policy.embed(history), action, previous, weight=1.0)
    trained = stats()
    assert not any(torch.equal(a, b) for a, b in zip(before, trained)), "a training step moves the running statistics"
    policy.eval()
    fca.evaluate(policy, args, 2, seed=0, device=torch.device("cpu"))
    assert all(torch.equal(a, b) for a, b in zip(trained, stats())), "evaluation must not move them"
    history = batch(7, n=5)[0]
    rebuilt = fca.make_policy(args, OBS, ACT, torch.zeros(2, OBS * HISTORY))
    rebuilt.load_state_dict(policy.state_dict())
    assert torch.equal(rebuilt.eval()(history), policy(history))
    assert not torch.allclose(policy.train()(history), policy.eval()(history)), "in eval mode the running statistics act"


def test_each_learning_rate_decays_from_its_own_start_and_the_adversary_error_is_the_epoch_mean(monkeypatch, capsys):
    """fit decays G's and F's rate and D's (a group of its own) linearly to 0, each from its own start, and prints
    D's mean loss over the epoch."""
    monkeypatch.setattr(fca, "evaluate", lambda *args: [0.0])
    args = fca.Args(epochs=2, batch_size=10, eval_every=1, learning_rate=1e-3, seeds=[1])
    weights = [torch.nn.Parameter(torch.zeros(1)) for _ in range(2)]
    optimizer = torch.optim.Adam([{"params": weights[:1]}, {"params": weights[1:], "lr": 3e-3}], lr=1e-3)
    rates = []

    def train_step(idx):
        rates.append([group["lr"] for group in optimizer.param_groups])
        return torch.tensor(0.5), torch.tensor(float(len(rates)))  # D's losses 1, 2 | 3, 4

    fca.fit(args, torch.nn.Linear(1, 1), optimizer, train_step, 20, seed=1, device=torch.device("cpu"))
    assert rates == [[1e-3 * (1 - step / 4), 3e-3 * (1 - step / 4)] for step in range(4)]
    errors = [line.split("| adversary error ")[1].split(" |")[0] for line in capsys.readouterr().out.splitlines()]
    assert errors == ["1.50000", "3.50000"]


def test_the_authors_hopper_setting_and_their_default_elsewhere():
    assert fca.authors_setting("Hopper-v4", None, None) == (2.0, 2.0)
    assert fca.authors_setting("Walker2d-v4", None, None) == (1.0, 1.0)
    assert fca.authors_setting("Hopper-v4", 0.5, 3.0) == (0.5, 3.0)


@pytest.mark.parametrize("flag, value, message", [("--adversary-weight", -1, "must be >= 0"), ("--adversary-lr-ratio", 0, "must be positive"),
                                                   ("--hidden", 0, "must be positive"), ("--embedding-dim", 0, "must be positive"),
                                                   # BatchNorm in training needs two rows: one raised torch's ValueError mid-run.
                                                   ("--batch-size", 1, "must be 2 or more for BatchNorm, got 1")])
def test_bad_method_parameters_are_rejected(flag, value, message):
    assert_usage_error(run_in_process("fca.py", flag, value), f"{flag} {message}")


def test_smoke_run_logs_the_adversary_error(tmp_path):
    stdout, summary = smoke_run("fca.py", tmp_path)
    errors = [float(error) for error in re.findall(r"^seed 1 \| epoch \d/2 \| loss [\d.]+ \| adversary error (\S+) \| last eval ", stdout, re.MULTILINE)]
    assert len(errors) == 2 and all(0 < error < np.inf for error in errors), stdout
    assert errors[0] != errors[1], "an epoch's mean of D's error, not a constant"
    # the reference is D's error were it to predict a_{t-1} = a_t, on the run's demos
    demos, _ = demo_file(tmp_path / SMOKE_DEMOS)
    previous = fca.previous_actions(demos["actions"], demos["episode_starts"])
    reference = re.search(r"adversary reference: predicting a_\{t-1\} = a_t has error (\S+)$", stdout, re.MULTILINE)
    assert reference and float(reference[1]) == pytest.approx(np.mean((previous - demos["actions"]) ** 2), abs=1e-5)
    learning_rate = summary["args"]["learning_rate"]
    assert f"w = 2; learning rates: G and F {learning_rate:g}, D {2 * learning_rate:g}" in stdout, "Hopper: the authors' Hopper command"
