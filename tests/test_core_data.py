"""The data pipeline every method shares (bc_oh.py holds the originals; check_copies keeps the copies equal):
noise on the velocities, history stacking in training and evaluation, the demos expert_ppo.py generates (--make-demos,
remade when its expert changes) and the method files load. Bad input is tested through the command line in
test_core_scripts.py and test_trust.py."""
import hashlib
import json
import os
import shutil

import gymnasium as gym
import numpy as np
import pytest
import torch

import bc_oh
import expert_ppo
from conftest import REPO_ROOT, demo_file, link_experts, load_demos, make_demos, run_in_process, tiny_args

HOPPER_VELOCITIES = list(range(5, 11))
POSITIONS = list(range(0, 5))


# ----------------------------------------------------------------------------------------------
# Noise


def test_demo_noise_touches_only_the_velocity_entries():
    observations = np.random.default_rng(0).normal(size=(100, 11))
    noisy = bc_oh.partially_observe(observations, HOPPER_VELOCITIES, 0.2, False, seed=1)
    assert np.array_equal(noisy[:, POSITIONS], observations[:, POSITIONS])
    difference = noisy[:, HOPPER_VELOCITIES] - observations[:, HOPPER_VELOCITIES]
    assert (difference != 0).all()
    assert difference.std() == pytest.approx(0.2, rel=0.1)
    assert np.array_equal(bc_oh.partially_observe(observations, HOPPER_VELOCITIES, 0.2, False, seed=1), noisy), "not seeded"
    assert not np.array_equal(bc_oh.partially_observe(observations, HOPPER_VELOCITIES, 0.2, False, seed=2), noisy)
    assert np.array_equal(bc_oh.partially_observe(observations, HOPPER_VELOCITIES, 0.0, False, seed=1), observations)
    assert (observations != noisy).any(), "the input array must not be modified in place"


def rollout(env, steps=20):
    """Observations of a fixed action sequence from reset(seed=3)."""
    observations = [env.reset(seed=3)[0]]
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 3))
    for action in actions:
        observations.append(env.step(action)[0])
    env.close()
    return np.array(observations)


def test_evaluation_noise_touches_only_the_velocity_entries_every_step():
    clean = rollout(gym.make("Hopper-v4"))
    noisy = rollout(bc_oh.PartialObservation(gym.make("Hopper-v4"), HOPPER_VELOCITIES, 0.5, False, seed=0))
    assert np.array_equal(noisy[:, POSITIONS], clean[:, POSITIONS]), "noise must not change the dynamics or positions"
    assert (noisy[:, HOPPER_VELOCITIES] != clean[:, HOPPER_VELOCITIES]).all(), "fresh noise on every velocity, every step"
    assert np.array_equal(rollout(bc_oh.PartialObservation(gym.make("Hopper-v4"), HOPPER_VELOCITIES, 0.0, False, seed=0)), clean)


def test_velocity_entries_of_v4_and_v5_envs():
    assert bc_oh.velocity_dims(gym.make("Hopper-v4"), "Hopper-v4") == HOPPER_VELOCITIES
    assert bc_oh.velocity_dims(gym.make("Hopper-v5"), "Hopper-v5") == HOPPER_VELOCITIES  # observation_structure
    assert bc_oh.velocity_dims(gym.make("Ant-v4"), "Ant-v4") == list(range(13, 27))
    with pytest.raises(bc_oh.UsageError, match="the velocity entries of Pendulum-v1 are unknown"):
        bc_oh.velocity_dims(gym.make("Pendulum-v1"), "Pendulum-v1")
    # A MuJoCo v4 env outside the table is told which envs are known, not to use a MuJoCo v4 env.
    known = "unknown: use Hopper, Walker2d, HalfCheetah or Ant, or a v5 env with observation_structure"
    with pytest.raises(bc_oh.UsageError, match=f"the velocity entries of Swimmer-v4 are {known}$"):
        bc_oh.velocity_dims(gym.make("Swimmer-v4"), "Swimmer-v4")


# ----------------------------------------------------------------------------------------------
# History


