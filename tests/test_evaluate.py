"""scripts/evaluate.py and scripts/watch.py: a model saved by any method file's --save-model, loaded by the
script, plays exactly the episodes of its run's last evaluation; bad checkpoints are refused in one line;
watch.py draws the policies side by side, one GIF frame per step (skipped where no OpenGL backend renders)."""
import contextlib
import json
import os
import re

import numpy as np
import pytest
import torch
from PIL import Image

import watch
from conftest import METHOD_FILES, REPO_ROOT, assert_usage_error, edited_checkpoint, link_experts, run_in_process, run_script

BUDGET = ("--env", "Hopper-v4", "--seeds", 1, "--epochs", 2, "--eval-every", 1, "--eval-episodes", 2, "--num-demo-samples", 1000, "--save-model")
EXTRA = {"dagger": ("--dagger-samples", 100, "--dagger-rounds", 2, "--dagger-epochs", 2)}
METHODS = [file.removesuffix(".py") for file in METHOD_FILES if file != "c2f_table3.py"]
"""the methods whose saved models are replayed: c2f_table3 at its defaults is c2f (test_c2f), so c2f stands for it"""
LAST_SEED = {method: 10_000 * 1 + 2 for method in METHODS}  # fit evaluates epoch E of training seed S with seed 10000 * S + E
LAST_SEED["dagger"] = 10_000 * 1 + (2 + 2 * 2) + 2 * 2  # its final learner (epoch 2 + rounds * epochs) thrice, the third E=2 episodes on
RETURN = re.compile(r"^episode (\d+) \| seed (\d+) \| return (\S+)$", re.M)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """method -> (its checkpoint seed1.pt, its JSON result): a tiny run of the method file, made once per module
    (in this process: a second or two each; the runs share the demos cached in their cwd)."""
    workdir, models = link_experts(tmp_path_factory.mktemp("saved_models")), {}

    def model(method):
        if method not in models:
            with contextlib.chdir(workdir):
                result = run_in_process(f"{method}.py", *BUDGET, *EXTRA.get(method, ()), "--output-dir", workdir / "out" / method)
            assert result.returncode == 0, result.stderr
            models[method] = workdir / "out" / method / "seed1.pt", json.loads((workdir / "out" / method / "result_seeds1.json").read_text())
        return models[method]

    return model


def evaluate(*args):
    """scripts/evaluate.py *args (in this process); returns (its result, the returns it printed, exactly)."""
    result = run_in_process("scripts/evaluate.py", *args)
    assert result.returncode == 0, result.stderr
    return result, [float(value) for _, _, value in RETURN.findall(result.stdout)]


@pytest.mark.parametrize("method", METHODS)
def test_a_saved_model_replays_its_runs_last_evaluation_exactly(trained, method):
    path, summary = trained(method)
    result, returns = evaluate(path, "--episodes", 2, "--seed", LAST_SEED[method])
    assert [int(seed) for _, seed, _ in RETURN.findall(result.stdout)] == [LAST_SEED[method], LAST_SEED[method] + 1]
    assert float(np.mean(returns)) == summary["scores"]["1"]["evaluations"][-1][1]  # bit for bit: same weights, normaliser, env, noise
    assert result.stdout.splitlines()[-1] == f"Hopper-v4 {method}: {np.mean(returns):.1f} ± {np.std(returns):.1f} over 2 episodes"


def test_dagger_s_final_score_is_three_evaluations_on_consecutive_episodes(trained):
    """Each of the three replays has the shape of the run's own evaluations (2 episodes in one batch), so it matches
    bit for bit on any CPU. One replay of all 6 episodes at once would not: MKL's default mode picks its kernels by
    matrix size too, so a batch of 6 rounds differently from one of 2 (they agreed only to 1e-7 on an AMD EPYC)."""
    path, summary = trained("dagger")
    means = [np.mean(evaluate(path, "--episodes", 2, "--seed", LAST_SEED["dagger"] - offset)[1]) for offset in (4, 2, 0)]
    assert float(np.mean(means)) == summary["scores"]["1"]["score"]


