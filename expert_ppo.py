# PPO expert that produces the demonstrations (paper section 5.1, "Data collection"); see README.md
"""Proximal Policy Optimisation for gymnasium 1.x MuJoCo envs, CleanRL style, in one file.

Train:     python expert_ppo.py --env Hopper-v4 --total-timesteps 3000000
Resume:    python expert_ppo.py --env Hopper-v4 --total-timesteps 3000000 --resume
Evaluate:  python expert_ppo.py --env Hopper-v4 --eval-only --checkpoint experts/Hopper-v4.pt
Demos:     python expert_ppo.py --env Hopper-v4 --make-demos   (demos/Hopper-v4_20000.npz: the imitation files' input)
Other rate: python expert_ppo.py --env Hopper-v4 --frame-skip 1   (writes runs/expert_ppo/Hopper-v4__1_fs1)

A checkpoint is a dict of tensors and numbers (experts/README.md); the imitation files copy ExpertPolicy, load_expert.
"""

import hashlib
import json
import os
import platform
import random
import re
import sys
import time
from dataclasses import asdict, dataclass

import gymnasium as gym
import mujoco
import numpy as np
import torch
import torch.nn as nn
import tyro

gym.logger.min_level = gym.logger.ERROR  # the paper's v4 envs are deprecated in gymnasium 1.x: keep stderr for errors
# MuJoCo 3.x warns of gymnasium's HalfCheetah XML (to ./MUJOCO_LOG.TXT too) each time it is made: drop that one
mujoco.set_mju_user_warning(lambda text: "settotalmass" in text or print(f"MuJoCo warning: {text}", file=sys.stderr))


@dataclass
class Args:
    env: str = "Hopper-v4"
    """gymnasium MuJoCo env id with continuous actions (Hopper, HalfCheetah, Walker2d, Ant; v4 or v5)"""
    frame_skip: int | None = None
    """simulator steps per action; None: the env's own (time limit and rewards rescaled: docs/methods.md)"""
    seed: int = 1
    """seed of the run (python, numpy, torch and the envs): one PPO run trains one seed"""
    total_timesteps: int = 3_000_000
    """env steps to train for, summed over the parallel envs"""
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
    """where training writes latest.pt (to resume) and best.pt; {rate}: _fsK at --frame-skip K, else empty"""
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
    """torch CPU threads; 1 is fastest for these small networks and lets several runs share a machine"""
    eval_only: bool = False
    """only evaluate --checkpoint, printing per-episode returns and a summary line"""
    checkpoint: str = "experts/{env}.pt"
    """checkpoint evaluated by --eval-only, at the frame skip it was trained at unless --frame-skip is given"""
    eval_episodes: int = 20
    """episodes of --eval-only and of the final evaluation after training"""
    ship_to: str | None = None
    """with --eval-only: also write the checkpoint, with its evaluated return recorded, to this path"""
    make_demos: bool = False
    """roll --checkpoint out into demos/<env>[_fs<K>]_<N>.npz, the demonstrations the imitation files load"""
    num_demo_samples: int | None = None
    """with --make-demos: demonstration steps; None: the paper's 20000 for Hopper and 10000 otherwise"""
    retarget: bool = False
    """with --eval-only: --checkpoint may be an expert for another version of --env (Hopper-v4 for Hopper-v5)"""


# ---- Env ----
# Copied from bc_oh.UsageError..require
class UsageError(Exception): ...  # bad input from the user: printed as one line on stderr, exit status 2, no traceback


def require(condition, message: str):  # refuse bad input in one line: a UsageError unless condition holds
    if not condition:
        raise UsageError(message)


