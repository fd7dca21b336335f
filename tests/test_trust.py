"""A command line a user can trust with their own runs and data: ordinary mistakes end in one line and exit 2
(never a silently wrong run), a run writes into a folder of its own, each seed's result is written when the seed ends
(an interrupted job keeps it), and the summary line says how good the score is."""
import json
import signal
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import (METHOD_FILES, REPO_ROOT, assert_usage_error, demo_file, fake_demos, link_experts, load_demos, make_demos, run_in_process,
                      run_script, skip_evaluation, tiny_args)

import average_ensemble
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
    save_demos(tmp_path / "all_starts.npz", {**demos, "episode_starts": np.ones(200, dtype=bool)})  # every step its own episode
    np.savez(tmp_path / "objects.npz", observations=np.array([None] * 200, dtype=object), actions=demos["actions"],
             episode_starts=demos["episode_starts"])


CASES = {
    "another env's demos": (["--demos", "walker.npz"], "walker.npz holds demos of Walker2d-v4: pass --env Walker2d-v4"),
    "another version's demos": (["--env", "Hopper-v5", "--demos", "v4.npz"], "v4.npz holds demos of Hopper-v4: pass --env Hopper-v4"),
    "actions out of bounds": (["--demos", "scaled.npz"], "scaled.npz: actions of rows [0"),  # the first offending row first
    "done flags as starts": (["--demos", "dones.npz"], "dones.npz: episode_starts[0] is False: it is True on each episode's start"),
    "object arrays": (["--demos", "objects.npz"], "objects.npz is not a readable demo file (ValueError): see the format in docs/methods.md"),
    "more samples than the file": (["--demos", "v4.npz", "--num-demo-samples", 500], "v4.npz holds 200 steps: pass --num-demo-samples 200 or fewer"),
    "a batch or fewer steps": (["--demos", "v4.npz", "--batch-size", 200],
                               "v4.npz: 200 steps, not more than a batch: use a smaller --batch-size or more demos"),
    # no history at all (each frame repeated), and a copy error of nan with numpy's warnings
    "starts at every step": (["--demos", "all_starts.npz"], "all_starts.npz: every step starts an episode: pass episodes of 2 steps or more"),
}


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("case", CASES)
def test_a_mistake_in_the_demos_is_refused_in_one_line(case, script, tmp_path, monkeypatch):
    monkeypatch.chdir(link_experts(tmp_path))  # DAgger's expert labels its rounds
    bad_demos(tmp_path)
    args, message = CASES[case]
    result = run_in_process(script, *args, "--epochs", 1, "--eval-episodes", 1, "--seeds", 1)
    assert_usage_error(result, message)


@pytest.mark.parametrize("script", METHOD_FILES)
def test_a_diverged_training_is_refused_in_one_line(script, tmp_path, monkeypatch):
    """An absurd learning rate gave `score nan` and exit 0 after every seed had trained; now the first epoch whose loss is
    not finite stops the job in one line, exit 2, and no result of that seed is written."""
    monkeypatch.chdir(link_experts(tmp_path))  # DAgger's expert labels its rounds
    save_demos(tmp_path / "d.npz", fake_demos(200), {"env_id": "Hopper-v4", "frame_skip": 4})
    flags = ["--demos", "d.npz", "--learning-rate", 1e30, "--epochs", 3, "--eval-episodes", 1, "--output-dir", "out"]
    if script == "bc_oh.py":
        # in worker processes: the error comes back to the main process, which prints it
        result = run_script(script, *flags, "--seeds", 1, 2, "--workers", 2, cwd=tmp_path)
    else:
        result = run_in_process(script, *flags, "--seeds", 1)
    assert_usage_error(result, "seed 1: training diverged at epoch 1 (")
    assert result.stderr.rstrip().endswith("): use a smaller --learning-rate or --obs-noise-std")
    assert result.returncode == 2 and not list((tmp_path / "out").glob("*.json")), "no result of a diverged seed"


