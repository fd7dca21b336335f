"""c2f.py: the paper's coarse-to-fine model, its stop-gradient and Eq. 2; c2f_table3.py: every Table 3 ablation
flag, two-stage training and the capacity control, and at its defaults exactly c2f.py; bc_so.py's policy (o_t
only); the same seed twice gives the same training on CPU."""
import copy
import re

import pytest
import torch

import bc_oh
import bc_so
import c2f
import c2f_table3
from conftest import assert_usage_error, fake_demos, run_in_process, skip_evaluation, tiny_args

OBS, ACT, H, HIDDEN = 11, 3, 3, 16


def paper_model(seed=0):
    """The model c2f.py builds."""
    torch.manual_seed(seed)
    inputs = torch.randn(64, H * OBS) * 3 + 1
    return c2f.make_policy(c2f.Args(history=H, hidden=HIDDEN), OBS, ACT, inputs)


def model(seed=0, **flags):
    """The model c2f_table3.py builds for these flags (the same random inputs as paper_model)."""
    torch.manual_seed(seed)
    inputs = torch.randn(64, H * OBS) * 3 + 1
    return c2f_table3.make_policy(c2f_table3.Args(history=H, hidden=HIDDEN, **flags), OBS, ACT, inputs)


def batch(seed=1):
    return torch.randn(8, H * OBS, generator=torch.Generator().manual_seed(seed)), torch.rand(8, ACT)


def shapes(policy):
    return {name: tuple(p.shape) for name, p in policy.named_parameters()}


def capture_inputs(policy, layers, obs_history):
    """Run the model; return (zeta, coarse feature, final, {layer name: its input})."""
    seen, hooks = {}, []
    for name in layers:
        def hook(module, args, output, name=name):
            seen[name] = args[0]
        hooks.append(policy.get_submodule(name).register_forward_hook(hook))
    zeta, feature = policy.coarse_model(obs_history)
    final = policy(obs_history)
    for handle in hooks:
        handle.remove()
    return zeta, feature, final, seen


# ----------------------------------------------------------------------------------------------
# c2f.py: the paper's model


def test_paper_model_dimensions():
    policy = paper_model()
    assert type(policy) is c2f.Policy
    assert [layer.in_features for layer in policy.coarse if isinstance(layer, torch.nn.Linear)] == [OBS, HIDDEN, HIDDEN]
    assert policy.coarse[-1].out_features == ACT, "zeta is an action"
    assert [policy.policy_first[0].in_features, policy.policy_rest[0].in_features, policy.policy_rest[2].out_features] == [H * OBS, HIDDEN, HIDDEN]
    assert (policy.head.in_features, policy.head.out_features) == (HIDDEN + ACT, ACT)


def test_the_paper_model_reads_zeta_from_o_t_and_joins_it_before_the_head():
    policy = paper_model()
    obs_history, _ = batch()
    zeta, final = policy.coarse_and_final(obs_history)
    assert torch.equal(zeta, policy.coarse(policy.normalize(obs_history)[:, -OBS:])), "zeta = pi_phi(o_t)"
    assert torch.equal(final, policy(obs_history))
    feature = policy.policy_rest(policy.policy_first(policy.normalize(obs_history)))
    assert torch.equal(final, policy.head(torch.cat([feature, zeta], dim=1)))
    changed = obs_history.clone()
    changed[:, :-OBS] += 5.0
    assert torch.equal(policy.coarse_and_final(changed)[0], zeta), "the coarse model sees o_t only"
    assert not torch.allclose(policy(changed), final), "the policy model sees the history"


def test_the_stop_gradient_keeps_the_final_loss_off_the_coarse_model():
    policy = paper_model()
    obs_history, target = batch()
    _, final = policy.coarse_and_final(obs_history)
    ((final - target) ** 2).mean().backward()
    assert all(p.grad is None or not p.grad.any() for p in policy.coarse.parameters())
    assert policy.policy_first[0].weight.grad.abs().sum() > 0 and policy.head.weight.grad.abs().sum() > 0


def train(module, monkeypatch, capsys, seed=1, demos=None, **overrides):
    """train_seed on fake demos without env rollouts; returns (state_dict, printed loss lines)."""
    skip_evaluation(monkeypatch, module)
    demos = fake_demos() if demos is None else demos
    _, policy, _ = module.train_seed(tiny_args(module, hidden=HIDDEN, **overrides), demos, seed, torch.device("cpu"))
    lines = [line for line in capsys.readouterr().out.splitlines() if "loss" in line]
    return {k: v.clone() for k, v in policy.state_dict().items()}, lines