# Copied from bc_oh.make_env
def make_env(env_id: str, frame_skip: int | None = None) -> gym.Env:
    try:
        env = gym.make(env_id)
    except Exception as error:  # gymnasium raises several error types for unknown or broken ids
        raise UsageError(f"cannot make env {env_id!r} ({error}): use a gymnasium MuJoCo id such as Hopper-v4")
    kind, native = type(env.action_space).__name__, getattr(env.unwrapped, "frame_skip", None)
    require(kind == "Box", f"env {env_id!r} has {kind} actions: imitation here needs Box ones")
    if frame_skip is None or frame_skip == native:
        return env
    require(native is not None, f"env {env_id!r} is not a MuJoCo env: --frame-skip needs one, leave it out")
    env = gym.make(env_id, max_episode_steps=round(env.spec.max_episode_steps * native / frame_skip))  # the same time
    env.unwrapped.frame_skip = frame_skip  # MuJoCo envs step the simulator frame_skip times per action; dt follows
    return gym.wrappers.TransformReward(env, lambda reward: reward * frame_skip / native)  # and the same return scale


def env_frame_skip(env_id: str, frame_skip: int | None = None) -> int | None:  # None: not a MuJoCo env
    """The frame skip of make_env(env_id, frame_skip), from one env made: bad input fails here, before any work."""
    if frame_skip is not None and frame_skip <= 0:  # make_env would divide by it, or make a negative time limit
        raise UsageError(f"--frame-skip must be positive, got {frame_skip}: e.g. 1, or leave it out for the env's own")
    env = make_env(env_id, frame_skip)
    resolved = getattr(env.unwrapped, "frame_skip", None)  # make_env set it to frame_skip when one was given
    env.close()
    return resolved


class RunningMeanStd:  # running mean and variance (parallel algorithm of Chan et al.), as gymnasium's normalisers
    def __init__(self, shape=()):
        self.mean, self.var, self.count = np.zeros(shape), np.ones(shape), 1e-4

    def update(self, batch: np.ndarray):
        batch_mean, batch_var, batch_count = batch.mean(0), batch.var(0), batch.shape[0]
        delta, total = batch_mean - self.mean, self.count + batch_count
        self.mean = self.mean + delta * batch_count / total
        sum_of_squares = self.var * self.count + batch_var * batch_count + delta**2 * self.count * batch_count / total
        self.var = sum_of_squares / total
        self.count = total

    def normalize(self, x: np.ndarray) -> np.ndarray:
        return np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -10.0, 10.0)


