"""copycat_analysis.py: the interventions and scores on hand-made policies (a copycat scores high, a policy
that ignores the history zero; do(zeta) of a zeta-blind policy is zero, of a pass-through the gap), and the
script on tiny models saved by the real bc_so.py, bc_oh.py, c2f.py and c2f_table3.py (bad input, the report, the
pictures)."""
import argparse
import dataclasses
import importlib
import json
import os

import numpy as np
import pytest
import torch
import torch.nn as nn
import tyro

import c2f
import c2f_table3
import copycat_analysis as ca
from conftest import assert_usage_error, edited_checkpoint, link_experts, make_demos, run_in_process, run_script

OBS, ACT, H = 4, 2, 2
W = np.array([[1.0, -0.5, 0.3, 0.0], [0.2, 0.8, -1.0, 0.5]])  # the hand-made expert: a_t = W o_t


@pytest.fixture(scope="module")
def demos():
    """Three 100-step episodes of a random walk in observation space, labelled by the linear expert."""
    rng = np.random.default_rng(0)
    observations = np.cumsum(rng.normal(size=(300, OBS)) * rng.exponential(size=(300, 1)), axis=0)
    starts = np.arange(300) % 100 == 0
    actions = observations @ W.T
    return {"observations": observations, "actions": actions, "episode_starts": starts,
            "histories": ca.stack_history(observations, starts, H), "scale": actions.std(0)}


def copycat(histories):
    """Acts on the oldest frame, o_{t-1}: outputs the previous frame's implied action a_{t-1}."""
    return histories[:, :OBS] @ W.T


def reads_current(histories):
    """Ignores the history: the expert's action on o_t."""
    return histories[:, -OBS:] @ W.T


def with_prev(demos):
    steps = np.flatnonzero(~demos["episode_starts"])
    return demos["histories"][steps], demos["actions"][steps - 1], demos["actions"][steps]


def test_repeat_current_puts_the_current_frame_everywhere(demos):
    repeated = ca.repeat_current(demos["histories"], OBS)
    assert repeated.shape == demos["histories"].shape
    for frame in range(H):
        np.testing.assert_array_equal(repeated[:, frame * OBS:(frame + 1) * OBS], demos["observations"])


def test_history_intervention_copycat_moves_towards_the_previous_action(demos):
    histories, prev, current = with_prev(demos)
    change, towards = ca.history_intervention(copycat, histories, OBS, prev, demos["scale"])
    # do(o_hist) turns a_{t-1} into a_t: the change is exactly |a_t - a_{t-1}| / scale, always away from a_{t-1}
    np.testing.assert_allclose(change, (np.abs(current - prev) / demos["scale"]).mean(1))
    assert change.min() > 0
    assert towards.all()


def test_history_intervention_of_a_history_blind_policy_is_zero(demos):
    histories, prev, _ = with_prev(demos)
    change, towards = ca.history_intervention(reads_current, histories, OBS, prev, demos["scale"])
    assert np.all(change == 0) and not towards.any()


def test_history_intervention_through_a_torch_module(demos):
    """as_actor wraps a torch module: a linear copycat on the flattened history, clipped to the bounds."""
    module = nn.Linear(H * OBS, ACT, bias=False)
    with torch.no_grad():
        module.weight.zero_()
        module.weight[:, :OBS] = torch.as_tensor(W, dtype=torch.float32)
    histories, prev, current = with_prev(demos)
    act = ca.as_actor(module, np.full(ACT, -1e9), np.full(ACT, 1e9))
    change, towards = ca.history_intervention(act, histories, OBS, prev, demos["scale"])
    np.testing.assert_allclose(change, (np.abs(current - prev) / demos["scale"]).mean(1), rtol=1e-4, atol=1e-4)
    assert towards.mean() > 0.99
    clipped = ca.as_actor(module, np.full(ACT, -0.1), np.full(ACT, 0.1))(histories)
    assert clipped.min() >= -0.1 and clipped.max() <= 0.1


def test_changepoints_are_the_largest_jumps_inside_episodes():
    actions = np.zeros((40, 1))
    actions[[5, 25]] = 3.0  # jumps at 5 and 25 (and back at 6 and 26), and a new episode starting at 20 ...
    actions[20:] += 10.0  # ... whose start is a jump of 10 that must not count
    starts = np.arange(40) % 20 == 0
    points = ca.changepoints(actions, starts, np.ones(1), quantile=0.9)
    np.testing.assert_array_equal(points, [5, 6, 25, 26])


