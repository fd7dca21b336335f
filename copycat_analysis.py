# Causal diagnostics of the copycat shortcut for saved BC-SO, BC-OH and C2F models
# (the paper's H3: section 5.4's interventions; the summaries below are ours); see README.md
"""Interventions that show whether a policy copies the previous action instead of reading the
current frame.

Loads the models that bc_so.py, bc_oh.py and c2f.py write with --save-model for one env (C2F's
may also be c2f_table3.py's, with --coarse-output action) and, on held-out expert demonstrations
(velocity noise drawn from --seed: for seed-1 models the same draws as their training noise, on
other steps) and on each policy's own rollouts in the noisy env, measures

1. do(o_hist) = [o_t, ..., o_t]: how far each policy's action moves when its history is replaced
   by the current frame repeated (mean |change| per action dim / the demo actions' std), and how
   often the real history pulls the action towards the previous action a_{t-1} (ours: section 5.4
   counts how often the intervention turns CARLA's accelerate into stop);
2. do(zeta), C2F only:
   CE_d = |pi_theta(o_hist, do(zeta_d = lo_d))_d - pi_theta(o_hist, do(zeta_d = hi_d))_d|
   per action dim d, the other zeta dims left at the coarse model's output, lo_d / hi_d the
   5th / 95th percentiles of the demo actions;
3. the copycat score on held-out demos (ours; its changepoints are those of Wen et al. 2021, the
   KeyFrame baseline): at action changepoints (the top decile of the std-scaled |a_t - a_{t-1}|),
   the fraction of predictions closer to a_{t-1} than to a_t.

It prints a table and writes the pictures and a JSON report to --output-dir.

    # Likewise bc_oh.py and c2f.py:
    python bc_so.py --env Hopper-v4 --seeds 1 --save-model --output-dir runs/bc_so/Hopper-v4
    # Reads runs/<method>/Hopper-v4/seed1.pt:
    python copycat_analysis.py --env Hopper-v4
    # And the capacity control (the first command is one line, wrapped here):
    python c2f_table3.py --env Hopper-v4 --seeds 1 --no-coarse-action --save-model
        --output-dir runs/c2f_no_coarse/Hopper-v4
    python copycat_analysis.py --env Hopper-v4 --control runs/c2f_no_coarse/Hopper-v4/seed1.pt
"""

import json
import os
import signal
import sys
from dataclasses import asdict, dataclass
from types import SimpleNamespace
from typing import Optional

import gymnasium as gym
import matplotlib
import matplotlib.pyplot as plt
import mujoco
import numpy as np
import torch
import torch.nn as nn
import tyro

# Files only, no display. pyplot chooses no backend when it is imported, so choosing Agg here
# still comes before any figure is made.
matplotlib.use("Agg")

# Our v4 envs are deprecated in gymnasium 1.x (the paper names no version): keep stderr for errors.
gym.logger.min_level = gym.logger.ERROR


# Copied from bc_oh.print_mujoco_warning
def print_mujoco_warning(text: str):
    # MuJoCo 3.x warns about gymnasium's HalfCheetah model each time it is made: skip that one.
    if "settotalmass" not in text:
        print(f"MuJoCo warning: {text}", file=sys.stderr)


mujoco.set_mju_user_warning(print_mujoco_warning)
METHODS = ("bc_so", "bc_oh", "c2f")
# The capacity control, c2f_table3.py --no-coarse-action: C2F's network, zeros in place of zeta.
CONTROL = "c2f_no_coarse"
C2F_METHODS = ("c2f", "c2f_table3")
"""the method files whose models load as C2F (c2f.py's are c2f_table3.py's at its defaults)"""
TABLE3_DEFAULTS = {
    "fusion": "late",
    "coarse_output": "action",
    "coarse_input": "current",
    "policy_input": "history",
    "stop_gradient": True,
    "coarse_action": True,
    "two_stage": False,
}
"""c2f_table3.py's ablation flags at their defaults, the paper's C2F: what c2f.py's models record
none of"""
COLORS = {"bc_so": "tab:blue", "bc_oh": "tab:red", "c2f": "tab:green", CONTROL: "tab:gray"}


@dataclass
class Args:
    env: str = "Hopper-v4"
    """gymnasium MuJoCo env id the models were trained on"""
    bc_so: str = "runs/bc_so/{env}/seed1.pt"
    """BC-SO model written by `bc_so.py --save-model`"""
    bc_oh: str = "runs/bc_oh/{env}/seed1.pt"
    """BC-OH model written by `bc_oh.py --save-model`"""
    c2f: str = "runs/c2f/{env}/seed1.pt"
    """C2F model written by `c2f.py --save-model` (or by `c2f_table3.py --save-model` with
    --coarse-output action, the default)"""
    control: Optional[str] = None
    """optional fourth model: the capacity control, `c2f_table3.py --no-coarse-action --save-model`
    (do(o_hist) and the copycat score only: it reads no zeta)"""
    demos: Optional[str] = None
    """held-out demonstrations (.npz as the method files read theirs, whole; refused if they share
    steps with the models' training demos, as files of `expert_ppo.py --make-demos` do); default:
    a fresh expert rollout from reset seed --seed (the training demos use seed 0), not cached"""
    expert: str = "experts/{env}.pt"
    """expert checkpoint that generates the held-out demos when --demos is not given"""
    num_demo_samples: int = 5000
    """held-out demo steps to generate when --demos is not given"""
    obs_noise_std: Optional[float] = None
    """std of the velocity noise on the demos' and the rollouts' observations (default: the models'
    training value; models trained with --hide-velocities get zeroed velocities instead, and refuse
    it)"""
    history: Optional[int] = None
    """frames in the history (default: the models'; it must be the BC-OH and C2F models' own)"""
    eval_episodes: int = 3
    """rollout episodes of each policy in the partially observed env"""
    zeta_quantile: float = 0.05
    """do(zeta_d) = lo_d / hi_d: the q and 1-q quantiles of the demo actions of dim d (0: their min
    and max)"""
    changepoint_quantile: float = 0.9
    """changepoints of the copycat score: the steps whose std-scaled |a_t - a_{t-1}| is at or
    above this quantile (0.9: the top decile)"""
    output_dir: str = "analysis/{env}"
    """where the pictures and the JSON report are written"""
    seed: int = 1
    """seed of the held-out demos (not 0, the training demos' seed), of their noise and of the
    rollouts"""


# Copied from bc_oh.UsageError
class UsageError(Exception):
    """Bad input from the user: printed as one line on stderr, exit status 2, no traceback."""


# ----------------------------------------------------------------------------------------------
# Env: the partially observed setting of the paper (noisy velocities)


# Copied from bc_oh.velocity_dims
def velocity_dims(env: gym.Env, env_id: str) -> list:
    """The indices of the joint velocities in an observation: where the noise goes."""
    structure = getattr(env.unwrapped, "observation_structure", None)
    if structure:
        # v5 envs describe their layout: positions first, then the qvel block.
        return list(range(structure["qpos"], structure["qpos"] + structure["qvel"]))
    # The v4 envs: the velocity entries [start, end) of their observations.
    known = {"Hopper": (5, 11), "Walker2d": (8, 17), "HalfCheetah": (8, 17), "Ant": (13, 27)}
    family = env_id.split("-")[0]
    if family not in known:
        known_envs = "Hopper, Walker2d, HalfCheetah or Ant, or a v5 env with observation_structure"
        raise UsageError(f"the velocity entries of {env_id} are unknown: use {known_envs}")
    start, end = known[family]
    return list(range(start, end))