def record_outputs(monkeypatch, policy_class) -> list:
    """Patch policy_class.coarse_and_final to record every (zeta, final) it returns."""
    outputs = []
    original = policy_class.coarse_and_final

    def recording(self, obs_history):
        outputs.append(original(self, obs_history))
        return outputs[-1]

    monkeypatch.setattr(policy_class, "coarse_and_final", recording)
    return outputs


def test_joint_training_minimises_both_losses(monkeypatch, capsys):
    """The printed loss is MSE(zeta) + MSE(final) of the last batch (Eq. 2); constant actions make the targets known."""
    outputs = record_outputs(monkeypatch, c2f.Policy)
    demos = fake_demos()
    demos["actions"][:] = [0.5, -0.25, 0.1]
    _, lines = train(c2f, monkeypatch, capsys, demos=demos, epochs=1)
    zeta, final = outputs[-1]
    target = torch.tensor([0.5, -0.25, 0.1])
    expected = ((zeta - target) ** 2).mean() + ((final - target) ** 2).mean()
    assert f"loss {expected.item():.5f} " in lines[-1]


def test_c2f_has_no_ablation_flag():
    fields = set(c2f.Args.__dataclass_fields__)
    assert not fields & {"fusion", "coarse_output", "coarse_input", "policy_input", "stop_gradient", "coarse_action", "two_stage"}
    assert set(c2f_table3.Args.__dataclass_fields__) - fields == set(TABLE3_DEFAULTS)


def without_timing(lines):
    """Progress lines without their wall-clock parts (ms/step, minutes left), which differ between identical runs."""
    return [re.sub(r" \| [0-9.]+ ms/step| \| [0-9.]+ min left", "", line) for line in lines]


@pytest.mark.parametrize("module", [bc_so, bc_oh, c2f, c2f_table3], ids=lambda module: module.METHOD)
def test_same_seed_gives_the_same_training(module, monkeypatch, capsys):
    first, first_lines = train(module, monkeypatch, capsys)
    second, second_lines = train(module, monkeypatch, capsys)
    other, other_lines = train(module, monkeypatch, capsys, seed=2)
    first_lines, second_lines, other_lines = (without_timing(lines) for lines in (first_lines, second_lines, other_lines))
    assert first_lines == second_lines and len(first_lines) == 2
    assert all(torch.equal(first[name], second[name]) for name in first)
    assert first_lines != other_lines


# ----------------------------------------------------------------------------------------------
# c2f_table3.py at its defaults is c2f.py


TABLE3_DEFAULTS = {"fusion": "late", "coarse_output": "action", "coarse_input": "current", "policy_input": "history",
                   "stop_gradient": True, "coarse_action": True, "two_stage": False}


def test_table3_defaults_are_the_papers():
    args = c2f_table3.Args()
    assert {name: getattr(args, name) for name in TABLE3_DEFAULTS} == TABLE3_DEFAULTS


def test_the_paper_model_is_table3s_model_at_its_defaults():
    """c2f_table3.py's Policy at its defaults builds c2f.py's layers in the same order (the same seed gives the
    same initial weights) and gives exactly the same outputs and gradients."""
    policy, general = paper_model(), model()
    obs_history, target = batch()
    assert type(general) is c2f_table3.Policy
    assert list(policy.state_dict()) == list(general.state_dict())
    assert all(torch.equal(a, b) for a, b in zip(policy.state_dict().values(), general.state_dict().values()))
    assert all(torch.equal(a, b) for a, b in zip(policy.coarse_and_final(obs_history), general.coarse_and_final(obs_history)))
    gradients = []
    for net in (policy, general):
        zeta, final = net.coarse_and_final(obs_history)
        (((final - target) ** 2).mean() + ((zeta - target) ** 2).mean()).backward()
        gradients.append([p.grad.clone() for p in net.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*gradients))


def test_table3_trains_as_c2f_at_its_defaults(monkeypatch, capsys):
    """The same seed and demos: the same printed losses and the same trained weights, bit for bit."""
    paper, paper_lines = train(c2f, monkeypatch, capsys)
    general, general_lines = train(c2f_table3, monkeypatch, capsys)
    assert without_timing(paper_lines) == without_timing(general_lines)
    assert list(paper) == list(general) and all(torch.equal(paper[name], general[name]) for name in paper)