def test_copycat_score_is_one_for_the_copycat_and_zero_for_the_expert(demos):
    points = ca.changepoints(demos["actions"], demos["episode_starts"], demos["scale"], 0.9)
    assert len(points) >= 25 and not demos["episode_starts"][points].any()
    args = (demos["actions"], points, demos["scale"])
    assert ca.copycat_score(copycat(demos["histories"]), *args) == 1.0
    assert ca.copycat_score(reads_current(demos["histories"]), *args) == 0.0


LO, HI = np.array([-0.5, 0.1]), np.array([0.7, 0.9])


def test_zeta_effect_of_a_zeta_blind_policy_is_zero_and_of_a_pass_through_the_gap(demos):
    zeta = reads_current(demos["histories"])
    blind = ca.zeta_effect(lambda h, z: reads_current(h), demos["histories"], zeta, LO, HI)
    through = ca.zeta_effect(lambda h, z: z, demos["histories"], zeta, LO, HI)
    assert blind.shape == through.shape == (300, ACT)
    assert np.all(blind == 0)
    np.testing.assert_allclose(through, np.broadcast_to(HI - LO, through.shape))
    # only zeta_d is set: a policy that passes zeta_0 into both outputs shows no effect of zeta_1 on output 1
    cross = ca.zeta_effect(lambda h, z: z[:, [0, 0]], demos["histories"], zeta, LO, HI)
    np.testing.assert_allclose(cross[:, 0], HI[0] - LO[0])
    assert np.all(cross[:, 1] == 0)


def c2f_policy(zeta_weight: float):
    """A real C2F policy (late fusion) whose head passes zeta through with this weight and ignores the rest."""
    torch.manual_seed(0)
    paper = {name: getattr(c2f_table3.Args(), name) for name in ca.TABLE3_DEFAULTS}
    policy = ca.C2FPolicy(OBS, ACT, torch.randn(16, H * OBS), argparse.Namespace(history=H, hidden=8, **paper))
    with torch.no_grad():
        policy.head.weight.zero_()
        policy.head.bias.zero_()
        policy.head.weight[:, 8:] = zeta_weight * torch.eye(ACT)
    return policy.eval()


def test_the_table3_defaults_filled_into_c2f_models_are_c2f_table3s_own():
    """c2f.py's models record no ablation flag: they load as c2f_table3.py's model at these defaults."""
    table3 = {field.name for field in dataclasses.fields(c2f_table3.Args)} - {field.name for field in dataclasses.fields(c2f.Args)}
    assert set(ca.TABLE3_DEFAULTS) == table3
    assert ca.TABLE3_DEFAULTS == {name: getattr(c2f_table3.Args(), name) for name in table3}


@pytest.mark.parametrize("weight", [0.0, 1.0])
def test_zeta_intervention_on_a_c2f_model(demos, weight):
    policy = c2f_policy(weight)
    coarse, final = ca.zeta_intervention(policy, np.full(ACT, -5.0), np.full(ACT, 5.0))
    zeta = coarse(demos["histories"])
    np.testing.assert_allclose(final(demos["histories"], zeta), policy(torch.as_tensor(demos["histories"], dtype=torch.float32)).detach().numpy(), atol=1e-6)
    effect = ca.zeta_effect(final, demos["histories"], zeta, LO, HI)
    np.testing.assert_allclose(effect, np.broadcast_to(weight * (HI - LO), effect.shape), atol=1e-6)
    assert "coarse_model" not in vars(policy), "the intervention leaves the model as it was"


# ---------------------------------------------------------------------------------------------
# The script, on tiny models saved by the method scripts


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """Tiny models of the three methods and of the no-coarse control (c2f_table3.py's), saved by the real scripts'
    run() from their command lines (in-process: four interpreter starts would cost more than the training)."""
    workdir = link_experts(tmp_path_factory.mktemp("copycat"))
    budget = ["--epochs", "1", "--num-demo-samples", "300", "--eval-episodes", "1", "--seeds", "1", "--save-model"]
    cwd = os.getcwd()
    os.chdir(workdir)  # demos/ is cached relative to the working directory
    try:
        for method in ca.METHODS:
            script = importlib.import_module(method)
            script.run(tyro.cli(script.Args, args=[*budget, "--output-dir", f"models/{method}"]))
        c2f_table3.run(tyro.cli(c2f_table3.Args, args=[*budget, "--no-coarse-action", "--output-dir", f"models/{ca.CONTROL}"]))
    finally:
        os.chdir(cwd)
    return workdir, {method: workdir / "models" / method / "seed1.pt" for method in (*ca.METHODS, ca.CONTROL)}