# Copied from bc_oh.PartialObservation
class PartialObservation(gym.ObservationWrapper):
    """The sensor: fresh N(0, std^2) noise on the velocities at each step, or zeros there."""

    def __init__(self, env: gym.Env, dims: list, std: float, hide: bool, seed: int):
        super().__init__(env)
        self.dims = np.asarray(dims)
        self.std = std
        self.hide = hide
        self.rng = np.random.default_rng(seed)

    def observation(self, obs):
        obs = np.array(obs, dtype=np.float64)
        if self.hide:
            obs[self.dims] = 0.0
        else:
            obs[self.dims] += self.rng.normal(0.0, self.std, len(self.dims))
        return obs


# Copied from bc_oh.make_env
def make_env(env_id: str, frame_skip: int | None = None) -> gym.Env:
    """The gymnasium env, at another control rate when frame_skip is given."""
    if "-v" not in env_id:
        raise UsageError(f"env {env_id!r} has no version: use {env_id}-v4 or {env_id}-v5")
    try:
        env = gym.make(env_id)
    except Exception as error:
        # gymnasium raises several error types for unknown or broken ids.
        raise UsageError(f"cannot make env {env_id!r} ({error}): use a MuJoCo id such as Hopper-v4")
    if not isinstance(env.action_space, gym.spaces.Box):
        raise UsageError(f"env {env_id!r} has discrete actions: imitation needs continuous ones")
    native = getattr(env.unwrapped, "frame_skip", None)
    if frame_skip is None or frame_skip == native:
        return env
    if native is None:
        raise UsageError(f"env {env_id!r} is not a MuJoCo env: leave --frame-skip out")
    # The same duration of an episode, and the same scale of returns, at the new rate.
    steps = round(env.spec.max_episode_steps * native / frame_skip)
    if steps < 1:
        raise UsageError(f"--frame-skip {frame_skip} outlasts an episode: pass a smaller one")
    env = gym.make(env_id, max_episode_steps=steps)
    env.unwrapped.frame_skip = frame_skip
    return gym.wrappers.TransformReward(env, lambda reward: reward * frame_skip / native)


# ----------------------------------------------------------------------------------------------
# Data: held-out expert demonstrations, noise, history


