"""A command line a user can trust with their own runs and data: ordinary mistakes end in one line and exit 2
(never a silently wrong run), a run never overwrites another run's result, each seed's result is written when the
seed ends and a rerun keeps it, and the summary line says how good the score is."""
import json

import numpy as np
import pytest
import torch
from conftest import (REPO_ROOT, assert_usage_error, fake_demos, link_experts, load_demos, make_demos, run_in_process, skip_evaluation,
                      tiny_args)

import bc_oh
import c2f
import dagger

SCRIPTS = ["bc_oh.py", "c2f.py", "dagger.py", "average_ensemble.py"]


def save_demos(path, demos, meta=None):
    np.savez(path, **demos, **({"meta": np.array(json.dumps(meta))} if meta else {}))
    return path


def bad_demos(tmp_path):
    """Demo files of the mistakes users make; each file is Hopper-shaped, so only the new checks can catch it."""
    demos = fake_demos(200)
    save_demos(tmp_path / "walker.npz", demos, {"env_id": "Walker2d-v4", "frame_skip": 4})
    save_demos(tmp_path / "v4.npz", demos, {"env_id": "Hopper-v4", "frame_skip": 4})
    save_demos(tmp_path / "scaled.npz", {**demos, "actions": demos["actions"] * 5})
    save_demos(tmp_path / "dones.npz", {**demos, "episode_starts": np.roll(demos["episode_starts"], -1)})  # done flags, not starts
    np.savez(tmp_path / "objects.npz", observations=np.array([None] * 200, dtype=object), actions=demos["actions"],
             episode_starts=demos["episode_starts"])


CASES = {
    "another env's demos": (["--demos", "walker.npz"], "walker.npz holds demos of Walker2d-v4: pass --env Walker2d-v4, or demos of Hopper-v4"),
    "another version's demos": (["--env", "Hopper-v5", "--demos", "v4.npz"], "v4.npz holds demos of Hopper-v4: pass --env Hopper-v4, or demos of Hopper-v5"),
    "actions out of bounds": (["--demos", "scaled.npz"], "scaled.npz: actions of rows [0"),  # the first offending row first
    "done flags as starts": (["--demos", "dones.npz"], "dones.npz: episode_starts[0] is False: it is True on each episode's first step"),
    "object arrays": (["--demos", "objects.npz"], "objects.npz is not a readable demo file (ValueError): see the format in README.md"),
    "more samples than the file": (["--demos", "v4.npz", "--num-demo-samples", 500], "v4.npz holds 200 steps: pass --num-demo-samples 200 or fewer"),
}


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("case", CASES)
def test_a_mistake_in_the_demos_is_refused_in_one_line(case, script, tmp_path, monkeypatch):
    monkeypatch.chdir(link_experts(tmp_path))  # DAgger's expert labels its rounds
    bad_demos(tmp_path)
    args, message = CASES[case]
    result = run_in_process(script, *args, "--epochs", 1, "--eval-episodes", 1, "--seeds", 1)
    assert_usage_error(result, message)


