# PPO expert that makes the demonstrations (paper section 8.3, "Data Collection"); see README.md
"""Proximal Policy Optimisation for gymnasium (>= 1.1) MuJoCo envs, CleanRL style, in one file.

Train:    python expert_ppo.py --env Hopper-v4 --total-timesteps 3000000
Resume:   python expert_ppo.py --env Hopper-v4 --total-timesteps 3000000 --resume
Evaluate: python expert_ppo.py --env Hopper-v4 --eval-only --checkpoint experts/Hopper-v4.pt
Demos:    python expert_ppo.py --env Hopper-v4 --make-demos   (input of bc_oh.py, c2f.py, ...)
"""

import hashlib
import json
import os
import platform
import re
import signal
import sys
import time
from dataclasses import asdict, dataclass

import gymnasium as gym
import mujoco
import numpy as np
import torch
import torch.nn as nn
import tyro


@dataclass
class Args:
    env: str = "Hopper-v4"
    """gymnasium MuJoCo env id (Hopper, HalfCheetah, Walker2d, Ant; v4 or v5)"""
    frame_skip: int | None = None
    """simulator steps per action; None: the env's own (the expert's with --eval-only)"""
    seed: int = 1
    """training seed (torch, envs); demos use seed 0, final evaluations 10000+"""
    total_timesteps: int = 3_000_000
    """env steps in all (a --resume's earlier ones too), summed over the envs, whole rollouts"""
    learning_rate: float = 3e-4
    """Adam learning rate, annealed linearly to zero over total-timesteps"""
    num_envs: int = 8
    """parallel envs in the (synchronous) vector env"""
    num_steps: int = 256
    """steps per env per rollout; a rollout holds num-envs * num-steps transitions"""
    gamma: float = 0.99
    """discount factor"""
    gae_lambda: float = 0.95
    """lambda of generalised advantage estimation"""
    num_minibatches: int = 32
    """minibatches per epoch over one rollout"""
    update_epochs: int = 10
    """epochs over each rollout"""
    clip_coef: float = 0.2
    """PPO ratio clipping"""
    ent_coef: float = 0.0
    """entropy bonus"""
    vf_coef: float = 0.5
    """weight of the value loss"""
    max_grad_norm: float = 0.5
    """gradient-norm clipping"""
    hidden: int = 64
    """width of the two tanh hidden layers of actor and critic"""
    output_dir: str = "runs/expert_ppo/{env}__{seed}{rate}"
    """where latest.pt and best.pt go; {rate}: _fsK at a --frame-skip K other than the env's"""
    save_every_steps: int = 100_000
    """write latest.pt every this many env steps"""
    eval_every_steps: int = 250_000
    """evaluate the deterministic policy every this many env steps, keeping the best as best.pt"""
    train_eval_episodes: int = 5
    """episodes of each periodic evaluation during training"""
    resume: bool = False
    """continue from output-dir/latest.pt when it exists (start fresh otherwise)"""
    max_minutes: float = 0.0
    """stop cleanly (checkpoint written) after this many minutes; 0 = no limit. Resume later."""
    threads: int = 1
    """torch CPU threads for training (--make-demos uses 1); 1 is fastest for small networks"""
    eval_only: bool = False
    """only evaluate --checkpoint, printing per-episode returns and a summary line"""
    checkpoint: str = "experts/{env}.pt"
    """expert to roll out; default rate: its training one (--eval-only), the env's (--make-demos)"""
    eval_episodes: int = 20
    """episodes of --eval-only and of the final evaluation after training"""
    ship_to: str | None = None
    """with --eval-only: also write the checkpoint, with its evaluated return, to this path"""
    make_demos: bool = False
    """roll --checkpoint out into ./demos/<env>[_fs<K>]_<N>.npz (kept if this expert made it)"""
    num_demo_samples: int | None = None
    """with --make-demos: steps; None: 20000 for Hopper, 10000 otherwise (8.3; HalfCheetah: ours)"""
    retarget: bool = False
    """with --eval-only: --checkpoint may be made for another version of --env (v4 for v5)"""


