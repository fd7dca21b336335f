"""benchmark/ensemble_twins.py, the Average-Ensemble's control: two members of one kind from different seeds."""
import json
import os
import signal

import numpy as np
import pytest
import torch
from conftest import fake_demos, run_in_process, run_module

import average_ensemble
from benchmark import ensemble_twins
from benchmark.machine import machine


@pytest.mark.parametrize("kind", ["bc_so", "bc_oh"])
def test_the_first_member_starts_as_the_ensembles_member_of_its_kind_and_its_twin_elsewhere(kind):
    inputs = torch.randn(50, 22)
    torch.manual_seed(7)
    ensemble = average_ensemble.AverageEnsemble(11, 3, 2, 16, inputs)
    torch.manual_seed(7)
    twins = ensemble_twins.TwinEnsemble(kind, 11, 3, 2, 16, inputs)
    first, twin = twins.members[kind], twins.members[f"{kind}_twin"]
    expected = ensemble.members[kind].state_dict()
    assert all(torch.equal(value, expected[key]) for key, value in first.state_dict().items())
    assert type(twin) is type(first) and not torch.equal(first.net[0].weight, twin.net[0].weight)
    assert torch.allclose(twins(inputs[:5]), (first(inputs[:5]) + twin(inputs[:5])) / 2)
    assert average_ensemble.make_policy is not ensemble_twins.make_policy, "importing the control leaves the file alone"


def test_two_workers_train_the_twins_and_each_result_records_its_machine(tmp_path):
    np.savez(tmp_path / "d.npz", **fake_demos(256))
    out = tmp_path / "out"
    done = run_module("benchmark.ensemble_twins", "--member", "bc_oh", "--demos", tmp_path / "d.npz", "--seeds", 1, 2, "--workers", 2,
                      "--epochs", 2, "--eval-every", 1, "--eval-episodes", 1, "--hidden", 16, "--output-dir", out)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1].startswith("Hopper-v4 ensemble_twins: ")
    for seed in (1, 2):
        result = json.loads((out / f"result_seeds{seed}.json").read_text())
        assert result["method"] == "ensemble_twins" and result["args"]["member"] == "bc_oh"
        assert list(result["scores"][str(seed)]["members"]) == ["bc_oh", "bc_oh_twin"]  # trained in a spawned worker
        assert result["machine"] == machine(), "the worker's machine record: the same CPU, versions and (inherited) environment"


@pytest.mark.parametrize("stop", ["ctrl-c", "kill"])
def test_an_interrupt_while_loading_the_demos_is_one_line(tmp_path, monkeypatch, stop):
    """Ctrl-C (or `kill`, SIGTERM) before training starts printed a KeyboardInterrupt traceback:
    the control called average_ensemble.run itself, outside run_cli."""

    def interrupted_loading(args, env):
        if stop == "kill":
            os.kill(os.getpid(), signal.SIGTERM)  # turned into Ctrl-C while the command runs
        raise KeyboardInterrupt

    # Run as __main__, the control swaps average_ensemble's policy: put it back afterwards.
    monkeypatch.setattr(average_ensemble, "make_policy", average_ensemble.make_policy)
    monkeypatch.setattr(average_ensemble, "METHOD", average_ensemble.METHOD)
    monkeypatch.setattr(average_ensemble, "load_demos", interrupted_loading)
    out = tmp_path / "out"
    try:
        result = run_in_process("benchmark/ensemble_twins.py", "--seeds", 1, "--output-dir", out)
    except KeyboardInterrupt:
        pytest.fail("the interrupt came out of the command as a traceback")
    assert (result.returncode, result.stderr) == (130, "interrupted\n")
    assert not out.exists()