def model_flags(paths, **overrides):
    flags = []
    for method in ca.METHODS:
        flags += ["--" + method.replace("_", "-"), overrides.get(method, paths[method])]
    return flags


def test_report_and_pictures_on_saved_models(saved):
    workdir, paths = saved
    result = run_script("copycat_analysis.py", *model_flags(paths), "--control", paths[ca.CONTROL], "--num-demo-samples", 300,
                        "--eval-episodes", 1, "--output-dir", "out", cwd=workdir)
    assert result.returncode == 0, result.stderr
    assert "copycat score" in result.stdout and "do(zeta)" in result.stdout and f"\n{ca.CONTROL} | " in result.stdout
    report = json.loads((workdir / "out" / "copycat_analysis.json").read_text())
    assert list(report["methods"]) == [*ca.METHODS, ca.CONTROL] and report["methods"][ca.CONTROL]["model"] == str(paths[ca.CONTROL])
    assert report["methods"][ca.CONTROL]["history_change_demos"] > 0  # the control reads its history, as BC-OH does
    assert report["demo_steps"] == 300 and report["changepoints"] >= 29 and report["history"] == 2
    bc_so = report["methods"]["bc_so"]  # reads o_t only: do(o_hist) cannot move it
    assert bc_so["history_change_demos"] == 0 and bc_so["towards_previous_rollouts"] == 0
    assert report["methods"]["bc_oh"]["history_change_demos"] > 0
    for row in report["methods"].values():
        assert 0 <= row["copycat_score"] <= 1 and len(row["rollout_returns"]) == 1
    zeta = report["zeta"]
    assert all(lo < hi for lo, hi in zip(zeta["lo"], zeta["hi"]))
    assert all(0 <= value <= 1 for value in zeta["relative_demos"] + zeta["relative_rollouts"])
    for picture in ("zeta_effect.png", "history_intervention.png"):
        assert (workdir / "out" / picture).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_control_and_c2f_in_each_others_place_are_refused(saved, monkeypatch):
    """do(zeta) of the control would be zero by construction, and C2F is no capacity control."""
    workdir, paths = saved
    assert "trained with --no-coarse-action: pass it as --control" in bad_run(workdir, paths, monkeypatch, c2f=paths[ca.CONTROL])
    assert "trained without --no-coarse-action: pass C2F's own model as --c2f" in bad_run(workdir, paths, monkeypatch, control=str(paths["c2f"]))


def test_a_model_of_another_method_is_rejected_in_one_line(saved, monkeypatch):
    workdir, paths = saved
    monkeypatch.chdir(workdir)
    result = run_in_process("copycat_analysis.py", *model_flags(paths, bc_so=paths["c2f"]))
    assert result.returncode == 2
    assert_usage_error(result, "is a c2f model, not bc_so")


def bad_run(workdir, paths, monkeypatch, **settings):
    """run() in-process (faster than a subprocess); returns the UsageError's message."""
    monkeypatch.chdir(workdir)
    models = {method: str(settings.pop(method, paths[method])) for method in ca.METHODS}
    with pytest.raises(ca.UsageError) as error:
        ca.run(ca.Args(**models, **{"num_demo_samples": 300, "eval_episodes": 1, "output_dir": "bad", **settings}))
    assert not (workdir / "bad").exists(), "nothing is written on bad input"
    return str(error.value)


def rollout_file(tmp_path, workdir, seed):
    """A demo file like those of `expert_ppo.py --make-demos`, but the expert's 200 steps from reset seed `seed`."""
    expert = ca.load_expert(str(workdir / "experts" / "Hopper-v4.pt"), "Hopper-v4")
    demos = ca.generate_demos("Hopper-v4", None, expert, 200, seed=seed)
    meta = {"env_id": "Hopper-v4", "frame_skip": 4, "seed": seed}
    path = tmp_path / f"seed{seed}.npz"
    np.savez(path, meta=np.array(json.dumps(meta)), **demos)
    return path