# ----------------------------------------------------------------------------------------------
# c2f_table3.py: the ablations of Table 3


FUSION_LAYERS = {"early": "policy_first.0", "middle": "policy_rest.0", "late": "head"}
WIDTH_WITHOUT_ZETA = {"early": H * OBS, "middle": HIDDEN, "late": HIDDEN}


@pytest.mark.parametrize("fusion", ["late", "middle", "early"])
def test_each_fusion_feeds_zeta_where_it_says(fusion):
    policy = model(fusion=fusion)
    obs_history, _ = batch()
    zeta, _, final, seen = capture_inputs(policy, FUSION_LAYERS.values(), obs_history)
    for stage, layer in FUSION_LAYERS.items():
        extra = ACT if stage == fusion else 0
        assert policy.get_submodule(layer).in_features == WIDTH_WITHOUT_ZETA[stage] + extra, layer
        assert seen[layer].shape[1] == WIDTH_WITHOUT_ZETA[stage] + extra
    assert torch.equal(seen[FUSION_LAYERS[fusion]][:, -ACT:], zeta), "zeta is concatenated at the end of that layer's input"
    if fusion == "early":
        assert torch.equal(seen["policy_first.0"][:, :-ACT], policy.normalize(obs_history)), "beside the normalised history"
    # perturbing zeta (through the coarse model's output layer) changes the final action
    with torch.no_grad():
        policy.coarse[-1].bias += 1.0
    assert not torch.allclose(policy(obs_history), final)


def test_coarse_output_feature_feeds_the_coarse_models_last_hidden_feature():
    policy = model(coarse_output="feature")
    obs_history, target = batch()
    _, feature, _, seen = capture_inputs(policy, ["head"], obs_history)
    assert policy.head.in_features == 2 * HIDDEN and feature.shape == (8, HIDDEN)
    assert torch.equal(seen["head"][:, -HIDDEN:], feature)
    assert torch.equal(feature, policy.coarse[:-1](policy.normalize(obs_history)[:, -OBS:])), "after the second ReLU"
    zeta, final = policy.coarse_and_final(obs_history)
    ((zeta - target) ** 2).mean().backward()
    assert policy.coarse[-1].weight.grad.abs().sum() > 0, "the action head still learns from the coarse loss"
    policy.zero_grad()
    ((final - target) ** 2).mean().backward()
    assert all(p.grad is None or not p.grad.any() for p in policy.coarse.parameters()), "stop-gradient on the feature too"


def older_frames_changed(obs_history):
    changed = obs_history.clone()
    changed[:, :-OBS] += 5.0
    return changed


@pytest.mark.parametrize("which", ["current", "history"])
def test_coarse_input(which):
    policy = model(coarse_input=which)
    assert policy.coarse[0].in_features == (H * OBS if which == "history" else OBS)
    obs_history, _ = batch()
    zeta_changed = not torch.allclose(policy.coarse_model(obs_history)[0], policy.coarse_model(older_frames_changed(obs_history))[0])
    assert zeta_changed == (which == "history"), "only a history coarse model sees the older frames"


@pytest.mark.parametrize("which", ["history", "current"])
def test_policy_input(which):
    policy = model(policy_input=which)
    assert policy.policy_first[0].in_features == (H * OBS if which == "history" else OBS)
    obs_history, _ = batch()
    final_changed = not torch.allclose(policy(obs_history), policy(older_frames_changed(obs_history)))
    assert final_changed == (which == "history"), "with o_t as both inputs the older frames are ignored"


@pytest.mark.parametrize("flags, changed", [
    (dict(fusion="middle"), {"policy_rest.0.weight", "head.weight"}),
    (dict(fusion="early"), {"policy_first.0.weight", "head.weight"}),
    (dict(coarse_output="feature"), {"head.weight"}),
    (dict(coarse_input="history"), {"coarse.0.weight"}),
    (dict(policy_input="current"), {"policy_first.0.weight"}),
    (dict(stop_gradient=False), set()),
])  # fmt: skip
def test_each_ablation_changes_only_the_layers_it_names(flags, changed):
    default, ablated = shapes(model()), shapes(model(**flags))
    assert default.keys() == ablated.keys()
    assert {name for name in default if default[name] != ablated[name]} == changed