def test_stack_history_repeats_the_first_frame_of_each_episode():
    observations = np.arange(6, dtype=float)[:, None] * [1.0, 10.0]  # o_t = (t, 10 t)
    starts = np.array([True, False, False, True, False, False])
    rows = bc_oh.stack_history(observations, starts, 3)
    frames = rows.reshape(6, 3, 2)[:, :, 0]  # the t of each frame, oldest first
    assert frames.tolist() == [[0, 0, 0], [0, 0, 1], [0, 1, 2], [3, 3, 3], [3, 3, 4], [3, 4, 5]]
    assert np.array_equal(rows[:, -2:], observations), "the last frame is o_t"
    assert np.array_equal(bc_oh.stack_history(observations, starts, 1), observations)


def test_evaluation_feeds_the_policy_the_history_of_stack_history():
    """The inputs evaluate() gives the policy over one episode are stack_history of that episode's observations."""
    seen = []

    def policy(inputs):
        seen.append(inputs.numpy()[0].copy())
        return torch.as_tensor(np.random.default_rng(len(seen)).uniform(-1, 1, (len(inputs), 3)))

    bc_oh.evaluate(policy, tiny_args(bc_oh, history=3), 1, 5, torch.device("cpu"))
    inputs = np.array(seen)  # (steps, 3 * 11), the loop ends with the episode
    assert len(inputs) > 3
    starts = np.zeros(len(inputs), bool)
    starts[0] = True
    observations = inputs[:, -11:]  # the current frame o_t of each step
    assert np.array_equal(inputs, bc_oh.stack_history(observations, starts, 3))
    assert np.array_equal(inputs[0], np.tile(observations[0], 3)), "an episode starts with its first frame repeated"
    assert len({row.tobytes() for row in observations}) == len(inputs), "a new frame every step"


@pytest.mark.parametrize("hide", [False, True])
def test_an_evaluation_makes_one_env_an_episode_and_each_reads_its_own_velocities(monkeypatch, hide):
    """Issue 56: evaluate() makes the envs it plays and no other (it once made one more, only to read the velocity
    layout); each sensor env finds Hopper's velocities itself: hidden, they are zeros in the policy's inputs."""
    made = []
    make_env = bc_oh.make_env

    def counting_make_env(*args, **kwargs):
        made.append(args)
        return make_env(*args, **kwargs)

    seen = []

    def policy(inputs):
        seen.append(inputs.numpy().copy())
        return torch.zeros(len(inputs), 3)

    monkeypatch.setattr(bc_oh, "make_env", counting_make_env)
    bc_oh.evaluate(policy, tiny_args(bc_oh, history=1, hide_velocities=hide, frame_skip=4), 3, 5, torch.device("cpu"))
    assert len(made) == 3
    velocities = np.concatenate(seen)[:, 5:11]
    assert (velocities == 0).all() == hide


# ----------------------------------------------------------------------------------------------
# Demonstrations


def hopper_expert():
    return expert_ppo.load_expert(str(REPO_ROOT / "experts" / "Hopper-v4.pt"), "Hopper-v4")


def test_demo_generation_is_deterministic():
    first = expert_ppo.generate_demos("Hopper-v4", None, hopper_expert(), 150)
    second = expert_ppo.generate_demos("Hopper-v4", None, hopper_expert(), 150)
    for key in ("observations", "actions", "episode_starts"):
        assert np.array_equal(first[key], second[key]), key
    assert first["observations"].shape == (150, 11) and first["actions"].shape == (150, 3)
    assert first["episode_starts"][0] and np.abs(first["actions"]).max() <= 1.0


def test_the_made_demo_file_loads_as_it_was_written(tmp_path, monkeypatch):
    """load_demos finds the file `expert_ppo.py --make-demos` wrote under the name it looks for, and returns its arrays
    and meta unchanged; the same file through --demos loads the same."""
    arrays, meta = demo_file(make_demos("Hopper-v4", 120))
    monkeypatch.chdir(link_experts(tmp_path))
    demos, loaded_meta = load_demos(bc_oh, num_demo_samples=120)
    for key in ("observations", "actions", "episode_starts"):
        assert demos[key].dtype == arrays[key].dtype and np.array_equal(demos[key], arrays[key]), key
    assert loaded_meta == meta and meta["env_id"] == "Hopper-v4" and meta["num_samples"] == 120
    again, _ = load_demos(bc_oh, demos=str(make_demos("Hopper-v4", 120)))
    assert all(np.array_equal(again[key], demos[key]) for key in demos)


