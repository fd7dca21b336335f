"""The shared setting of the copycat regime map (bc_oh.py holds the originals): the control rate
(--frame-skip), positions-only observations (--hide-velocities), the copy-error line, demo files per
rate (made by expert_ppo.py --make-demos, loaded by the method files); and C2F's output fusion (--fusion output)."""
import argparse
import json

import gymnasium as gym
import numpy as np
import pytest
import torch

import bc_oh
import c2f
import c2f_table3
from conftest import (assert_usage_error, check_summary, demo_file, fake_demos, link_experts, load_demos, make_demos, run_in_process,
                      run_script, tiny_args)

HOPPER_VELOCITIES = list(range(5, 11))
POSITIONS = list(range(0, 5))


# ----------------------------------------------------------------------------------------------
# --frame-skip


def step_once(env, action):
    env.reset(seed=3)
    start = env.unwrapped.data.time
    reward = env.step(action)[1]
    return reward, env.unwrapped.data.time - start


def test_frame_skip_one_keeps_simulated_time_and_return_scale():
    native, fast = bc_oh.make_env("Hopper-v4"), bc_oh.make_env("Hopper-v4", 1)
    assert (native.spec.max_episode_steps, native.unwrapped.frame_skip) == (1000, 4)
    assert (fast.spec.max_episode_steps, fast.unwrapped.frame_skip) == (4000, 1)  # 1000 x 4 / 1 steps: the same 8 s
    assert fast.unwrapped.dt == pytest.approx(0.002) and native.unwrapped.dt == pytest.approx(0.008)
    action = np.array([0.3, -0.2, 0.5])
    raw = gym.make("Hopper-v4")
    raw.unwrapped.frame_skip = 1  # the same simulator step, reward not rescaled
    (fast_reward, fast_time), (raw_reward, _) = step_once(fast, action), step_once(raw, action)
    assert fast_reward == pytest.approx(raw_reward / 4)  # every reward x frame_skip / native
    assert fast_time == pytest.approx(0.002) and step_once(native, action)[1] == pytest.approx(0.008)
    assert bc_oh.make_env("HalfCheetah-v4", 1).spec.max_episode_steps == 5000  # native 5
    # step by step: the plain env's states at frame skip 1, each reward a quarter of its (expert_ppo.make_env, which
    # makes the experts' demos, is a checked copy of bc_oh.make_env: test_check_copies)
    (obs, _), (raw_obs, _) = fast.reset(seed=3), raw.reset(seed=3)
    np.testing.assert_array_equal(obs, raw_obs)
    for action in np.random.default_rng(0).uniform(-1, 1, (5, 3)):
        obs, reward, *_ = fast.step(action)
        raw_obs, raw_reward, *_ = raw.step(action)
        np.testing.assert_array_equal(obs, raw_obs)
        assert reward == pytest.approx(raw_reward / 4, rel=1e-12)


def test_frame_skip_one_episode_return_matches_the_native_scale():
    """Holding each action for four fast steps replays the native episode: the returns agree."""
    actions = np.random.default_rng(0).uniform(-0.3, 0.3, (30, 3))
    native, fast = bc_oh.make_env("Hopper-v4"), bc_oh.make_env("Hopper-v4", 1)
    native.reset(seed=5), fast.reset(seed=5)
    native_return = sum(native.step(a)[1] for a in actions)
    fast_return = sum(fast.step(a)[1] for a in actions for _ in range(4))
    assert fast_return == pytest.approx(native_return, rel=1e-6)


def test_default_and_native_frame_skip_are_the_plain_env():
    for frame_skip in (None, 4):
        env = bc_oh.make_env("Hopper-v4", frame_skip)
        assert not isinstance(env, gym.wrappers.TransformReward) and env.spec.max_episode_steps == 1000