def test_output_fusion_joins_an_action_sized_policy_output_with_zeta():
    policy = model(fusion="output")
    obs_history, _ = batch()
    zeta, _, final, seen = capture_inputs(policy, ["head"], obs_history)
    assert [type(layer) for layer in policy.policy_rest] == [torch.nn.Linear, torch.nn.ReLU, torch.nn.Linear], "no last ReLU"
    assert policy.policy_rest[-1].out_features == ACT and policy.head.in_features == 2 * ACT
    assert torch.equal(seen["head"][:, -ACT:], zeta)
    # the last layer sees exactly [the policy MLP's action-sized output, sg(zeta)], and gives the final action
    policy_output = policy.policy_rest(policy.policy_first(policy.normalize(obs_history)))
    assert torch.equal(seen["head"], torch.cat([policy_output, zeta], dim=1))
    assert zeta.shape == final.shape == (len(obs_history), ACT)
    assert torch.allclose(final, policy.head(torch.cat([policy_output, zeta], dim=1)))


@pytest.mark.parametrize("stop_gradient", [True, False])
def test_stop_gradient_keeps_the_final_loss_off_the_coarse_model(stop_gradient):
    policy = model(stop_gradient=stop_gradient)
    obs_history, target = batch()
    _, final = policy.coarse_and_final(obs_history)
    ((final - target) ** 2).mean().backward()
    coarse_grad = sum(p.grad.abs().sum() for p in policy.coarse.parameters() if p.grad is not None)
    assert (coarse_grad > 0) == (not stop_gradient)
    assert policy.policy_first[0].weight.grad.abs().sum() > 0 and policy.head.weight.grad.abs().sum() > 0
    # the stop-gradient changes only the backward pass: same outputs, same gradients on the policy model
    other = model(stop_gradient=not stop_gradient)
    _, other_final = other.coarse_and_final(obs_history)
    assert torch.equal(other_final, final)
    ((other_final - target) ** 2).mean().backward()
    assert torch.allclose(other.head.weight.grad, policy.head.weight.grad)


def record_stages(monkeypatch) -> list:
    """Patch c2f_table3.fit to record (evaluate_policy, weights before, weights after) of every call."""
    calls, original = [], c2f_table3.fit

    def recording_fit(args, policy, *rest, **kwargs):
        before = copy.deepcopy(policy.state_dict())
        output = original(args, policy, *rest, **kwargs)
        calls.append((kwargs.get("evaluate_policy", True), before, copy.deepcopy(policy.state_dict())))
        return output

    monkeypatch.setattr(c2f_table3, "fit", recording_fit)
    return calls


def test_two_stage_trains_the_coarse_model_first_then_leaves_it_unchanged(monkeypatch, capsys):
    """Stage 1 and stage 2 are two runs of the one training loop, fit: the first trains only the coarse model."""
    calls = record_stages(monkeypatch)
    final, lines = train(c2f_table3, monkeypatch, capsys, two_stage=True)
    assert [evaluates for evaluates, _, _ in calls] == [False, True], "stage 1 does not evaluate, stage 2 does"
    (_, initial, after_one), (_, _, after_two) = calls
    coarse = [name for name in final if name.startswith("coarse.")]
    rest = [name for name in final if not name.startswith(("coarse.", "normalize."))]
    assert all(not torch.equal(initial[name], after_one[name]) for name in coarse), "stage 1 trains the coarse model"
    assert all(torch.equal(initial[name], after_one[name]) for name in rest), "stage 1 trains nothing else"
    assert all(torch.equal(after_one[name], final[name]) for name in coarse), "stage 2 must not change the coarse model"
    assert all(not torch.equal(after_one[name], final[name]) for name in rest), "stage 2 trains the rest"
    assert all(torch.equal(after_two[name], final[name]) for name in final)
    epochs = [line for line in lines if "| epoch " in line]
    assert [("last eval n/a" in line) for line in epochs] == [True, True, False, False], "2 epochs of stage 1, then 2 evaluated ones"


