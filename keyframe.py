# KeyFrame: keyframe-focused imitation (Wen et al. 2021), a baseline of the paper's Table 2
"""KeyFrame: BC-OH whose loss is weighted up on the keyframes, the samples where a model that
predicts a_t from the previous actions errs most.

Those are often the moments where the expert's action changes: the ones a copycat policy misses. As
the authors do, the action-prediction model is trained first, once per seed; the samples with the
top 10% of its error (APE) weigh 5 in the behavioural-cloning loss, all others 1.

    python keyframe.py --env Hopper-v4
"""

import functools
import json
import multiprocessing
import os
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import gymnasium as gym
import mujoco
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
import tyro

METHOD = "keyframe"
LOSS = "the KeyFrame-weighted MSE to the expert's actions"


@dataclass
class Args:
    """KeyFrame: BC-OH weighted up where past actions predict a_t worst (APE), on MuJoCo."""

    exp_name: str = Path(__file__).stem
    """the name of this experiment, part of the default output folder"""
    env: str = "Hopper-v4"
    """gymnasium MuJoCo env id with its version (Hopper, HalfCheetah, Walker2d, Ant; v4 or v5)"""
    frame_skip: int | None = None
    """simulator steps per action; None: the env's own"""
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3])
    """training seeds, one run each; the result is their mean ± std"""
    workers: int | None = None
    """seeds trained at once, one process each; None: one per seed; with --cuda always 1"""
    demos: str | None = None
    """demonstrations (.npz); None: demos/<env>_<N>.npz, made by expert_ppo.py --make-demos"""
    num_demo_samples: int | None = None
    """demonstration steps; None: 20000 for Hopper, 10000 otherwise (--demos: the whole file)"""
    obs_noise_std: float = 0.2
    """std of the Gaussian noise on the velocity entries of each observation"""
    hide_velocities: bool = False
    """set the velocity entries to zero instead of adding noise (positions only)"""
    history: int = 2
    """frames H in the observation history, o_t included"""
    epochs: int = 1000
    """epochs of (demo steps // batch size) minibatches, each drawn uniformly with replacement"""
    batch_size: int = 64
    """minibatch size"""
    learning_rate: float | None = None
    """Adam learning rate, decayed linearly to 0; None: 1e-5 for Hopper, 1e-4 otherwise"""
    hidden: int = 256
    """width of the hidden layers"""
    eval_every: int = 100
    """evaluate every this many epochs and after the last; a seed's score: the mean of the last 3"""
    eval_episodes: int = 10
    """episodes per evaluation"""
    output_dir: str | None = None
    """folder of the results and models; None: runs/<env>__<exp-name>__<unix time>"""
    save_model: bool = False
    """save each seed's policy (weights, normalisation, args)"""
    cuda: bool = False
    """train on the GPU"""
    keyframe_k: int = 4
    """K, previous actions the action-prediction model sees (MuJoCo: ours; the authors' CARLA: 9)"""
    keyframe_spacing: int = 1
    """steps between them: a_{t-Ks}, ..., a_{t-2s}, a_{t-s} (MuJoCo: ours; the authors' CARLA: 3)"""
    keyframe_fraction: float = 0.1
    """share of the samples, those of highest APE, that are keyframes, in (0, 1]"""
    keyframe_weight: float = 5.0
    """loss weight of a keyframe with --weighting threshold; the other samples weigh 1"""
    weighting: Literal["threshold", "softmax"] = "threshold"
    """threshold: --keyframe-weight on the keyframes; softmax: N softmax(APE / T) in a batch of N"""
    keyframe_temperature: float = 1.0
    """T, the temperature of --weighting softmax, in APE's units (a squared action error)"""
    keyframe_model_epochs: int = 20
    """passes over the demos (minibatches of --batch-size) that train the action-prediction model"""