def test_held_out_demos_from_a_file_are_read_whole_as_the_method_files_read_theirs(saved, monkeypatch, tmp_path):
    """--demos: the file's steps, all of them (not --num-demo-samples'), are the held-out demos of the analysis."""
    workdir, paths = saved
    demo_file = rollout_file(tmp_path, workdir, seed=1)
    monkeypatch.chdir(workdir)
    ca.run(ca.Args(**{m: str(paths[m]) for m in ca.METHODS}, demos=str(demo_file), eval_episodes=1, output_dir="from_file"))
    report = json.loads((workdir / "from_file" / "copycat_analysis.json").read_text())
    with np.load(demo_file) as data:
        actions = data["actions"].astype(np.float64)
    assert report["demo_steps"] == 200 and report["args"]["num_demo_samples"] == 5000
    assert report["action_std"] == actions.std(0).clip(1e-6).tolist()


def test_held_out_demos_that_share_the_models_training_steps_are_refused(saved, monkeypatch):
    """A file of `expert_ppo.py --make-demos` is the expert's rollout from reset seed 0: its first steps are the ones
    the models trained on (their demos/Hopper-v4_300.npz), so the analysis would not be held out."""
    message = bad_run(*saved, monkeypatch, demos=str(make_demos("Hopper-v4", 200)))
    assert "shares 200 steps with demos/Hopper-v4_300.npz, the training demos of bc_so, bc_oh, c2f" in message
    assert "leave --demos out" in message


def test_held_out_actions_that_do_not_vary_are_refused(saved, monkeypatch, tmp_path):
    """do(zeta_d) moves zeta_d from lo_d to hi_d, the demo actions' quantiles: a dim with lo_d == hi_d (e.g. 20 steps
    that keep it at its bound) made its relative effect NaN in the report."""
    path = rollout_file(tmp_path, saved[0], seed=3)
    with np.load(path) as data:
        arrays = dict(data)
    arrays["actions"][:, 1] = 0.5
    np.savez(path, **arrays)
    message = bad_run(*saved, monkeypatch, demos=str(path))
    assert "the held-out actions of dims [1] do not vary between their 0.05 and 0.95 quantiles: pass more" in message


def test_held_out_check_says_when_the_training_demos_are_not_here(saved, monkeypatch, tmp_path, capsys):
    """Models whose training file is gone: the analysis runs on the given demos and says the overlap is unchecked."""
    workdir, paths = saved
    demo_file = rollout_file(tmp_path, workdir, seed=2)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "experts").symlink_to(workdir / "experts")
    monkeypatch.chdir(elsewhere)
    ca.run(ca.Args(**{m: str(paths[m]) for m in ca.METHODS}, demos=str(demo_file), eval_episodes=1, output_dir="out"))
    assert "the training demos demos/Hopper-v4_300.npz of bc_so, bc_oh, c2f are not readable here" in capsys.readouterr().out
    assert (elsewhere / "out" / "copycat_analysis.json").exists()


def with_nan_at_row_17(tmp_path):
    with np.load(make_demos("Hopper-v4", 300)) as data:
        arrays = dict(data)
    arrays["observations"][17, 3] = np.nan
    np.savez(tmp_path / "nan.npz", **arrays)
    return tmp_path / "nan.npz"


BAD_DEMOS = {
    "not found": (lambda tmp: tmp / "nowhere.npz", "nowhere.npz not found in "),
    "another rate": (lambda tmp: make_demos("Hopper-v4", 300, 1),
                     "was made at frame skip 1 (the env's own if its meta has none), not 4, the models' rate: pass --demos made at frame skip 4"),
    "a non-finite value": (with_nan_at_row_17, "observations hold non-finite values at rows [17]: fix them"),
    # The method files' fixes ("pass --env Walker2d-v4", "use a smaller --batch-size") are no flags of this script.
    "another env": (lambda tmp: make_demos("Walker2d-v4", 300), "holds demos of Walker2d-v4: pass --demos of Hopper-v4, the models' env"),
    "one step": (lambda tmp: one_step(tmp), "one_step.npz holds one step: pass --demos of two steps or more"),
}


def one_step(tmp_path):
    with np.load(make_demos("Hopper-v4", 300)) as data:
        arrays = {key: data[key][:1] for key in ("observations", "actions", "episode_starts")}
    np.savez(tmp_path / "one_step.npz", **arrays)
    return tmp_path / "one_step.npz"


@pytest.mark.parametrize("case", list(BAD_DEMOS))
def test_bad_held_out_demos_are_refused_as_the_method_files_refuse_them(saved, monkeypatch, tmp_path, case):
    make, message = BAD_DEMOS[case]
    assert message in bad_run(*saved, monkeypatch, demos=str(make(tmp_path)))


