"""Tests of expert_ppo.py: a tiny training run, its checkpoint, resuming, evaluation, --make-demos and bad input."""
import contextlib
import errno
import hashlib
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import expert_ppo
from conftest import REPO_ROOT, assert_usage_error, demo_file, link_experts, run_in_process, run_script

TINY = ["--num-envs", 2, "--num-steps", 512, "--num-minibatches", 4, "--update-epochs", 1, "--eval-every-steps", 2048,
        "--save-every-steps", 2048, "--train-eval-episodes", 1, "--eval-episodes", 1]
SUMMARY = re.compile(r"^Hopper-v4 expert: (-?\d+\.\d) ± (\d+\.\d) over (\d+) episodes$")
SHIPPED_EXPERT = REPO_ROOT / "experts" / "Hopper-v4.pt"


def summary(result):
    """(mean, episodes) from the last stdout line, which must be the summary line."""
    assert result.returncode == 0, result.stderr
    match = SUMMARY.match(result.stdout.splitlines()[-1])
    assert match, result.stdout
    return float(match.group(1)), int(match.group(3))


def load(path):
    return torch.load(path, map_location="cpu", weights_only=True)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """One tiny Hopper-v4 training run of 4096 steps, shared by the tests of this file (do not modify)."""
    run_dir = tmp_path_factory.mktemp("tiny_run")
    result = run_script("expert_ppo.py", "--total-timesteps", 4096, *TINY, "--output-dir", run_dir)
    return run_dir, result


@pytest.fixture
def checkpoint(tiny_run):
    return tiny_run[0] / "latest.pt"


def test_training_writes_a_complete_checkpoint(tiny_run, checkpoint):
    run_dir, result = tiny_run
    train_mean, _ = summary(result)
    state = load(checkpoint)
    assert state["env_id"] == "Hopper-v4"
    assert state["obs_shape"] == [11] and state["action_shape"] == [3]
    assert state["global_step"] == 4096
    assert state["eval_return"] == pytest.approx(train_mean, abs=0.05)
    for name, initial in (("obs_mean", 0.0), ("obs_var", 1.0)):
        assert state[name].shape == (11,)
        assert torch.isfinite(state[name]).all()
        assert not torch.allclose(state[name], torch.full((11,), initial, dtype=torch.float64)), f"{name} never updated"
    assert (state["obs_var"] > 0).all()
    assert (run_dir / "best.pt").is_file()
    assert not list(run_dir.glob("*.tmp*")), "save_atomically left a temporary file"


def test_eval_only_reproduces_the_final_evaluation_and_ships(tiny_run, checkpoint, tmp_path):
    # --eval-only and the final evaluation of training both use seeds 10000, 10001, ...
    train_mean, _ = summary(tiny_run[1])
    shipped = tmp_path / "shipped.pt"
    result = run_script("expert_ppo.py", "--eval-only", "--checkpoint", checkpoint, "--eval-episodes", 1, "--ship-to", shipped)
    assert summary(result) == (train_mean, 1)
    # --ship-to writes the same checkpoint with the evaluation recorded
    original, copy = load(checkpoint), load(shipped)
    assert copy["eval_return"] == pytest.approx(train_mean, abs=0.05) and copy["eval_episodes"] == 1
    assert torch.equal(copy["obs_mean"], original["obs_mean"]) and copy["global_step"] == original["global_step"]


def test_load_expert_round_trip(checkpoint):
    state = load(checkpoint)
    first, second = (expert_ppo.load_expert(str(checkpoint), "Hopper-v4") for _ in range(2))
    obs = torch.randn(64, 11) * 3
    actions = first(obs)
    assert actions.shape == (64, 3)
    assert torch.equal(actions, second(obs))
    assert torch.equal(first.obs_mean, state["obs_mean"].float())
    assert torch.equal(first.obs_var, state["obs_var"].float())
    assert (actions >= -1).all() and (actions <= 1).all()  # Hopper's action bounds


