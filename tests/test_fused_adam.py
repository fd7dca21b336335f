"""Fused Adam (issue 56): every optimizer of the method files and the expert is torch's fused Adam, whose
update is the default Adam's arithmetic in one kernel, so only its rounding differs."""

import copy
import importlib

import pytest
import torch

import bc_oh
import c2f
import fca
from conftest import METHOD_FILES, REPO_ROOT, fake_demos, skip_evaluation, tiny_args

METHODS = [file.removesuffix(".py") for file in METHOD_FILES]
STATE_STEPS = 5
"""default Adam steps taken before the compared step, so that Adam's moments and step count are not zero"""


def policy_and_optimizer(module, fused: bool, betas=(0.9, 0.999)):
    """A Hopper-sized policy of `module` (fixed weights) and an Adam over it."""
    torch.manual_seed(0)
    inputs = torch.randn(256, 11 * 2)
    policy = module.make_policy(tiny_args(module, history=2, hidden=64), 11, 3, inputs)
    optimizer = torch.optim.Adam(policy.parameters(), lr=1e-3, betas=betas, fused=fused)
    return policy, optimizer, inputs


def every_output(policy, inputs) -> list:
    """Outputs that every parameter of the policy feeds: C2F's coarse action too, FCA's adversary too."""
    if isinstance(policy, c2f.Policy):
        return list(policy.coarse_and_final(inputs))
    if isinstance(policy, fca.Policy):
        embedding = policy.embed(inputs)
        action = policy.head(embedding)
        return [action, policy.predict_previous_action(embedding, action)]
    return [policy(inputs)]


def adam_step(policy, optimizer, inputs, targets):
    optimizer.zero_grad()
    loss = sum(((output - targets) ** 2).mean() for output in every_output(policy, inputs))
    loss.backward()
    optimizer.step()


@pytest.mark.parametrize(
    "module, betas", [(bc_oh, (0.9, 0.999)), (c2f, (0.9, 0.999)), (fca, (0.5, 0.999))]
)
def test_one_fused_step_matches_one_default_step_from_the_same_state(module, betas):
    """From one state (weights, Adam's moments and step count after a few default steps), one fused step and one
    default step on the same minibatch give the same weights to about 1e-6 relative; the step itself moves them by
    far more, so the comparison can fail."""
    policy, optimizer, inputs = policy_and_optimizer(module, fused=False, betas=betas)
    targets = torch.randn(len(inputs), 3)
    for _ in range(STATE_STEPS):
        adam_step(policy, optimizer, inputs, targets)
    fused_policy = copy.deepcopy(policy)
    fused_optimizer = torch.optim.Adam(fused_policy.parameters(), lr=1e-3, betas=betas, fused=True)
    # A copy: load_state_dict keeps the very tensors of Adam's moments, which the default step updates.
    fused_optimizer.load_state_dict(copy.deepcopy(optimizer.state_dict()))
    before = [parameter.detach().clone() for parameter in policy.parameters()]
    adam_step(policy, optimizer, inputs, targets)
    adam_step(fused_policy, fused_optimizer, inputs, targets)
    pairs = zip(before, policy.parameters(), fused_policy.parameters())
    for old, default, fused in pairs:
        scale = default.detach().abs().max()
        assert (fused - default).abs().max() <= 1e-6 * scale
        assert (default - old).abs().max() > 1e-4 * scale


@pytest.mark.parametrize("script", METHODS)
def test_every_method_file_trains_with_fused_adam(script, monkeypatch):
    """A tiny training of each method file: every Adam it builds (keyframe's APE model and DAgger's rounds too)
    is fused."""
    module = importlib.import_module(script)
    made = []
    adam = torch.optim.Adam

    def recording_adam(*args, **kwargs):
        made.append(kwargs.get("fused"))
        return adam(*args, **kwargs)

    monkeypatch.setattr(torch.optim, "Adam", recording_adam)
    skip_evaluation(monkeypatch, module)
    overrides = {"epochs": 1}
    if script == "dagger":
        # One round of 50 states labelled by the shipped expert: the rounds train on.
        expert = str(REPO_ROOT / "experts" / "Hopper-v4.pt")
        overrides.update(dagger_rounds=1, dagger_samples=50, dagger_epochs=1, expert=expert)
    module.train_seed(tiny_args(module, **overrides), fake_demos(128), 1, torch.device("cpu"))
    assert made and all(fused is True for fused in made)


def test_the_expert_trains_with_fused_adam(monkeypatch, tmp_path):
    """expert_ppo.train builds one fused Adam (stopped there: PPO itself is tested in test_expert_ppo.py)."""
    import expert_ppo

    made = []

    class Built(Exception):
        pass

    def recording_adam(*args, **kwargs):
        made.append(kwargs.get("fused"))
        raise Built

    monkeypatch.setattr(torch.optim, "Adam", recording_adam)
    args = expert_ppo.Args(env="Hopper-v4", num_envs=1, output_dir=str(tmp_path))
    with pytest.raises(Built):
        expert_ppo.train(args)
    assert made == [True]