def test_the_defaults_are_the_runs_episode_count_from_seed_0_and_the_settings_are_named(trained, tmp_path):
    path, _ = trained("c2f")
    hidden = torch.load(path, weights_only=True)
    hidden["args"].update(hide_velocities=True, eval_episodes=3)
    torch.save(hidden, tmp_path / "hidden.pt")
    result, returns = evaluate(tmp_path / "hidden.pt")
    assert [int(seed) for _, seed, _ in RETURN.findall(result.stdout)] == [0, 1, 2]
    assert "c2f from" in result.stdout and "Hopper-v4, velocities hidden, frame skip 4, history 2: 3 episodes from --seed 0" in result.stdout
    _, noisy = evaluate(path, "--episodes", 3)
    assert returns != noisy  # the sensor the checkpoint records is the one evaluated


def test_one_episode_reads_one_episode(trained):
    """The plural only above 1: "1 episode" in the first line and the summary."""
    path, _ = trained("bc_oh")
    result, returns = evaluate(path, "--episodes", 1, "--seed", 5)
    assert result.stdout.splitlines()[0].endswith(": 1 episode from --seed 5")
    assert result.stdout.splitlines()[-1] == f"Hopper-v4 bc_oh: {returns[0]:.1f} ± 0.0 over 1 episode"


def test_a_checkpoint_from_before_expert_and_cuda_graph_went_plays_the_same_episodes(trained, tmp_path):
    """Models saved before the method files dropped --expert and --cuda-graph (e.g. the shipped results/h3 ones) record
    them; neither changes the policy or its evaluation, so they are ignored (dagger.py keeps --expert, and uses it)."""
    path, _ = trained("bc_oh")
    older = edited(path, tmp_path, expert="experts/{env}.pt", cuda_graph=True)
    assert evaluate(older, "--episodes", 2, "--seed", 7)[1] == evaluate(path, "--episodes", 2, "--seed", 7)[1]


def test_a_c2f_model_saved_before_c2f_table3_existed_plays_with_c2f_table3():
    """c2f.py held Table 3's settings before issue 55 moved them to c2f_table3.py; its models (the shipped results/h3
    ones, which the README's watch command plays) record them. c2f_table3.py, c2f.py at its defaults, loads them (every
    weight: load_state_dict is strict) and plays as trained: the README's episode, --seed 0, returned 546 on AMD EPYCs
    (a BC-OH policy after one epoch scores about 10); the bound leaves room for another CPU's digits."""
    shipped = REPO_ROOT / "results" / "h3" / "native_hidden" / "runs" / "c2f" / "Hopper-v4" / "seed1.pt"
    result, returns = evaluate(shipped, "--episodes", 1, "--seed", 0)
    assert result.stdout.splitlines()[-1].startswith("Hopper-v4 c2f_table3: ")
    assert returns[0] > 300, returns


def damaged(path, tmp_path):
    (tmp_path / "damaged.pt").write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    return tmp_path / "damaged.pt"


def edited(path, tmp_path, **changes):
    """A copy of the checkpoint with changes to its keys, or else to its args."""

    def change(checkpoint):
        for key, value in changes.items():
            if key in checkpoint:
                checkpoint[key] = value
            else:
                checkpoint["args"][key] = value

    return edited_checkpoint(path, tmp_path, change)