def test_two_stage_coarse_model_is_bc_so(monkeypatch, capsys):
    """Stage 1 trains exactly a BC-SO policy: same init, data, batches and lr schedule give the same weights."""
    calls = record_stages(monkeypatch)
    train(c2f_table3, monkeypatch, capsys, two_stage=True)
    bc_so_weights, _ = train(bc_so, monkeypatch, capsys)
    after_stage_one = calls[0][2]
    for name, value in after_stage_one.items():
        if name.startswith("coarse."):
            assert torch.allclose(bc_so_weights[f"net.{name.removeprefix('coarse.')}"], value, atol=1e-6), name


def test_two_stage_without_the_coarse_action_is_refused_as_the_flags_are_parsed(tmp_path, monkeypatch):
    """Args refuses the pair when it is built: the script prints one line, exits 2 and writes nothing
    (no output folder), and code that builds Args itself gets the same UsageError."""
    monkeypatch.chdir(tmp_path)
    result = run_in_process("c2f_table3.py", "--two-stage", "--no-coarse-action", "--output-dir", tmp_path / "out")
    assert_usage_error(result, "--two-stage trains the coarse model first, --no-coarse-action never uses it: pass one of them")
    assert result.returncode == 2
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(c2f_table3.UsageError, match="--two-stage trains the coarse model first"):
        tiny_args(c2f_table3, two_stage=True, coarse_action=False)


@pytest.mark.parametrize("other", ["--two-stage", "--no-coarse-action"])
def test_no_stop_gradient_is_refused_where_it_would_change_nothing(tmp_path, other):
    """A frozen (--two-stage) or unused (--no-coarse-action) coarse model gets no gradient from the final action's
    loss, so --no-stop-gradient would silently give the digits of the run without it: refused in one line."""
    tiny = ["--seeds", "1", "--epochs", "1", "--eval-episodes", "1", "--output-dir", tmp_path / "out"]
    result = run_in_process("c2f_table3.py", "--no-stop-gradient", other, *tiny)
    assert_usage_error(result, "--no-stop-gradient changes nothing with --two-stage or --no-coarse-action: leave it out")
    with pytest.raises(c2f_table3.UsageError, match="--no-stop-gradient changes nothing"):
        tiny_args(c2f_table3, stop_gradient=False, two_stage=other == "--two-stage", coarse_action=other != "--no-coarse-action")


def test_a_history_input_to_an_idle_coarse_model_is_refused(tmp_path):
    """With --no-coarse-action the coarse model is never used: --coarse-input history would change only its random
    initial weights (and so the draws of the layers after it), a run that looks like an ablation and is not one."""
    tiny = ["--seeds", "1", "--epochs", "1", "--eval-episodes", "1", "--output-dir", tmp_path / "out"]
    result = run_in_process("c2f_table3.py", "--coarse-input", "history", "--no-coarse-action", *tiny)
    assert_usage_error(result, "--coarse-input history feeds a coarse model that --no-coarse-action leaves idle: pass one of them")
    assert not (tmp_path / "out").exists()
    with pytest.raises(c2f_table3.UsageError, match="leaves idle"):
        tiny_args(c2f_table3, coarse_input="history", coarse_action=False)
    assert tiny_args(c2f_table3, coarse_input="history").coarse_action


# ----------------------------------------------------------------------------------------------
# c2f_table3.py: the capacity controls, --no-coarse-action and --fusion penultimate


def count(module) -> int:
    return sum(p.numel() for p in module.parameters())


def history_path(policy) -> int:
    return count(policy.policy_first) + count(policy.policy_rest) + count(policy.head)


def test_the_controls_capacity_on_hopper():
    """No coarse action: C2F's history path exactly; penultimate: BC-OH's MLP plus the coarse model plus act_dim^2
    weights (README's and NOTES' figures: BC-OH 72,451, C2F 207,887 with a 138,252 history path)."""
    torch.manual_seed(0)
    inputs = torch.randn(64, 2 * 11)

    def build(**flags):
        return c2f_table3.make_policy(c2f_table3.Args(history=2, hidden=256, **flags), 11, 3, inputs)

    paper, control, penultimate = build(), build(coarse_action=False), build(fusion="penultimate")
    bc_oh_net = bc_oh.Policy(11, 3, 2, 256, inputs)
    c2f_net = c2f.Policy(11, 3, 2, 256, inputs)
    assert (count(bc_oh_net), count(paper), history_path(paper)) == (72451, 207887, 138252)
    assert count(c2f_net) == count(paper) and history_path(c2f_net) == history_path(paper)
    assert count(control) == count(paper) and history_path(control) == history_path(paper)
    assert count(penultimate) == count(bc_oh_net) + count(paper.coarse) + 3 * 3 == 142095
    assert history_path(penultimate) == count(bc_oh_net) + 3 * 3
    assert [m.out_features for m in penultimate.modules() if isinstance(m, torch.nn.Linear)][3:] == [256, 256, 3], "two hidden layers, as BC-OH"