def test_missing_model(saved, monkeypatch):
    message = bad_run(*saved, monkeypatch, bc_oh="nowhere/seed1.pt")
    assert "bc_oh model nowhere/seed1.pt not found" in message and "--save-model" in message
    message = bad_run(*saved, monkeypatch, control="nowhere/seed1.pt")
    train = "`python c2f_table3.py --env Hopper-v4 --seeds 1 --no-coarse-action --save-model --output-dir nowhere`"
    assert "capacity control nowhere/seed1.pt not found" in message
    assert f"{train} (it writes nowhere/seed1.pt), or pass --control PATH" in message
    # A name other than seed<S>.pt: the command writes seed1.pt into its folder, and says so.
    message = bad_run(*saved, monkeypatch, control="nowhere/model.pt")
    assert "--output-dir nowhere` (it writes nowhere/seed1.pt), or pass --control PATH" in message


def test_c2f_models_of_either_file_load_with_the_table3_defaults(saved, tmp_path):
    """c2f.py's model records no ablation flag; c2f_table3.py's model at its defaults records them all: both load
    as C2F, with the same weights giving the same actions; a control must be a model trained without zeta."""
    _, paths = saved
    checkpoint = torch.load(paths["c2f"], weights_only=True)
    assert checkpoint["method"] == "c2f" and not set(ca.TABLE3_DEFAULTS) & set(checkpoint["args"])
    policy, args = ca.load_model(str(paths["c2f"]), "c2f", "Hopper-v4", 11, 3)
    assert {name: args[name] for name in ca.TABLE3_DEFAULTS} == ca.TABLE3_DEFAULTS
    checkpoint["method"], checkpoint["args"] = "c2f_table3", {**checkpoint["args"], **ca.TABLE3_DEFAULTS}
    torch.save(checkpoint, tmp_path / "table3.pt")
    same, _ = ca.load_model(str(tmp_path / "table3.pt"), "c2f", "Hopper-v4", 11, 3)
    histories = torch.randn(5, 22)
    torch.testing.assert_close(same(histories), policy(histories))
    control = torch.load(paths[ca.CONTROL], weights_only=True)
    assert control["method"] == "c2f_table3" and control["args"]["coarse_action"] is False
    with pytest.raises(ca.UsageError, match="is a c2f model trained without --no-coarse-action"):
        ca.load_model(str(paths["c2f"]), "c2f", "Hopper-v4", 11, 3, control=True)


def test_a_model_trained_with_noise_on_other_entries_is_refused(saved, monkeypatch, tmp_path):
    """Models of the old --velocity-dims recorded the entries their noise went to: others than the env's velocities
    would be analysed with the wrong noise; None (the built-in table) loads."""
    workdir, paths = saved
    checkpoint = torch.load(paths["bc_oh"], weights_only=True)
    checkpoint["args"]["velocity_dims"] = [0, 1]
    torch.save(checkpoint, tmp_path / "other_dims.pt")
    message = bad_run(workdir, paths, monkeypatch, bc_oh=tmp_path / "other_dims.pt")
    assert "was trained with the noise on observation entries [0, 1], not on Hopper-v4's velocities [5, 6, 7, 8, 9, 10]" in message


def test_history_that_does_not_match_the_models(saved, monkeypatch):
    assert "--history 3 does not match the models, trained with history 2" in bad_run(*saved, monkeypatch, history=3)


def test_model_of_another_env(saved, monkeypatch):
    assert "is a model of Hopper-v4, not HalfCheetah-v4" in bad_run(*saved, monkeypatch, env="HalfCheetah-v4")


def test_weights_that_do_not_fit_the_saved_history(saved, monkeypatch, tmp_path):
    """A checkpoint whose recorded history disagrees with its weights is refused, not half-loaded."""
    workdir, paths = saved
    checkpoint = torch.load(paths["bc_oh"], weights_only=True)
    checkpoint["args"]["history"] = 3
    torch.save(checkpoint, tmp_path / "edited.pt")
    assert "its weights do not fit a bc_oh policy with history 3" in bad_run(workdir, paths, monkeypatch, bc_oh=tmp_path / "edited.pt")


def test_c2f_without_an_action_zeta_and_a_non_model_file(saved, monkeypatch, tmp_path):
    workdir, paths = saved
    checkpoint = torch.load(paths["c2f"], weights_only=True)
    checkpoint["args"]["coarse_output"] = "feature"
    torch.save(checkpoint, tmp_path / "feature.pt")
    assert "--coarse-output action" in bad_run(workdir, paths, monkeypatch, c2f=tmp_path / "feature.pt")
    (tmp_path / "junk.pt").write_text("not a model")
    assert "is not a model saved with --save-model" in bad_run(workdir, paths, monkeypatch, c2f=tmp_path / "junk.pt")