def test_frame_skip_needs_a_mujoco_env_and_a_positive_value(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(bc_oh.UsageError, match="not a MuJoCo env"):
        bc_oh.make_env("Pendulum-v1", 1)
    assert_usage_error(run_in_process("bc_oh.py", "--frame-skip", "0"), "--frame-skip must be positive")


# ----------------------------------------------------------------------------------------------
# --hide-velocities


def test_hidden_velocities_are_zero_in_the_demos_and_nothing_else_changes():
    observations = np.random.default_rng(0).normal(size=(100, 11))
    hidden = bc_oh.partially_observe(observations, HOPPER_VELOCITIES, 0.2, True, seed=1)
    assert (hidden[:, HOPPER_VELOCITIES] == 0).all()
    assert np.array_equal(hidden[:, POSITIONS], observations[:, POSITIONS])
    assert (observations[:, HOPPER_VELOCITIES] != 0).all(), "the clean demos are not modified"


def test_hidden_velocities_are_zero_at_evaluation_every_step(monkeypatch):
    """evaluate() feeds the policy histories whose velocity entries are zero in every frame, while the
    positions move: the env itself is untouched."""
    seen = []

    class Recorder(torch.nn.Module):
        def forward(self, inputs):
            seen.append(inputs.numpy().copy())
            return torch.full((len(inputs), 3), 0.1)

    args = tiny_args(bc_oh, hide_velocities=True, frame_skip=1)
    bc_oh.evaluate(Recorder(), args, episodes=2, seed=0, device=torch.device("cpu"))
    frames = np.concatenate(seen).reshape(-1, 2, 11)  # history 2, oldest first
    assert len(seen) > 10
    assert (frames[:, :, HOPPER_VELOCITIES] == 0).all()
    assert frames[:, :, POSITIONS].std(0).min() > 0


def test_hidden_velocities_train_on_zeroed_velocities(monkeypatch):
    """The normaliser saw zero velocities (mean 0) and real positions: train_seed hid them."""
    monkeypatch.setattr(bc_oh, "evaluate", lambda policy, args, episodes, seed, device: [0.0])
    demos = fake_demos()
    _, policy, _ = bc_oh.train_seed(tiny_args(bc_oh, hide_velocities=True), demos, 1, torch.device("cpu"))
    mean = policy.normalize.mean.reshape(2, 11)
    assert (mean[:, HOPPER_VELOCITIES] == 0).all() and (mean[:, POSITIONS] != 0).all()


# ----------------------------------------------------------------------------------------------
# The copy error of the demos


def test_the_copy_error_line_against_hand_computed_values(tmp_path, capsys):
    """Episodes 0, 1, 0, 1, ... and -1, 0, -1, 0, ...: within them each step changes by 1 (MSE 1) and Var(a) = 0.5, so
    the copy error is 2.000; the step across the episode boundary (1 to -1) does not count (with it, 2.154). A slow
    ramp, a step of 1/39 across [0, 1], is the shortcut: (1/39)^2 / Var = 12 / 1599 = 0.008."""
    def copy_error_line(actions):
        path = tmp_path / f"demos{len(list(tmp_path.iterdir()))}.npz"
        starts = np.arange(40) % 20 == 0
        np.savez(path, observations=np.zeros((40, 11)), actions=actions, episode_starts=starts)
        load_demos(bc_oh, demos=str(path))
        return next(line for line in capsys.readouterr().out.splitlines() if "copy error" in line)

    alternating = np.repeat((np.arange(40) % 2 - (np.arange(40) >= 20))[:, None], 3, axis=1).astype(np.float32)
    assert "copy error MSE(a_{t-1}, a_t)/Var(a) = 2.000 (0: copying" in copy_error_line(alternating)
    ramp = np.repeat((np.arange(40) / 39)[:, None], 3, axis=1).astype(np.float32)
    assert "copy error MSE(a_{t-1}, a_t)/Var(a) = 0.008 (0: copying" in copy_error_line(ramp)


# ----------------------------------------------------------------------------------------------
# Demo caches per rate


def reported_copy_error(out: str) -> float:
    line = next(line for line in out.splitlines() if line.startswith("demos: copy error"))
    return float(line.split("copy error MSE(a_{t-1}, a_t)/Var(a) = ")[1].split()[0])


def test_demos_per_rate_and_the_copy_error_line(tmp_path, monkeypatch, capsys):
    """The method file loads, at --frame-skip 1, the file --make-demos wrote at that rate, and says its copy error:
    smaller than at the native rate (the actions change less from one step to the next)."""
    monkeypatch.chdir(link_experts(tmp_path))
    fast, meta = load_demos(bc_oh, num_demo_samples=120, frame_skip=1)
    out = capsys.readouterr().out
    assert "demos: 120 steps from demos/Hopper-v4_fs1_120.npz\n" in out
    assert meta["frame_skip"] == 1 and meta == demo_file(make_demos("Hopper-v4", 120, 1))[1]
    native, meta = load_demos(bc_oh, num_demo_samples=120)
    native_out = capsys.readouterr().out
    assert meta["frame_skip"] == 4 and "demos: 120 steps from demos/Hopper-v4_120.npz\n" in native_out
    assert not np.array_equal(native["observations"], fast["observations"])
    assert 0 < reported_copy_error(out) < reported_copy_error(native_out)


def test_a_file_made_at_another_rate_is_not_reused(tmp_path, monkeypatch):
    """A file at the native name that holds demos recorded at frame skip 1: the method file refuses it, and
    expert_ppo.py --make-demos rolls the native demos out again instead of keeping it."""
    monkeypatch.chdir(link_experts(tmp_path, demos=False))
    made = run_in_process("expert_ppo.py", "--make-demos", "--frame-skip", 1, "--num-demo-samples", 120)
    assert made.returncode == 0 and made.stdout.splitlines()[-1] == "wrote demos/Hopper-v4_fs1_120.npz", made.stderr
    fast = demo_file("demos/Hopper-v4_fs1_120.npz")[0]["observations"]
    (tmp_path / "demos" / "Hopper-v4_fs1_120.npz").rename(tmp_path / "demos" / "Hopper-v4_120.npz")
    with pytest.raises(bc_oh.UsageError, match=r"^demos/Hopper-v4_120.npz was made at frame skip 1 \(the env's own if its meta has none\), not 4: pass --frame-skip 1$"):
        load_demos(bc_oh, num_demo_samples=120)
    again = run_in_process("expert_ppo.py", "--make-demos", "--num-demo-samples", 120)
    assert again.returncode == 0 and again.stdout.splitlines()[-1] == "wrote demos/Hopper-v4_120.npz", again.stderr
    native, meta = load_demos(bc_oh, num_demo_samples=120)
    assert meta["frame_skip"] == 4 and not np.array_equal(native["observations"], fast)


@pytest.mark.parametrize("flags, message", [
    (["--frame-skip", 0], "--frame-skip must be positive, got 0: e.g. 1, or leave it out for the env's own"),
    (["--frame-skip", -2], "--frame-skip must be positive, got -2: "),
    (["--env", "Pendulum-v1", "--frame-skip", 1], "env 'Pendulum-v1' is not a MuJoCo env: leave --frame-skip out"),
], ids=["zero", "negative", "not-mujoco"])
def test_make_demos_refuses_a_frame_skip_the_env_cannot_take(flags, message, tmp_path, monkeypatch):
    monkeypatch.chdir(link_experts(tmp_path, demos=False))
    result = run_in_process("expert_ppo.py", "--make-demos", "--num-demo-samples", 120, *flags)
    assert_usage_error(result, message)
    assert result.returncode == 2 and not (tmp_path / "demos").exists(), "refused before any rollout"


def test_demos_of_another_rate_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    link_experts(tmp_path)
    made = run_script("bc_oh.py", "--frame-skip", "1", "--num-demo-samples", 120, "--epochs", 1, "--eval-every", 1, "--eval-episodes", 1,
                      "--seeds", 1, "--output-dir", tmp_path / "out", cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    assert made.stdout.splitlines()[-1].startswith("Hopper-v4 bc_oh: "), made.stdout
    result = run_in_process("bc_oh.py", "--demos", tmp_path / "demos" / "Hopper-v4_fs1_120.npz", "--epochs", 1)
    assert_usage_error(result, "Hopper-v4_fs1_120.npz was made at frame skip 1 (the env's own if its meta has none), not 4: pass --frame-skip 1")
    summary = json.loads((tmp_path / "out" / "result_seeds1.json").read_text())
    assert (summary["args"]["frame_skip"], summary["args"]["hide_velocities"]) == (1, False)


# ----------------------------------------------------------------------------------------------
# C2F: output fusion


def c2f_policy(**options):
    """The model c2f_table3.py builds with these flags."""
    flags = {name: getattr(c2f_table3.Args(), name) for name in TABLE3_FLAGS}
    args = argparse.Namespace(history=2, hidden=32, **{**flags, **options})
    return c2f_table3.make_policy(args, 11, 3, torch.randn(50, 22))


TABLE3_FLAGS = ["fusion", "coarse_output", "coarse_input", "policy_input", "stop_gradient", "coarse_action", "two_stage"]


@pytest.mark.parametrize("stop_gradient", [True, False])
def test_output_fusion_stop_gradient(stop_gradient):
    policy = c2f_policy(fusion="output", stop_gradient=stop_gradient)
    action = policy.coarse_and_final(torch.randn(7, 22))[1]
    action.pow(2).mean().backward()  # the final loss alone
    coarse_gradient = sum(p.grad.abs().sum() for p in policy.coarse.parameters() if p.grad is not None)
    assert (coarse_gradient == 0) == stop_gradient
    assert policy.head.weight.grad.abs().sum() > 0 and policy.policy_first[0].weight.grad.abs().sum() > 0


def test_late_fusion_default_is_unchanged():
    """The default (late) policy MLP keeps its hidden feature: head sees hidden + action dims."""
    policy = c2f_policy()
    assert policy.head.in_features == 32 + 3 and isinstance(policy.policy_rest[-1], torch.nn.ReLU)


def test_hidden_velocities_touch_only_the_policys_view(tmp_path, monkeypatch):
    """The demo file and the expert keep the velocities: --hide-velocities hides them from the policy only."""
    monkeypatch.chdir(link_experts(tmp_path))
    demos, _ = load_demos(bc_oh, num_demo_samples=120, hide_velocities=True)
    assert (demos["observations"][:, HOPPER_VELOCITIES] != 0).mean() > 0.9
    assert np.array_equal(demo_file(make_demos("Hopper-v4", 120))[0]["observations"], demos["observations"])


@pytest.mark.parametrize("env", ["Hopper-v5", "Ant-v5"])
def test_a_method_file_runs_on_v5_envs_with_the_shipped_experts(tmp_path, env):
    """v5: demos from the shipped (re-targeted) expert, noise on the velocities that observation_structure names
    (Ant-v5: 13-26 of 105), on the demos and in the sensor the evaluation reads, through c2f.py's own functions, and a
    tiny training run of c2f.py that ends with the summary line."""
    link_experts(tmp_path)
    demos, meta = demo_file(make_demos(env, 200))  # linked as tmp_path/demos/{env}_200.npz
    assert meta["source"] == f"experts/{env}.pt"
    result = run_script("c2f.py", "--env", env, "--seeds", 1, "--epochs", 1, "--eval-every", 1, "--eval-episodes", 1,
                        "--num-demo-samples", 200, "--output-dir", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    check_summary(result.stdout, tmp_path, tmp_path / "out", "c2f", expert=meta["expert_return"], env=env)
    plain = gym.make(env)
    structure = plain.unwrapped.observation_structure
    velocities = list(range(structure["qpos"], structure["qpos"] + structure["qvel"]))
    assert velocities == (list(range(13, 27)) if env == "Ant-v5" else HOPPER_VELOCITIES)
    assert demos["observations"].shape[1] == plain.observation_space.shape[0]
    # training: the noise train_seed draws on the demos changes those entries, all of them, and no other
    dims = c2f.velocity_dims(c2f.make_env(env), env)
    noisy = c2f.partially_observe(demos["observations"], dims, 0.2, False, seed=1)
    assert np.flatnonzero((noisy != demos["observations"]).any(axis=0)).tolist() == velocities
    assert np.array_equal(np.delete(noisy, velocities, axis=1), np.delete(demos["observations"], velocities, axis=1))
    # evaluation: the sensor env observes the plain env's state with noise on those entries only
    sensor = c2f.make_sensor_env(c2f.Args(env=env), seed=1)
    observed, true = sensor.reset(seed=3)[0], plain.reset(seed=3)[0]
    for action in [None, *np.random.default_rng(0).uniform(-0.5, 0.5, (3, plain.action_space.shape[0]))]:
        if action is not None:
            observed, true = sensor.step(action)[0], plain.step(action)[0]
        assert np.flatnonzero(observed != true).tolist() == velocities


def test_a_demo_file_without_a_rate_counts_as_native_and_is_refused_at_another(tmp_path, monkeypatch):
    """A user's demo file with no meta (no frame_skip record) is native: at --frame-skip 1 it is refused in one line."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    path = tmp_path / "user.npz"
    np.savez(path, observations=rng.normal(size=(200, 11)), actions=rng.uniform(-1, 1, (200, 3)).astype(np.float32),
             episode_starts=np.arange(200) % 50 == 0)
    assert_usage_error(run_in_process("bc_oh.py", "--demos", path, "--frame-skip", 1, "--epochs", 1),
                       "user.npz was made at frame skip 4 (the env's own if its meta has none), not 1: pass --frame-skip 4")