REFUSED = {
    "damaged": (damaged, "damaged.pt is not a readable checkpoint (RuntimeError): the file is damaged"),
    "missing method file": (lambda path, tmp: edited(path, tmp, method="gail"), "was saved by gail.py, which is not in"),
    # It was told to find "a checkout that has ensemble_twins.py": every checkout has it, in benchmark/.
    "a benchmark variant": (lambda path, tmp: edited(path, tmp, method="ensemble_twins"), "was saved by benchmark/ensemble_twins.py, whose models this script does not replay"),
    "an expert": (lambda path, tmp: REPO_ROOT / "experts" / "Hopper-v4.pt", "is not a model saved with --save-model: it has no 'method' (an expert"),
    "a JSON result": (lambda path, tmp: path.with_name("result_seeds1.json"), "is not a readable checkpoint"),
    "not found": (lambda path, tmp: tmp / "nowhere.pt", "not found: pass a seed<S>.pt that a method file wrote with --save-model"),
    "other weights": (lambda path, tmp: edited(path, tmp, hidden=16), "its weights do not fit the bc_oh policy its args describe (size mismatch"),
    "a newer file's setting": (lambda path, tmp: edited(path, tmp, warp_drive=True), "records the setting 'warp_drive', which this bc_oh.py does not have"),
    "a method file's bad value": (lambda path, tmp: edited(path, tmp, env="Nope-v0"), "cannot make env 'Nope-v0'"),
    # Its sensor raised the method's UsageError mid-evaluation, with a traceback.
    "unknown velocities": (lambda path, tmp: edited(path, tmp, env="Swimmer-v4"), "the velocity entries of Swimmer-v4 are unknown"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_bad_checkpoint_is_refused_in_one_line(trained, tmp_path, case):
    make, message = REFUSED[case]
    result = run_in_process("scripts/evaluate.py", make(trained("bc_oh")[0], tmp_path))
    assert result.returncode == 2
    assert_usage_error(result, message)


def test_the_command_refuses_a_damaged_checkpoint_with_exit_2_and_no_traceback(trained, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = run_in_process("scripts/evaluate.py", damaged(trained("bc_oh")[0], tmp_path), "--seed", 3)
    assert result.returncode == 2 and result.stdout == ""
    assert_usage_error(result, "damaged.pt is not a readable checkpoint")


def test_a_negative_seed_is_refused_in_one_line(trained):
    """numpy's generators refuse a negative seed, with a traceback from inside the sensor."""
    result = run_in_process("scripts/evaluate.py", trained("bc_oh")[0], "--seed", -1)
    assert result.returncode == 2
    assert_usage_error(result, "argument --seed: invalid non_negative value: '-1'")


def test_more_episodes_than_can_run_at_once_are_refused_in_one_line_before_the_checkpoint_loads(tmp_path):
    """--episodes 10**11 built a list of 10**11 envs: a MemoryError traceback after minutes, or the machine's memory
    filled. The flag is refused before the checkpoint is read (a missing file would be refused otherwise)."""
    result = run_in_process("scripts/evaluate.py", tmp_path / "nowhere.pt", "--episodes", 10**11)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == ("error: --episodes 100000000000 is more than 10000, the most evaluated (one env each, all at once): "
                             "pass --episodes 10000 or less\n")


def test_a_checkpoints_eval_episodes_beyond_the_bound_is_refused_unless_episodes_is_given(trained, tmp_path):
    """Without --episodes a run's --eval-episodes is played: a hand-edited 10**11 filled the memory as the flag did."""
    path = edited(trained("bc_oh")[0], tmp_path, eval_episodes=10**11)
    result = run_in_process("scripts/evaluate.py", path)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == (f"error: {path}: its args hold eval_episodes 100000000000, more than 10000, the most evaluated "
                             "(one env each, all at once): pass --episodes 10000 or less\n")
    assert evaluate(path, "--episodes", 1)[1]  # --episodes overrides it


BAD_SETTINGS = {  # a hand-edited value -> what the one line says of it, before ": re-save it with --save-model"
    "env 5": ({"env": 5}, "its args hold env 5, which is not a str"),
    "frame skip 0": ({"frame_skip": 0}, "its args hold frame_skip 0, which is not positive and finite"),
    "frame skip '4'": ({"frame_skip": "4"}, "its args hold frame_skip '4', which is not an int or None"),
    "0 episodes": ({"eval_episodes": 0}, "its args hold eval_episodes 0, which is not positive and finite"),
    "history 0": ({"history": 0}, "its args hold history 0, which is not positive and finite"),
    "history '2'": ({"history": "2"}, "its args hold history '2', which is not an int"),
    "hidden -1": ({"hidden": -1}, "its args hold hidden -1, which is not positive and finite"),
    "noise std 'x'": ({"obs_noise_std": "x"}, "its args hold obs_noise_std 'x', which is not a number"),
    "noise std nan": ({"obs_noise_std": float("nan")}, "its args hold obs_noise_std nan, which is not >= 0 and finite"),
    "hide velocities 'yes'": ({"hide_velocities": "yes"}, "its args hold hide_velocities 'yes', which is not True or False"),
    "seeds '1'": ({"seeds": "1"}, "its args hold seeds '1', which is not a list of int values"),
    "obs_dim '11'": ({"obs_dim": "11"}, "its obs_dim '11' is not a positive int"),
    "act_dim 3.5": ({"act_dim": 3.5}, "its act_dim 3.5 is not a positive int"),
}


@pytest.mark.parametrize("case", list(BAD_SETTINGS))
def test_a_bad_setting_in_a_checkpoint_is_refused_in_one_line_naming_it(trained, tmp_path, case):
    """A hand-edited value gave a traceback (frame skip 0 or '4', history '2', hidden -1, env 5, noise std 'x', 0
    episodes), a misleading refusal (history 0: "its weights do not fit"; obs_dim '11': "of width 11, but Hopper-v4 here
    has 11") or a silently wrong run (hide_velocities 'yes', seeds '1'; noise std nan: a return of nan, exit 0). Each is
    checked against the type of the method file's Args field, and the sizes as its run() checks the flags."""
    changes, problem = BAD_SETTINGS[case]
    path = edited(trained("bc_oh")[0], tmp_path, **changes)
    result = run_in_process("scripts/evaluate.py", path)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"error: {path}: {problem}: re-save it with --save-model\n"


@pytest.mark.parametrize("name, value", [("net.0.weight", float("nan")), ("normalize.std", float("inf"))])
def test_a_checkpoint_whose_weights_are_not_finite_is_refused_in_one_line(trained, tmp_path, name, value):
    """NaN weights (a diverged run) evaluated to a return of nan with exit 0; an infinite std of the normaliser quietly
    zeroed an input."""
    path = trained("bc_oh")[0]
    weights = torch.load(path, weights_only=True)["state_dict"]
    weights[name][0] = value
    result = run_in_process("scripts/evaluate.py", edited(path, tmp_path, state_dict=weights))
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"error: {tmp_path / 'edited.pt'}: its weights hold non-finite values ({name}): re-train it\n"


# ---- scripts/watch.py ----


@pytest.fixture(scope="module")
def backend():
    """A MUJOCO_GL value that renders here, or a skip saying what to install."""
    found = watch.find_backend()
    if found is None:
        tried = f"MUJOCO_GL={os.environ['MUJOCO_GL']}" if os.environ.get("MUJOCO_GL") else "no OpenGL backend"
        pytest.skip(f"{tried} renders no MuJoCo frame here: apt-get install libosmesa6 (OSMesa) or a GPU driver (EGL)")
    return found


def test_watch_refuses_a_negative_seed_and_an_output_that_is_a_folder(trained, backend, tmp_path):
    bc_oh = trained("bc_oh")[0]
    assert_usage_error(run_in_process("scripts/watch.py", bc_oh, "--seed", -1), "argument --seed: invalid non_negative value: '-1'")
    # The GIF was drawn, then os.replace onto the folder raised IsADirectoryError.
    (tmp_path / "dir.gif").mkdir()
    result = run_script("scripts/watch.py", bc_oh, "--output", tmp_path / "dir.gif", "--max-steps", 3, env=dict(os.environ, MUJOCO_GL=backend))
    assert_usage_error(result, f"cannot use {tmp_path / 'dir.gif'}: Is a directory: pass another path")


def test_watch_draws_one_panel_per_policy_and_a_frame_per_step_and_plays_evaluates_episode(trained, backend, tmp_path, monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", backend)  # the script's subprocess probes only this one
    (bc_oh, _), (c2f, _) = trained("bc_oh"), trained("c2f")
    result = run_script("scripts/watch.py", bc_oh, c2f, "--output", tmp_path / "w.gif", "--seed", 5, "--max-steps", 30, "--every", 1,
                        "--width", 64, "--height", 48)
    assert result.returncode == 0, result.stderr
    panels = re.findall(r"^(\w+): return (\S+) over (\d+) steps( \(episode ended\))?$", result.stdout, re.M)
    assert [name for name, *_ in panels] == ["bc_oh", "c2f"]
    steps = max(int(count) for _, _, count, _ in panels)
    assert steps <= 30 and (steps == 30 or all(ended for *_, ended in panels))
    with Image.open(tmp_path / "w.gif") as gif:
        assert (gif.n_frames, gif.size) == (steps + 1, (2 * 64, 48))  # the start, then every step; two panels side by side
        gif.seek(steps)
        last = np.asarray(gif.convert("RGB"))
    assert not np.array_equal(last[:, :64], last[:, 64:])
    for (name, value, _, ended), path in zip(panels, (bc_oh, c2f)):
        if ended:  # a whole episode: the one `evaluate.py --episodes 1 --seed 5` plays, to the last digit
            assert float(value) == evaluate(path, "--episodes", 1, "--seed", 5)[1][0]
    assert any(ended for *_, ended in panels), "expected the tiny BC-OH policy to fall within 30 steps"


def test_watch_frames_follow_every_and_play_in_real_time(trained, backend, tmp_path, monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", backend)
    result = run_script("scripts/watch.py", trained("c2f")[0], "--output", tmp_path / "w.gif", "--max-steps", 12, "--width", 32, "--height", 24)
    assert result.returncode == 0, result.stderr
    with Image.open(tmp_path / "w.gif") as gif:  # Hopper: 0.008 s a step, so by default a frame every 5 steps, 40 ms
        assert (gif.n_frames, gif.size, gif.info["duration"]) == (1 + 2 + 1, (32, 24), 40)  # steps 0, 5, 10 and the last, 12


def test_watch_names_what_to_install_where_no_backend_renders(monkeypatch):
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.setattr(watch, "renders", lambda backend: False)
    with pytest.raises(watch.UsageError, match=r"tried MUJOCO_GL=egl and osmesa\): install OSMesa \(apt-get install libosmesa6\)"):
        watch.use_backend()


WATCH_REFUSED = {
    "not a gif": (lambda path, tmp: [path, "--output", tmp / "w.mp4"], "", "is not a .gif"),
    "two envs": (lambda path, tmp: [path, edited(path, tmp, env="Hopper-v5"), "--output", tmp / "w.gif"], "",
                 "is a policy for Hopper-v4 at frame skip 4"),
    "a bad checkpoint": (lambda path, tmp: [tmp / "nowhere.pt", "--output", tmp / "w.gif"], "", "nowhere.pt not found"),
    "a backend that cannot render": (lambda path, tmp: [path, "--output", tmp / "w.gif"], "bogus", "cannot render with MUJOCO_GL=bogus"),
}


@pytest.mark.parametrize("case", list(WATCH_REFUSED))
def test_watch_refuses_bad_input_in_one_line(trained, tmp_path, monkeypatch, case):
    make, gl, message = WATCH_REFUSED[case]
    if gl:
        monkeypatch.setenv("MUJOCO_GL", gl)
    result = run_in_process("scripts/watch.py", *make(trained("bc_oh")[0], tmp_path))
    assert result.returncode == 2
    assert_usage_error(result, message)
    assert not (tmp_path / "w.gif").exists()


@pytest.mark.parametrize("side", ["width", "height"])
def test_watch_refuses_a_panel_larger_than_4096_pixels_in_one_line(trained, tmp_path, side):
    """--width 20000 failed with MuJoCo's "Offscreen framebuffer is not complete" and a traceback (Mesa's limit is
    16384; a 4K panel is the largest drawn)."""
    result = run_in_process("scripts/watch.py", trained("bc_oh")[0], "--output", tmp_path / "w.gif", f"--{side}", 20000)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"error: --{side} 20000 is more than 4096 pixels, the largest panel drawn: pass --{side} 4096 or less\n"


def test_watch_refuses_a_frame_wider_than_a_gif_holds_in_one_line_before_loading_anything(tmp_path):
    """16 panels of --width 4096 side by side: 65536 pixels, one more than a GIF holds. Every frame was drawn, then
    saving the GIF failed with an OverflowError traceback. The panels' files are not read first (here there are none:
    15 panels, a frame of 61440 pixels, go on to be refused as not found)."""
    missing = tmp_path / "nowhere.pt"
    result = run_in_process("scripts/watch.py", *[missing] * 16, "--output", tmp_path / "w.gif", "--width", 4096)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == ("error: 16 panels of --width 4096 make a frame 65536 pixels wide, more than a GIF's 65535: "
                             "pass --width 4095 or less, or fewer checkpoints\n")
    fits = run_in_process("scripts/watch.py", *[missing] * 15, "--output", tmp_path / "w.gif", "--width", 4096)
    assert_usage_error(fits, f"checkpoint {missing} not found")
    assert not (tmp_path / "w.gif").exists()


def test_watch_refuses_checkpoints_whose_env_cannot_be_compared_in_one_line(trained, tmp_path):
    """An env of a list (unhashable) failed with a TypeError before the two settings were compared."""
    path = trained("bc_oh")[0]
    other = edited(path, tmp_path, env=[1])
    result = run_in_process("scripts/watch.py", path, other, "--output", tmp_path / "w.gif")
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == (f"error: {path} is a policy for Hopper-v4 at frame skip 4, {other} for [1] at frame skip 4: "
                             "panels step together, so watch policies of one env and control rate at a time\n")


WATCH_REFUSED_AFTER_LOADING = {  # (edits of the checkpoint, flags) -> the one line, once a backend renders and it loaded
    # OverflowError: a GIF frame of 800 s.
    "every 100000": ({}, ("--every", 100000), "--every 100000 is not less than --max-steps 1000: no frame would be "
                                              "drawn between the first and the last; pass --every 999 or less"),
    # A GIF of the first and the last frame only, exit 0: Hopper-v4's episodes end after 1000 steps.
    "every as long as the episode": ({}, ("--max-steps", 5000, "--every", 1000),
                               "--every 1000 is not less than the 1000 steps of an episode of Hopper-v4 at frame skip 4: no "
                               "frame would be drawn between the first and the last; pass --every 999 or less"),
    # One step watched: a frame of 800 s overflowed the GIF's duration, as above.
    "one step watched": ({}, ("--max-steps", 1, "--every", 100000), "--every 100000 is not less than --max-steps 1: no frame "
                                                                   "would be drawn between the first and the last; pass --every 1 or less"),
    # RuntimeError: Trying to create tensor with negative dimension -1.
    "a bad setting": ({"hidden": -1}, (), "{path}: its args hold hidden -1, which is not positive and finite: re-save it "
                                          "with --save-model"),
}


@pytest.mark.parametrize("case", list(WATCH_REFUSED_AFTER_LOADING))
def test_watch_refuses_an_every_longer_than_the_steps_watched_and_a_bad_setting_in_one_line(trained, backend, tmp_path,
                                                                                            monkeypatch, case):
    monkeypatch.setenv("MUJOCO_GL", backend)
    monkeypatch.setenv("PYOPENGL_PLATFORM", "")  # use_backend sets both; the test's teardown restores them
    changes, flags, message = WATCH_REFUSED_AFTER_LOADING[case]
    path = trained("bc_oh")[0]
    if changes:
        path = edited(path, tmp_path, **changes)
    result = run_in_process("scripts/watch.py", path, "--output", tmp_path / "w.gif", *flags)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"error: {message.format(path=path)}\n"
    assert not (tmp_path / "w.gif").exists()