def make_demos_here(*flags):
    """`python expert_ppo.py --make-demos --num-demo-samples 120 --checkpoint expert.pt FLAGS` in this process; returns
    its last line of output."""
    result = run_in_process("expert_ppo.py", "--make-demos", "--num-demo-samples", 120, "--checkpoint", "expert.pt", *flags)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    return result.stdout.splitlines()[-1]


def test_demos_follow_their_expert(tmp_path, monkeypatch):
    """expert_ppo.py --make-demos keeps a file rolled out by the same expert file, and rolls out again for an expert
    retrained at the same path (the meta holds the expert's SHA-256, not only its path); the method files need no
    expert at all to load the file."""
    monkeypatch.chdir(tmp_path)
    shutil.copy(REPO_ROOT / "experts" / "Hopper-v4.pt", tmp_path / "expert.pt")
    path = tmp_path / "demos" / "Hopper-v4_120.npz"
    assert make_demos_here() == "wrote demos/Hopper-v4_120.npz"
    first, meta = demo_file(path)
    assert meta["expert_sha256"] == hashlib.sha256((tmp_path / "expert.pt").read_bytes()).hexdigest()
    stamp = path.stat().st_mtime_ns
    assert make_demos_here() == "demos/Hopper-v4_120.npz: already made from expert.pt with these settings"
    assert path.stat().st_mtime_ns == stamp, "kept, not rewritten"

    checkpoint = torch.load("expert.pt", weights_only=True)  # "retrain" it: other weights, same path
    checkpoint["actor"] = {key: value + 0.05 for key, value in checkpoint["actor"].items()}
    torch.save(checkpoint, "expert.pt")
    assert make_demos_here() == "wrote demos/Hopper-v4_120.npz"
    retrained, meta = demo_file(path)
    assert meta["expert_sha256"] == hashlib.sha256((tmp_path / "expert.pt").read_bytes()).hexdigest()
    assert not np.array_equal(retrained["actions"], first["actions"]), "the old expert's demos were kept"

    np.savez(path, **{**retrained, "meta": np.array("[1, 2]")})  # a meta not of our format: rolled out again
    assert make_demos_here() == "wrote demos/Hopper-v4_120.npz"
    assert demo_file(path)[1]["expert_sha256"] == meta["expert_sha256"]

    os.remove("expert.pt")  # demos copied without their expert: loaded as they are
    assert np.array_equal(load_demos(bc_oh, num_demo_samples=120)[0]["actions"], retrained["actions"])


def test_mujoco_deprecation_warning_of_halfcheetah_is_dropped_and_others_kept(tmp_path, monkeypatch, capfd):
    """Importing a script installs MuJoCo's warning hook: making HalfCheetah prints nothing and leaves no
    MUJOCO_LOG.TXT (without the hook MuJoCo writes both), while any other MuJoCo warning is printed."""
    import mujoco

    monkeypatch.chdir(tmp_path)
    capfd.readouterr()
    gym.make("HalfCheetah-v4").close()
    assert "settotalmass" not in "".join(capfd.readouterr()) and not (tmp_path / "MUJOCO_LOG.TXT").exists()
    mujoco.get_mju_user_warning()("something else")
    assert capfd.readouterr().err == "MuJoCo warning: something else\n"


# ----------------------------------------------------------------------------------------------
# Demo files a user's own converter may produce


def user_demo_file(tmp_path, drop=None, **arrays):
    """A Hopper-shaped demo file of 200 steps, with `arrays` replacing (or `drop` removing) entries."""
    rng = np.random.default_rng(0)
    content = {"observations": rng.normal(size=(200, 11)), "actions": rng.uniform(-1, 1, (200, 3)).astype(np.float32),
               "episode_starts": np.arange(200) % 50 == 0, **arrays}
    content.pop(drop, None)
    path = tmp_path / "user.npz"
    np.savez(path, **content)
    return str(path)


def load_user_demos(path):
    return load_demos(bc_oh, demos=path)[0]