# Copied from expert_ppo.ExpertPolicy
class ExpertPolicy(nn.Module):
    """The deterministic expert: frozen obs normalisation, the actor's mean action, clipped."""

    def __init__(self, checkpoint: dict):
        super().__init__()
        obs_dim = checkpoint["obs_shape"][0]
        act_dim = checkpoint["action_shape"][0]
        hidden = checkpoint["hidden"]
        layers = [nn.Linear(obs_dim, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh()]
        self.net = nn.Sequential(*layers, nn.Linear(hidden, act_dim))
        self.net.load_state_dict(checkpoint["actor"])
        for name in ("obs_mean", "obs_var", "action_low", "action_high"):
            self.register_buffer(name, checkpoint[name].float())

    @torch.no_grad()
    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        # An expert retargeted to a wider observation (Ant-v5's) reads its leading entries.
        obs = obs[..., : len(self.obs_mean)]
        obs = ((obs - self.obs_mean) / torch.sqrt(self.obs_var + 1e-8)).clamp(-10.0, 10.0)
        return torch.maximum(torch.minimum(self.net(obs), self.action_high), self.action_low)


# Copied from expert_ppo.load_expert
def load_expert(path: str, env_id: str) -> ExpertPolicy:
    """Load an expert checkpoint written by expert_ppo.py, checking that it was made for env_id."""
    if not os.path.isfile(path):
        train = f"python expert_ppo.py --env {env_id} writes runs/expert_ppo/{env_id}__1/best.pt"
        raise UsageError(f"expert checkpoint {path} not found: give its path ({train})")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
        policy = ExpertPolicy(checkpoint)
        trained_on = checkpoint["env_id"]
    except Exception as error:
        problem = f"{path} is not a readable expert checkpoint ({type(error).__name__})"
        raise UsageError(f"{problem}: re-copy or re-train it")
    if trained_on != env_id:
        other = f"{path} is an expert for {trained_on}, not {env_id}"
        raise UsageError(f"{other}: pass the one made for {env_id}")
    return policy.eval()


# Copied from expert_ppo.generate_demos
def generate_demos(env_id: str, frame_skip, expert, num_samples: int, seed: int = 0) -> dict:
    """Roll out the deterministic expert: o_t, a_t, episode starts, and Minari's other fields."""
    env = make_env(env_id, frame_skip)
    steps = []
    final_observations = []
    obs, _ = env.reset(seed=seed)
    start = True
    for step in range(num_samples):
        action = expert(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
        next_obs, reward, terminated, truncated, _ = env.step(action)
        # The budget ends the last episode.
        truncated = truncated or step == num_samples - 1
        steps.append((obs, action, start, reward, terminated, truncated))
        obs = next_obs
        start = terminated or truncated
        if start:
            final_observations.append(next_obs)
            obs, _ = env.reset()
    env.close()
    observations, actions, starts, rewards, terminations, truncations = zip(*steps)
    return {
        "observations": np.array(observations, np.float64),
        "actions": np.array(actions, np.float32),
        "episode_starts": np.array(starts),
        "rewards": np.array(rewards, np.float64),
        "terminations": np.array(terminations),
        "truncations": np.array(truncations),
        "final_observations": np.array(final_observations, np.float64),
    }


# Copied from expert_ppo.write_atomically
def write_atomically(path: str, write):
    """Call write(file) on a temporary file, then rename it to path: never half a file."""
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
        with open(tmp, "wb") as file:
            write(file)
        os.replace(tmp, path)
    except OSError as error:
        raise UsageError(f"cannot write {path} ({error.strerror}): check the path and its folder")
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


# Copied from bc_oh.load_demos
def load_demos(args, env: gym.Env) -> tuple:
    """(demos, meta) from --demos or from the file `expert_ppo.py --make-demos` writes."""
    obs_dim = env.observation_space.shape[0]
    act_dim = env.action_space.shape[0]
    native = getattr(env.unwrapped, "frame_skip", None)
    # Section 8.3's demo sizes: 20k for Hopper, 10k for Ant and Walker2d; here 10k for the others.
    paper_n = 20000 if args.env.startswith("Hopper") else 10000
    n = args.num_demo_samples or paper_n
    path = args.demos
    if path is None and args.frame_skip == native:
        path = f"demos/{args.env}_{n}.npz"
    elif path is None:
        path = f"demos/{args.env}_fs{args.frame_skip}_{n}.npz"
    here = os.path.dirname(os.path.abspath(__file__))
    if not os.path.isfile(path) and os.path.isfile(os.path.join(here, path)):
        raise UsageError(f"demo file {path} not found in {os.getcwd()}: run from {here}")
    if not os.path.isfile(path) and args.demos is not None:
        raise UsageError(f"demo file {path} not found in {os.getcwd()}: check --demos")
    if not os.path.isfile(path):
        make = f"python expert_ppo.py --env {args.env} --frame-skip {args.frame_skip}"
        make += f" --num-demo-samples {n} --make-demos"
        fix = f"make it: {make}"
        # Fewer steps at the env's own rate: the first steps of a larger shipped file will do.
        shipped = f"demos/{args.env}_{paper_n}.npz"
        if path == f"demos/{args.env}_{n}.npz" and n < paper_n and os.path.isfile(shipped):
            fix += f", or the shipped file's first steps: --demos {shipped} --num-demo-samples {n}"
        raise UsageError(f"demo file {path} not found in {os.getcwd()}: {fix}")
    dtypes = {"observations": np.float64, "actions": np.float32, "episode_starts": bool}
    demos = {}
    meta = {}
    try:
        with np.load(path, allow_pickle=False) as data:
            if "meta" in data:
                meta = json.loads(str(data["meta"]))
            for key, dtype in dtypes.items():
                if key in data:
                    demos[key] = data[key].astype(dtype)
    except Exception as error:
        # The error's type only: numpy's own message may advise allow_pickle, unsafe here.
        message = f"{path} is not a readable demo file ({type(error).__name__})"
        raise UsageError(f"{message}: see the format in docs/methods.md")
    # A file without meta loads (from elsewhere, at the env's own rate); expert_return may be null.
    if not isinstance(meta, dict) or not isinstance(meta.get("expert_return") or 0, (int, float)):
        raise UsageError(f"{path}: its meta does not follow docs/methods.md: fix or remove it")
    made_for = meta.get("env_id", args.env)
    made_at = meta.get("frame_skip", native)
    if made_for != args.env:
        raise UsageError(f"{path} holds demos of {made_for}: pass --env {made_for}")
    if made_at != args.frame_skip:
        rates = f"frame skip {made_at} (the env's own if its meta has none), not {args.frame_skip}"
        raise UsageError(f"{path} was made at {rates}: pass --frame-skip {made_at}")
    for key in dtypes:
        if key not in demos:
            raise UsageError(f"{path} has no {key!r} array: see the format in docs/methods.md")
    obs = demos["observations"]
    actions = demos["actions"]
    starts = demos["episode_starts"]
    if obs.shape[1:] != (obs_dim,) or actions.shape[1:] != (act_dim,):
        shapes = f"observations {obs.shape} and actions {actions.shape}"
        needs = f"{args.env} needs (N, {obs_dim}) and (N, {act_dim})"
        raise UsageError(f"{path} holds {shapes}, but {needs}: use demos of this env")
    if starts.ndim != 1 or not len(obs) == len(actions) == len(starts):
        raise UsageError(f"{path}: the arrays need one row per step each, episode_starts 1-D")
    take = args.num_demo_samples or len(obs)
    if len(obs) < take:
        steps = len(obs)
        raise UsageError(f"{path} holds {steps} steps: pass --num-demo-samples {steps} or fewer")
    if take <= args.batch_size:
        fix = "use a smaller --batch-size or more demos"
        raise UsageError(f"{path}: {take} steps, not more than a batch: {fix}")
    obs = obs[:take]
    actions = actions[:take]
    starts = starts[:take]
    for key, values in [("observations", obs), ("actions", actions)]:
        bad_rows = np.flatnonzero(~(np.abs(values) <= np.finfo(np.float32).max).all(axis=1))
        if len(bad_rows):
            rows = bad_rows[:3].tolist()
            raise UsageError(f"{path}: {key} hold non-finite values at rows {rows}: fix them")
    low = env.action_space.low
    high = env.action_space.high
    outside = np.flatnonzero(((actions < low) | (actions > high)).any(axis=1))
    if len(outside):
        bounds = f"[{low.min():g}, {high.max():g}]"
        rows = outside[:3].tolist()
        raise UsageError(f"{path}: actions of rows {rows} lie outside {bounds}: rescale them")
    if not starts[0]:
        raise UsageError(f"{path}: episode_starts[0] is False: it is True on each episode's start")
    if starts.all():
        raise UsageError(f"{path}: every step starts an episode: pass episodes of 2 steps or more")

    # The copycat shortcut's pull: MSE(a_{t-1}, a_t) within episodes over Var(a), per action entry,
    # averaged: 0 if actions never change, 1 if copying is as good as the mean, 2 if unrelated.
    step_error = ((actions[1:] - actions[:-1])[~starts[1:]] ** 2).mean(0)
    copy_error = (step_error / np.maximum(actions.var(0), 1e-12)).mean()
    total = len(demos["actions"])
    note = f" (the first {take} of its {total})" if take < total else ""
    print(f"demos: {take} steps from {path}{note}")
    scale = "0: copying a_{t-1} is exact; 1: no better than the mean action; 2: unrelated"
    print(f"demos: copy error MSE(a_{{t-1}}, a_t)/Var(a) = {copy_error:.3f} ({scale})")
    return {"observations": obs, "actions": actions, "episode_starts": starts}, meta


def heldout_demos(args, env: gym.Env, frame_skip: Optional[int]) -> dict:
    """--demos, checked as the method files check theirs (its env, rate, arrays, shapes, values),
    or a fresh expert rollout from reset seed --seed: states the policies were not trained on."""
    # The whole file; batch_size 1: any file of two steps or more.
    if args.demos is not None:
        # load_demos would call a folder not found.
        if os.path.isdir(args.demos):
            raise UsageError(f"--demos {args.demos} is a folder: pass a .npz file")
        # The models' rate (None: the env's own).
        rate = frame_skip or getattr(env.unwrapped, "frame_skip", None)
        given = SimpleNamespace(
            env=args.env, demos=args.demos, num_demo_samples=None, batch_size=1, frame_skip=rate
        )
        try:
            return load_demos(given, env)[0]
        except UsageError as error:
            # The method files' fixes name their own flags: here the models set the env and the
            # rate, and a file of two steps or more will do.
            message = str(error)
            if ": pass --frame-skip" in message:
                problem = message.partition(": pass --frame-skip")[0]
                fix = f"the models' rate: pass --demos made at frame skip {rate}"
                raise UsageError(f"{problem}, {fix}")
            if ": pass --env" in message:
                problem = message.partition(": pass --env")[0]
                raise UsageError(f"{problem}: pass --demos of {args.env}, the models' env")
            if "use a smaller --batch-size" in message:
                steps = "one step"
                if message.startswith(f"{args.demos}: 0 steps"):
                    steps = "no step"
                raise UsageError(f"{args.demos} holds {steps}: pass --demos of two steps or more")
            raise
    expert_path = args.expert.format(env=args.env)
    if not os.path.isfile(expert_path):
        raise UsageError(
            f"no expert for {args.env} at {expert_path}: "
            "pass --expert, or held-out demos with --demos"
        )
    print(
        f"generating {args.num_demo_samples} held-out demonstration steps with {expert_path} "
        f"(reset seed {args.seed})"
    )
    return generate_demos(
        args.env,
        frame_skip,
        load_expert(expert_path, args.env),
        args.num_demo_samples,
        seed=args.seed,
    )


def training_demos_path(training: dict, env: gym.Env, env_id: str) -> tuple:
    """(path, steps) of the demos a model of env_id trained on, by the rule of bc_oh.load_demos."""
    native = getattr(env.unwrapped, "frame_skip", None)
    frame_skip = training.get("frame_skip") or native
    paper_n = 20000 if env_id.startswith("Hopper") else 10000
    n = training.get("num_demo_samples") or paper_n
    path = training.get("demos")
    if path is None and frame_skip == native:
        path = f"demos/{env_id}_{n}.npz"
    elif path is None:
        path = f"demos/{env_id}_fs{frame_skip}_{n}.npz"
    # With --demos, a model trained on the file's first --num-demo-samples steps, or on all of them.
    steps = training.get("num_demo_samples")
    return path, steps


def check_held_out(demos: dict, saved: dict, env: gym.Env, env_id: str, demos_path: str):
    """Refuse held-out demos that share steps with a model's training demos: the analysis would
    score the models on the states they were fit to. Every file `expert_ppo.py --make-demos` writes
    is the expert's rollout from reset seed 0, so it starts with the training demos' steps."""
    held_out = {row.tobytes() for row in demos["observations"].astype(np.float64)}
    # The models' training files, each with the models that trained on it.
    sources = {}
    for method, training in saved.items():
        source = training_demos_path(training, env, env_id)
        sources.setdefault(source, []).append(method)
    for (path, steps), methods in sources.items():
        try:
            with np.load(path, allow_pickle=False) as data:
                trained_on = data["observations"][:steps].astype(np.float64)
        except Exception:
            print(f"the training demos {path} of {', '.join(methods)} are not readable here:")
            print("    whether --demos shares their steps is not checked")
            continue
        shared = 0
        for row in trained_on:
            if row.tobytes() in held_out:
                shared += 1
        if shared:
            fix = "pass demos of another rollout, or leave --demos out (then: a fresh rollout)"
            raise UsageError(
                f"--demos {demos_path} shares {shared} steps with {path}, "
                f"the training demos of {', '.join(methods)}: {fix}"
            )


# Copied from bc_oh.partially_observe
def partially_observe(observations, dims: list, std: float, hide: bool, seed: int) -> np.ndarray:
    """PartialObservation's noise on the demos, drawn once from seed and fixed for all epochs."""
    observed = observations.copy()
    rng = np.random.default_rng(seed)
    if hide:
        observed[:, dims] = 0.0
    else:
        observed[:, dims] += rng.normal(0.0, std, (len(observed), len(dims)))
    return observed


# Copied from bc_oh.stack_history
def stack_history(observations: np.ndarray, episode_starts: np.ndarray, history: int) -> np.ndarray:
    """Row t: [o_{t-H+1}, ..., o_t], oldest first; a frame before t's episode is its first frame."""
    index = np.arange(len(observations))
    first_of_episode = np.maximum.accumulate(np.where(episode_starts, index, 0))
    frames = []
    for lag in reversed(range(history)):
        frames.append(observations[np.maximum(index - lag, first_of_episode)])
    return np.concatenate(frames, axis=1)


# ----------------------------------------------------------------------------------------------
# Networks: the three policies, rebuilt from their checkpoints


# Copied from bc_oh.mlp
def mlp(in_dim: int, out_dim: int, hidden: int) -> nn.Sequential:
    """The paper's three-layer MLP (section 8.3)."""
    layers = [nn.Linear(in_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU()]
    return nn.Sequential(*layers, nn.Linear(hidden, out_dim))


# Copied from bc_oh.Normalizer
class Normalizer(nn.Module):
    """Standardises entries by the training inputs' mean and std (>= 1e-6); saved with the model."""

    def __init__(self, inputs: torch.Tensor):
        super().__init__()
        self.register_buffer("mean", inputs.mean(0))
        self.register_buffer("std", inputs.std(0).clamp_min(1e-6))

    def forward(self, x):
        return (x - self.mean) / self.std


# Copied from bc_so.Policy with Policy->SOPolicy
class SOPolicy(nn.Module):
    """BC-SO: only o_t, the history's last obs_dim entries, goes into one MLP (`history` unused)."""

    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, inputs: torch.Tensor):
        super().__init__()
        self.obs_dim = obs_dim
        self.normalize = Normalizer(inputs[:, -obs_dim:])
        self.net = mlp(obs_dim, act_dim, hidden)

    def forward(self, obs_history):
        return self.net(self.normalize(obs_history[:, -self.obs_dim :]))


# Copied from bc_oh.Policy with Policy->OHPolicy
class OHPolicy(nn.Module):
    """BC-OH: the whole history, flattened, goes into one MLP."""

    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, inputs: torch.Tensor):
        super().__init__()
        self.normalize = Normalizer(inputs)
        self.net = mlp(obs_dim * history, act_dim, hidden)

    def forward(self, obs_history):
        return self.net(self.normalize(obs_history))


# Copied from c2f_table3.Policy with Policy->C2FPolicy
class C2FPolicy(nn.Module):
    """C2F on MuJoCo (section 8.3, Fig. 10), with the ablations of Table 3 open."""

    def __init__(self, obs_dim: int, act_dim: int, inputs: torch.Tensor, args):
        super().__init__()
        self.normalize = Normalizer(inputs)
        self.args = args
        # Each model reads the last *_in_dim entries of [o_{t-H+1}, ..., o_t]: o_t, or them all.
        self.coarse_in_dim = obs_dim
        if args.coarse_input == "history":
            self.coarse_in_dim = obs_dim * args.history
        self.policy_in_dim = obs_dim * args.history
        if args.policy_input == "current":
            self.policy_in_dim = obs_dim
        # The coarse model pi_phi: an MLP on o_t (as BC-SO), or on the history; it outputs zeta.
        self.coarse = mlp(self.coarse_in_dim, act_dim, args.hidden)
        # --coarse-output: the coarse model passes on zeta, or its last hidden feature.
        fed_dim = act_dim
        if args.coarse_output == "feature":
            fed_dim = args.hidden
        # pi_theta as in c2f.py, split after its first layer; output and penultimate change its end.
        first_in = self.policy_in_dim
        if args.fusion == "early":
            first_in += fed_dim
        self.policy_first = nn.Sequential(nn.Linear(first_in, args.hidden), nn.ReLU())
        second_in = args.hidden
        if args.fusion == "middle":
            second_in += fed_dim
        layers = [nn.Linear(second_in, args.hidden), nn.ReLU()]
        # A third hidden layer, except: output's third layer gives an action, penultimate has none.
        if args.fusion == "output":
            layers.append(nn.Linear(args.hidden, act_dim))
        elif args.fusion != "penultimate":
            layers += [nn.Linear(args.hidden, args.hidden), nn.ReLU()]
        self.policy_rest = nn.Sequential(*layers)
        # A last Linear maps pi_theta's output, with sg(zeta) unless fused earlier, to the action.
        head_in = args.hidden
        if args.fusion == "output":
            head_in = act_dim
        if args.fusion in ("late", "output", "penultimate"):
            head_in += fed_dim
        self.head = nn.Linear(head_in, act_dim)

    def coarse_model(self, obs_history):
        """zeta = pi_phi(o_t, or the history), and the coarse model's last hidden feature."""
        coarse_input = self.normalize(obs_history)[:, -self.coarse_in_dim :]
        coarse_feature = self.coarse[:-1](coarse_input)
        zeta = self.coarse[-1](coarse_feature)
        return zeta, coarse_feature

    def coarse_and_final(self, obs_history):
        """zeta and the final action: what Eq. 2 (or the loss the flags choose) trains."""
        args = self.args
        zeta, coarse_feature = self.coarse_model(obs_history)
        fed = zeta
        if args.coarse_output == "feature":
            fed = coarse_feature
        # detach() is the stop-gradient sg: the final action's loss does not train the coarse model.
        if args.stop_gradient:
            fed = fed.detach()
        # The capacity control: zeros in place of sg(zeta), no coarse information for pi_theta.
        if not args.coarse_action:
            fed = torch.zeros_like(fed)
        h = self.normalize(obs_history)[:, -self.policy_in_dim :]
        if args.fusion == "early":
            h = torch.cat([h, fed], dim=1)
        h = self.policy_first(h)
        if args.fusion == "middle":
            h = torch.cat([h, fed], dim=1)
        h = self.policy_rest(h)
        if args.fusion in ("late", "output", "penultimate"):
            h = torch.cat([h, fed], dim=1)
        final = self.head(h)
        return zeta, final

    def forward(self, obs_history):
        _, final = self.coarse_and_final(obs_history)
        return final


def load_model(
    path: str, method: str, env_id: str, obs_dim: int, act_dim: int, control: bool = False
):
    """Rebuild the policy a method script saved with --save-model; returns (policy, its
    training args).

    method "c2f": a model of c2f.py or c2f_table3.py, its args completed with c2f_table3.py's
        defaults.
    control: the model of --control, a c2f_table3.py model trained with --no-coarse-action."""
    flag = "--" + method.replace("_", "-")
    script = f"{method}.py"
    what = f"{method} model"
    accepted = (method,)
    if method == "c2f":
        accepted = C2F_METHODS
    if control:
        flag = "--control"
        script = "c2f_table3.py"
        what = "capacity control"
    if os.path.isdir(path):
        example = os.path.join(path, "seed1.pt")
        raise UsageError(f"{flag} {path} is a folder: pass the model file in it, e.g. {example}")
    if not os.path.isfile(path):
        folder, name = os.path.split(path)
        seed = "1"
        if name.startswith("seed") and name.endswith(".pt") and name[4:-3].isdigit():
            seed = name[4:-3]
        train = f"python {script} --env {env_id} --seeds {seed}"
        if control:
            train += " --no-coarse-action"
        train += f" --save-model --output-dir {folder or '.'}"
        writes = os.path.join(folder, f"seed{seed}.pt")
        raise UsageError(
            f"{what} {path} not found: train one with `{train}` (it writes {writes}), "
            f"or pass {flag} PATH"
        )
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
        saved_method = checkpoint["method"]
        saved_env = checkpoint["env_id"]
        saved = checkpoint["args"]
        weights = checkpoint["state_dict"]
    except Exception as error:
        problem = f"{flag} {path} is not a model saved with --save-model ({type(error).__name__})"
        raise UsageError(f"{problem}: pass a seed<S>.pt written by {script}")
    problem = checkpoint_problem(saved_method, saved_env, saved, weights)
    if problem:
        raise UsageError(f"{flag} {path}: {problem}: re-save it with {script}")
    if saved_method not in accepted:
        raise UsageError(
            f"{flag} {path} is a {saved_method} model, not {method}: "
            f"pass the model written by {script}"
        )
    if saved_env != env_id:
        raise UsageError(
            f"{flag} {path} is a model of {saved_env}, not {env_id}: "
            f"pass a model trained on {env_id}, or --env {saved_env}"
        )
    if method == "c2f":
        # c2f.py's models record no Table 3 flag: they are c2f_table3.py's at its defaults.
        saved = {**TABLE3_DEFAULTS, **saved}
        for name, default in TABLE3_DEFAULTS.items():
            if type(saved[name]) is not type(default):
                raise UsageError(
                    f"{flag} {path}: its args hold {name} {saved[name]!r}, which is not a "
                    f"{type(default).__name__}: re-save it with {script}"
                )
        if saved["coarse_action"] and control:
            raise UsageError(
                f"{flag} {path} is a {saved_method} model trained without --no-coarse-action: "
                "pass C2F's own model as --c2f"
            )
        if not saved["coarse_action"] and not control:
            raise UsageError(
                f"{flag} {path} is a {saved_method} model trained with --no-coarse-action: "
                "pass it as --control (it reads no zeta)"
            )
        if saved["coarse_output"] == "feature":
            raise UsageError(
                f"{flag} {path} passes a feature, not an action zeta, to its policy model: "
                "do(zeta) needs a C2F model trained with --coarse-output action"
            )
    history = saved["history"]
    hidden = saved["hidden"]
    does_not_fit = UsageError(
        f"{flag} {path}: its weights do not fit a {method} policy with history {history} "
        f"and hidden {hidden} on {env_id}'s {obs_dim}-d observations: re-save it with {script}"
    )
    # The sizes are checked on the weights before the policy is built: an edited history or
    # hidden asked for terabytes. BC-SO normalizes o_t only.
    normalized = obs_dim * history
    first_layer = weights.get("net.0.weight")
    if method == "bc_so":
        normalized = obs_dim
    if method == "c2f":
        first_layer = weights.get("coarse.0.weight")
    mean = weights.get("normalize.mean")
    if mean is None or mean.shape != (normalized,):
        raise does_not_fit
    if first_layer is None or first_layer.shape[0] != hidden:
        raise does_not_fit
    # The Normalizer's statistics come from the state_dict.
    inputs = torch.zeros(2, normalized)
    if method == "bc_so":
        policy = SOPolicy(obs_dim, act_dim, history, hidden, inputs)
    elif method == "bc_oh":
        policy = OHPolicy(obs_dim, act_dim, history, hidden, inputs)
    else:
        policy = C2FPolicy(obs_dim, act_dim, inputs, SimpleNamespace(**saved))
    try:
        policy.load_state_dict(weights)
    except RuntimeError:
        raise does_not_fit
    # A training that diverged saves nan weights: every measure of the analysis would be nan.
    for value in weights.values():
        if value.is_floating_point() and not torch.isfinite(value).all():
            raise UsageError(f"{flag} {path}: its weights are not finite: retrain it with {script}")
    return policy.eval(), saved


SAVED_SETTINGS = {
    "history": "a positive int",
    "hidden": "a positive int",
    "obs_noise_std": "a number >= 0 and finite",
    "hide_velocities": "True or False",
    "frame_skip": "a positive int or None",
    "velocity_dims": "a list of ints or None",
}
"""the training settings the analysis reads from a model, as they must be"""
OPTIONAL_SETTINGS = {"hide_velocities": False, "frame_skip": None, "velocity_dims": None}
"""settings that older models may lack, with the value their absence stands for"""


def setting_fits(name: str, value) -> bool:
    """Whether a model's training setting `name` holds what SAVED_SETTINGS says it must."""
    if name in ("history", "hidden"):
        return type(value) is int and value > 0
    if name == "obs_noise_std":
        return type(value) in (int, float) and 0 <= value < np.inf
    if name == "hide_velocities":
        return type(value) is bool
    if value is None:
        return True
    if name == "frame_skip":
        return type(value) is int and value > 0
    return type(value) is list and all(type(entry) is int for entry in value)


def checkpoint_problem(method, env_id, saved, weights) -> Optional[str]:
    """What makes a checkpoint's content unusable (a value of the wrong type, or out of range, as an
    edited or other program's file may hold), or None."""
    for key, value in [("method", method), ("env_id", env_id)]:
        if type(value) is not str:
            return f"its {key} {value!r} is not a str"
    if not isinstance(saved, dict):
        return f"its args are a {type(saved).__name__}, not a dict"
    if not isinstance(weights, dict):
        return f"its state_dict is a {type(weights).__name__}, not a dict"
    for name, value in weights.items():
        if not isinstance(value, torch.Tensor):
            return f"its state_dict holds a {type(value).__name__} as {name}, not a tensor"
    for name, wanted in SAVED_SETTINGS.items():
        if name not in saved and name not in OPTIONAL_SETTINGS:
            return f"its args have no {name}"
        value = saved.get(name, OPTIONAL_SETTINGS.get(name))
        if not setting_fits(name, value):
            return f"its args hold {name} {value!r}, which is not {wanted}"
    return None


def agreed(saved: dict, key: str, flag: str, readers=None, fix="pass models trained alike"):
    """The training value of `key` shared by the models in `readers` (default: all), or a clear
    error when they differ."""
    readers = tuple(saved) if readers is None else readers
    values = {method: saved[method].get(key) for method in readers}
    if len(set(map(str, values.values()))) > 1:
        raise UsageError(f"the models were trained with different {flag} ({values}): {fix}")
    return values[readers[0]]


def as_actor(policy: nn.Module, low: np.ndarray, high: np.ndarray):
    """numpy histories (N, H * obs_dim) -> the clipped actions the env would execute."""

    @torch.no_grad()
    def act(histories: np.ndarray) -> np.ndarray:
        return policy(torch.as_tensor(histories, dtype=torch.float32)).numpy().clip(low, high)

    return act


def zeta_intervention(policy: C2FPolicy, low: np.ndarray, high: np.ndarray):
    """numpy (coarse, final): zeta = pi_phi(o_t), and pi_theta(o_hist, do(zeta)) clipped to the
    action bounds."""

    @torch.no_grad()
    def coarse(histories: np.ndarray) -> np.ndarray:
        return policy.coarse_model(torch.as_tensor(histories, dtype=torch.float32))[0].numpy()

    @torch.no_grad()
    def final(histories: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        obs_history = torch.as_tensor(histories, dtype=torch.float32)
        fixed = torch.as_tensor(zeta, dtype=torch.float32)
        feature = policy.coarse_model(obs_history)[1]

        def fixed_coarse_model(_):
            return fixed, feature

        # This shadows the method for one call: the rest of the forward is the trained one.
        policy.coarse_model = fixed_coarse_model
        try:
            return policy.coarse_and_final(obs_history)[1].numpy().clip(low, high)
        finally:
            del policy.coarse_model

    return coarse, final


# ----------------------------------------------------------------------------------------------
# Interventions and scores (plain numpy functions of policies: histories -> actions)


def distance(a: np.ndarray, b: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per row, the Euclidean distance of two actions measured in units of the demo actions' std."""
    return np.linalg.norm((a - b) / scale, axis=1)


def repeat_current(histories: np.ndarray, obs_dim: int) -> np.ndarray:
    """do(o_hist) = [o_t, ..., o_t]: every frame of each history replaced by its current (last)
    frame."""
    return np.tile(histories[:, -obs_dim:], histories.shape[1] // obs_dim)


def history_intervention(
    act, histories: np.ndarray, obs_dim: int, prev_actions: np.ndarray, scale: np.ndarray
):
    """Per step: how far the action moves under do(o_hist) (mean over dims of |change| / scale),
    and whether the real history pulls it towards a_{t-1} (pi(o_hist) strictly closer to a_{t-1}
    than pi(do(o_hist)))."""
    factual = act(histories)
    counterfactual = act(repeat_current(histories, obs_dim))
    change = (np.abs(factual - counterfactual) / scale).mean(1)
    towards = distance(factual, prev_actions, scale) < distance(counterfactual, prev_actions, scale)
    return change, towards


def changepoints(
    actions: np.ndarray, episode_starts: np.ndarray, scale: np.ndarray, quantile: float
) -> np.ndarray:
    """Steps t with a predecessor in their episode whose |a_t - a_{t-1}| (scaled) is at or above
    its `quantile`."""
    steps = np.flatnonzero(~episode_starts.astype(bool))
    steps = steps[steps > 0]
    jump = distance(actions[steps], actions[steps - 1], scale)
    return steps[jump >= np.quantile(jump, quantile)]


def copycat_score(
    predictions: np.ndarray, actions: np.ndarray, points: np.ndarray, scale: np.ndarray
) -> float:
    """The fraction of the changepoints t whose prediction is closer to a_{t-1} than to a_t."""
    to_prev = distance(predictions[points], actions[points - 1], scale)
    return float(np.mean(to_prev < distance(predictions[points], actions[points], scale)))


def zeta_effect(
    final, histories: np.ndarray, zeta: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """CE[t, d] = |final(h_t, zeta_t with zeta_d = lo_d)_d
    - final(h_t, zeta_t with zeta_d = hi_d)_d|."""
    effect = np.zeros_like(zeta, dtype=np.float64)
    for d in range(zeta.shape[1]):
        low_zeta = zeta.copy()
        low_zeta[:, d] = lo[d]
        high_zeta = zeta.copy()
        high_zeta[:, d] = hi[d]
        effect[:, d] = np.abs(final(histories, low_zeta)[:, d] - final(histories, high_zeta)[:, d])
    return effect


# ----------------------------------------------------------------------------------------------
# Rollouts of each policy in the noisy env


def rollout(
    act,
    env_id: str,
    frame_skip: Optional[int],
    dims: list,
    std: float,
    hide: bool,
    history: int,
    seed: int,
) -> dict:
    """One episode of the deterministic policy on the partially observed env: its histories,
    executed actions, observations (the positions are noise-free) and return."""
    env = PartialObservation(make_env(env_id, frame_skip), dims, std, hide, seed)
    obs, _ = env.reset(seed=seed)
    # The last H frames, the first one repeated (stack_history's rule).
    frames = np.repeat(obs[None], history, axis=0)
    record = {"histories": [], "actions": [], "observations": []}
    total = 0.0
    done = False
    while not done:
        histories = frames.reshape(1, -1)
        action = act(histories)[0]
        record["histories"].append(histories[0])
        record["actions"].append(action)
        record["observations"].append(obs)
        obs, reward, terminated, truncated, _ = env.step(action)
        frames = np.concatenate([frames[1:], obs[None]])
        total += float(reward)
        done = terminated or truncated
    env.close()
    return {**{key: np.array(value) for key, value in record.items()}, "return": total}


def with_previous(episodes: list):
    """(histories, previous actions) of every step but each episode's first, over a list of
    rollouts."""
    histories = np.concatenate([episode["histories"][1:] for episode in episodes])
    return histories, np.concatenate([episode["actions"][:-1] for episode in episodes])


# ----------------------------------------------------------------------------------------------
# Pictures

ACTION_NAMES = {
    "Hopper": ["thigh", "leg", "foot"],
    "Walker2d": ["right thigh", "right leg", "right foot", "left thigh", "left leg", "left foot"],
}
STATE_ROWS = {
    "Hopper": [(0, "torso height (m)"), (2, "thigh angle (rad)")],
    "Walker2d": [(0, "torso height (m)"), (2, "right thigh angle (rad)")],
}


def plot_zeta_effect(
    path: str,
    env_id: str,
    effect: np.ndarray,
    observations: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    episode_return: float,
    late_fusion: bool,
):
    """CE_d / (hi_d - lo_d) along one trajectory (1: the action follows zeta fully, 0: ignores
    it), the state beneath."""
    family = env_id.split("-")[0]
    names = ACTION_NAMES.get(family, [f"a[{d}]" for d in range(effect.shape[1])])
    fig, (top, bottom) = plt.subplots(
        2, 1, sharex=True, figsize=(11, 6), gridspec_kw={"height_ratios": [2, 1]}
    )
    for d in range(effect.shape[1]):
        top.plot(
            effect[:, d] / (hi[d] - lo[d]),
            lw=1,
            label=f"{names[d]}: do(zeta) = {lo[d]:.2f} vs {hi[d]:.2f}",
        )
    top.set_ylabel("CE / (hi - lo)")
    # Late or output fusion: one linear layer after the join, so the effect is a weight of it.
    if late_fusion:
        fig.text(
            0.01,
            0.01,
            "late fusion: the final layer is linear in zeta, so CE / (hi - lo) = "
            "|its weight on zeta_d| wherever the action is not clipped at its bounds "
            "(dips: clipped)",
            fontsize=8,
        )
    top.set_title(
        f"{env_id}, C2F on its own noisy rollout (return {episode_return:.0f}): "
        "causal effect of the coarse action zeta"
    )
    top.legend(loc="upper right", fontsize=8)
    top.grid(alpha=0.3)
    rows = STATE_ROWS.get(family, [(0, "obs[0]"), (1, "obs[1]")])
    bottom.plot(observations[:, rows[0][0]], color="black", lw=1)
    bottom.set_ylabel(rows[0][1])
    twin = bottom.twinx()
    twin.plot(observations[:, rows[1][0]], color="tab:purple", lw=1)
    twin.set_ylabel(rows[1][1], color="tab:purple")
    bottom.set_xlabel("step")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    write_atomically(path, lambda file: fig.savefig(file, format="png", dpi=110))
    plt.close(fig)


def plot_history_intervention(path: str, env_id: str, changes: dict):
    """Per source (held-out demos, own rollouts), the distribution of each method's per-step
    |change| under do(o_hist)."""
    fig, axes = plt.subplots(1, len(changes), figsize=(6 * len(changes), 4))
    for ax, (source, per_method) in zip(np.atleast_1d(axes), changes.items()):
        top = max(float(np.quantile(np.concatenate(list(per_method.values())), 0.99)), 1e-3)
        bins = np.linspace(0, top, 41)
        for method, change in per_method.items():
            ax.hist(
                np.minimum(change, top),
                bins,
                weights=np.full(len(change), 1 / len(change)),
                histtype="step",
                lw=1.5,
                color=COLORS[method],
                label=f"{method} (mean {change.mean():.3f})",
            )
        ax.set_yscale("log")
        ax.set_xlabel(
            "mean |pi(o_hist) - pi(do(o_hist) = [o_t, ..., o_t])| / demo action std\n"
            "(above the 99th percentile: last bin)"
        )
        ax.set_ylabel("fraction of steps")
        ax.set_title(f"{env_id}: intervention on the history, {source}")
        ax.legend(fontsize=8)
    fig.tight_layout()
    write_atomically(path, lambda file: fig.savefig(file, format="png", dpi=110))
    plt.close(fig)


# ----------------------------------------------------------------------------------------------
# The analysis


def check_args(args):
    """Reject bad values before anything slow happens."""
    if args.num_demo_samples < 2:
        raise UsageError(f"--num-demo-samples must be at least 2, got {args.num_demo_samples}")
    if args.eval_episodes <= 0:
        raise UsageError(f"--eval-episodes must be positive, got {args.eval_episodes}")
    if args.history is not None and args.history <= 0:
        raise UsageError(f"--history must be positive, got {args.history}")
    if args.obs_noise_std is not None and not 0 <= args.obs_noise_std < np.inf:
        raise UsageError(f"--obs-noise-std must be >= 0 and finite, got {args.obs_noise_std}")
    if not 0 <= args.zeta_quantile < 0.5:
        raise UsageError(f"--zeta-quantile must lie in [0, 0.5), got {args.zeta_quantile}")
    if not 0 <= args.changepoint_quantile < 1:
        raise UsageError(
            f"--changepoint-quantile must lie in [0, 1), got {args.changepoint_quantile}"
        )
    if not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed must lie in [0, 2**32), got {args.seed}")
    if args.demos is None and args.seed == 0:
        raise UsageError(
            "--seed 0 would regenerate the training demonstrations: "
            "use another seed for held-out demos"
        )
    # An empty --output-dir wrote into this folder, an empty --control ran without the control.
    for name in ["bc_so", "bc_oh", "c2f", "control", "demos", "expert", "output_dir"]:
        if getattr(args, name) == "":
            flag = f"--{name.replace('_', '-')}"
            raise UsageError(f"{flag} is empty: pass a path, or leave {flag} out")
    # The paths may name the env as {env}; another field failed in str.format, after the analysis.
    for name in ["bc_so", "bc_oh", "c2f", "control", "expert", "output_dir"]:
        template = getattr(args, name)
        try:
            if template is not None:
                template.format(env=args.env)
        except (KeyError, IndexError, ValueError):
            flag = f"--{name.replace('_', '-')}"
            raise UsageError(f"{flag} {template}: the one field a path may hold is {{env}}")
    check_output_dir(args.output_dir.format(env=args.env))


def check_output_dir(out_dir: str):
    """Refuse an --output-dir that cannot be made or written in, before the analysis, not after it
    (nothing is made here: the nearest path on its way that exists must be a writable folder)."""
    existing = os.path.abspath(out_dir)
    while not os.path.lexists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise UsageError(
            f"--output-dir {out_dir}: {existing} is not a folder: pass another --output-dir"
        )
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UsageError(
            f"--output-dir {out_dir}: cannot write in {existing}: pass another --output-dir"
        )


def check_actions(actors: dict, paths: dict, histories: np.ndarray, clean: np.ndarray, std: float):
    """Refuse a policy whose actions on the held-out histories are not finite (its weights are):
    every measure of it would be nan. `clean`: the histories without the velocity noise."""
    for method, act in actors.items():
        if np.isfinite(act(histories)).all():
            continue
        flag = "--" + method.replace("_", "-")
        if method == CONTROL:
            flag = "--control"
        problem = f"{flag} {paths[method]} gives non-finite actions on the held-out demos"
        if np.isfinite(act(clean)).all():
            fix = "pass a smaller --obs-noise-std"
            raise UsageError(f"{problem} with velocity noise std {std:g}: {fix}")
        fix = "pass --demos whose observations lie in the range of its training demos"
        raise UsageError(f"{problem}, even without noise: {fix}")


def run(args):
    """Load the three models (four with --control), intervene on held-out demos and on their own
    rollouts, report and draw."""
    check_args(args)
    env = make_env(args.env)
    obs_dim = env.observation_space.shape[0]
    act_dim = env.action_space.shape[0]
    low = env.action_space.low
    high = env.action_space.high
    # An env without a known velocity layout is refused here, before a model's advice to train one.
    dims = velocity_dims(env, args.env)
    models = {}
    saved = {}
    paths = {method: getattr(args, method).format(env=args.env) for method in METHODS}
    for method in METHODS:
        models[method], saved[method] = load_model(
            paths[method], method, args.env, obs_dim, act_dim
        )
    if args.control:
        paths[CONTROL] = args.control.format(env=args.env)
        models[CONTROL], saved[CONTROL] = load_model(
            paths[CONTROL], "c2f", args.env, obs_dim, act_dim, control=True
        )
    for method, training in saved.items():
        # Models made with the old --velocity-dims recorded where their noise went.
        recorded = training.get("velocity_dims")
        if recorded and sorted(set(recorded)) != dims:
            raise UsageError(
                f"{paths[method]} was trained with the noise on observation entries "
                f"{sorted(set(recorded))}, not on {args.env}'s velocities {dims}: retrain it"
            )
    # Models made before the method files recorded their rate hold None: the env's own.
    native = getattr(env.unwrapped, "frame_skip", None)
    rates = {}
    for method, training in saved.items():
        rates[method] = {"frame_skip": training.get("frame_skip") or native}
    # BC-SO reads o_t only: any history fits it.
    model_history = agreed(
        saved,
        "history",
        "--history",
        tuple(m for m in saved if m != "bc_so"),
        "pass models trained with one history length",
    )
    history = args.history or model_history
    if history != model_history:
        raise UsageError(
            f"--history {history} does not match the models, trained with history "
            f"{model_history}: drop --history or pass {model_history}"
        )
    hide = bool(agreed(saved, "hide_velocities", "--hide-velocities"))
    if hide and args.obs_noise_std is not None:
        raise UsageError(
            f"--obs-noise-std {args.obs_noise_std:g}: the models were trained with "
            "--hide-velocities, so the velocities are zeroed, not noisy: leave --obs-noise-std out"
        )
    std = args.obs_noise_std
    if args.obs_noise_std is None:
        fix = "pass --obs-noise-std for the analysis"
        # With the velocities hidden that flag is refused (above): only alike models will do.
        if hide:
            fix = "pass models trained alike"
        std = agreed(saved, "obs_noise_std", "--obs-noise-std", fix=fix)
    frame_skip = agreed(rates, "frame_skip", "--frame-skip")
    # do(o_hist) and the scores need steps with a previous action in their episode.
    episode_steps = env.spec.max_episode_steps
    if frame_skip:
        episode_steps = round(episode_steps * native / frame_skip)
    if episode_steps < 2:
        raise UsageError(
            f"the models were trained at frame skip {frame_skip}, at which an episode of "
            f"{args.env} ends before its second step: pass models of a smaller --frame-skip"
        )

    demos = heldout_demos(args, env, frame_skip)
    if args.demos is not None:
        check_held_out(demos, saved, env, args.env, args.demos)
    actions = demos["actions"].astype(np.float64)
    starts = demos["episode_starts"]
    # The steps with a previous action in their episode.
    steps = np.flatnonzero(~starts)
    if len(steps) == 0:
        source = args.demos or "the held-out demos"
        raise UsageError(
            f"{source}: every step starts an episode, so none has a previous action: "
            "pass demos whose episodes last two steps or more"
        )
    # The expert's action scale, per dim.
    scale = actions.std(0).clip(1e-6)
    lo = np.quantile(actions, args.zeta_quantile, axis=0)
    hi = np.quantile(actions, 1 - args.zeta_quantile, axis=0)
    # do(zeta) sets zeta_d to lo_d, then to hi_d: with lo_d == hi_d its effect is not defined.
    flat = np.flatnonzero(hi <= lo).tolist()
    if flat:
        q = args.zeta_quantile
        spread = f"between their {q:g} and {1 - q:g} quantiles"
        fix = "pass more held-out steps (--num-demo-samples, or a longer --demos)"
        raise UsageError(f"the held-out actions of dims {flat} do not vary {spread}: {fix}")
    observed = partially_observe(demos["observations"], dims, std, hide, args.seed)
    histories = stack_history(observed, starts, history)
    actors = {method: as_actor(model, low, high) for method, model in models.items()}
    clean = stack_history(demos["observations"], starts, history)
    check_actions(actors, paths, histories, clean, std)
    points = changepoints(actions, starts, scale, args.changepoint_quantile)

    rollouts = {
        method: [
            rollout(
                actors[method], args.env, frame_skip, dims, std, hide, history, 1000 * args.seed + i
            )
            for i in range(args.eval_episodes)
        ]
        for method in models
    }
    changes = {"held-out demos": {}, "own rollouts": {}}
    report = {}
    for method in models:
        change, towards = history_intervention(
            actors[method], histories[steps], obs_dim, actions[steps - 1], scale
        )
        roll_histories, roll_prev = with_previous(rollouts[method])
        roll_change, roll_towards = history_intervention(
            actors[method], roll_histories, obs_dim, roll_prev, scale
        )
        changes["held-out demos"][method] = change
        changes["own rollouts"][method] = roll_change
        report[method] = {
            "model": paths[method],
            "rollout_returns": [episode["return"] for episode in rollouts[method]],
            "history_change_demos": float(change.mean()),
            "towards_previous_demos": float(towards.mean()),
            "history_change_rollouts": float(roll_change.mean()),
            "towards_previous_rollouts": float(roll_towards.mean()),
            "copycat_score": copycat_score(actors[method](histories), actions, points, scale),
        }
    coarse, final = zeta_intervention(models["c2f"], low, high)
    c2f_histories = np.concatenate([episode["histories"] for episode in rollouts["c2f"]])
    effect_demos = zeta_effect(final, histories, coarse(histories), lo, hi)
    effect_rollouts = zeta_effect(final, c2f_histories, coarse(c2f_histories), lo, hi)
    first = rollouts["c2f"][0]
    zeta = {
        "lo": lo.tolist(),
        "hi": hi.tolist(),
        "effect_demos": effect_demos.mean(0).tolist(),
        "effect_rollouts": effect_rollouts.mean(0).tolist(),
        "relative_demos": (effect_demos.mean(0) / (hi - lo)).tolist(),
        "relative_rollouts": (effect_rollouts.mean(0) / (hi - lo)).tolist(),
    }

    out_dir = args.output_dir.format(env=args.env)
    plot_zeta_effect(
        os.path.join(out_dir, "zeta_effect.png"),
        args.env,
        effect_rollouts[: len(first["actions"])],
        first["observations"],
        lo,
        hi,
        first["return"],
        saved["c2f"]["fusion"] in ("late", "output"),
    )
    plot_history_intervention(os.path.join(out_dir, "history_intervention.png"), args.env, changes)
    summary = {
        "env": args.env,
        "args": asdict(args),
        "history": history,
        "obs_noise_std": std,
        "frame_skip": frame_skip,
        "hide_velocities": hide,
        "demo_steps": len(actions),
        "changepoints": len(points),
        "action_std": scale.tolist(),
        "methods": report,
        "zeta": zeta,
    }
    write_atomically(
        os.path.join(out_dir, "copycat_analysis.json"),
        lambda file: file.write(json.dumps(summary, indent=1).encode()),
    )

    noise = f"noise std {std}"
    if hide:
        noise = "velocities hidden"
    print(
        f"\n{args.env}: {len(actions)} held-out demo steps ({len(points)} changepoints), "
        f"{args.eval_episodes} rollouts per policy, {noise}, history {history}, "
        f"frame skip {frame_skip or 'native'}"
    )
    print(
        "do(o_hist): mean |change| / action std, "
        "and the fraction of steps the history pulls towards a_{t-1}"
    )
    header = [
        f"{'method':>13}",
        f"{'return':>7}",
        f"{'change demos':>12}",
        f"{'towards':>7}",
        f"{'change rollouts':>15}",
        f"{'towards':>7}",
        f"{'copycat score':>13}",
    ]
    print(" | ".join(header))
    for method, row in report.items():
        cells = [
            f"{method:>13}",
            f"{np.mean(row['rollout_returns']):7.1f}",
            f"{row['history_change_demos']:12.3f}",
            f"{row['towards_previous_demos']:7.2f}",
            f"{row['history_change_rollouts']:15.3f}",
            f"{row['towards_previous_rollouts']:7.2f}",
            f"{row['copycat_score']:13.2f}",
        ]
        print(" | ".join(cells))
    print(
        "do(zeta), c2f: CE = |pi(do(zeta_d) = lo_d) - pi(do(zeta_d) = hi_d)|_d, and CE / (hi - lo)"
    )
    header = [
        f"{'dim':>3}",
        f"{'lo':>6}",
        f"{'hi':>6}",
        f"{'CE demos':>8}",
        f"{'rel':>5}",
        f"{'CE rollouts':>11}",
        f"{'rel':>5}",
    ]
    print(" | ".join(header))
    for d in range(act_dim):
        cells = [
            f"{d:>3}",
            f"{lo[d]:6.2f}",
            f"{hi[d]:6.2f}",
            f"{zeta['effect_demos'][d]:8.3f}",
            f"{zeta['relative_demos'][d]:5.2f}",
            f"{zeta['effect_rollouts'][d]:11.3f}",
            f"{zeta['relative_rollouts'][d]:5.2f}",
        ]
        print(" | ".join(cells))
    print(
        f"pictures and report: {out_dir}/ "
        "(zeta_effect.png, history_intervention.png, copycat_analysis.json)"
    )


if __name__ == "__main__":
    # `kill PID` stops the analysis as Ctrl-C does.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        run(tyro.cli(Args))
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    except OSError as error:
        # A path that cannot be written: a folder, or a file in the way.
        problem = f"cannot use {error.filename}: {error.strerror}"
        print(f"error: {problem}: pass another path", file=sys.stderr)
        sys.exit(2)