def test_bad_values(saved, monkeypatch):
    assert "--seed 0 would regenerate the training demonstrations" in bad_run(*saved, monkeypatch, seed=0)
    assert "--zeta-quantile" in bad_run(*saved, monkeypatch, zeta_quantile=0.5)
    # gymnasium refused a negative reset seed with a traceback.
    assert "--seed must lie in [0, 2**32), got -1" in bad_run(*saved, monkeypatch, seed=-1)
    # A field other than {env} in a path raised KeyError in str.format, after the whole analysis.
    assert bad_run(*saved, monkeypatch, output_dir="out{x}") == "--output-dir out{x}: the one field a path may hold is {env}"
    assert bad_run(*saved, monkeypatch, expert="experts/{0}.pt").startswith("--expert experts/{0}.pt: the one field")


def test_models_of_different_history_lengths_are_refused():
    saved = {"bc_so": {"history": 5}, "bc_oh": {"history": 2}, "c2f": {"history": 2}}
    assert ca.agreed(saved, "history", "--history", ("bc_oh", "c2f")) == 2  # BC-SO's own history does not matter
    saved["c2f"]["history"] = 3
    with pytest.raises(ca.UsageError, match=r"different --history .*'bc_oh': 2, 'c2f': 3.*one history length"):
        ca.agreed(saved, "history", "--history", ("bc_oh", "c2f"), "pass models trained with one history length")


def test_models_of_another_control_rate_and_hidden_velocities_are_analysed_at_their_setting(tmp_path):
    """The analysis takes the rate and the kind of partial observability from the models; models that
    disagree on them are refused."""
    workdir = link_experts(tmp_path)
    budget = ["--epochs", "1", "--num-demo-samples", "300", "--eval-episodes", "1", "--seeds", "1", "--save-model", "--frame-skip", "1"]
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        for method in ca.METHODS:
            script = importlib.import_module(method)
            script.run(tyro.cli(script.Args, args=[*budget, "--hide-velocities", "--output-dir", f"models/{method}"]))
        paths = {method: workdir / "models" / method / "seed1.pt" for method in ca.METHODS}
        ca.run(ca.Args(**{m: str(p) for m, p in paths.items()}, num_demo_samples=300, eval_episodes=1, output_dir="out"))
        report = json.loads((workdir / "out" / "copycat_analysis.json").read_text())
        assert (report["frame_skip"], report["hide_velocities"]) == (1, True)
        importlib.import_module("bc_so").run(tyro.cli(importlib.import_module("bc_so").Args, args=[*budget, "--output-dir", "models/native"]))
        with pytest.raises(ca.UsageError, match="different --hide-velocities"):
            ca.run(ca.Args(**{**{m: str(p) for m, p in paths.items()}, "bc_so": "models/native/seed1.pt"}, num_demo_samples=300, eval_episodes=1))
    finally:
        os.chdir(cwd)


def test_an_env_without_a_velocity_layout_is_refused_before_the_models(tmp_path, monkeypatch):
    """Swimmer-v4 has no known velocity entries: the refusal says so, where it advised training a model with
    `python bc_so.py --env Swimmer-v4`, which bc_so.py refuses for the same reason."""
    monkeypatch.chdir(tmp_path)
    result = run_in_process("copycat_analysis.py", "--env", "Swimmer-v4")
    assert_usage_error(result, "the velocity entries of Swimmer-v4 are unknown")
    assert "train one" not in result.stderr


# ---------------------------------------------------------------------------------------------
# Bad input found by fuzzing the command: each refused in one line, exit 2, before the analysis writes anything


def refusal(saved, monkeypatch, *flags, **models):
    """The one stderr line of `copycat_analysis.py` (run in-process on the saved models, those in `models` replaced, and
    `flags` last) refusing its input: exit 2, no traceback, nothing written to its --output-dir."""
    workdir, paths = saved
    monkeypatch.chdir(workdir)
    result = run_in_process("copycat_analysis.py", *model_flags(paths, **models), "--num-demo-samples", 300, "--eval-episodes", 1,
                            "--output-dir", "bad", *flags)
    assert_usage_error(result, "error: ")
    assert result.returncode == 2
    assert not (workdir / "bad").exists()
    return result.stderr.strip()