# ---- Networks ----
def mlp(in_dim: int, out_dim: int, hidden: int, last_std: float) -> nn.Sequential:  # tanh layers, Huang et al.'s init
    layers = [nn.Linear(in_dim, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(), nn.Linear(hidden, out_dim)]
    for layer, std in zip(layers[::2], (np.sqrt(2), np.sqrt(2), last_std)):
        nn.init.orthogonal_(layer.weight, std)
        nn.init.zeros_(layer.bias)
    return nn.Sequential(*layers)


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
        dist = torch.distributions.Normal(mean, self.actor_logstd.expand_as(mean).exp())
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.value(obs)


class ExpertPolicy(nn.Module):
    """The deterministic expert: frozen obs normalisation, mean action of the actor, clipped to bounds."""

    def __init__(self, checkpoint: dict):
        super().__init__()
        obs_dim, act_dim, hidden = checkpoint["obs_shape"][0], checkpoint["action_shape"][0], checkpoint["hidden"]
        hidden_layers = [nn.Linear(obs_dim, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh()]
        self.net = nn.Sequential(*hidden_layers, nn.Linear(hidden, act_dim))  # the actor's mean, as Agent's
        self.net.load_state_dict(checkpoint["actor"])
        for name in ("obs_mean", "obs_var", "action_low", "action_high"):
            self.register_buffer(name, checkpoint[name].float())

    @torch.no_grad()
    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        obs = obs[..., : len(self.obs_mean)]  # an expert re-targeted to a wider observation (Ant-v5's) reads its start
        obs = ((obs - self.obs_mean) / torch.sqrt(self.obs_var + 1e-8)).clamp(-10.0, 10.0)
        return torch.maximum(torch.minimum(self.net(obs), self.action_high), self.action_low)


def load_expert(path: str, env_id: str) -> ExpertPolicy:
    """Load an expert checkpoint written by expert_ppo.py, checking that it is one and fits env_id."""
    train = f"train one (python expert_ppo.py --env {env_id}), or give its path"
    require(os.path.isfile(path), f"expert checkpoint {path} not found: {train}")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
        policy, trained_on = ExpertPolicy(checkpoint), checkpoint["env_id"]
    except Exception as error:
        raise UsageError(f"{path} is not a readable expert checkpoint ({type(error).__name__}): re-copy or re-train it")
    require(trained_on == env_id, f"{path} is an expert for {trained_on}, not {env_id}: pass the one made for {env_id}")
    return policy.eval()


# ---- Checkpoints ----
def machine() -> dict:  # where a result was made: the same command, kind of CPU and versions give the same digits
    cpus = open("/proc/cpuinfo").read() if os.path.isfile("/proc/cpuinfo") else ""
    cpu = re.search(r"^model name\s*: (.*)$", cpus, re.M)
    return {
        "cpu": cpu[1] if cpu else platform.processor(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        **{name: os.environ.get(name) for name in ("MKL_CBWR", "MKL_ENABLE_INSTRUCTIONS")},
        "torch": str(torch.__version__),
        "numpy": np.__version__,
        "mujoco": mujoco.__version__,
        "gymnasium": gym.__version__,
    }


def write_atomically(path: str, write):  # write(file) to a temporary file, then rename: never half a file
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, "wb") as file:
            write(file)
        os.replace(tmp, path)
    finally:  # after an interruption, remove the half-written temporary file
        if os.path.exists(tmp):
            os.remove(tmp)


def save_atomically(obj, path: str):  # torch.save through write_atomically: never half a checkpoint
    write_atomically(path, lambda file: torch.save(obj, file))


# ---- Evaluation ----
def evaluate(policy: ExpertPolicy, env_id: str, episodes: int, seed: int, frame_skip: int | None = None) -> list:
    """Returns of `episodes` episodes of the deterministic policy, one env, seeds seed, seed+1, ..."""
    env, returns = make_env(env_id, frame_skip), []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        done, total = False, 0.0
        while not done:
            action = policy(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
            obs, reward, terminated, truncated, _ = env.step(action)
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    env.close()
    return returns


def retargeted_expert(path: str, env_id: str):  # --retarget: (the expert at path, the env it was made for)
    """Refused unless made for another version of env_id (Hopper-v4 for Hopper-v5) with the same action shape and the
    same observation, or one that is its leading positions and velocities (Ant-v4's 27 entries of Ant-v5's 105)."""
    made_for = checkpoint_env(path) or env_id  # an unreadable file: load_expert says what is wrong with it
    policy, env = load_expert(path, made_for), make_env(env_id)
    structure = getattr(env.unwrapped, "observation_structure", {})
    observations = (env.observation_space.shape[0], structure.get("qpos", 0) + structure.get("qvel", 0))
    shapes = policy.net[0].in_features in observations and policy.net[-1].out_features == env.action_space.shape[0]
    other = f"{path} is an expert for {made_for}, another env or other shapes than {env_id}'s: train one for {env_id}"
    require(made_for.split("-")[0] == env_id.split("-")[0] and shapes, other)
    return policy, made_for


def checkpoint_env(path: str) -> str | None:  # the env it was made for; None: unreadable (load_expert says why)
    try:
        return torch.load(path, map_location="cpu", weights_only=True)["env_id"]
    except Exception:
        return None


def eval_only(args: Args):
    path = args.checkpoint.format(env=args.env)
    native = env_frame_skip(args.env)
    if args.frame_skip is not None:
        env_frame_skip(args.env, args.frame_skip)  # fail early for a frame skip the env cannot take
    require(args.eval_episodes > 0, f"--eval-episodes must be positive, got {args.eval_episodes}")
    recorded = checkpoint_env(path)
    other = f"{path} is an expert for {recorded}, not {args.env}: pass --retarget to evaluate it on {args.env} (and"
    other += f" --ship-to to ship it there), or a checkpoint made for {args.env}"
    require(args.retarget or recorded in (None, args.env) or recorded.split("-")[0] != args.env.split("-")[0], other)
    # load_expert checks that the file is a readable checkpoint made for --env (with --retarget: for its family)
    policy, made_for = retargeted_expert(path, args.env) if args.retarget else (load_expert(path, args.env), args.env)
    checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    # a policy acts well at the rate it was trained at: evaluate there unless told otherwise
    trained_at = checkpoint.get("frame_skip", native)  # checkpoints without the record were trained at the env's own
    frame_skip = args.frame_skip or trained_at
    there = f"{path} was trained at frame skip {trained_at}: --ship-to records its return there"
    require(not args.ship_to or frame_skip == trained_at, f"{there}, drop --frame-skip {frame_skip} or --ship-to")
    if frame_skip != native:  # said only at another rate, so that the default output stays as it was
        rates = f"the env's own is {native}; the expert was trained at {trained_at}"
        print(f"evaluating at frame skip {frame_skip} ({rates})")
    returns = evaluate(policy, args.env, args.eval_episodes, seed=10_000, frame_skip=frame_skip)
    for i, episode_return in enumerate(returns):
        print(f"episode {i}: return {episode_return:.1f}")
    if args.ship_to:  # e.g. experts/Hopper-v4.pt: the checkpoint carries the return it was shipped with
        mean, std = float(np.mean(returns)), float(np.std(returns))
        checkpoint.update(eval_return=mean, eval_std=std, eval_episodes=len(returns))
        if made_for != args.env:  # shipped for --env: load_expert accepts it there, and it says where it came from
            checkpoint.update(env_id=args.env, retargeted_from=made_for)
        save_atomically(checkpoint, args.ship_to)
        print(f"wrote {args.ship_to}")
    print(f"{args.env} expert: {np.mean(returns):.1f} ± {np.std(returns):.1f} over {len(returns)} episodes")


# ---- Demonstrations (--make-demos): the imitation files' input ----
def generate_demos(env_id: str, frame_skip: int | None, expert: ExpertPolicy, num_samples: int, seed: int = 0) -> dict:
    """Roll out the deterministic expert on the clean env; episodes cut by the budget end early (truncated).
    Besides o_t, a_t and the episode starts, it keeps what a dataset format such as Minari needs: each
    step's reward, termination and truncation, and each episode's observation after its last step."""
    env, steps, final_observations = make_env(env_id, frame_skip), [], []
    obs, _ = env.reset(seed=seed)
    start = True
    for step in range(num_samples):
        action = expert(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
        next_obs, reward, terminated, truncated, _ = env.step(action)
        truncated = truncated or step == num_samples - 1  # the budget ends the last episode
        steps.append((obs, action, start, reward, terminated, truncated))
        obs, start = next_obs, terminated or truncated
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


def demo_path(env_id: str, frame_skip: int, native: int, num_samples: int) -> str:
    """Where --make-demos writes, and where the imitation files look when --demos is not given."""
    return f"demos/{env_id}{'' if frame_skip == native else f'_fs{frame_skip}'}_{num_samples}.npz"


def make_demos(args: Args):  # a file already made from the same expert file with the same settings is kept
    """Roll the expert out (seed 0, one thread: the arrays the imitation files made before they only loaded them) into
    demos/, with a meta that names the expert (its SHA-256) and its return."""
    native, frame_skip = env_frame_skip(args.env), env_frame_skip(args.env, args.frame_skip)
    default = 20000 if args.env.startswith("Hopper") else 10000
    num_samples = default if args.num_demo_samples is None else args.num_demo_samples
    require(num_samples > 1, f"--num-demo-samples must be more than 1, got {num_samples}")
    expert_path, path = args.checkpoint.format(env=args.env), demo_path(args.env, frame_skip, native, num_samples)
    expert = load_expert(expert_path, args.env)  # one clear line for a missing or wrong checkpoint
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
    except Exception:  # none yet, or not one of ours: make it
        made = {}
    if all(made.get(key) == meta[key] for key in ("env_id", "expert_sha256", "num_samples", "frame_skip")):
        print(f"{path}: already made from {expert_path} with these settings")
        return
    if meta["expert_return"] is None:  # an expert not shipped with --eval-only --ship-to: no return to compare with
        del meta["expert_return"], meta["expert_frame_skip"]
    torch.set_num_threads(1)  # as the imitation files rolled it out: the same digits
    print(f"generating {num_samples} demonstration steps with {expert_path} -> {path}")
    demos = generate_demos(args.env, frame_skip, expert, num_samples)
    write_atomically(path, lambda file: np.savez(file, meta=np.array(json.dumps(meta)), **demos))
    print(f"wrote {path}")


# ---- Training ----
def validate(args: Args):  # `not value > 0` also refuses a NaN float
    positive = "total_timesteps num_envs num_steps num_minibatches update_epochs hidden save_every_steps"
    positive += " eval_every_steps train_eval_episodes eval_episodes threads learning_rate clip_coef max_grad_norm"
    for name in positive.split():
        require(getattr(args, name) > 0, f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}")
    require(0 < args.gamma <= 1 and 0 <= args.gae_lambda <= 1, "--gamma must be in (0, 1] and --gae-lambda in [0, 1]")
    divides = (args.num_envs * args.num_steps) % args.num_minibatches == 0
    require(divides, "--num-minibatches must divide num-envs * num-steps")


def train(args: Args):
    validate(args)
    native = env_frame_skip(args.env)
    # resolved first, so that args and checkpoints record the rate used; at the env's own, make_env is gym.make(env)
    args.frame_skip = env_frame_skip(args.env, args.frame_skip)
    rate = "" if args.frame_skip == native else f"_fs{args.frame_skip}"
    output_dir = args.output_dir.format(env=args.env, seed=args.seed, rate=rate)
    latest_path, best_path = os.path.join(output_dir, "latest.pt"), os.path.join(output_dir, "best.pt")
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)

    # SAME_STEP autoreset: a step that ends an episode returns the *reset* observation and puts the last one in
    # info["final_obs"]: every stored transition belongs to one episode; a truncated one bootstraps from V(final_obs)
    envs = gym.vector.SyncVectorEnv(
        [lambda: make_env(args.env, args.frame_skip) for _ in range(args.num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    obs_dim, act_dim = envs.single_observation_space.shape[0], envs.single_action_space.shape[0]
    action_low, action_high = envs.single_action_space.low, envs.single_action_space.high
    agent = Agent(obs_dim, act_dim, args.hidden)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    obs_rms, ret_rms = RunningMeanStd((obs_dim,)), RunningMeanStd()
    global_step, best_return = 0, -np.inf

    if args.resume and os.path.isfile(latest_path):
        try:
            state = torch.load(latest_path, map_location="cpu", weights_only=True)
            trained_on = state["env_id"]
        except Exception as error:
            raise UsageError(f"cannot resume from {latest_path} ({type(error).__name__}): delete it or drop --resume")
        other = f"{latest_path} was trained on {trained_on}, not {args.env}"
        require(trained_on == args.env, f"{other}: use another --output-dir")
        # Another rate is another task (other dynamics per action, other horizon): continuing would mix them.
        trained_at = state.get("frame_skip", native)  # checkpoints without the record were trained at the env's own
        rate = f"{latest_path} was trained at frame skip {trained_at}, not {args.frame_skip}"
        require(trained_at == args.frame_skip, f"{rate}: pass --frame-skip {trained_at} or use another --output-dir")
        try:
            agent.load_state_dict(state["agent"])
            optimizer.load_state_dict(state["optimizer"])
        except Exception as error:
            raise UsageError(f"cannot resume from {latest_path} ({type(error).__name__}): delete it or drop --resume")
        # state["args"] is a record only, never read back: old checkpoints resume, and the flags given now rule
        for rms, name in ((obs_rms, "obs"), (ret_rms, "ret")):
            rms.mean, rms.var = state[f"{name}_mean"].numpy(), state[f"{name}_var"].numpy()
            rms.count = state[f"{name}_count"]
        global_step, best_return = state["global_step"], state["best_return"]
        print(f"resumed from {latest_path} at step {global_step}")
    elif args.resume:
        print(f"no {latest_path} yet: starting fresh")

    def checkpoint(eval_return=None):  # a plain dict of tensors and numbers (experts/README.md)
        def to_tensor(x):
            return torch.as_tensor(np.asarray(x), dtype=torch.float64)

        return {
            "format": "copycat-suite/expert-ppo/1",
            "env_id": args.env,
            "frame_skip": args.frame_skip,  # the rate it was trained at (None resolved above to the env's own)
            "obs_shape": list(envs.single_observation_space.shape),
            "action_shape": list(envs.single_action_space.shape),
            "hidden": args.hidden,
            "actor": agent.actor_mean.state_dict(),
            "obs_mean": to_tensor(obs_rms.mean),
            "obs_var": to_tensor(obs_rms.var),
            "action_low": to_tensor(envs.single_action_space.low),
            "action_high": to_tensor(envs.single_action_space.high),
            "args": asdict(args),
            "global_step": global_step,
            "eval_return": eval_return,
            "machine": machine(),  # where it was trained (checkpoints made before this have none)
            # only needed to resume training:
            "agent": agent.state_dict(),
            "optimizer": optimizer.state_dict(),
            "obs_count": obs_rms.count,
            "ret_mean": to_tensor(ret_rms.mean),
            "ret_var": to_tensor(ret_rms.var),
            "ret_count": ret_rms.count,
            "best_return": best_return,
        }

    def frozen_policy():
        return ExpertPolicy(checkpoint())

    def normalized(raw: np.ndarray) -> torch.Tensor:  # the observations as the networks read them
        return torch.as_tensor(obs_rms.normalize(raw), dtype=torch.float32)

    batch_size = args.num_envs * args.num_steps
    obs_buf, act_buf = (torch.zeros((args.num_steps, args.num_envs, dim)) for dim in (obs_dim, act_dim))
    logp_buf, rew_buf, done_buf, val_buf = (torch.zeros((args.num_steps, args.num_envs)) for _ in range(4))

    raw_obs, _ = envs.reset(seed=args.seed + global_step)  # a resumed run gets fresh episodes
    discounted_return = np.zeros(args.num_envs)  # for reward scaling, as gymnasium's NormalizeReward
    episode_return, recent_returns = np.zeros(args.num_envs), []
    start_time, start_step = time.time(), global_step
    next_save, next_eval = global_step + args.save_every_steps, global_step + args.eval_every_steps

    while global_step < args.total_timesteps:
        optimizer.param_groups[0]["lr"] = args.learning_rate * max(1.0 - global_step / args.total_timesteps, 0.0)

        with torch.no_grad():  # ---- rollout (it and the advantage estimation below need no gradients)
            for step in range(args.num_steps):
                obs_rms.update(raw_obs)
                obs = normalized(raw_obs)
                action, logp, _, value = agent.action_and_value(obs)
                raw_obs, reward, terminated, truncated, info = envs.step(action.numpy().clip(action_low, action_high))
                global_step += args.num_envs
                episode_return += reward

                discounted_return = discounted_return * args.gamma + reward
                ret_rms.update(discounted_return)
                scaled_reward = np.clip(reward / np.sqrt(ret_rms.var + 1e-8), -10, 10)
                done = terminated | truncated
                if truncated.any():  # time limit, not death: bootstrap from the value of the last observation
                    final_obs = np.stack(
                        [info["final_obs"][i] if truncated[i] else raw_obs[i] for i in range(args.num_envs)]
                    )
                    final_value = agent.value(normalized(final_obs)).numpy()
                    scaled_reward = scaled_reward + args.gamma * final_value * (truncated & ~terminated)
                for i in np.flatnonzero(done):
                    recent_returns = (recent_returns + [episode_return[i]])[-20:]
                    episode_return[i], discounted_return[i] = 0.0, 0.0

                obs_buf[step], act_buf[step], logp_buf[step], val_buf[step] = obs, action, logp, value
                rew_buf[step] = torch.as_tensor(scaled_reward, dtype=torch.float32)
                done_buf[step] = torch.as_tensor(done, dtype=torch.float32)

            # ---- generalised advantage estimation; done[t] cuts the episode after step t
            next_value = agent.value(normalized(raw_obs))
            advantages, last_gae = torch.zeros_like(rew_buf), 0.0
            for t in reversed(range(args.num_steps)):
                following_value = next_value if t == args.num_steps - 1 else val_buf[t + 1]
                not_done = 1.0 - done_buf[t]
                delta = rew_buf[t] + args.gamma * following_value * not_done - val_buf[t]
                advantages[t] = last_gae = delta + args.gamma * args.gae_lambda * not_done * last_gae
            returns = advantages + val_buf

        # ---- PPO update
        b_obs, b_act = obs_buf.reshape(-1, obs_dim), act_buf.reshape(-1, act_dim)
        b_logp, b_adv, b_ret = logp_buf.reshape(-1), advantages.reshape(-1), returns.reshape(-1)
        for _ in range(args.update_epochs):
            for idx in torch.randperm(batch_size).split(batch_size // args.num_minibatches):
                _, new_logp, entropy, new_value = agent.action_and_value(b_obs[idx], b_act[idx])
                ratio = (new_logp - b_logp[idx]).exp()
                adv = (b_adv[idx] - b_adv[idx].mean()) / (b_adv[idx].std() + 1e-8)
                policy_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)).mean()
                value_loss = 0.5 * ((new_value - b_ret[idx]) ** 2).mean()
                loss = policy_loss - args.ent_coef * entropy.mean() + args.vf_coef * value_loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()

        # ---- progress, evaluation, checkpoints
        elapsed = time.time() - start_time
        sps = (global_step - start_step) / max(elapsed, 1e-6)
        recent = f"{np.mean(recent_returns):.0f}" if recent_returns else "n/a"
        eta_min = (args.total_timesteps - global_step) / max(sps, 1e-6) / 60
        line = f"step {global_step:>9} | {sps:5.0f} steps/s | recent return {recent:>6}"
        print(f"{line} | value loss {value_loss.item():.3f} | ETA {eta_min:.1f} min", flush=True)
        if global_step >= next_eval:
            next_eval += args.eval_every_steps
            episodes = (frozen_policy(), args.env, args.train_eval_episodes, args.seed + global_step, args.frame_skip)
            eval_return = float(np.mean(evaluate(*episodes)))
            best = max(best_return, eval_return)
            print(f"eval at step {global_step}: {eval_return:.1f} (best {best:.1f})", flush=True)
            if eval_return > best_return:
                best_return = eval_return
                save_atomically(checkpoint(eval_return), best_path)
        if global_step >= next_save:
            next_save += args.save_every_steps
            save_atomically(checkpoint(), latest_path)
        if args.max_minutes and elapsed > args.max_minutes * 60 and global_step < args.total_timesteps:
            break

    save_atomically(checkpoint(), latest_path)
    envs.close()
    if global_step < args.total_timesteps:  # stopped by --max-minutes
        stopped = f"stopped after {args.max_minutes} min at step {global_step}"
        print(f"{stopped}: continue with the same command and --resume")
        return
    returns = evaluate(frozen_policy(), args.env, args.eval_episodes, seed=10_000, frame_skip=args.frame_skip)
    save_atomically(checkpoint(float(np.mean(returns))), latest_path)
    print(f"wrote {latest_path} (last) and {best_path} (best periodic evaluation, {best_return:.1f})")
    print(f"{args.env} expert: {np.mean(returns):.1f} ± {np.std(returns):.1f} over {len(returns)} episodes")


if __name__ == "__main__":
    try:
        args = tyro.cli(Args)
        mode = make_demos if args.make_demos else eval_only if args.eval_only else train
        mode(args)
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