# ---- The method: PPO's actor and critic, and its running normalisation ----
def mlp(in_dim: int, out_dim: int, hidden: int, last_std: float) -> nn.Sequential:
    """Two tanh hidden layers with orthogonal init, as in Huang et al.'s PPO details."""
    first = nn.Linear(in_dim, hidden)
    second = nn.Linear(hidden, hidden)
    last = nn.Linear(hidden, out_dim)
    for layer, std in ((first, np.sqrt(2)), (second, np.sqrt(2)), (last, last_std)):
        nn.init.orthogonal_(layer.weight, std)
        nn.init.zeros_(layer.bias)
    return nn.Sequential(first, nn.Tanh(), second, nn.Tanh(), last)


class Agent(nn.Module):
    def __init__(self, obs_dim: int, act_dim: int, hidden: int):
        super().__init__()
        self.critic = mlp(obs_dim, 1, hidden, 1.0)
        self.actor_mean = mlp(obs_dim, act_dim, hidden, 0.01)
        self.actor_logstd = nn.Parameter(torch.zeros(1, act_dim))

    def value(self, obs):
        return self.critic(obs).squeeze(-1)

    def action_and_value(self, obs, action=None):
        mean = self.actor_mean(obs)
        std = self.actor_logstd.expand_as(mean).exp()
        # Not validated: train refuses the NaN weights of a diverged update itself, in one line.
        dist = torch.distributions.Normal(mean, std, validate_args=False)
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.value(obs)


class RunningMeanStd:
    """Running mean and variance (Chan et al.), one for all envs; normalize() clips to +-10."""

    def __init__(self, shape=()):
        self.mean = np.zeros(shape)
        self.var = np.ones(shape)
        self.count = 1e-4

    def update(self, batch: np.ndarray):
        batch_count = batch.shape[0]
        delta = batch.mean(0) - self.mean
        total = self.count + batch_count
        self.mean = self.mean + delta * batch_count / total
        correction = delta**2 * self.count * batch_count / total
        self.var = (self.var * self.count + batch.var(0) * batch_count + correction) / total
        self.count = total

    def normalize(self, x: np.ndarray) -> torch.Tensor:
        clipped = np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -10.0, 10.0)
        return torch.as_tensor(clipped, dtype=torch.float32)


# ---- Training: rollouts, advantages (GAE), the clipped update, checkpoints ----
def validate(args: Args):
    # require(0 < value < inf) refuses a NaN too: every comparison with NaN is False.
    positive = "total_timesteps num_envs num_steps num_minibatches update_epochs hidden"
    positive += " save_every_steps eval_every_steps train_eval_episodes eval_episodes threads"
    positive += " learning_rate clip_coef max_grad_norm"
    for name in positive.split():
        value = getattr(args, name)
        flag = "--" + name.replace("_", "-")
        require(0 < value < np.inf, f"{flag} must be positive and finite, got {value}")
    require(args.clip_coef < 1e38, f"--clip-coef must be below 1e38, got {args.clip_coef}")
    # 0 is allowed here (no entropy bonus, no time limit); NaN or a negative value is refused.
    for name in ["ent_coef", "vf_coef", "max_minutes"]:
        value = getattr(args, name)
        flag = "--" + name.replace("_", "-")
        require(0 <= value < np.inf, f"{flag} must lie in [0, inf), got {value}")
    require(0 <= args.seed < 2**32, f"--seed must lie in [0, 2**32), got {args.seed}")
    require(0 < args.gamma <= 1, f"--gamma must be in (0, 1], got {args.gamma}")
    require(0 <= args.gae_lambda <= 1, f"--gae-lambda must be in [0, 1], got {args.gae_lambda}")
    batch_size = args.num_envs * args.num_steps
    fits = batch_size % args.num_minibatches == 0 and batch_size >= 2 * args.num_minibatches
    require(fits, "--num-minibatches must divide num-envs * num-steps, 2 steps a minibatch or more")