def test_noise_that_makes_the_actions_non_finite_is_refused(saved, monkeypatch):
    """--obs-noise-std 1e300 overflows float32: every measure was nan, printed with exit 0."""
    line = refusal(saved, monkeypatch, "--obs-noise-std", "1e300")
    assert line == (f"error: --bc-so {saved[1]['bc_so']} gives non-finite actions on the held-out demos with velocity noise std "
                    "1e+300: pass a smaller --obs-noise-std")


def test_non_finite_actions_without_noise_are_blamed_on_the_demos():
    histories = np.zeros((4, 2))
    clean = histories.copy()
    histories[1, 0] = np.inf
    with pytest.raises(ca.UsageError, match=r"^--bc-oh m.pt gives non-finite actions on the held-out demos with velocity noise std 0.2: pass a"):
        ca.check_actions({"bc_oh": lambda h: h[:, :1]}, {"bc_oh": "m.pt"}, histories, clean, 0.2)
    with pytest.raises(ca.UsageError, match=r"^--control c.pt gives non-finite actions on the held-out demos, even without noise: pass --demos"):
        ca.check_actions({ca.CONTROL: lambda h: h[:, :1]}, {ca.CONTROL: "c.pt"}, histories, histories, 0.2)


BAD_CHECKPOINTS = {
    # A traceback before each of these but the last three: KeyError, TypeError, TypeError, TypeError, TypeError.
    "no state_dict": (lambda c: c.pop("state_dict"), " is not a model saved with --save-model (KeyError): pass a seed<S>.pt written by bc_oh.py"),
    "args not a dict": (lambda c: c.update(args="x"), ": its args are a str, not a dict: re-save it with bc_oh.py"),
    "state_dict not a dict": (lambda c: c.update(state_dict="x"), ": its state_dict is a str, not a dict: re-save it with bc_oh.py"),
    "history a str": (lambda c: c["args"].update(history="2"), ": its args hold history '2', which is not a positive int: re-save it with bc_oh.py"),
    "velocity_dims an int": (lambda c: c["args"].update(velocity_dims=5),
                             ": its args hold velocity_dims 5, which is not a list of ints or None: re-save it with bc_oh.py"),
    # It said "is a model of 5, not Hopper-v4: ..., or --env 5".
    "env_id an int": (lambda c: c.update(env_id=5), ": its env_id 5 is not a str: re-save it with bc_oh.py"),
    # torch asked for 88 TB in a traceback.
    "hidden huge": (lambda c: c["args"].update(hidden=10**12), ": its weights do not fit a bc_oh policy with history 2 and hidden 1000000000000 "
                                                               "on Hopper-v4's 11-d observations: re-save it with bc_oh.py"),
    # A diverged training: every measure of the model was nan, exit 0.
    "nan weights": (lambda c: c["state_dict"]["net.0.weight"].fill_(np.nan), ": its weights are not finite: retrain it with bc_oh.py"),
}


@pytest.mark.parametrize("case", list(BAD_CHECKPOINTS))
def test_corrupt_checkpoints_are_refused_in_one_line(saved, monkeypatch, tmp_path, case):
    edit, message = BAD_CHECKPOINTS[case]
    path = edited_checkpoint(saved[1]["bc_oh"], tmp_path, edit)
    assert refusal(saved, monkeypatch, bc_oh=path) == f"error: --bc-oh {path}{message}"


def test_a_control_whose_coarse_action_is_not_a_bool_is_refused(saved, monkeypatch, tmp_path):
    """A str "False" counted as True: the control was told it was trained without --no-coarse-action."""
    path = edited_checkpoint(saved[1][ca.CONTROL], tmp_path, lambda c: c["args"].update(coarse_action="False"))
    line = refusal(saved, monkeypatch, "--control", path)
    assert line == f"error: --control {path}: its args hold coarse_action 'False', which is not a bool: re-save it with c2f_table3.py"


def test_a_folder_in_place_of_a_model_or_the_demos_is_refused(saved, monkeypatch, tmp_path):
    """They were 'not found', and the model's advice was to train one into the folder's parent."""
    folder = saved[1]["bc_oh"].parent
    line = refusal(saved, monkeypatch, bc_oh=folder)
    assert line == f"error: --bc-oh {folder} is a folder: pass the model file in it, e.g. {folder / 'seed1.pt'}"
    assert refusal(saved, monkeypatch, "--demos", tmp_path) == f"error: --demos {tmp_path} is a folder: pass a .npz file"


