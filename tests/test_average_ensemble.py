"""average_ensemble.py: the ensemble acts with the exact mean of a BC-SO and a BC-OH member, the BC-SO
member reads only the current frame, each member is trained exactly as its own script trains it, and a
tiny run reports the ensemble and both members."""
import re

import numpy as np
import torch

import average_ensemble
import bc_oh
import bc_so
from conftest import fake_demos, skip_evaluation, smoke_run, table_row, tiny_args

OBS_DIM, ACT_DIM, HISTORY = 11, 3, 3


def make_ensemble(seed=0):
    torch.manual_seed(seed)
    inputs = torch.randn(500, OBS_DIM * HISTORY) * 3 + 1
    args = tiny_args(average_ensemble, history=HISTORY)
    return average_ensemble.make_policy(args, OBS_DIM, ACT_DIM, inputs), inputs


def test_ensemble_action_is_exactly_the_mean_of_its_members():
    ensemble, _ = make_ensemble()
    assert set(ensemble.members) == {"bc_so", "bc_oh"}
    x = torch.randn(64, OBS_DIM * HISTORY) * 2
    so, oh = ensemble.members["bc_so"](x), ensemble.members["bc_oh"](x)
    assert not torch.allclose(so, oh), "members with identical outputs would make the test vacuous"
    assert torch.equal(ensemble(x), (so + oh) / 2)
    # gradients of an ensemble loss reach both members
    ensemble(x).sum().backward()
    for member in ensemble.members.values():
        assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in member.net.parameters())


def test_bc_so_member_ignores_the_past_frames():
    ensemble, inputs = make_ensemble()
    member = ensemble.members["bc_so"]
    x = torch.randn(32, OBS_DIM * HISTORY)
    changed_past = x.clone()
    changed_past[:, :-OBS_DIM] = torch.randn(32, OBS_DIM * (HISTORY - 1)) * 10
    assert torch.equal(member(changed_past), member(x))
    changed_current = x.clone()
    changed_current[:, -OBS_DIM:] += 1.0
    assert not torch.allclose(member(changed_current), member(x))
    # its normaliser holds the statistics of the current frame only; the BC-OH member's, of the whole history
    assert torch.allclose(member.normalize.mean, inputs[:, -OBS_DIM:].mean(0))
    assert torch.allclose(ensemble.members["bc_oh"].normalize.mean, inputs.mean(0))
    assert not torch.allclose(ensemble.members["bc_oh"](changed_past), ensemble.members["bc_oh"](x)), "BC-OH reads them"


def test_members_train_exactly_as_bc_so_and_bc_oh(monkeypatch):
    """Same seed, same demos: each member ends with the weights its own script's policy ends with."""
    demos = fake_demos()
    for module in (average_ensemble, bc_so, bc_oh):
        skip_evaluation(monkeypatch, module)
    trained = average_ensemble.train_seed(tiny_args(average_ensemble), demos, 1, torch.device("cpu"))
    evaluations, member_evaluations, ensemble, _ = trained
    for name, module in (("bc_so", bc_so), ("bc_oh", bc_oh)):
        _, policy, _ = module.train_seed(tiny_args(module), demos, 1, torch.device("cpu"))
        alone = policy.state_dict()
        member = ensemble.members[name].state_dict()
        assert member.keys() == alone.keys()
        assert all(torch.equal(member[key], alone[key]) for key in alone), name
    evaluated_epochs = [epoch for epoch, _ in evaluations]
    assert evaluated_epochs == [1, 2]
    assert {name: [epoch for epoch, _ in evals] for name, evals in member_evaluations.items()} == {
        "bc_so": evaluated_epochs, "bc_oh": evaluated_epochs}


def test_tiny_run_reports_the_ensemble_and_both_members(tmp_path):
    stdout, data = smoke_run("average_ensemble.py", tmp_path)  # the ensemble's summary, table column and JSON agree
    assert (data["args"]["frame_skip"], data["args"]["output_dir"]) == (4, "out"), "the resolved rate, a relative folder"
    seed = data["scores"]["1"]
    ensemble_score, so_score, oh_score = map(float, table_row(stdout, 1))
    assert round(seed["score"], 1) == ensemble_score
    for name, score in (("bc_so", so_score), ("bc_oh", oh_score)):
        member = seed["members"][name]
        assert [epoch for epoch, _ in member["evaluations"]] == [epoch for epoch, _ in seed["evaluations"]] == [1, 2]
        assert round(member["score"], 1) == score
        assert np.isclose(member["score"], np.mean([ret for _, ret in member["evaluations"][-3:]]))
        assert data["members"][name]["mean"] == member["score"]
    assert re.search(r"^members: bc_so -?[\d.]+ ± [\d.]+, bc_oh -?[\d.]+ ± [\d.]+$", stdout, re.M)