def train(args: Args):
    validate(args)
    native = env_frame_skip(args.env)
    # None becomes the env's own frame skip here, so that args and checkpoints record the rate used.
    args.frame_skip = env_frame_skip(args.env, args.frame_skip)
    rate = "" if args.frame_skip == native else f"_fs{args.frame_skip}"
    try:
        output_dir = args.output_dir.format(env=args.env, seed=args.seed, rate=rate)
        os.makedirs(output_dir, exist_ok=True)
    except (KeyError, IndexError, ValueError, OSError) as error:
        raise UsageError(f"cannot make --output-dir {args.output_dir} ({error!r}): pass another")
    require(os.access(output_dir, os.W_OK), f"--output-dir {output_dir} is read-only: pass another")
    latest_path = os.path.join(output_dir, "latest.pt")
    best_path = os.path.join(output_dir, "best.pt")
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)

    # SAME_STEP autoreset: a step that ends an episode returns the reset observation and puts the
    # last one in info["final_obs"], from which a truncated episode bootstraps.
    envs = gym.vector.SyncVectorEnv(
        [lambda: make_env(args.env, args.frame_skip) for _ in range(args.num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    obs_dim = envs.single_observation_space.shape[0]
    act_dim = envs.single_action_space.shape[0]
    action_low, action_high = envs.single_action_space.low, envs.single_action_space.high
    agent = Agent(obs_dim, act_dim, args.hidden)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5, fused=True)
    obs_rms = RunningMeanStd((obs_dim,))
    ret_rms = RunningMeanStd()
    global_step = 0
    best_return = -np.inf

    # A checkpoint: a plain dict that torch.load(weights_only=True) reads (experts/README.md).
    def checkpoint(eval_return=None):
        return {
            "format": "copycat-suite/expert-ppo/1",
            "env_id": args.env,
            "frame_skip": args.frame_skip,
            "obs_shape": list(envs.single_observation_space.shape),
            "action_shape": list(envs.single_action_space.shape),
            "hidden": args.hidden,
            "actor": agent.actor_mean.state_dict(),
            "obs_mean": torch.as_tensor(obs_rms.mean, dtype=torch.float64),
            "obs_var": torch.as_tensor(obs_rms.var, dtype=torch.float64),
            "action_low": torch.as_tensor(envs.single_action_space.low, dtype=torch.float64),
            "action_high": torch.as_tensor(envs.single_action_space.high, dtype=torch.float64),
            "args": asdict(args),
            "global_step": global_step,
            "eval_return": eval_return,
            "machine": machine(),
            # Only needed to resume training:
            "agent": agent.state_dict(),
            "optimizer": optimizer.state_dict(),
            "obs_count": obs_rms.count,
            "ret_mean": torch.as_tensor(ret_rms.mean, dtype=torch.float64),
            "ret_var": torch.as_tensor(ret_rms.var, dtype=torch.float64),
            "ret_count": ret_rms.count,
            "best_return": best_return,
        }

    if args.resume and os.path.isfile(latest_path):
        cannot = f"cannot resume from {latest_path}"
        try:
            state = torch.load(latest_path, map_location="cpu", weights_only=True)
            trained_on = state["env_id"]
        except Exception as error:
            raise UsageError(f"{cannot} ({type(error).__name__}): delete it or drop --resume")
        other = f"{latest_path} was trained on {trained_on}, not {args.env}"
        require(trained_on == args.env, f"{other}: use another --output-dir")
        # Another rate is another task (other dynamics, other horizon): continuing would mix them.
        trained_at = state.get("frame_skip", native)
        mismatch = f"{latest_path} was trained at frame skip {trained_at}, not {args.frame_skip}"
        fix = f"pass --frame-skip {trained_at} or use another --output-dir"
        require(trained_at == args.frame_skip, f"{mismatch}: {fix}")
        try:
            agent.load_state_dict(state["agent"])
            optimizer.load_state_dict(state["optimizer"])
        except Exception as error:
            raise UsageError(f"{cannot} ({type(error).__name__}): check --hidden or drop --resume")
        finite = nn.utils.parameters_to_vector(agent.parameters()).isfinite().all()
        require(finite, f"{cannot}: its weights are not finite (a diverged run): delete it")
        # state["args"] is a record only, never read back: the flags given now rule.
        for rms, name in ((obs_rms, "obs"), (ret_rms, "ret")):
            rms.mean = state[f"{name}_mean"].numpy()
            rms.var = state[f"{name}_var"].numpy()
            rms.count = state[f"{name}_count"]
        global_step = state["global_step"]
        best_return = state["best_return"]
        print(f"resumed from {latest_path} at step {global_step}")
    elif args.resume:
        print(f"no {latest_path} yet: starting fresh")

    batch_size = args.num_envs * args.num_steps
    obs_buf = torch.zeros((args.num_steps, args.num_envs, obs_dim))
    act_buf = torch.zeros((args.num_steps, args.num_envs, act_dim))
    logp_buf = torch.zeros((args.num_steps, args.num_envs))
    rew_buf = torch.zeros((args.num_steps, args.num_envs))
    done_buf = torch.zeros((args.num_steps, args.num_envs))
    val_buf = torch.zeros((args.num_steps, args.num_envs))

    # A resumed run gets fresh episodes and torch's seed again: not an unbroken run's digits.
    raw_obs, _ = envs.reset(seed=args.seed + global_step)
    # Each env's discounted return, whose running std scales the rewards; zeroed after any end.
    discounted_return = np.zeros(args.num_envs)
    episode_return = np.zeros(args.num_envs)
    recent_returns = []
    start_time = time.time()
    start_step = global_step
    next_save = global_step + args.save_every_steps
    next_eval = global_step + args.eval_every_steps

    while global_step < args.total_timesteps:
        frac = 1.0 - global_step / args.total_timesteps
        optimizer.param_groups[0]["lr"] = args.learning_rate * frac

        # ---- Rollout and GAE, no gradients; the env gets clipped actions, the buffer the sampled
        with torch.no_grad():
            for step in range(args.num_steps):
                obs_rms.update(raw_obs)
                obs = obs_rms.normalize(raw_obs)
                action, logp, _, value = agent.action_and_value(obs)
                clipped_action = action.numpy().clip(action_low, action_high)
                raw_obs, reward, terminated, truncated, info = envs.step(clipped_action)
                global_step += args.num_envs
                episode_return += reward
                discounted_return = discounted_return * args.gamma + reward
                ret_rms.update(discounted_return)
                scaled_reward = np.clip(reward / np.sqrt(ret_rms.var + 1e-8), -10, 10)
                done = terminated | truncated
                # A time limit is not a death: bootstrap from the value of the last observation.
                if truncated.any():
                    final_obs = raw_obs.copy()
                    final_obs[truncated] = np.stack(info["final_obs"][truncated])
                    final_value = agent.value(obs_rms.normalize(final_obs)).numpy()
                    bootstrap = (truncated & ~terminated).astype(np.float32)
                    scaled_reward = scaled_reward + args.gamma * final_value * bootstrap
                recent_returns = (recent_returns + list(episode_return[done]))[-20:]
                episode_return[done] = 0.0
                discounted_return[done] = 0.0

                obs_buf[step] = obs
                act_buf[step] = action
                logp_buf[step] = logp
                val_buf[step] = value
                rew_buf[step] = torch.as_tensor(scaled_reward, dtype=torch.float32)
                done_buf[step] = torch.as_tensor(done, dtype=torch.float32)

            # ---- Generalised advantage estimation (GAE); done[t] ends the episode after step t
            next_value = agent.value(obs_rms.normalize(raw_obs))
            advantages = torch.zeros_like(rew_buf)
            last_gae = 0.0
            for t in reversed(range(args.num_steps)):
                following_value = next_value if t == args.num_steps - 1 else val_buf[t + 1]
                not_done = 1.0 - done_buf[t]
                delta = rew_buf[t] + args.gamma * following_value * not_done - val_buf[t]
                last_gae = delta + args.gamma * args.gae_lambda * not_done * last_gae
                advantages[t] = last_gae
            returns = advantages + val_buf

        # ---- PPO update: clipped surrogate (PPO Eq. 7), value loss (unclipped; CleanRL clips)
        b_obs = obs_buf.reshape(-1, obs_dim)
        b_act = act_buf.reshape(-1, act_dim)
        b_logp = logp_buf.reshape(-1)
        b_adv = advantages.reshape(-1)
        b_ret = returns.reshape(-1)
        for _ in range(args.update_epochs):
            for idx in torch.randperm(batch_size).split(batch_size // args.num_minibatches):
                _, new_logp, entropy, new_value = agent.action_and_value(b_obs[idx], b_act[idx])
                ratio = (new_logp - b_logp[idx]).exp()
                adv = (b_adv[idx] - b_adv[idx].mean()) / (b_adv[idx].std() + 1e-8)
                clipped_ratio = ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)
                policy_loss = torch.max(-adv * ratio, -adv * clipped_ratio).mean()
                value_loss = 0.5 * ((new_value - b_ret[idx]) ** 2).mean()
                loss = policy_loss - args.ent_coef * entropy.mean() + args.vf_coef * value_loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()
        finite = nn.utils.parameters_to_vector(agent.parameters()).isfinite().all()
        require(finite, f"training diverged at step {global_step}: use a smaller --learning-rate")

        # ---- Progress, evaluation, checkpoints (ExpertPolicy's init draws on torch's RNG too)
        elapsed = time.time() - start_time
        sps = (global_step - start_step) / max(elapsed, 1e-6)
        recent = f"{np.mean(recent_returns):.0f}" if recent_returns else "n/a"
        eta_min = (args.total_timesteps - global_step) / max(sps, 1e-6) / 60
        line = f"step {global_step:>9} | {sps:5.0f} steps/s | recent return {recent:>6}"
        print(f"{line} | value loss {value_loss.item():.3f} | ETA {eta_min:.1f} min", flush=True)
        if global_step >= next_eval:
            next_eval += args.eval_every_steps
            policy = ExpertPolicy(checkpoint())
            seed = args.seed + global_step
            scores = evaluate(policy, args.env, args.train_eval_episodes, seed, args.frame_skip)
            eval_return = float(np.mean(scores))
            best = max(best_return, eval_return)
            print(f"eval at step {global_step}: {eval_return:.1f} (best {best:.1f})", flush=True)
            if eval_return > best_return:
                best_return = eval_return
                save_atomically(checkpoint(eval_return), best_path)
        if global_step >= next_save:
            next_save += args.save_every_steps
            save_atomically(checkpoint(), latest_path)
        if args.max_minutes and elapsed > args.max_minutes * 60:
            break

    save_atomically(checkpoint(), latest_path)
    envs.close()
    if global_step < args.total_timesteps:
        print(f"stopped after {args.max_minutes} min at step {global_step}: rerun it with --resume")
        return
    # The final evaluation: seeds 10000, 10001, ..., as --eval-only.
    policy = ExpertPolicy(checkpoint())
    returns = evaluate(policy, args.env, args.eval_episodes, 10_000, args.frame_skip)
    mean, std = float(np.mean(returns)), float(np.std(returns))
    save_atomically(checkpoint(mean), latest_path)
    print(f"wrote {latest_path} (the last policy)")
    if best_return > -np.inf:
        print(f"{best_path} keeps the best periodic evaluation ({best_return:.1f})")
    print(f"{args.env} expert: {mean:.1f} ± {std:.1f} over {len(returns)} episodes")


# ---- Evaluation, and the deterministic expert the imitation files load ----
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


def evaluate(policy, env_id: str, episodes: int, seed: int, frame_skip: int | None = None) -> list:
    """The returns of the deterministic policy, one episode each of seeds seed, seed+1, ..."""
    env = make_env(env_id, frame_skip)
    returns = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        done, total = False, 0.0
        while not done:
            action = policy(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
            obs, reward, terminated, truncated, _ = env.step(action)
            total = total + float(reward)
            done = terminated or truncated
        returns.append(total)
    env.close()
    return returns


def retargeted_expert(path: str, env_id: str, made_for: str) -> ExpertPolicy:
    """--retarget: the expert at path, made for another version of env_id (e.g. v4 for v5) with
    the same shapes, or whose observation is env_id's leading positions and velocities."""
    policy = load_expert(path, made_for)
    env = make_env(env_id)
    structure = getattr(env.unwrapped, "observation_structure", {})
    positions_and_velocities = structure.get("qpos", 0) + structure.get("qvel", 0)
    observations = (env.observation_space.shape[0], positions_and_velocities)
    same_input = policy.net[0].in_features in observations
    same_output = policy.net[-1].out_features == env.action_space.shape[0]
    same_family = made_for.split("-")[0] == env_id.split("-")[0]
    other = f"{path} is an expert for {made_for}, whose family or shapes are not {env_id}'s"
    require(same_family and same_input and same_output, f"{other}: train one for {env_id}")
    return policy


def eval_only(args: Args):
    path = args.checkpoint.replace("{env}", args.env)
    native = env_frame_skip(args.env)
    env_frame_skip(args.env, args.frame_skip)
    require(args.eval_episodes > 0, f"--eval-episodes must be positive, got {args.eval_episodes}")
    folder = f"--ship-to {args.ship_to} is a folder: give the path of the file to write"
    require(args.ship_to is None or not os.path.isdir(args.ship_to), folder)
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
        recorded = checkpoint["env_id"]
    except Exception:
        # load_expert, below, says why it cannot be read.
        recorded = None
    same_family = recorded is not None and recorded.split("-")[0] == args.env.split("-")[0]
    other = f"{path} is an expert for {recorded}, not {args.env}: pass --retarget to evaluate it"
    fix = f"on {args.env} (and --ship-to to ship it there), or a checkpoint made for {args.env}"
    require(args.retarget or recorded == args.env or not same_family, f"{other} {fix}")
    if args.retarget:
        policy = retargeted_expert(path, args.env, recorded or args.env)
    else:
        policy = load_expert(path, args.env)
    # A policy acts well at the rate it was trained at (the env's own, if not recorded).
    trained_at = checkpoint.get("frame_skip", native)
    frame_skip = args.frame_skip or trained_at
    there = f"{path} was trained at frame skip {trained_at}: --ship-to records a return only there"
    fix = f"drop --frame-skip {frame_skip} or --ship-to"
    require(not args.ship_to or frame_skip == trained_at, f"{there}, {fix}")
    if frame_skip != native:
        rates = f"the env's own is {native}; the expert was trained at {trained_at}"
        print(f"evaluating at frame skip {frame_skip} ({rates})")
    returns = evaluate(policy, args.env, args.eval_episodes, seed=10_000, frame_skip=frame_skip)
    for i, episode_return in enumerate(returns):
        print(f"episode {i}: return {episode_return:.1f}")
    mean, std = float(np.mean(returns)), float(np.std(returns))
    if args.ship_to:
        # e.g. experts/Hopper-v4.pt, recording its return (and, retargeted, the env it came from).
        checkpoint.update(eval_return=mean, eval_std=std, eval_episodes=len(returns))
        if recorded != args.env:
            checkpoint.update(env_id=args.env, retargeted_from=recorded)
        save_atomically(checkpoint, args.ship_to)
        print(f"wrote {args.ship_to}")
    print(f"{args.env} expert: {mean:.1f} ± {std:.1f} over {len(returns)} episodes")


# ---- Bad input (UsageError, require) and the env ----
# Copied from bc_oh.UsageError
class UsageError(Exception):
    """Bad input from the user: printed as one line on stderr, exit status 2, no traceback."""


def require(condition, message: str):
    """Refuse bad input in one line: a UsageError unless condition holds."""
    if not condition:
        raise UsageError(message)


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


def env_frame_skip(env_id: str, frame_skip: int | None = None) -> int | None:
    """The frame skip of make_env(env_id, frame_skip), None if not MuJoCo; bad input fails here."""
    fix = "e.g. 1, or leave it out for the env's own"
    positive = frame_skip is None or frame_skip > 0
    require(positive, f"--frame-skip must be positive, got {frame_skip}: {fix}")
    env = make_env(env_id, frame_skip)
    resolved = getattr(env.unwrapped, "frame_skip", None)
    env.close()
    return resolved


# Copied from bc_oh.print_mujoco_warning
def print_mujoco_warning(text: str):
    # MuJoCo 3.x warns about gymnasium's HalfCheetah model each time it is made: skip that one.
    if "settotalmass" not in text:
        print(f"MuJoCo warning: {text}", file=sys.stderr)


# Our v4 envs are deprecated in gymnasium 1.x (the paper names no version): keep stderr for errors.
gym.logger.min_level = gym.logger.ERROR
mujoco.set_mju_user_warning(print_mujoco_warning)


# ---- Checkpoints ----
def machine() -> dict:
    """Where a result was made: the same command, kind of CPU and versions give the same digits."""
    cpu = None
    if os.path.isfile("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as file:
            cpu = re.search(r"^model name\s*: (.*)$", file.read(), re.M)
    return {
        "cpu": cpu[1] if cpu else platform.processor(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "MKL_CBWR": os.environ.get("MKL_CBWR"),
        "MKL_ENABLE_INSTRUCTIONS": os.environ.get("MKL_ENABLE_INSTRUCTIONS"),
        "torch": str(torch.__version__),
        "numpy": np.__version__,
        "mujoco": mujoco.__version__,
        "gymnasium": gym.__version__,
    }


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


def save_atomically(obj, path: str):
    write_atomically(path, lambda file: torch.save(obj, file))


# ---- Demonstrations (--make-demos): the input of the imitation files ----
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


def make_demos(args: Args):
    """Roll the expert out into demos/, unless a file of the same expert and settings is there."""
    native = env_frame_skip(args.env)
    frame_skip = env_frame_skip(args.env, args.frame_skip)
    num_samples = args.num_demo_samples
    if num_samples is None:
        num_samples = 20000 if args.env.startswith("Hopper") else 10000
    require(num_samples > 1, f"--num-demo-samples must be more than 1, got {num_samples}")
    expert_path = args.checkpoint.replace("{env}", args.env)
    rate = "" if frame_skip == native else f"_fs{frame_skip}"
    path = f"demos/{args.env}{rate}_{num_samples}.npz"
    require(not os.path.isfile("demos"), f"./demos is a file in the way of {path}: move it")
    expert = load_expert(expert_path, args.env)
    with open(expert_path, "rb") as file:
        expert_sha256 = hashlib.sha256(file.read()).hexdigest()
    checkpoint = torch.load(expert_path, map_location="cpu", weights_only=True)
    meta = {
        "env_id": args.env,
        "source": expert_path,
        "expert_sha256": expert_sha256,
        "num_samples": num_samples,
        "seed": 0,
        "frame_skip": frame_skip,
        "expert_return": checkpoint.get("eval_return"),
        "expert_frame_skip": checkpoint.get("frame_skip", native),
    }
    try:
        with np.load(path, allow_pickle=False) as data:
            made = json.loads(str(data["meta"]))
    except Exception:
        made = {}
    settings = ("env_id", "expert_sha256", "num_samples", "frame_skip")
    if isinstance(made, dict) and all(made.get(key) == meta[key] for key in settings):
        print(f"{path}: already made from {expert_path} with these settings")
        return
    # One thread, as when the shipped demos were made: the same digits.
    torch.set_num_threads(1)
    print(f"generating {num_samples} demonstration steps with {expert_path} -> {path}")
    demos = generate_demos(args.env, frame_skip, expert, num_samples)
    write_atomically(path, lambda file: np.savez(file, meta=np.array(json.dumps(meta)), **demos))
    print(f"wrote {path}")


if __name__ == "__main__":
    # `kill PID` stops a run as Ctrl-C does; latest.pt is never half written.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        args = tyro.cli(Args)
        if args.make_demos:
            make_demos(args)
        elif args.eval_only:
            eval_only(args)
        else:
            train(args)
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted: a training run goes on with --resume", file=sys.stderr)
        sys.exit(130)