@pytest.mark.parametrize("flag", ["--output-dir", "--control"])
def test_an_empty_path_is_refused(saved, monkeypatch, flag):
    """An empty --output-dir wrote into the working folder and said it wrote into /; an empty --control was ignored."""
    assert refusal(saved, monkeypatch, flag, "") == f"error: {flag} is empty: pass a path, or leave {flag} out"


def test_an_output_dir_under_a_file_is_refused_before_the_analysis(saved, monkeypatch, tmp_path):
    """It was refused after the whole analysis, as a file that could not be written (File exists)."""
    (tmp_path / "file").write_text("")
    line = refusal(saved, monkeypatch, "--output-dir", tmp_path / "file" / "out")
    assert line == f"error: --output-dir {tmp_path / 'file' / 'out'}: {tmp_path / 'file'} is not a folder: pass another --output-dir"


def demos_without_steps(tmp_path, workdir):
    with np.load(make_demos("Hopper-v4", 300)) as data:
        np.savez(tmp_path / "empty.npz", **{key: data[key][:0] for key in ("observations", "actions", "episode_starts")})
    return tmp_path / "empty.npz"


def demos_of_one_step_episodes(tmp_path, workdir):
    path = rollout_file(tmp_path, workdir, seed=4)
    with np.load(path) as data:
        arrays = dict(data)
    arrays["episode_starts"][:] = True
    np.savez(path, **arrays)
    return path


BAD_HELD_OUT = {
    # It said "holds one step".
    "no step": (demos_without_steps, "empty.npz holds no step: pass --demos of two steps or more"),
    # An IndexError in np.quantile, after two numpy warnings.
    "one-step episodes": (demos_of_one_step_episodes, "seed4.npz: every step starts an episode: pass episodes of 2 steps or more"),
}


@pytest.mark.parametrize("case", list(BAD_HELD_OUT))
def test_held_out_demos_without_a_previous_action_are_refused(saved, monkeypatch, tmp_path, case):
    make, message = BAD_HELD_OUT[case]
    assert refusal(saved, monkeypatch, "--demos", make(tmp_path, saved[0])) == f"error: {tmp_path}/{message}"


@pytest.mark.parametrize("frame_skip", [4000, 8000])
def test_models_of_a_rate_without_two_steps_an_episode_are_refused(saved, monkeypatch, tmp_path, frame_skip):
    """Hopper-v4's 1000 steps at frame skip 4 last 1 step at 4000 (the held-out actions 'did not vary', or an IndexError)
    and none at 8000 (the refusal named --frame-skip, no flag of this script)."""
    models = {}
    for method in ca.METHODS:
        (tmp_path / method).mkdir()
        models[method] = edited_checkpoint(saved[1][method], tmp_path / method, lambda c: c["args"].update(frame_skip=frame_skip))
    line = refusal(saved, monkeypatch, **models)
    assert line == (f"error: the models were trained at frame skip {frame_skip}, at which an episode of Hopper-v4 ends before its second "
                    "step: pass models of a smaller --frame-skip")


def test_noise_for_models_that_hide_the_velocities_is_refused(saved, monkeypatch, tmp_path):
    """The velocities were zeroed and the report recorded the ignored noise std."""
    models = {}
    for method in ca.METHODS:
        (tmp_path / method).mkdir()
        models[method] = edited_checkpoint(saved[1][method], tmp_path / method, lambda c: c["args"].update(hide_velocities=True))
    line = refusal(saved, monkeypatch, "--obs-noise-std", "0.5", **models)
    assert line == ("error: --obs-noise-std 0.5: the models were trained with --hide-velocities, so the velocities are zeroed, not noisy: "
                    "leave --obs-noise-std out")


def test_models_that_hide_the_velocities_with_other_noise_stds_are_told_to_agree(saved, monkeypatch, tmp_path):
    """The refusal of models trained with different --obs-noise-std said to pass --obs-noise-std, which models that hide
    the velocities refuse: the advice looped."""
    models = {}
    for method in ca.METHODS:
        (tmp_path / method).mkdir()
        std = 0.1 if method == "bc_so" else 0.2
        models[method] = edited_checkpoint(saved[1][method], tmp_path / method, lambda c: c["args"].update(hide_velocities=True, obs_noise_std=std))
    line = refusal(saved, monkeypatch, **models)
    assert line.startswith("error: the models were trained with different --obs-noise-std (")
    assert line.endswith("): pass models trained alike")