def test_demos_of_any_real_dtype_are_converted(tmp_path):
    integer = np.arange(200 * 11).reshape(200, 11) % 7
    demos = load_user_demos(user_demo_file(tmp_path, observations=integer, actions=np.zeros((200, 3), np.int32),
                                           episode_starts=(np.arange(200) % 50 == 0).astype(np.int8)))
    assert demos["observations"].dtype == np.float64 and demos["actions"].dtype == np.float32 and demos["episode_starts"].dtype == bool
    assert np.array_equal(demos["observations"], integer) and demos["episode_starts"].sum() == 4
    noisy = bc_oh.partially_observe(demos["observations"], HOPPER_VELOCITIES, 0.2, False, seed=1)  # no casting error
    assert noisy.dtype == np.float64


@pytest.mark.parametrize("key, row, column, value", [("observations", 17, 4, np.nan), ("actions", 150, 2, np.nan),
                                                     ("observations", 30, 0, 1e39), ("observations", 31, 1, -np.inf)])
def test_a_non_finite_demo_value_is_refused_with_its_row(tmp_path, key, row, column, value):
    """1e39 is finite in the file's float64 but not in the float32 that training reads (it would train on inf)."""
    rng = np.random.default_rng(0)
    values = rng.uniform(-1, 1, size=(200, 11 if key == "observations" else 3))  # within the action bounds
    values[row, column] = value
    with pytest.raises(bc_oh.UsageError, match=rf"user.npz: {key} hold non-finite values at rows \[{row}\]: fix them$"):
        load_user_demos(user_demo_file(tmp_path, **{key: values}))


def test_a_missing_demo_array_is_named(tmp_path):
    with pytest.raises(bc_oh.UsageError, match=r"user.npz has no 'episode_starts' array: see the format in docs/methods.md$"):
        load_user_demos(user_demo_file(tmp_path, drop="episode_starts"))


def test_demos_of_text_are_refused(tmp_path):
    """Text does not convert to numbers: the conversion's error is refused in one line."""
    with pytest.raises(bc_oh.UsageError, match=r"user.npz is not a readable demo file \(ValueError\): see the format in docs/methods.md$"):
        load_user_demos(user_demo_file(tmp_path, actions=np.full((200, 3), "a")))


# Not a JSON object, or an expert's return that is not a number: the share of the expert's return is
# printed after training, so a text there raised at the very end.
@pytest.mark.parametrize("meta", ["[1, 2]", '"Hopper-v4"', '{"env_id": "Hopper-v4", "expert_return": "3000"}'])
def test_a_meta_of_the_wrong_kind_is_refused_before_training(tmp_path, meta):
    with pytest.raises(bc_oh.UsageError, match=r"user.npz: its meta does not follow docs/methods.md: fix or remove it$"):
        load_user_demos(user_demo_file(tmp_path, meta=np.array(meta)))


@pytest.mark.parametrize("expert_return", [3000, 3000.5, None])  # null: demos made elsewhere, no expert known
def test_a_meta_with_a_numeric_or_null_expert_return_loads(tmp_path, expert_return):
    text = json.dumps({"expert_return": expert_return})
    meta = load_demos(bc_oh, demos=user_demo_file(tmp_path, meta=np.array(text)))[1]
    assert meta == {"expert_return": expert_return}


def test_demos_record_what_a_dataset_format_needs():
    """Rewards, terminations and truncations per step, and each episode's final observation: an episode
    ends exactly where the next starts, and the budget truncates the last one."""
    demos = expert_ppo.generate_demos("Hopper-v4", None, hopper_expert(), 1200)
    ends = demos["terminations"] | demos["truncations"]
    assert np.array_equal(ends[:-1], demos["episode_starts"][1:]) and ends[-1] and demos["truncations"][-1]
    assert len(demos["final_observations"]) == ends.sum() == demos["episode_starts"].sum()
    env = gym.make("Hopper-v4")  # the first step's reward, replayed
    env.reset(seed=0)
    assert demos["rewards"][0] == env.step(demos["actions"][0])[1]
    assert demos["rewards"].dtype == np.float64 and demos["final_observations"].shape[1] == 11