def test_resume_continues_from_the_checkpoint(tiny_run, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run[0], run_dir)
    before = load(run_dir / "latest.pt")
    # a checkpoint written before the flags were renamed records its args under the old names: it resumes
    old_names = {"output_dir": "run_dir", "eval_every_steps": "eval_every", "save_every_steps": "save_every"}
    old = dict(before, args={old_names.get(name, name): value for name, value in before["args"].items()})
    assert {"run_dir", "eval_every", "save_every"} <= set(old["args"]) and "output_dir" not in old["args"]
    torch.save(old, run_dir / "latest.pt")
    result = run_script("expert_ppo.py", "--total-timesteps", 6144, *TINY, "--output-dir", run_dir, "--resume")
    summary(result)
    assert f"resumed from {run_dir / 'latest.pt'} at step 4096" in result.stdout
    after = load(run_dir / "latest.pt")
    assert after["global_step"] == 6144
    # the observation statistics went on from the checkpoint's (4096 + 2048 observations), not from scratch
    assert after["obs_count"] == pytest.approx(before["obs_count"] + 2048)
    assert after["args"]["output_dir"] == str(run_dir) and "run_dir" not in after["args"]  # recorded under today's names


def test_shipped_expert_scores_well():
    mean, episodes = summary(run_script("expert_ppo.py", "--eval-only", "--checkpoint", SHIPPED_EXPERT, "--eval-episodes", 2))
    assert episodes == 2 and mean > 1000  # a random policy scores about 20
    # the score depends on the saved normalisation statistics: without them the actor is much worse
    state = load(SHIPPED_EXPERT)
    state["obs_mean"], state["obs_var"] = torch.zeros(11, dtype=torch.float64), torch.ones(11, dtype=torch.float64)
    assert np.mean(expert_ppo.evaluate(expert_ppo.ExpertPolicy(state), "Hopper-v4", 2, seed=10_000)) < mean / 2


@pytest.mark.parametrize(
    "args, message",
    [
        (["--env", "Nope-v0"], "cannot make env 'Nope-v0'"),
        (["--env", "CartPole-v1"], "has discrete actions: imitation needs continuous ones"),
        (["--eval-only", "--checkpoint", "missing.pt"], "expert checkpoint missing.pt not found"),
        (["--eval-only", "--checkpoint", "my{{x}}.pt"], "expert checkpoint my{x}.pt not found"),
        (["--eval-only", "--checkpoint", "garbage.pt"], "garbage.pt is not a readable expert checkpoint"),
        (["--env", "Walker2d-v4", "--eval-only", "--checkpoint", "{tiny}"], "is an expert for Hopper-v4, not Walker2d-v4"),
        (["--total-timesteps", 0], "--total-timesteps must be positive"),
        (["--learning-rate", 0], "--learning-rate must be positive"),
        (["--frame-skip", 0], "--frame-skip must be positive"),
        (["--env", "Pendulum-v1", "--frame-skip", 2], "is not a MuJoCo env"),
        (["--frame-skip", 10000], "--frame-skip 10000 outlasts an episode: pass a smaller one"),
        (["--eval-only", "--checkpoint", "{tiny}", "--frame-skip", 1, "--ship-to", "x.pt"], "was trained at frame skip 4"),
        (["--gamma", 1.5], "--gamma must be in (0, 1], got 1.5"),
        (["--gamma", "nan"], "--gamma must be in (0, 1], got nan"),
        (["--gae-lambda", -0.1], "--gae-lambda must be in [0, 1], got -0.1"),
        # An infinite rate trained, and shipped, a NaN expert; a negative seed raised in gymnasium.
        (["--learning-rate", "inf"], "--learning-rate must be positive and finite, got inf"),
        # Past float32's range: torch's clamp raised "value cannot be converted to type float without overflow".
        (["--clip-coef", "1e40"], "--clip-coef must be below 1e38, got 1e+40"),
        (["--seed", -1], "--seed must lie in [0, 2**32), got -1"),
        # NaN weights raised in torch.distributions, a negative one trained a wrong expert in silence.
        (["--ent-coef", "nan"], "--ent-coef must lie in [0, inf), got nan"),
        (["--vf-coef", -1], "--vf-coef must lie in [0, inf), got -1.0"),
        # A minibatch of one step normalised its advantage by a NaN std, and raised.
        (["--num-envs", 1, "--num-steps", 4, "--num-minibatches", 4], "--num-minibatches must divide num-envs * num-steps, 2 steps a minibatch or more"),
        (["--num-minibatches", 3], "--num-minibatches must divide num-envs * num-steps, 2 steps a minibatch or more"),
    ],
    ids=["unknown-env", "discrete-env", "missing-checkpoint", "braces-in-checkpoint", "corrupt-checkpoint", "other-env-checkpoint", "zero-timesteps", "zero-lr",
         "zero-frame-skip", "frame-skip-non-mujoco", "frame-skip-over-an-episode", "ship-at-other-rate", "gamma-above-1", "gamma-nan", "negative-gae-lambda",
         "infinite-lr", "huge-clip-coef", "negative-seed", "nan-ent-coef", "negative-vf-coef", "minibatch-of-one", "minibatches-not-dividing"],
)
def test_bad_input_is_one_clear_line(args, message, checkpoint, tmp_path, monkeypatch):
    (tmp_path / "garbage.pt").write_bytes(np.random.default_rng(0).bytes(4096))
    args = [str(arg).format(tiny=checkpoint) for arg in args]
    monkeypatch.chdir(tmp_path)
    # In this process (a tenth of a second, not three); --max-minutes bounds the run should a check stop working.
    result = run_in_process("expert_ppo.py", *args, "--output-dir", tmp_path / "run", "--max-minutes", 0.01)
    assert_usage_error(result, message)
    assert result.returncode == 2
    assert not (tmp_path / "run").exists()  # failed before training started


