"""scripts/minari_demos.py: Minari datasets <-> demo .npz files, exactly, and its refusals (skipped without minari)."""
import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

minari = pytest.importorskip("minari")
import gymnasium as gym  # noqa: E402

from conftest import assert_usage_error, demo_file, make_demos, run_script, tiny_args  # noqa: E402

KEYS = ("observations", "actions", "episode_starts", "rewards", "terminations", "truncations", "final_observations")


@pytest.fixture(autouse=True)
def minari_store(tmp_path, monkeypatch):
    """A private local Minari store: the script's subprocesses inherit MINARI_DATASETS_PATH."""
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path / "minari"


def rollout(episodes=4, max_steps=30, seed=0):
    """Seeded random-action Hopper-v4 episodes, cut (truncated) at max_steps: per episode T+1 observations."""
    env = gym.make("Hopper-v4")
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    result = []
    for _ in range(episodes):
        episode = {"observations": [obs], "actions": [], "rewards": [], "terminations": [], "truncations": []}
        while True:
            action = env.action_space.sample()
            obs, reward, terminated, truncated, _ = env.step(action)
            truncated = truncated or len(episode["actions"]) == max_steps - 1
            for key, value in zip(("observations", "actions", "rewards", "terminations", "truncations"), (obs, action, reward, terminated, truncated)):
                episode[key].append(value)
            if terminated or truncated:
                break
        result.append({key: np.array(value) for key, value in episode.items()})
        obs, _ = env.reset()
    env.close()
    assert any(e["terminations"][-1] for e in result) and any(e["truncations"][-1] for e in result)
    return result