# ---- The method: KeyFrame's weights, network, loss and training loop ----
# Copied from bc_oh.mlp..stack_history
def mlp(in_dim: int, out_dim: int, hidden: int) -> nn.Sequential:
    """The paper's three-layer MLP (section 8.3)."""
    layers = [nn.Linear(in_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU()]
    return nn.Sequential(*layers, nn.Linear(hidden, out_dim))


class Normalizer(nn.Module):
    """Standardises entries by the training inputs' mean and std (>= 1e-6); saved with the model."""

    def __init__(self, inputs: torch.Tensor):
        super().__init__()
        self.register_buffer("mean", inputs.mean(0))
        self.register_buffer("std", inputs.std(0).clamp_min(1e-6))

    def forward(self, x):
        return (x - self.mean) / self.std


class Policy(nn.Module):
    """BC-OH: the whole history, flattened, goes into one MLP."""

    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, inputs: torch.Tensor):
        super().__init__()
        self.normalize = Normalizer(inputs)
        self.net = mlp(obs_dim * history, act_dim, hidden)

    def forward(self, obs_history):
        return self.net(self.normalize(obs_history))


def make_policy(args, obs_dim: int, act_dim: int, inputs: torch.Tensor) -> nn.Module:
    return Policy(obs_dim, act_dim, args.history, args.hidden, inputs)


def stack_history(observations: np.ndarray, episode_starts: np.ndarray, history: int) -> np.ndarray:
    """Row t: [o_{t-H+1}, ..., o_t], oldest first; a frame before t's episode is its first frame."""
    index = np.arange(len(observations))
    first_of_episode = np.maximum.accumulate(np.where(episode_starts, index, 0))
    frames = []
    for lag in reversed(range(history)):
        frames.append(observations[np.maximum(index - lag, first_of_episode)])
    return np.concatenate(frames, axis=1)


def previous_actions(actions, episode_starts, k: int, spacing: int) -> np.ndarray:
    """Row t holds [a_{t-Ks}, ..., a_{t-s}]; before an episode's start, its first action."""
    span = k * spacing + 1
    frames = stack_history(actions, episode_starts, span).reshape(len(actions), span, -1)
    # Every s-th of the actions before a_t, oldest first: the slice stops before a_t, the last.
    return frames[:, 0 : k * spacing : spacing].reshape(len(actions), -1)