@pytest.mark.parametrize("output_dir, problem", [("a_file", "FileExistsError("), ("a_file/sub", "NotADirectoryError("),
                                                  ("runs/{name}", "KeyError('name')")], ids=["a-file", "under-a-file", "unknown-field"])
def test_an_output_dir_that_cannot_be_made_is_refused_before_training(output_dir, problem, tmp_path, monkeypatch):
    """A file in the way raised at the first checkpoint, after training had run; a field other than {env}, {seed} and
    {rate} raised in str.format. Both are refused in one line before the first rollout."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a_file").write_text("")
    result = run_in_process("expert_ppo.py", "--output-dir", output_dir, "--max-minutes", 0.01)
    assert_usage_error(result, f"cannot make --output-dir {output_dir} ({problem}")
    assert result.returncode == 2 and result.stdout == "", "refused before anything else happens"


def test_a_negative_time_limit_is_refused():
    """(The test above passes --max-minutes itself.) A negative limit stopped after the first rollout."""
    with pytest.raises(expert_ppo.UsageError, match=r"^--max-minutes must lie in \[0, inf\), got -1.0$"):
        expert_ppo.validate(expert_ppo.Args(max_minutes=-1.0))
    expert_ppo.validate(expert_ppo.Args(max_minutes=0.0))  # 0: no limit


@pytest.mark.parametrize("old, new", [("--run-dir", "--output-dir"), ("--eval-every", "--eval-every-steps"), ("--save-every", "--save-every-steps")])
def test_renamed_flags_are_gone(old, new):
    """The flags speak the method files' vocabulary: --output-dir as theirs; counts of env steps say so, since
    their --eval-every counts epochs. The old names are unknown flags (tyro's error, exit 2), not aliases."""
    result = run_in_process("expert_ppo.py", old, "x")
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert f"Unrecognized options: {old}" in " ".join(re.sub(r"[│╭╮╰╯─|+]", " ", result.stderr).split())
    help_text = run_in_process("expert_ppo.py", "--help").stdout
    assert re.search(rf"{new} (STR|INT)\b", help_text) and not re.search(rf"{old} (STR|INT)\b", help_text)


@pytest.fixture
def interrupted_save(tmp_path, monkeypatch):
    """tmp_path/latest.pt written by save_atomically, then a second save interrupted half way."""
    path = tmp_path / "latest.pt"
    expert_ppo.save_atomically({"global_step": 1}, str(path))

    def half_save(obj, file):  # save_atomically hands torch.save the open temporary file
        file.write(b"half a checkpoint")
        raise KeyboardInterrupt

    monkeypatch.setattr(expert_ppo.torch, "save", half_save)
    with pytest.raises(KeyboardInterrupt):
        expert_ppo.save_atomically({"global_step": 2}, str(path))
    monkeypatch.undo()
    return path


def test_interrupted_save_keeps_the_old_checkpoint(interrupted_save):
    assert load(interrupted_save) == {"global_step": 1}


def test_interrupted_save_leaves_no_tmp_file(interrupted_save):
    assert not list(interrupted_save.parent.glob("*.tmp*"))


def test_an_interrupted_training_says_how_to_go_on_in_one_line(tmp_path):
    """Ctrl-C printed a traceback and `kill` nothing; both now end in one line, exit 130, and latest.pt (written
    atomically) is whole for --resume. `kill` is tried: it becomes the KeyboardInterrupt that Ctrl-C raises."""
    # The last of a repeated flag counts: a checkpoint after each rollout of 1024 steps.
    command = [sys.executable, str(REPO_ROOT / "expert_ppo.py"), *map(str, TINY), "--save-every-steps", "1024", "--output-dir", str(tmp_path)]
    job = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    for line in job.stdout:  # the 2nd rollout: latest.pt was written after the 1st
        if line.startswith("step      2048 |"):
            break
    job.send_signal(signal.SIGTERM)
    _, stderr = job.communicate(timeout=60)
    assert job.returncode == 130 and stderr.splitlines() == ["interrupted: a training run goes on with --resume"], stderr
    assert load(tmp_path / "latest.pt")["global_step"] >= 1024


def test_a_checkpoint_that_cannot_be_written_is_one_line(tmp_path, monkeypatch):
    """A read-only --output-dir (a read-only mount; chmod does not stop root) raised PermissionError at the first
    checkpoint. The OS's answer is played here by os.replace, which moves the finished temporary file into place."""

    def refuse(source, target):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(os, "replace", refuse)
    result = run_in_process("expert_ppo.py", *TINY, "--total-timesteps", 1024, "--output-dir", tmp_path)
    assert_usage_error(result, f"cannot write {tmp_path / 'latest.pt'} (Permission denied): check the path and its folder")
    assert list(tmp_path.iterdir()) == [], "no temporary file is left"


def read_only(folder, monkeypatch):
    """Play a read-only mount at folder (chmod does not stop root): os.access says no to writing there, and os.replace,
    which moves a finished temporary file into place, fails as the OS would."""
    access = os.access

    def no_write_access(path, mode, *args, **kwargs):
        return not (Path(path) == folder and mode & os.W_OK) and access(path, mode, *args, **kwargs)

    def refuse(source, target):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(os, "access", no_write_access)
    monkeypatch.setattr(os, "replace", refuse)


@pytest.mark.parametrize("case", ["ship-to-a-folder", "demos-is-a-file", "read-only-output-dir"])
def test_an_output_that_cannot_be_written_is_refused_before_any_work(case, tmp_path, monkeypatch):
    """--ship-to a folder, a file named demos where --make-demos puts its folder, and a read-only --output-dir were
    refused in one line only once the work was done (the evaluation episodes, the demo rollout, training up to the
    first checkpoint), and the demos case named the file it wanted to write, not the one in the way. Each is refused
    now before the work starts: nothing printed on stdout (each mode prints as it works), nothing written."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "demos").write_text("mine")
    folder = tmp_path / "folder"
    folder.mkdir()
    if case == "ship-to-a-folder":
        flags = ["--eval-only", "--eval-episodes", 1, "--checkpoint", SHIPPED_EXPERT, "--ship-to", folder]
        message = f"--ship-to {folder} is a folder: give the path of the file to write"
    elif case == "demos-is-a-file":
        flags = ["--make-demos", "--num-demo-samples", 20, "--checkpoint", SHIPPED_EXPERT]
        message = "./demos is a file in the way of demos/Hopper-v4_20.npz: move it"
    else:
        read_only(folder, monkeypatch)
        flags = [*TINY, "--total-timesteps", 1024, "--output-dir", folder]
        message = f"--output-dir {folder} is read-only: pass another"
    result = run_in_process("expert_ppo.py", *flags)
    assert_usage_error(result, message)
    assert result.returncode == 2 and result.stdout == "", "refused before any episode, rollout or training step"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["demos", "folder"] and list(folder.iterdir()) == []
    assert (tmp_path / "demos").read_text() == "mine"


DIVERGED = ": use a smaller --learning-rate"


@pytest.mark.parametrize("rate", [1e10, 10], ids=["rate-1e10", "rate-10"])
def test_a_diverged_training_is_one_line_and_saves_no_nan_weights(rate, tmp_path):
    """--learning-rate 1e10 made the weights NaN within the first update, and the next forward pass raised torch's
    ValueError (Normal: invalid scale) in a traceback; 10 made them NaN within the first update too, which the run saved
    as latest.pt before the next rollout raised. Now one line names the problem and the fix (exit 2), and the run stops
    before it saves or evaluates NaN weights."""
    flags = [*TINY, "--save-every-steps", 1024, "--total-timesteps", 4096, "--learning-rate", rate]
    result = run_in_process("expert_ppo.py", *flags, "--output-dir", tmp_path, "--max-minutes", 0.2)
    assert_usage_error(result, f"training diverged at step 1024{DIVERGED}")
    assert result.returncode == 2
    # nothing was saved, not even a progress line printed
    assert result.stdout == "" and list(tmp_path.iterdir()) == []


def test_a_diverged_resume_keeps_the_checkpoints_already_written(tiny_run, tmp_path):
    """A --resume at --learning-rate 1e10 raised torch's ValueError in its first update. Now it stops there in one
    line, and latest.pt and best.pt stay as they were, for a --resume at a sound rate."""
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run[0], run_dir)
    before = {name: (run_dir / name).read_bytes() for name in ("latest.pt", "best.pt")}
    flags = [*TINY, "--save-every-steps", 1024, "--total-timesteps", 8192, "--learning-rate", 1e10, "--resume"]
    result = run_in_process("expert_ppo.py", *flags, "--output-dir", run_dir)
    assert_usage_error(result, f"training diverged at step 5120{DIVERGED}")
    assert result.returncode == 2 and result.stdout.splitlines() == [f"resumed from {run_dir / 'latest.pt'} at step 4096"]
    assert {name: (run_dir / name).read_bytes() for name in before} == before
    assert sorted(path.name for path in run_dir.iterdir()) == ["best.pt", "latest.pt"]



def test_a_resume_from_non_finite_weights_is_one_line(tiny_run, tmp_path):
    """A latest.pt whose weights are NaN (saved by a diverged run before this was refused) ended a --resume in torch's
    traceback at the first rollout; it is refused in one line that says to delete it, and is left as it was."""
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run[0], run_dir)
    state = load(run_dir / "latest.pt")
    for weights in state["agent"].values():
        weights.fill_(float("nan"))
    torch.save(state, run_dir / "latest.pt")
    before = (run_dir / "latest.pt").read_bytes()
    flags = [*TINY, "--total-timesteps", 8192, "--resume", "--output-dir", run_dir]
    result = run_in_process("expert_ppo.py", *flags)
    latest = run_dir / "latest.pt"
    assert_usage_error(result, f"cannot resume from {latest}: its weights are not finite (a diverged run): delete it")
    assert (run_dir / "latest.pt").read_bytes() == before

# ----------------------------------------------------------------------------------------------
# --frame-skip


class CountSteps(gym.Wrapper):
    """A pass-through wrapper that counts the steps taken, to tell the envs a run used from mere checks."""

    steps = 0

    def step(self, action):
        self.steps += 1
        return super().step(action)


@pytest.fixture(scope="module")
def fs1_run(tmp_path_factory):
    """A tiny Hopper-v4 training run at --frame-skip 1 (1024 steps, in process), with every env it made
    (wrapped in CountSteps): (run dir, envs, checkpoint, final evaluation's return)."""
    run_dir, made = tmp_path_factory.mktemp("fs1_run"), []
    make_env = expert_ppo.make_env

    def counting_make_env(env_id, frame_skip=None):
        made.append(CountSteps(make_env(env_id, frame_skip)))
        return made[-1]

    args = expert_ppo.Args(env="Hopper-v4", frame_skip=1, total_timesteps=1024, num_envs=2, num_steps=512, num_minibatches=4,
                           update_epochs=1, eval_every_steps=2048, save_every_steps=2048, train_eval_episodes=1, eval_episodes=1,
                           output_dir=str(run_dir))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(expert_ppo, "make_env", counting_make_env)
        expert_ppo.train(args)
    state = load(run_dir / "latest.pt")
    return run_dir, made, state


def test_default_records_the_native_frame_skip(checkpoint):
    state = load(checkpoint)
    assert state["frame_skip"] == 4 and state["args"]["frame_skip"] == 4  # Hopper's own


def test_frame_skip_1_trains_and_evaluates_at_that_rate(fs1_run):
    _, made, state = fs1_run
    stepped = [env for env in made if env.steps]
    assert len(stepped) >= 3  # the 2 training envs and the final evaluation's
    for env in stepped:  # 4x the steps of 0.002 s: the same 8 s of simulated time as 1000 native steps
        assert env.spec.max_episode_steps == 4000
        assert env.unwrapped.frame_skip == 1 and env.unwrapped.dt == pytest.approx(0.002)
    assert state["frame_skip"] == 1 and state["args"]["frame_skip"] == 1
    assert state["global_step"] == 1024


def test_eval_only_uses_the_recorded_frame_skip(fs1_run, capsys):
    # the final evaluation of training and --eval-only both use seeds 10000, ...: same rate, same return
    run_dir, _, state = fs1_run
    expert_ppo.eval_only(expert_ppo.Args(env="Hopper-v4", eval_only=True, checkpoint=str(run_dir / "latest.pt"), eval_episodes=1))
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("evaluating at frame skip 1 ")
    assert float(SUMMARY.match(lines[-1]).group(1)) == pytest.approx(state["eval_return"], abs=0.05)


def test_resume_at_another_frame_skip_is_refused(tiny_run, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run[0], run_dir)
    before = (run_dir / "latest.pt").read_bytes()
    result = run_in_process("expert_ppo.py", "--total-timesteps", 6144, *TINY, "--output-dir", run_dir, "--resume", "--frame-skip", 1)
    assert_usage_error(result, "was trained at frame skip 4, not 1")
    assert result.returncode == 2
    assert (run_dir / "latest.pt").read_bytes() == before


def test_retarget_ships_an_expert_for_another_version_of_its_env(tmp_path):
    """--retarget: a Hopper-v4 expert evaluated on Hopper-v5 (same shapes) and shipped for it, saying where it
    came from; another family or other shapes are refused in one line."""
    shipped = tmp_path / "Hopper-v5.pt"
    result = run_script("expert_ppo.py", "--env", "Hopper-v5", "--eval-only", "--retarget", "--eval-episodes", 1,
                        "--checkpoint", REPO_ROOT / "experts" / "Hopper-v4.pt", "--ship-to", shipped)
    assert result.returncode == 0, result.stderr
    checkpoint = torch.load(shipped, weights_only=True)
    assert (checkpoint["env_id"], checkpoint["retargeted_from"], checkpoint["eval_episodes"]) == ("Hopper-v5", "Hopper-v4", 1)
    assert checkpoint["eval_return"] > 3000
    expert_ppo.load_expert(str(shipped), "Hopper-v5")  # accepted for v5 now
    for env, checkpoint_env in (("Walker2d-v5", "Hopper-v4"), ("HalfCheetah-v5", "Ant-v4")):
        refused = run_in_process("expert_ppo.py", "--env", env, "--eval-only", "--retarget", "--checkpoint", REPO_ROOT / "experts" / f"{checkpoint_env}.pt")
        assert_usage_error(refused, f"is an expert for {checkpoint_env}, whose family or shapes are not {env}'s: train one for {env}")
    without = run_in_process("expert_ppo.py", "--env", "Hopper-v5", "--eval-only", "--checkpoint", REPO_ROOT / "experts" / "Hopper-v4.pt")
    assert_usage_error(without, "is an expert for Hopper-v4, not Hopper-v5")


def test_shipped_v5_experts_act_on_their_envs_observations():
    """Each v5 expert is accepted for its env and acts on that env's observation; Ant-v4's expert reads the 27
    leading entries of Ant-v5's 105 (positions and velocities; the contact forces come after)."""
    for family in ("Hopper", "Walker2d", "HalfCheetah", "Ant"):
        env = gym.make(f"{family}-v5")
        policy = expert_ppo.load_expert(str(REPO_ROOT / "experts" / f"{family}-v5.pt"), f"{family}-v5")
        obs = torch.as_tensor(env.reset(seed=0)[0], dtype=torch.float32)[None]
        assert policy(obs).shape == (1, env.action_space.shape[0])
        assert policy.net[0].in_features == (27 if family == "Ant" else obs.shape[1])
    obs = torch.randn(4, 105)
    changed = obs.clone()
    changed[:, 27:] += 5.0  # the contact forces do not move Ant's expert
    assert torch.equal(policy(obs), policy(changed)) and not torch.equal(policy(obs), policy(obs * 2))


# ----------------------------------------------------------------------------------------------
# --make-demos: the demonstrations the imitation files load


def make_demos_in(folder, capsys, **settings) -> str:
    """expert_ppo.make_demos run in `folder` (the shipped experts linked there) on Hopper-v4; returns what it printed."""
    with contextlib.chdir(folder):
        expert_ppo.make_demos(expert_ppo.Args(env="Hopper-v4", make_demos=True, **settings))
    return capsys.readouterr().out


@pytest.fixture
def demo_folder(tmp_path):
    return link_experts(tmp_path, demos=False)


def test_make_demos_writes_the_rollout_of_generate_demos_and_names_its_expert(demo_folder, capsys):
    out = make_demos_in(demo_folder, capsys, num_demo_samples=120)
    assert out.splitlines()[-1] == "wrote demos/Hopper-v4_120.npz"
    demos, meta = demo_file(demo_folder / "demos" / "Hopper-v4_120.npz")
    expected = expert_ppo.generate_demos("Hopper-v4", None, expert_ppo.load_expert(str(SHIPPED_EXPERT), "Hopper-v4"), 120)
    assert set(demos) == set(expected)
    for key, values in expected.items():  # seed 0, the same arrays (dtypes included)
        assert demos[key].dtype == values.dtype, key
        np.testing.assert_array_equal(demos[key], values, err_msg=key)
    assert len(demos["actions"]) == 120 and demos["truncations"][-1]  # the budget ends the last episode
    shipped = load(SHIPPED_EXPERT)
    assert meta == {"env_id": "Hopper-v4", "source": "experts/Hopper-v4.pt", "num_samples": 120, "seed": 0, "frame_skip": 4,
                    "expert_sha256": hashlib.sha256(SHIPPED_EXPERT.read_bytes()).hexdigest(),
                    "expert_return": shipped["eval_return"], "expert_frame_skip": 4}
    assert meta["expert_return"] > 3000 and not list((demo_folder / "demos").glob("*.tmp*"))


def test_make_demos_names_its_file_by_frame_skip_and_sample_count(demo_folder, capsys, monkeypatch):
    rollouts, generate = [], expert_ppo.generate_demos

    def short_rollout(env_id, frame_skip, expert, num_samples, seed=0):  # the name of a default-sized file, in a blink
        rollouts.append((env_id, frame_skip, num_samples))
        return generate(env_id, frame_skip, expert, 30, seed)

    monkeypatch.setattr(expert_ppo, "generate_demos", short_rollout)
    for settings, name in [({"frame_skip": 1, "num_demo_samples": 120}, "Hopper-v4_fs1_120.npz"),
                           ({"frame_skip": 4, "num_demo_samples": 120}, "Hopper-v4_120.npz"),  # the native rate: no _fs
                           ({}, "Hopper-v4_20000.npz")]:  # the paper's count for Hopper
        assert make_demos_in(demo_folder, capsys, **settings).splitlines()[-1] == f"wrote demos/{name}"
        assert demo_file(demo_folder / "demos" / name)[1]["frame_skip"] == settings.get("frame_skip", 4)
    assert rollouts == [("Hopper-v4", 1, 120), ("Hopper-v4", 4, 120), ("Hopper-v4", 4, 20000)]
    assert sorted(path.name for path in (demo_folder / "demos").iterdir()) == ["Hopper-v4_120.npz", "Hopper-v4_20000.npz",
                                                                                "Hopper-v4_fs1_120.npz"]


def test_make_demos_keeps_a_file_of_the_same_expert_and_remakes_one_of_another(demo_folder, capsys, monkeypatch):
    make_demos_in(demo_folder, capsys, num_demo_samples=120)
    path = demo_folder / "demos" / "Hopper-v4_120.npz"
    made, stamp = path.read_bytes(), path.stat().st_mtime_ns

    def no_rollout(*args, **kwargs):
        raise AssertionError("rolled the expert out again")

    with monkeypatch.context() as patch:
        patch.setattr(expert_ppo, "generate_demos", no_rollout)
        out = make_demos_in(demo_folder, capsys, num_demo_samples=120)
    assert out.strip() == "demos/Hopper-v4_120.npz: already made from experts/Hopper-v4.pt with these settings"
    assert path.read_bytes() == made and path.stat().st_mtime_ns == stamp  # kept, not rewritten
    # another expert file (here the shipped one, its recorded return changed): the file is made again from it
    other = load(SHIPPED_EXPERT)
    other["eval_return"] += 1.0
    torch.save(other, demo_folder / "other.pt")
    out = make_demos_in(demo_folder, capsys, num_demo_samples=120, checkpoint="other.pt")
    assert out.splitlines()[-1] == "wrote demos/Hopper-v4_120.npz"
    demos, meta = demo_file(path)
    assert meta["source"] == "other.pt" and meta["expert_sha256"] == hashlib.sha256((demo_folder / "other.pt").read_bytes()).hexdigest()
    assert meta["expert_return"] == other["eval_return"] and path.read_bytes() != made


@pytest.mark.parametrize("args, message", [
    (["--num-demo-samples", 1], "--num-demo-samples must be more than 1, got 1"),
    (["--num-demo-samples", -3], "--num-demo-samples must be more than 1, got -3"),
    (["--num-demo-samples", 0], "--num-demo-samples must be more than 1, got 0"),
    # Training writes runs/expert_ppo/..., not the default experts/<env>.pt: the message names where.
    (["--checkpoint", "missing.pt"], "expert checkpoint missing.pt not found: give its path "
                                     "(python expert_ppo.py --env Hopper-v4 writes runs/expert_ppo/Hopper-v4__1/best.pt)"),
    (["--checkpoint", "my{x}.pt"], "expert checkpoint my{x}.pt not found"),
    (["--env", "Walker2d-v4", "--checkpoint", SHIPPED_EXPERT], "is an expert for Hopper-v4, not Walker2d-v4"),
], ids=["one-sample", "negative-samples", "zero-samples", "missing-checkpoint", "braces-in-checkpoint", "other-env-checkpoint"])
def test_make_demos_refuses_bad_input_in_one_line(args, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = run_in_process("expert_ppo.py", "--make-demos", *args)
    assert_usage_error(result, message)
    assert result.returncode == 2 and not (tmp_path / "demos").exists()