def test_actions_out_of_bounds_name_their_rows(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    demos = fake_demos(200)
    demos["actions"][:] = 0.5
    demos["actions"][7, 2], demos["actions"][150, 0] = 1.25, -1.5  # just outside [-1, 1], below and above
    save_demos(tmp_path / "one.npz", demos)
    result = run_in_process("bc_oh.py", "--demos", "one.npz", "--epochs", 1, "--seeds", 1)
    assert_usage_error(result, "one.npz: actions of rows [7, 150] lie outside the bounds [-1, 1]: rescale or clip them")


def test_a_users_unreadable_file_gets_no_advice_to_delete_or_unpickle_it(tmp_path, monkeypatch):
    """A file that is no .npz (numpy reads it as a pickle) is the user's own: not to be deleted, and not to be loaded with
    allow_pickle, which numpy's own message suggests."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.npz").write_bytes(b"not a zip")
    result = run_in_process("bc_oh.py", "--demos", "mine.npz", "--epochs", 1, "--seeds", 1)
    assert_usage_error(result, "mine.npz is not a readable demo file (ValueError): see the format in README.md")
    assert "delete" not in result.stderr and "allow_pickle" not in result.stderr


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without a GPU")
@pytest.mark.parametrize("script", SCRIPTS)
def test_cuda_without_a_gpu_is_refused(script, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = run_in_process(script, "--cuda", "--epochs", 1, "--seeds", 1)
    assert_usage_error(result, "--cuda, but torch sees no CUDA GPU here: drop --cuda")


def test_num_demo_samples_with_demos_takes_the_first_steps(tmp_path, monkeypatch):
    demos = fake_demos(300)
    save_demos(tmp_path / "d.npz", demos)
    monkeypatch.chdir(tmp_path)
    taken, _ = load_demos(bc_oh, demos=str(tmp_path / "d.npz"), num_demo_samples=120)
    assert len(taken["actions"]) == 120 and np.array_equal(taken["observations"], demos["observations"][:120])
    assert np.array_equal(taken["actions"], demos["actions"][:120]) and np.array_equal(taken["episode_starts"], demos["episode_starts"][:120])


def test_num_demo_samples_with_demos_is_printed(tmp_path, monkeypatch, capsys):
    save_demos(tmp_path / "d.npz", fake_demos(300))
    monkeypatch.chdir(tmp_path)
    load_demos(bc_oh, demos="d.npz", num_demo_samples=120)
    assert capsys.readouterr().out.startswith("demos: 120 steps from d.npz (the first 120 of its 300); copy error ")


def test_a_file_without_meta_still_loads(tmp_path, monkeypatch):
    save_demos(tmp_path / "d.npz", fake_demos(200))
    monkeypatch.chdir(tmp_path)
    demos, meta = load_demos(bc_oh, demos="d.npz")
    assert len(demos["actions"]) == 200 and meta == {}


# ----------------------------------------------------------------------------------------------
# Where results go, and what survives an interruption


def test_each_run_of_other_settings_gets_a_folder_its_flags_name():
    assert c2f.run_name(c2f.Args()) == "c2f"
    assert c2f.run_name(c2f.Args(fusion="early", stop_gradient=False)) == "c2f__fusion-early__no-stop-gradient"
    assert c2f.run_name(c2f.Args(seeds=[4, 5], cuda=True, save_model=True, output_dir="x")) == "c2f", "no result changes"
    assert bc_oh.run_name(bc_oh.Args(demos="data/my_demos.npz", hide_velocities=True, learning_rate=1e-4)) == \
        "bc_oh__demos-my_demos__hide-velocities__learning-rate-0.0001"
    assert bc_oh.Args().output_dir == "runs/{run_name}/{env}"


def run_in(folder, module, monkeypatch, **overrides):
    """module.run on tiny fake demos in folder (no env rollouts); returns the seeds it trained."""
    save_demos(folder / "d.npz", fake_demos(256))
    monkeypatch.chdir(folder if (folder / "experts").exists() else link_experts(folder))  # DAgger's expert labels its rounds
    skip_evaluation(monkeypatch, module, score=7.0)
    trained, train_seed = [], module.train_seed
    monkeypatch.setattr(module, "train_seed", lambda args, demos, seed, device: trained.append(seed) or train_seed(args, demos, seed, device))
    args = tiny_args(module, demos="d.npz", learning_rate=None, **overrides)
    module.run(args)
    return trained


def test_an_ablation_does_not_overwrite_the_default_run(tmp_path, monkeypatch):
    run_in(tmp_path, c2f, monkeypatch)
    run_in(tmp_path, c2f, monkeypatch, fusion="early")
    folders = sorted(path.parent.parent.name for path in (tmp_path / "runs").glob("*/Hopper-v4/result_seeds1.json"))
    assert len(folders) == 2 and folders[1] == folders[0] + "__fusion-early"


@pytest.mark.parametrize("module", [bc_oh, dagger], ids=lambda module: module.METHOD)
def test_each_seed_is_written_when_it_ends_and_a_rerun_keeps_it(tmp_path, monkeypatch, capsys, module):
    def interrupted(args, demos, seed, device):
        if seed == 2:
            raise KeyboardInterrupt  # Ctrl-C during the second seed
        return train_seed(args, demos, seed, device)

    train_seed = module.train_seed
    monkeypatch.setattr(module, "train_seed", interrupted)
    skip_evaluation(monkeypatch, module, score=7.0)
    save_demos(tmp_path / "d.npz", fake_demos(256))
    monkeypatch.chdir(link_experts(tmp_path))
    extra = dict(dagger_samples=40, dagger_rounds=1, dagger_epochs=1) if module is dagger else {}
    with pytest.raises(SystemExit) as interrupted_run:
        module.run(tiny_args(module, demos="d.npz", learning_rate=None, seeds=[1, 2], **extra))
    assert interrupted_run.value.code == "interrupted: seeds 1 finished and kept, 2 lost: the same command trains only those"
    (folder,) = (tmp_path / "runs").glob("*/Hopper-v4")
    assert sorted(path.name for path in folder.glob("*.json")) == ["result_seeds1.json"], "seed 1 is kept, no combined result yet"
    first = json.loads((folder / "result_seeds1.json").read_text())
    assert first["args"]["seeds"] == [1] and list(first["scores"]) == ["1"]
    monkeypatch.setattr(module, "train_seed", train_seed)
    assert run_in(tmp_path, module, monkeypatch, seeds=[1, 2], **extra) == [2], "the rerun trains only the unfinished seed"
    assert f"seeds 1: kept their finished results in {folder.relative_to(tmp_path)} (delete to retrain)" in capsys.readouterr().out
    both = json.loads((folder / "result_seeds1-2.json").read_text())
    assert both["scores"]["1"] == first["scores"]["1"] and list(both["scores"]) == ["1", "2"]


def test_a_seed_made_with_other_settings_is_trained_again(tmp_path, monkeypatch):
    run_in(tmp_path, bc_oh, monkeypatch, output_dir="out")
    assert run_in(tmp_path, bc_oh, monkeypatch, output_dir="out") == []
    assert run_in(tmp_path, bc_oh, monkeypatch, output_dir="out", hidden=16) == [1], "same folder, other settings: trained again"


def demo_meta(path) -> dict:
    with np.load(path, allow_pickle=False) as data:
        return json.loads(str(data["meta"]))


def test_the_summary_line_gives_the_share_of_the_experts_return(tmp_path, monkeypatch, capsys):
    """The share comes from the expert's return that expert_ppo.py --make-demos recorded in the demos' meta (each
    seed's evaluations return a set share of it here: 40% for seed 1, 42% for seed 2)."""
    meta = demo_meta(make_demos("Hopper-v4", 300))
    expert = torch.load(REPO_ROOT / "experts" / "Hopper-v4.pt", weights_only=True)["eval_return"]
    assert (meta["expert_return"], meta["expert_frame_skip"]) == (expert, 4)
    share = lambda policy, args, episodes, seed, device: [expert * (0.38 + 0.02 * (seed // 10_000))] * episodes  # noqa: E731
    monkeypatch.setattr(bc_oh, "evaluate", share)
    bc_oh.run(tiny_args(bc_oh, seeds=[1, 2], demos=str(make_demos("Hopper-v4", 300)), output_dir=str(tmp_path / "a")))
    assert capsys.readouterr().out.splitlines()[-1] == \
        f"Hopper-v4 bc_oh: {expert * 0.41:.1f} ± {expert * 0.01:.1f} over 2 seeds, 41% of the expert's {expert:.0f}"
    fast = make_demos("Hopper-v4", 300, 1)  # the same expert, rolled out at frame skip 1
    bc_oh.run(tiny_args(bc_oh, seeds=[6], frame_skip=1, demos=str(fast), output_dir=str(tmp_path / "b")))
    assert capsys.readouterr().out.splitlines()[-1] == \
        f"Hopper-v4 bc_oh: {expert * 0.5:.1f} ± 0.0 over 1 seed, 50% of the expert's {expert:.0f} at its own frame skip 4"