def action_prediction_errors(actions, episode_starts, k, spacing, epochs, batch_size, device):
    """APE_t = ||f(a_{t-Ks}, ..., a_{t-s}) - a_t||^2, f trained first (the caller seeds torch)."""
    previous = previous_actions(actions, episode_starts, k, spacing)
    inputs = torch.as_tensor(previous, dtype=torch.float32, device=device)
    targets = torch.as_tensor(actions, dtype=torch.float32, device=device)
    # The authors' model (one hidden layer of 300, LeakyReLU(0.2)) and Adam lr; not their schedule.
    layers = [nn.Linear(inputs.shape[1], 300), nn.LeakyReLU(0.2), nn.Linear(300, targets.shape[1])]
    model = nn.Sequential(*layers).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3, fused=True)
    for _ in range(epochs * max(1, len(inputs) // batch_size)):
        idx = torch.randint(len(inputs), (batch_size,), device=device)
        optimizer.zero_grad()
        loss = F.mse_loss(model(inputs[idx]), targets[idx])
        loss.backward()
        optimizer.step()
    # Each sample's squared error summed over the action's entries; the threshold uses its rank.
    with torch.no_grad():
        return ((model(inputs) - targets) ** 2).sum(1)


def keyframes(ape: torch.Tensor, fraction: float) -> torch.Tensor:
    """The keyframes: a mask of the round(fraction * N) samples of highest APE, at least one."""
    count = max(1, round(fraction * len(ape)))
    top = torch.topk(ape, count).indices
    mask = torch.zeros_like(ape, dtype=torch.bool)
    return mask.index_fill_(0, top, True)


def keyframe_weights(ape: torch.Tensor, fraction: float, weight: float) -> torch.Tensor:
    """The authors' threshold weighting: `weight` on the keyframes, 1 on the other samples."""
    return torch.where(keyframes(ape, fraction), weight, 1.0)


def softmax_weights(ape: torch.Tensor, temperature: float) -> torch.Tensor:
    """The authors' other weighting, of one batch: N softmax(APE / temperature), whose mean is 1."""
    return torch.softmax(ape / temperature, dim=0) * len(ape)


def changepoints(actions: np.ndarray, episode_starts: np.ndarray, fraction=0.1) -> np.ndarray:
    """A mask of the largest action changes ||a_t - a_{t-1}|| within episodes (the top 10%)."""
    previous = previous_actions(actions, episode_starts, 1, 1)
    jump = np.linalg.norm(actions - previous, axis=1)
    count = max(1, round(fraction * len(actions)))
    top = np.argsort(-jump, kind="stable")[:count]
    return np.isin(np.arange(len(actions)), top)


def train_seed(args, demos: dict, seed: int, device) -> tuple:
    """Train on the demos; return (evaluations [(epoch, mean return)], the policy, ms/step)."""
    torch.manual_seed(seed)
    env = make_env(args.env)
    obs_dim = env.observation_space.shape[0]
    act_dim = env.action_space.shape[0]
    # Section 5.1: noise on the demos' velocities (drawn once), then histories of H frames.
    dims = velocity_dims(env, args.env)
    observations = demos["observations"]
    observed = partially_observe(observations, dims, args.obs_noise_std, args.hide_velocities, seed)
    histories = stack_history(observed, demos["episode_starts"], args.history)
    inputs = torch.as_tensor(histories, dtype=torch.float32, device=device)
    targets = torch.as_tensor(demos["actions"], dtype=torch.float32, device=device)
    # KeyFrame: the action-prediction errors, and the weights of the samples in the loss.
    actions = demos["actions"]
    starts = demos["episode_starts"]
    k = args.keyframe_k
    spacing = args.keyframe_spacing
    epochs = args.keyframe_model_epochs
    ape = action_prediction_errors(actions, starts, k, spacing, epochs, args.batch_size, device)
    weights = keyframe_weights(ape, args.keyframe_fraction, args.keyframe_weight)
    # Printed only: how many keyframes sit on the largest action changes (a copycat misses them).
    is_key = keyframes(ape, args.keyframe_fraction).cpu().numpy()
    at_change = changepoints(actions, starts)
    found = f"{is_key.sum()} of {len(is_key)} samples"
    found += f", {(is_key & at_change).sum()} of them at action changepoints"
    found += f" (top 10% of ||a_t - a_{{t-1}}||; {at_change.sum()} in all)"
    print(f"seed {seed} | keyframes (top {args.keyframe_fraction:.0%} of APE): {found}")
    policy = make_policy(args, obs_dim, act_dim, inputs).to(device)
    optimizer = torch.optim.Adam(policy.parameters(), lr=args.learning_rate, fused=True)

    def train_step(idx):
        if args.weighting == "threshold":
            weight = weights[idx]
        else:
            weight = softmax_weights(ape[idx], args.keyframe_temperature)
        # BC, each sample's squared error times its weight, not renormalised (as the authors do).
        error = ((policy(inputs[idx]) - targets[idx]) ** 2).mean(1)
        loss = (weight * error).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        return loss

    evaluations, ms_per_step = fit(args, policy, optimizer, train_step, len(inputs), seed, device)
    return evaluations, policy, ms_per_step


# Copied from bc_oh.fit..train_seeds
def fit(args, policy, optimizer, train_step, num_samples: int, seed: int, device) -> tuple:
    """The training loop: random minibatches, a linearly decaying learning rate, evaluations."""
    steps_per_epoch = num_samples // args.batch_size
    total_steps = args.epochs * steps_per_epoch
    generator = torch.Generator(device=device).manual_seed(seed)
    evaluations = []
    step = 0
    train_time = 0.0
    start = time.time()
    for epoch in range(1, args.epochs + 1):
        epoch_start = time.time()
        for _ in range(steps_per_epoch):
            # Linear learning-rate decay (section 8.3), from the initial rate towards 0.
            for group in optimizer.param_groups:
                group["lr"] = args.learning_rate * (1 - step / total_steps)
            idx = torch.randint(num_samples, (args.batch_size,), device=device, generator=generator)
            loss = train_step(idx)
            step += 1
        # The epoch's last minibatch loss; item() waits for the GPU, so train_time counts it all.
        last_loss = loss.item()
        train_time += time.time() - epoch_start
        if not np.isfinite(last_loss):
            diverged = f"seed {seed}: training diverged at epoch {epoch} (loss {last_loss})"
            raise UsageError(f"{diverged}: use a smaller --learning-rate or --obs-noise-std")
        evaluating = epoch % args.eval_every == 0 or epoch == args.epochs
        if evaluating:
            policy.eval()
            returns = evaluate(policy, args, args.eval_episodes, 10_000 * seed + epoch, device)
            evaluations.append((epoch, float(np.mean(returns))))
            policy.train()
        if evaluating or epoch == 1 or epoch % max(1, args.epochs // 20) == 0:
            last_return = f"{evaluations[-1][1]:.1f}" if evaluations else "n/a"
            ms_per_step = 1000 * train_time / step
            minutes_left = (time.time() - start) / epoch * (args.epochs - epoch) / 60
            progress = f"seed {seed} | epoch {epoch}/{args.epochs} | loss {last_loss:.5f}"
            progress += f" | last eval {last_return} | {ms_per_step:.2f} ms/step"
            print(f"{progress} | {minutes_left:.1f} min left", flush=True)
    return evaluations, 1000 * train_time / step


# ---- Evaluation ----
@torch.no_grad()
def evaluate(policy: nn.Module, args, episodes: int, seed: int, device) -> list:
    """The deterministic policy's returns, one episode per env; seed + i: env i's start, noise."""
    env_fns = [functools.partial(make_sensor_env, args, seed + i) for i in range(episodes)]
    autoreset = gym.vector.AutoresetMode.SAME_STEP
    envs = gym.vector.SyncVectorEnv(env_fns, autoreset_mode=autoreset)
    low = envs.single_action_space.low
    high = envs.single_action_space.high
    obs, _ = envs.reset(seed=seed)
    # The history starts as the first frame repeated, as stack_history does.
    frames = np.repeat(obs[:, None], args.history, axis=1)
    returns = np.zeros(episodes)
    running = np.ones(episodes, dtype=bool)
    while running.any():
        inputs = torch.as_tensor(frames.reshape(episodes, -1), dtype=torch.float32, device=device)
        actions = policy(inputs).cpu().numpy().clip(low, high)
        obs, reward, terminated, truncated, _ = envs.step(actions)
        # Each env plays one episode: what comes after its end does not count.
        returns[running] += reward[running]
        running &= ~(terminated | truncated)
        frames = np.concatenate([frames[:, 1:], obs[:, None]], axis=1)
    envs.close()
    return returns.tolist()


# ---- The env and its partial observability (section 5.1) ----
class UsageError(Exception):
    """Bad input from the user: printed as one line on stderr, exit status 2, no traceback."""


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


def make_sensor_env(args, seed: int) -> gym.Env:
    env = make_env(args.env, args.frame_skip)
    dims = velocity_dims(env, args.env)
    return PartialObservation(env, dims, args.obs_noise_std, args.hide_velocities, seed)


def partially_observe(observations, dims: list, std: float, hide: bool, seed: int) -> np.ndarray:
    """PartialObservation's noise on the demos, drawn once from seed and fixed for all epochs."""
    observed = observations.copy()
    rng = np.random.default_rng(seed)
    if hide:
        observed[:, dims] = 0.0
    else:
        observed[:, dims] += rng.normal(0.0, std, (len(observed), len(dims)))
    return observed


def print_mujoco_warning(text: str):
    # MuJoCo 3.x warns about gymnasium's HalfCheetah model each time it is made: skip that one.
    if "settotalmass" not in text:
        print(f"MuJoCo warning: {text}", file=sys.stderr)


# At import (spawned workers too): mute gymnasium's warnings (v4 is deprecated); filter MuJoCo's.
gym.logger.min_level = gym.logger.ERROR
mujoco.set_mju_user_warning(print_mujoco_warning)


# ---- The demonstrations, checked: a wrong file must not give a silently wrong result ----
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


# ---- Seeds and main: each seed in its own process, its result written when it ends ----
def train_and_record(args, demos: dict, seed: int, output_dir: str) -> dict:
    """Train one seed, save its policy if asked, and write its result at once."""
    # Small networks gain nothing from more threads; a pool worker starts with all the cores.
    torch.set_num_threads(1)
    print(f"seed {seed} | training", flush=True)
    device = torch.device("cuda" if args.cuda else "cpu")
    evaluations, policy, ms_per_step = train_seed(args, demos, seed, device)
    # A seed's score is the mean return of its last three evaluations (section 8.3).
    score = float(np.mean([mean_return for _, mean_return in evaluations[-3:]]))
    entry = {"score": score, "evaluations": evaluations, "ms_per_step": ms_per_step}
    if args.save_model:
        checkpoint = {"method": METHOD, "env_id": args.env, "args": asdict(args)}
        checkpoint["obs_dim"] = demos["observations"].shape[1]
        checkpoint["act_dim"] = demos["actions"].shape[1]
        checkpoint["state_dict"] = policy.cpu().state_dict()
        path = os.path.join(output_dir, f"seed{seed}.pt")
        # Write a temporary file, then rename it: an interrupted run leaves no half-written file.
        torch.save(checkpoint, f"{path}.tmp")
        os.replace(f"{path}.tmp", path)
    write_result(output_dir, args, {seed: entry})
    return entry


def write_result(output_dir: str, args, per_seed: dict) -> str:
    """Write result_seeds<seeds>.json: the args, each seed's score and evaluations, mean and std."""
    scores = [entry["score"] for entry in per_seed.values()]
    recorded = asdict(args)
    recorded["seeds"] = list(per_seed)
    recorded["output_dir"] = os.path.relpath(output_dir)
    result = {"env": args.env, "method": METHOD, "args": recorded, "scores": per_seed}
    result["mean"] = np.mean(scores)
    result["std"] = np.std(scores)
    seeds = "-".join(str(seed) for seed in per_seed)
    path = Path(output_dir, f"result_seeds{seeds}.json")
    # Write a temporary file, then rename it: a reader never finds half a result.
    Path(f"{path}.tmp").write_text(json.dumps(result, indent=1))
    os.replace(f"{path}.tmp", path)
    return str(path)


def start_worker():
    # One write per printed line, so that the lines of parallel seeds do not mix.
    sys.stdout.reconfigure(line_buffering=True, write_through=False)


def train_seeds(args, demos: dict, output_dir: str) -> list:
    """Train every seed, one process each (one after another with --workers 1 or --cuda); return
    their entries. Ctrl-C, `kill` or a worker's death stops them all in one line."""
    workers = min(args.workers or len(args.seeds), len(args.seeds))
    if args.cuda:
        workers = 1
    jobs = [(args, demos, seed, output_dir) for seed in args.seeds]
    callers_children = set(multiprocessing.active_children())
    try:
        if workers == 1:
            entries = [train_and_record(*job) for job in jobs]
        else:
            # spawn, not fork: torch and MuJoCo are not fork-safe.
            context = multiprocessing.get_context("spawn")
            pool = ProcessPoolExecutor(workers, context, initializer=start_worker)
            # Ctrl-C reaches every process of the job, but only the main process should handle it:
            # the workers start (in submit) while it is ignored, and they keep ignoring it.
            handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
            futures = [pool.submit(train_and_record, *job) for job in jobs]
            signal.signal(signal.SIGINT, handler)
            # Every seed runs to its end, even when another fails, before the results are read.
            wait(futures)
            entries = [future.result() for future in futures]
    except (KeyboardInterrupt, BrokenProcessPool) as error:
        # Ctrl-C, `kill` or a killed worker (out of memory?): the finished seeds' results stay.
        finished = [s for s in args.seeds if Path(output_dir, f"result_seeds{s}.json").exists()]
        message = "no seed finished"
        if finished:
            message = f"seeds {finished} finished, their results are in {output_dir}"
        if isinstance(error, BrokenProcessPool):
            print(f"a worker died (killed, out of memory or crashed): {message}", file=sys.stderr)
            sys.exit(1)
        print(f"interrupted: {message}", file=sys.stderr)
        sys.exit(130)
    finally:
        # Stop the pool's workers at once (their own exit takes seconds), not the caller's children.
        for worker in set(multiprocessing.active_children()) - callers_children:
            worker.terminate()
    return entries


def run(args):
    """Check the flags, load the demos, train every seed, print the table and mean ± std."""
    # Sizes must be positive; None leaves a flag at its default.
    sizes = ["history", "epochs", "batch_size", "hidden", "eval_every", "eval_episodes"]
    sizes += ["keyframe_k", "keyframe_spacing", "keyframe_weight", "keyframe_temperature"]
    sizes += ["keyframe_model_epochs"]
    for name in sizes + ["learning_rate", "frame_skip", "num_demo_samples", "workers"]:
        value = getattr(args, name)
        if value is not None and not 0 < value < np.inf:
            raise UsageError(f"--{name.replace('_', '-')} must be positive and finite, got {value}")
    if not 0 <= args.obs_noise_std < np.inf:
        raise UsageError(f"--obs-noise-std must be >= 0 and finite, got {args.obs_noise_std}")
    if not 0 < args.keyframe_fraction <= 1:
        raise UsageError(f"--keyframe-fraction must lie in (0, 1], got {args.keyframe_fraction}")
    if len(args.seeds) == 0 or len(set(args.seeds)) < len(args.seeds):
        raise UsageError(f"--seeds needs distinct seeds, got {args.seeds}: e.g. --seeds 1 2 3")
    # A range that numpy's and torch's generators both take (numpy's refuse a negative seed).
    if min(args.seeds) < 0 or max(args.seeds) >= 2**32:
        raise UsageError(f"--seeds must lie in [0, 2**32), got {args.seeds}")
    if args.cuda and not torch.cuda.is_available():
        raise UsageError("--cuda, but torch sees no CUDA GPU here: leave --cuda out")

    # Bad env ids, velocity layouts, frame skips fail here, not in a worker; None flags get values.
    env = make_env(args.env)
    velocity_dims(env, args.env)
    if args.frame_skip is None:
        args.frame_skip = getattr(env.unwrapped, "frame_skip", None)
    make_env(args.env, args.frame_skip)
    # Section 8.3's learning rates: 1e-5 for Hopper, 1e-4 for HalfCheetah and Ant (the rest too).
    if args.learning_rate is None:
        args.learning_rate = 1e-5 if args.env.startswith("Hopper") else 1e-4
    demos, meta = load_demos(args, env)
    output_dir = args.output_dir or f"runs/{args.env}__{args.exp_name}__{int(time.time())}"
    try:
        os.makedirs(output_dir, exist_ok=True)
    except OSError as error:
        raise UsageError(f"cannot make {output_dir} ({error.strerror}): pass another --output-dir")
    if not os.access(output_dir, os.W_OK):
        raise UsageError(f"cannot write in {output_dir}: pass another --output-dir")

    print(f"progress lines: loss = {LOSS}; last eval = the mean return of the latest evaluation")
    entries = train_seeds(args, demos, output_dir)

    per_seed = dict(zip(args.seeds, entries))
    result_path = write_result(output_dir, args, per_seed)
    print(f"\n{'seed':>6} | score (mean return of the last 3 evaluations, or all if fewer)")
    for seed, entry in per_seed.items():
        print(f"{seed:>6} | {entry['score']:.1f}")
    scores = [entry["score"] for entry in per_seed.values()]
    mean = np.mean(scores)
    seeds = "seed" if len(scores) == 1 else "seeds"
    spread = f"mean ± std over {len(scores)} {seeds}"
    line = f"{args.env} {METHOD}: score {mean:.1f} ± {np.std(scores):.1f} ({spread})"
    # Demos from elsewhere (e.g. Minari) have no expert to compare with.
    if meta.get("expert_return"):
        line += f", {mean / meta['expert_return']:.0%} of the expert's {meta['expert_return']:.0f}"
    print(f"result: {result_path}")
    print(line)


if __name__ == "__main__":
    # `kill PID` stops the job as Ctrl-C does.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        run(tyro.cli(Args))
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        # Ctrl-C before the seeds start (while the env and demos load) or after they end.
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    finally:
        # The job is over: a second Ctrl-C or `kill` must not break its exit (the pool's cleanup).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