def make_dataset(dataset_id, episodes, env="Hopper-v4", **spaces):
    buffers = [minari.data_collector.EpisodeBuffer(id=i, **episode) for i, episode in enumerate(episodes)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return minari.create_dataset_from_buffers(dataset_id, buffers, env=env, data_format="hdf5", **spaces)


def as_demos(episodes):
    """The episodes in the .npz layout (what expert_ppo.generate_demos returns)."""
    return {"observations": np.concatenate([e["observations"][:-1] for e in episodes]).astype(np.float64),
            "actions": np.concatenate([e["actions"] for e in episodes]).astype(np.float32),
            "episode_starts": np.concatenate([np.arange(len(e["actions"])) == 0 for e in episodes]),
            "rewards": np.concatenate([e["rewards"] for e in episodes]).astype(np.float64),
            "terminations": np.concatenate([e["terminations"] for e in episodes]).astype(bool),
            "truncations": np.concatenate([e["truncations"] for e in episodes]).astype(bool),
            "final_observations": np.array([e["observations"][-1] for e in episodes], np.float64)}


def assert_same_demos(got, expected):
    for key in KEYS:
        assert got[key].dtype == expected[key].dtype, key
        np.testing.assert_array_equal(got[key], expected[key], err_msg=key)


def assert_same_dataset(dataset, episodes):
    assert dataset.total_episodes == len(episodes)
    for got, expected in zip(dataset.iterate_episodes(), episodes):
        for key in ("observations", "actions", "rewards", "terminations", "truncations"):
            np.testing.assert_array_equal(getattr(got, key), expected[key], err_msg=key)


def test_dataset_to_npz_to_dataset(tmp_path, minari_store):
    episodes = rollout()
    make_dataset("test/hopper/random-v0", episodes)
    result = run_script("scripts/minari_demos.py", "import", "test/hopper/random-v0", tmp_path / "demos.npz")
    assert result.returncode == 0, result.stderr
    demos, meta = demo_file(tmp_path / "demos.npz")
    assert_same_demos(demos, as_demos(episodes))
    assert meta["env_id"] == "Hopper-v4" and meta["source"] == "minari:test/hopper/random-v0"
    assert meta["num_samples"] == sum(len(e["actions"]) for e in episodes) and meta["frame_skip"] == 4

    result = run_script("scripts/minari_demos.py", "export", tmp_path / "demos.npz", "test/hopper/again-v0")
    assert result.returncode == 0, result.stderr
    assert_same_dataset(minari.load_dataset("test/hopper/again-v0"), episodes)
    # a dataset folder works as well as an id
    result = run_script("scripts/minari_demos.py", "import", minari_store / "test/hopper/again-v0", tmp_path / "again.npz")
    assert result.returncode == 0, result.stderr
    assert_same_demos(demo_file(tmp_path / "again.npz")[0], as_demos(episodes))


def test_npz_to_dataset_to_npz(tmp_path):
    episodes = rollout(seed=1)
    demos = as_demos(episodes)
    meta = {"env_id": "Hopper-v4", "source": "test", "num_samples": len(demos["actions"]), "seed": 1, "frame_skip": 4}
    np.savez(tmp_path / "demos.npz", meta=np.array(json.dumps(meta)), **demos)
    result = run_script("scripts/minari_demos.py", "export", tmp_path / "demos.npz", "copycat/hopper/test-v0")
    assert result.returncode == 0, result.stderr
    dataset = minari.load_dataset("copycat/hopper/test-v0")
    assert dataset.env_spec.id == "Hopper-v4"
    assert_same_dataset(dataset, episodes)
    result = run_script("scripts/minari_demos.py", "import", "copycat/hopper/test-v0", tmp_path / "back.npz")
    assert result.returncode == 0, result.stderr
    assert_same_demos(demo_file(tmp_path / "back.npz")[0], demos)


def test_num_samples_cuts_the_last_episode(tmp_path):
    episodes = rollout()
    make_dataset("test/hopper/random-v0", episodes)
    n = len(episodes[0]["actions"]) + 5  # five steps into the second episode
    result = run_script("scripts/minari_demos.py", "import", "test/hopper/random-v0", tmp_path / "cut.npz", "--num-samples", n)
    assert result.returncode == 0, result.stderr
    (demos, meta), full = demo_file(tmp_path / "cut.npz"), as_demos(episodes)
    for key in ("observations", "actions", "episode_starts", "rewards", "terminations"):
        np.testing.assert_array_equal(demos[key], full[key][:n], err_msg=key)
    np.testing.assert_array_equal(demos["truncations"], np.r_[full["truncations"][:n - 1], True])
    np.testing.assert_array_equal(demos["final_observations"], [full["final_observations"][0], episodes[1]["observations"][5]])
    assert meta["num_samples"] == n
    result = run_script("scripts/minari_demos.py", "import", "test/hopper/random-v0", tmp_path / "cut.npz", "--num-samples", 10**6)
    refused(result, "--num-samples")


def test_imported_demos_load_in_bc_oh(tmp_path):
    import bc_oh

    episodes = rollout()
    make_dataset("test/hopper/random-v0", episodes)
    assert run_script("scripts/minari_demos.py", "import", "test/hopper/random-v0", tmp_path / "demos.npz").returncode == 0
    args = tiny_args(bc_oh, demos=str(tmp_path / "demos.npz"), frame_skip=4)  # as run() resolves it: Hopper's own rate
    demos, meta = bc_oh.load_demos(args, bc_oh.make_env("Hopper-v4"))
    for key in ("observations", "actions", "episode_starts"):
        np.testing.assert_array_equal(demos[key], as_demos(episodes)[key], err_msg=key)
    assert meta["source"] == "minari:test/hopper/random-v0" and meta["frame_skip"] == 4


def test_a_make_demos_file_goes_to_minari_and_back_unchanged(tmp_path):
    """The demos the method files load (expert_ppo.py --make-demos, i.e. expert_ppo.generate_demos) export and
    import back with the same arrays."""
    made = make_demos("Hopper-v4", 120)
    result = run_script("scripts/minari_demos.py", "export", made, "copycat/hopper/made-v0")
    assert result.returncode == 0, result.stderr
    result = run_script("scripts/minari_demos.py", "import", "copycat/hopper/made-v0", tmp_path / "back.npz")
    assert result.returncode == 0, result.stderr
    assert_same_demos(demo_file(tmp_path / "back.npz")[0], demo_file(made)[0])


def refused(result, expected):
    """Exit status 2 and one stderr line holding `expected`, no traceback."""
    assert_usage_error(result, expected)
    assert result.returncode == 2, result.stderr


def random_episodes(obs_space, act_dim, steps=20, episodes=2):
    rng = np.random.default_rng(0)
    return [{"observations": rng.normal(size=(steps + 1, *obs_space.shape)), "actions": rng.uniform(-1, 1, (steps, act_dim)).astype(np.float32),
             "rewards": rng.normal(size=steps), "terminations": np.zeros(steps, bool), "truncations": np.arange(steps) == steps - 1}
            for _ in range(episodes)]


def test_refusals(tmp_path):
    make_dataset("test/pendulum-v0", random_episodes(gym.spaces.Box(-np.inf, np.inf, (4,)), 1), env="InvertedPendulum-v4")
    refused(run_script("scripts/minari_demos.py", "import", "test/pendulum-v0", tmp_path / "x.npz"), "not a MuJoCo env the method files know")
    wide = gym.spaces.Box(-np.inf, np.inf, (12,), np.float64)
    make_dataset("test/wide-v0", random_episodes(wide, 3), observation_space=wide)
    refused(run_script("scripts/minari_demos.py", "import", "test/wide-v0", tmp_path / "x.npz"), "width 12")
    space = gym.spaces.Dict({"state": gym.spaces.Box(-np.inf, np.inf, (11,), np.float64)})
    episodes = [{**e, "observations": {"state": e["observations"]}} for e in random_episodes(space["state"], 3)]
    make_dataset("test/dict-v0", episodes, observation_space=space)
    refused(run_script("scripts/minari_demos.py", "import", "test/dict-v0", tmp_path / "x.npz"), "Dict")
    refused(run_script("scripts/minari_demos.py", "import", "test/missing-v0", tmp_path / "x.npz"), "minari download")
    # np.savez added .npz to the temporary name, which the check then did not find, and the file stayed behind.
    refused(run_script("scripts/minari_demos.py", "import", "test/pendulum-v0", tmp_path / "demos"), "demos must end in .npz")
    assert not list(tmp_path.glob("demos*"))
    assert not (tmp_path / "x.npz").exists()

    hopper_episodes = random_episodes(gym.spaces.Box(-1, 1, (11,)), 3)
    demos = as_demos(hopper_episodes)
    old = {key: demos[key] for key in ("observations", "actions", "episode_starts")}  # made before rewards were kept
    np.savez(tmp_path / "old.npz", meta=np.array(json.dumps({"env_id": "Hopper-v4", "frame_skip": 4})), **old)
    result = run_script("scripts/minari_demos.py", "export", tmp_path / "old.npz", "test/old-v0")
    refused(result, "make it again with `python expert_ppo.py --env <env> --make-demos`")
    np.savez(tmp_path / "fs1.npz", meta=np.array(json.dumps({"env_id": "Hopper-v4", "frame_skip": 1})), **demos)
    refused(run_script("scripts/minari_demos.py", "export", tmp_path / "fs1.npz", "test/fs1-v0"), "frame skip 1")
    np.savez(tmp_path / "list.npz", meta=np.array("[1, 2]"), **demos)  # raised an AttributeError on meta.get
    refused(run_script("scripts/minari_demos.py", "export", tmp_path / "list.npz", "test/list-v0"), "list.npz: its meta is not a JSON object")
    np.savez(tmp_path / "new.npz", **demos)
    refused(run_script("scripts/minari_demos.py", "export", tmp_path / "new.npz", "test/new-v0"), "pass --env")
    refused(run_script("scripts/minari_demos.py", "export", tmp_path / "new.npz", "test/new-v0", "--env", "Walker2d-v4"), "width 11")
    refused(run_script("scripts/minari_demos.py", "export", tmp_path / "new.npz", "no version"), "not a Minari dataset id")
    refused(run_script("scripts/minari_demos.py", "export", tmp_path / "new.npz", "test/pendulum-v0", "--env", "Hopper-v4"), "already exists")
    refused(run_script("scripts/minari_demos.py", "frobnicate"), "invalid choice")
    result = run_script("scripts/minari_demos.py", "export", tmp_path / "new.npz", "test/new-v0", "--env", "Hopper-v4")
    assert result.returncode == 0, result.stderr  # the same file with its env named is fine: its episodes, on that env
    dataset = minari.load_dataset("test/new-v0")
    assert dataset.env_spec.id == "Hopper-v4"
    assert_same_dataset(dataset, hopper_episodes)


def test_the_import_goes_through_the_method_files_loader(tmp_path, monkeypatch, capsys):
    """What bc_oh's loader refuses, the import refuses too (one line, exit 2) and writes no file."""
    import bc_oh
    import minari_demos

    make_dataset("test/hopper/random-v0", rollout())
    seen = []

    def refusing_loader(args, env):
        seen.append((args.demos, args.env, args.frame_skip))
        raise bc_oh.UsageError(f"{args.demos}: planted refusal")

    monkeypatch.setattr(bc_oh, "load_demos", refusing_loader)
    with pytest.raises(SystemExit) as stop:
        minari_demos.run_cli(lambda: minari_demos.main(["import", "test/hopper/random-v0", str(tmp_path / "x.npz")]))
    # The refusal names the demo file asked for: it named the temporary file, which is gone.
    refusal = f"the method files would refuse this import ({tmp_path / 'x.npz'}: planted refusal)"
    assert stop.value.code == 2 and refusal in capsys.readouterr().err
    assert seen and seen[0][1:] == ("Hopper-v4", 4) and not list(tmp_path.glob("x.npz*")), "no output, no temporary file"


def refused_in_process(*args, message):
    """minari_demos.py run in this process: exactly `error: message` on stderr, exit status 2."""
    from conftest import run_in_process

    result = run_in_process("scripts/minari_demos.py", *args)
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n"), result.stderr
    return result


def deny_writing(monkeypatch, folder):
    """Play a read-only folder (chmod does not stop root): os.access, which the checks ask,
    says no."""
    real_access = os.access

    def access(path, mode, **kwargs):
        return real_access(path, mode, **kwargs) and Path(path) != folder

    monkeypatch.setattr(os, "access", access)


def test_import_refuses_an_output_it_cannot_write_before_opening_the_dataset(tmp_path, monkeypatch):
    """A folder in place of the file, a file in place of its folder, a read-only folder: refused
    first (the dataset does not exist here); they failed at the end, after reading the dataset."""
    (tmp_path / "dir.npz").mkdir()
    (tmp_path / "afile").write_text("")
    (tmp_path / "ro").mkdir()
    deny_writing(monkeypatch, tmp_path / "ro")
    for out, reason in [(tmp_path / "dir.npz", f"{tmp_path / 'dir.npz'} is a folder"),
                        (tmp_path / "afile/x.npz", f"{tmp_path / 'afile'} is not a folder"),
                        (tmp_path / "ro/x.npz", f"{tmp_path / 'ro'} is not writable")]:
        message = f"cannot write the demo file {out}: {reason}: pass another path"
        refused_in_process("import", "test/missing-v0", out, message=message)
    # A name of only ".npz" left its temporary file behind, under a message about the loader.
    message = f"the demo file {tmp_path / '.npz'} has no name before .npz: e.g. demos/hopper.npz"
    refused_in_process("import", "test/missing-v0", tmp_path / ".npz", message=message)


def test_import_refuses_one_step_which_no_method_file_trains_on(tmp_path):
    """--num-samples 0 or 1 is refused before opening the dataset; a dataset of one step is refused
    as such. A demo file of one step is less than a batch: the loader refused it, naming the
    temporary file and --batch-size, which this script does not take."""
    for n in (0, 1, -5):
        message = (f"--num-samples {n} is too few: the method files train on more steps than one "
                   "batch, pass 2 or more, or leave it out")
        refused_in_process("import", "test/missing-v0", tmp_path / "x.npz", "--num-samples", n,
                           message=message)
    episodes = random_episodes(gym.spaces.Box(-1, 1, (11,)), 3, steps=1, episodes=1)
    make_dataset("test/one-v0", episodes)
    message = ("dataset test/one-v0 holds 1 steps: the method files train on more steps than one "
               "batch, use a dataset of 2 steps or more")
    refused_in_process("import", "test/one-v0", tmp_path / "x.npz", message=message)
    assert not list(tmp_path.glob("x.npz*"))


def test_import_tells_a_path_or_a_bad_id_from_a_dataset_to_download(tmp_path, monkeypatch):
    """A source that is neither a folder nor a dataset id was to be downloaded (`minari download
    bad id`); a MINARI_DATASETS_PATH that cannot be a folder was "cannot use ...: pass another
    path"."""
    for source in ("bad id", str(tmp_path / "no/such/folder")):
        message = (f"{source!r} is neither a folder nor a Minari dataset id: "
                   "pass a dataset folder, or an id (namespace/)name-vN, e.g. mujoco/hopper/expert-v0")
        refused_in_process("import", source, tmp_path / "x.npz", message=message)
    (tmp_path / "afile").write_text("")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "afile"))
    message = (f"cannot make the local Minari store {tmp_path / 'afile'} (File exists): "
               "set MINARI_DATASETS_PATH to a folder you can write")
    refused_in_process("import", "test/hopper-v0", tmp_path / "x.npz", message=message)
    refused_in_process("export", tmp_path / "d.npz", "test/hopper-v0", message=message)