def test_penultimate_joins_zeta_before_bc_ohs_last_layer():
    policy = model(fusion="penultimate")
    obs_history, target = batch()
    zeta, _, final, seen = capture_inputs(policy, ["head", "policy_rest.0"], obs_history)
    assert policy.head.in_features == HIDDEN + ACT and seen["head"].shape == (8, HIDDEN + ACT)
    assert torch.equal(seen["head"][:, -ACT:], zeta)
    assert torch.equal(seen["head"][:, :HIDDEN], policy.policy_rest(policy.policy_first(policy.normalize(obs_history))))
    ((final - target) ** 2).mean().backward()
    assert all(p.grad is None or not p.grad.any() for p in policy.coarse.parameters()), "sg(zeta)"


def test_no_coarse_action_feeds_zeros_and_ignores_the_coarse_model():
    policy = model(coarse_action=False)
    obs_history, target = batch()
    zeta, _, final, seen = capture_inputs(policy, ["head"], obs_history)
    assert seen["head"].shape == (8, HIDDEN + ACT) and not seen["head"][:, -ACT:].any(), "zeros where sg(zeta) was"
    paper = model()
    assert all(torch.equal(a, b) for a, b in zip(paper.state_dict().values(), policy.state_dict().values())), \
        "the same seed starts the control from C2F's own initial weights"
    with torch.no_grad():
        policy.coarse[-1].bias += 1.0
    assert torch.equal(policy(obs_history), final), "the coarse model does not reach the action"
    ((final - target) ** 2).mean().backward()
    assert all(p.grad is None or not p.grad.any() for p in policy.coarse.parameters())
    assert policy.policy_first[0].weight.grad.abs().sum() > 0


def test_no_coarse_action_trains_without_the_coarse_loss(monkeypatch, capsys):
    """The printed loss is MSE(final) alone; the coarse model keeps its initial weights."""
    outputs = record_outputs(monkeypatch, c2f_table3.Policy)
    built, make_policy = [], c2f_table3.make_policy

    def recording_make_policy(*args):
        built.append(make_policy(*args))
        return copy.deepcopy(built[-1])

    monkeypatch.setattr(c2f_table3, "make_policy", recording_make_policy)
    demos = fake_demos()
    demos["actions"][:] = [0.5, -0.25, 0.1]
    final_weights, lines = train(c2f_table3, monkeypatch, capsys, demos=demos, epochs=1, coarse_action=False)
    expected = ((outputs[-1][1] - torch.tensor([0.5, -0.25, 0.1])) ** 2).mean()
    assert f"loss {expected.item():.5f} " in lines[-1]
    initial = built[0].state_dict()
    assert all(torch.equal(final_weights[name], initial[name]) == name.startswith(("coarse.", "normalize.")) for name in initial)


# ----------------------------------------------------------------------------------------------
# bc_so.py


def test_bc_so_reads_only_the_current_frame():
    torch.manual_seed(0)
    inputs = torch.randn(64, H * OBS) * 3 + 1
    policy = bc_so.Policy(OBS, ACT, H, HIDDEN, inputs)
    assert policy.net[0].in_features == OBS
    assert torch.equal(policy.normalize.mean, inputs[:, -OBS:].mean(0)), "normalised with statistics of o_t"
    obs_history, _ = batch()
    assert torch.equal(policy(obs_history), policy(older_frames_changed(obs_history)))
    changed = obs_history.clone()
    changed[:, -1] += 5.0
    assert not torch.equal(policy(obs_history), policy(changed))


def test_bc_so_result_does_not_depend_on_history(monkeypatch, capsys):
    one, one_lines = train(bc_so, monkeypatch, capsys, history=1)
    three, three_lines = train(bc_so, monkeypatch, capsys, history=3)
    assert without_timing(one_lines) == without_timing(three_lines)
    assert all(torch.equal(one[name], three[name]) for name in one)
