"""dagger.py: the budget split and beta schedule, expert labels computed from the clean observation
while the learner sees the noisy history, aggregation by exactly the stated number of labels, round 0
being bc_oh.py's training, the rejection of a budget below one round, and a tiny run."""

import numpy as np
import pytest
import torch

import bc_oh
import dagger
from conftest import REPO_ROOT, assert_usage_error, fake_demos, run_in_process, smoke_run, table_row, tiny_args

EXPERT = str(REPO_ROOT / "experts" / "{env}.pt")
HOPPER_VELOCITIES, HOPPER_POSITIONS, OBS_DIM = list(range(5, 11)), list(range(0, 5)), 11


@pytest.fixture(scope="module")
def expert():
    return dagger.load_expert(EXPERT.format(env="Hopper-v4"), "Hopper-v4")


def expert_on(expert, observations):
    """The expert's action row by row, as collect_round queries it (a batched matmul may differ in the last bit)."""
    return np.stack([expert(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy() for obs in observations])


def collect(expert, beta, num_labels, history=2, seed=0):
    args = tiny_args(dagger, history=history, expert=EXPERT)
    torch.manual_seed(0)
    learner = dagger.make_policy(args, OBS_DIM, 3, torch.randn(100, OBS_DIM * history))
    return dagger.collect_round(learner, expert, args, num_labels, beta, np.random.default_rng(seed), torch.device("cpu"))


def test_budget_split():
    assert dagger.split_budget(8000, 4) == [2000] * 4
    assert dagger.split_budget(10, 3) == [4, 3, 3]
    assert dagger.split_budget(3, 3) == [1, 1, 1]


def test_labels_are_the_experts_action_on_the_clean_observation(expert):
    data = collect(expert, beta=0.5, num_labels=150, history=3)
    clean, inputs, labels = data["clean_observations"], data["inputs"], data["labels"]
    assert clean.shape == (150, OBS_DIM) and inputs.shape == (150, 3 * OBS_DIM) and labels.shape == (150, 3)
    assert np.array_equal(labels, expert_on(expert, clean))
    # the learner saw the noisy frame: the clean one plus noise on the velocities only
    current = inputs[:, -OBS_DIM:]
    assert np.array_equal(current[:, HOPPER_POSITIONS], clean[:, HOPPER_POSITIONS].astype(np.float32))
    assert (current[:, HOPPER_VELOCITIES] != clean[:, HOPPER_VELOCITIES].astype(np.float32)).all()
    assert np.std(current[:, HOPPER_VELOCITIES] - clean[:, HOPPER_VELOCITIES]) == pytest.approx(0.2, rel=0.2)
    on_noisy = expert_on(expert, current)
    assert (np.abs(on_noisy - labels).max(axis=1) > 1e-3).mean() > 0.9, "labels must not come from the noisy frame"
    # ... inside a history that shifts by one frame per step within an episode
    starts = np.all(inputs == np.tile(current, 3), axis=1)  # an episode starts with its first frame repeated
    assert starts[0] and 1 < starts.sum() < 20
    assert np.array_equal(inputs, dagger.stack_history(current, starts, 3)), "stack_history's rule, step by step"
    assert 0.3 < data["expert_acted"].mean() < 0.7


def test_beta_decides_who_acts(expert):
    all_expert, all_learner = collect(expert, beta=1.0, num_labels=20), collect(expert, beta=0.0, num_labels=20)
    assert all_expert["expert_acted"].all() and not all_learner["expert_acted"].any()
    # the same start (same rng), then different trajectories: the learner, not the expert, acted
    assert np.array_equal(all_expert["clean_observations"][0], all_learner["clean_observations"][0])
    assert not np.allclose(all_expert["clean_observations"][5], all_learner["clean_observations"][5])


@pytest.mark.parametrize("beta_rounds, betas", [(None, [2 / 3, 1 / 3, 0.0]),  # beta decays to 0 over --dagger-rounds
                                                 (2, [0.5, 0.0, 0.0]),  # ... or faster, then stays at 0
                                                 (15, [14 / 15, 13 / 15, 12 / 15])])  # imitation's default rampdown
def test_aggregate_grows_by_the_budget_and_round_0_is_bc_oh(monkeypatch, tmp_path, expert, beta_rounds, betas):
    """A seed with 50 labels over 3 rounds; evaluation replaced by a fingerprint of the weights, so
    the round-0 evaluations show that DAgger starts from exactly the policy bc_oh.py trains, and the
    rounds' records show beta's schedule."""
    def fingerprint(policy, args, episodes, seed, device):
        return [sum(p.double().sum().item() for p in policy.parameters())] * episodes

    collected, collect_round = [], dagger.collect_round

    def recorded_collect_round(*arguments):
        collected.append(collect_round(*arguments))
        return collected[-1]

    monkeypatch.setattr(dagger, "evaluate", fingerprint)
    monkeypatch.setattr(bc_oh, "evaluate", fingerprint)
    monkeypatch.setattr(dagger, "collect_round", recorded_collect_round)
    demos = fake_demos(n=256)
    args = tiny_args(dagger, expert=EXPERT, dagger_samples=50, dagger_rounds=3, dagger_epochs=1, dagger_beta_rounds=beta_rounds)
    entry = dagger.train_and_record(args, demos, 1, str(tmp_path))
    assert [r["labels"] for r in entry["rounds"]] == [17, 17, 16]
    assert [r["aggregate"] for r in entry["rounds"]] == [256 + 17, 256 + 34, 256 + 50]
    assert [r["beta"] for r in entry["rounds"]] == pytest.approx(betas)
    data = {key: np.concatenate([round_data[key] for round_data in collected]) for key in collected[0]}
    assert len(data["labels"]) == len(data["inputs"]) == len(data["clean_observations"]) == 50
    assert np.array_equal(data["labels"], expert_on(expert, data["clean_observations"]))
    # evaluations: round 0 at epochs 1, 2 (as bc_oh.py), one per round after, three of the final learner
    assert [epoch for epoch, _ in entry["evaluations"]] == [1, 2, 3, 4, 5, 5, 5]
    alone, _, _ = bc_oh.train_seed(tiny_args(bc_oh), demos, 1, torch.device("cpu"))
    assert entry["evaluations"][:2] == alone
    assert entry["bc_oh_score"] == np.mean([ret for _, ret in alone])
    assert entry["evaluations"][2][1] != alone[-1][1], "the learner trains on after round 0"


def test_bad_dagger_settings_are_rejected(tmp_path):
    missing = str(tmp_path / "none.pt")
    for flags, message in ((("--dagger-samples", 3, "--dagger-rounds", 4), "--dagger-samples must be at least --dagger-rounds 4, got 3"),
                           (("--dagger-samples", 0, "--dagger-rounds", 1), "--dagger-samples must be at least --dagger-rounds 1, got 0"),
                           (("--dagger-epochs", 0), "--dagger-epochs must be positive and finite, got 0"),
                           (("--dagger-rounds", 0), "--dagger-rounds must be positive and finite, got 0"),
                           (("--dagger-beta-rounds", -1), "--dagger-beta-rounds must be positive and finite, got -1")):
        assert_usage_error(run_in_process("dagger.py", "--expert", EXPERT, *flags), message)
    # The expert is checked before the demos are loaded.
    assert_usage_error(run_in_process("dagger.py", "--expert", missing), f"expert checkpoint {missing} not found")
    # Braces other than {env} are part of the path: str.format raised KeyError or ValueError on them.
    for braces in ("{x}.pt", "{.pt"):
        assert_usage_error(run_in_process("dagger.py", "--expert", braces), f"expert checkpoint {braces} not found")
    assert_usage_error(run_in_process("dagger.py", "--expert", EXPERT.format(env="Ant-v4")), "is an expert for Ant-v4, not Hopper-v4")
    # One label a round is enough: the run gets past DAgger's checks to the demo file.
    ok = ("--dagger-samples", 4, "--dagger-rounds", 4, "--demos", str(tmp_path / "none.npz"))
    assert_usage_error(run_in_process("dagger.py", "--expert", EXPERT, *ok), "none.npz not found")


def test_tiny_run_prints_the_summary_and_writes_the_json(tmp_path):
    stdout, data = smoke_run("dagger.py", tmp_path, "--dagger-samples", 60, "--dagger-rounds", 2, "--dagger-epochs", 1)
    seed = data["scores"]["1"]
    assert data["method"] == "dagger" and data["args"]["dagger_samples"] == 60
    assert (data["args"]["frame_skip"], data["args"]["output_dir"]) == (4, "out"), "the resolved rate, a relative folder"
    assert [(r["labels"], r["aggregate"], r["beta"]) for r in seed["rounds"]] == [(30, 330, 0.5), (30, 360, 0.0)]
    assert [epoch for epoch, _ in seed["evaluations"]] == [1, 2, 3, 4, 4, 4]
    assert table_row(stdout, 1) == [f"{seed['score']:.1f}", f"{seed['bc_oh_score']:.1f}"]