def test_export_refuses_a_store_it_cannot_write_and_demo_files_it_would_export_wrong(
        tmp_path, minari_store):
    demos = as_demos(random_episodes(gym.spaces.Box(-1, 1, (11,)), 3))
    meta = {"env_id": "Hopper-v4"}
    np.savez(tmp_path / "ok.npz", meta=np.array(json.dumps(meta)), **demos)
    with pytest.MonkeyPatch.context() as monkeypatch:
        minari_store.mkdir()
        deny_writing(monkeypatch, minari_store)
        message = (f"cannot write Minari dataset test/ro-v0 into the local store: {minari_store} "
                   "is not writable: set MINARI_DATASETS_PATH to a folder you can write")
        refused_in_process("export", tmp_path / "ok.npz", "test/ro-v0", message=message)
    (tmp_path / "dir.npz").mkdir()
    message = f"demo file {tmp_path / 'dir.npz'} is a folder: pass the .npz file itself"
    refused_in_process("export", tmp_path / "dir.npz", "test/dir-v0", message=message)
    # An env_id that is no string raised a TypeError.
    np.savez(tmp_path / "int.npz", meta=np.array(json.dumps({"env_id": 5})), **demos)
    message = (f"{tmp_path / 'int.npz'}: the env_id in its meta is 5, not an env id: "
               "pass --env, e.g. --env Hopper-v4")
    refused_in_process("export", tmp_path / "int.npz", "test/int-v0", message=message)
    # A frame skip written as text read "recorded at frame skip 4, but ... own rate 4".
    text = {"env_id": "Hopper-v4", "frame_skip": "4"}
    np.savez(tmp_path / "text.npz", meta=np.array(json.dumps(text)), **demos)
    message = (f"{tmp_path / 'text.npz'} was recorded at frame skip '4', but a Minari env spec "
               "records Hopper-v4's own rate 4: export demos made without --frame-skip")
    refused_in_process("export", tmp_path / "text.npz", "test/text-v0", message=message)
    # A NaN was exported into the dataset, which the import then refused.
    demos["observations"][3, 2] = np.nan
    np.savez(tmp_path / "nan.npz", meta=np.array(json.dumps(meta)), **demos)
    message = (f"{tmp_path / 'nan.npz'}: observations has a non-finite value at row 3: "
               "make the demo file again")
    refused_in_process("export", tmp_path / "nan.npz", "test/nan-v0", message=message)
    assert not (minari_store / "test").exists()