def test_actions_out_of_bounds_name_their_rows(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    demos = fake_demos(200)
    demos["actions"][:] = 0.5
    demos["actions"][7, 2], demos["actions"][150, 0] = 1.25, -1.5  # just outside [-1, 1], below and above
    save_demos(tmp_path / "one.npz", demos)
    result = run_in_process("bc_oh.py", "--demos", "one.npz", "--epochs", 1, "--seeds", 1)
    assert_usage_error(result, "one.npz: actions of rows [7, 150] lie outside [-1, 1]: rescale them")


def test_a_users_unreadable_file_gets_no_advice_to_delete_or_unpickle_it(tmp_path, monkeypatch):
    """A file that is no .npz (numpy reads it as a pickle) is the user's own: not to be deleted, and not to be loaded with
    allow_pickle, which numpy's own message suggests."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.npz").write_bytes(b"not a zip")
    result = run_in_process("bc_oh.py", "--demos", "mine.npz", "--epochs", 1, "--seeds", 1)
    assert_usage_error(result, "mine.npz is not a readable demo file (ValueError): see the format in docs/methods.md")
    assert "delete" not in result.stderr and "allow_pickle" not in result.stderr


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without a GPU")
@pytest.mark.parametrize("script", SCRIPTS)
def test_cuda_without_a_gpu_is_refused(script, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = run_in_process(script, "--cuda", "--epochs", 1, "--seeds", 1)
    assert_usage_error(result, "--cuda, but torch sees no CUDA GPU here: leave --cuda out")


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
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "demos: 120 steps from d.npz (the first 120 of its 300)"
    assert lines[1].startswith("demos: copy error MSE(a_{t-1}, a_t)/Var(a) = ")


def test_a_file_without_meta_still_loads(tmp_path, monkeypatch):
    save_demos(tmp_path / "d.npz", fake_demos(200))
    monkeypatch.chdir(tmp_path)
    demos, meta = load_demos(bc_oh, demos="d.npz")
    assert len(demos["actions"]) == 200 and meta == {}


# ----------------------------------------------------------------------------------------------
# Where results go, and what survives an interruption


def test_a_run_writes_into_a_folder_named_by_its_env_experiment_and_start_time(tmp_path, monkeypatch):
    """CleanRL's convention: runs/<env>__<exp-name>__<unix time>, the exp name the file's name by default."""
    assert bc_oh.Args().exp_name == "bc_oh" and c2f.Args().exp_name == "c2f"
    save_demos(tmp_path / "d.npz", fake_demos(256))
    monkeypatch.chdir(tmp_path)
    skip_evaluation(monkeypatch, bc_oh, score=7.0)
    monkeypatch.setattr(bc_oh.time, "time", lambda: 1733500000.5)
    bc_oh.run(tiny_args(bc_oh, demos="d.npz", exp_name="mine"))
    (result,) = (tmp_path / "runs").glob("*/result_seeds1.json")
    assert result.parent.name == "Hopper-v4__mine__1733500000"
    assert json.loads(result.read_text())["args"]["output_dir"] == "runs/Hopper-v4__mine__1733500000"


@pytest.mark.parametrize("module", [bc_oh, dagger], ids=lambda module: module.METHOD)
def test_an_interrupted_job_keeps_each_seed_that_finished(tmp_path, monkeypatch, capsys, module):
    def interrupted(args, demos, seed, device):
        if seed == 2:
            raise KeyboardInterrupt  # Ctrl-C during the second seed
        return train_seed(args, demos, seed, device)

    train_seed = module.train_seed
    monkeypatch.setattr(module, "train_seed", interrupted)
    skip_evaluation(monkeypatch, module, score=7.0)
    save_demos(tmp_path / "d.npz", fake_demos(256))
    monkeypatch.chdir(link_experts(tmp_path))
    extra = {}
    if module is dagger:
        extra = dict(dagger_samples=40, dagger_rounds=1, dagger_epochs=1)
    handlers = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))
    with pytest.raises(SystemExit) as interrupted_run:
        module.run(tiny_args(module, demos="d.npz", learning_rate=None, seeds=[1, 2], output_dir="out", **extra))
    assert interrupted_run.value.code == 130
    # A program (or notebook) that calls run() can still be interrupted: it left Ctrl-C and `kill` ignored.
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers
    assert capsys.readouterr().err == "interrupted: seeds [1] finished, their results are in out\n"
    assert sorted(path.name for path in (tmp_path / "out").glob("*.json")) == ["result_seeds1.json"], "no combined result"
    first = json.loads((tmp_path / "out" / "result_seeds1.json").read_text())
    assert first["args"]["seeds"] == [1] and list(first["scores"]) == ["1"] and first["scores"]["1"]["score"] == 7.0


@pytest.mark.parametrize("module", [bc_oh, average_ensemble], ids=lambda module: module.METHOD)
def test_a_result_file_is_replaced_whole_or_not_at_all(tmp_path, monkeypatch, module):
    """A seed's result is written to a temporary file, then renamed: a write cut short (a full disk, a kill) leaves the
    previous result_seeds<S>.json as it was, where the old code left half a JSON file in its place. The other method
    files copy bc_oh's write_result; the ensemble's has its own."""
    members = {"members": {"bc_so": {"score": 1.0}, "bc_oh": {"score": 1.0}}}
    args = tiny_args(module, seeds=[1])
    path = module.write_result(str(tmp_path), args, {1: {"score": 1.0, "evaluations": [[1, 1.0]], "ms_per_step": 0.1, **members}})
    before = Path(path).read_text()
    real_write_text = Path.write_text

    def cut_short(self, text, *args, **kwargs):
        real_write_text(self, text[: len(text) // 2])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", cut_short)
    with pytest.raises(OSError):
        module.write_result(str(tmp_path), args, {1: {"score": 2.0, "evaluations": [[1, 2.0]], "ms_per_step": 0.1, **members}})
    assert Path(path).read_text() == before and json.loads(before)["scores"]["1"]["score"] == 1.0


def test_the_summary_line_gives_the_share_of_the_experts_return(tmp_path, monkeypatch, capsys):
    """The share comes from the expert's return that expert_ppo.py --make-demos recorded in the demos' meta (each
    seed's evaluations return a set share of it here: 40% for seed 1, 42% for seed 2)."""
    meta = demo_file(make_demos("Hopper-v4", 300))[1]
    expert = torch.load(REPO_ROOT / "experts" / "Hopper-v4.pt", weights_only=True)["eval_return"]
    assert (meta["expert_return"], meta["expert_frame_skip"]) == (expert, 4)
    share = lambda policy, args, episodes, seed, device: [expert * (0.38 + 0.02 * (seed // 10_000))] * episodes  # noqa: E731
    monkeypatch.setattr(bc_oh, "evaluate", share)
    bc_oh.run(tiny_args(bc_oh, seeds=[1, 2], demos=str(make_demos("Hopper-v4", 300)), output_dir=str(tmp_path / "a")))
    assert capsys.readouterr().out.splitlines()[-1] == \
        f"Hopper-v4 bc_oh: score {expert * 0.41:.1f} ± {expert * 0.01:.1f} (mean ± std over 2 seeds), 41% of the expert's {expert:.0f}"
    fast = make_demos("Hopper-v4", 300, 1)  # the same expert, rolled out at frame skip 1, its returns on the same scale
    bc_oh.run(tiny_args(bc_oh, seeds=[6], frame_skip=1, demos=str(fast), output_dir=str(tmp_path / "b")))
    assert capsys.readouterr().out.splitlines()[-1] == \
        f"Hopper-v4 bc_oh: score {expert * 0.5:.1f} ± 0.0 (mean ± std over 1 seed), 50% of the expert's {expert:.0f}"
