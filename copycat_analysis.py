# Causal diagnostics of the copycat shortcut for saved BC-SO, BC-OH and C2F models (paper section 5.4, H3); see README.md
"""Interventions that show whether a policy copies the previous action instead of reading the current frame.

Loads the models that bc_so.py, bc_oh.py and c2f.py write with --save-model for one env and, on held-out
expert demonstrations (with fresh velocity noise) and on each policy's own rollouts in the noisy env, measures

1. do(o_hist) = [o_t, ..., o_t]: how far each policy's action moves when its history is replaced by the
   current frame repeated (mean |change| per action dim / the demo actions' std), and how often the real
   history pulls the action towards the previous action a_{t-1};
2. do(zeta), C2F only: CE_d = |pi_theta(o_hist, do(zeta_d = lo_d))_d - pi_theta(o_hist, do(zeta_d = hi_d))_d|
   per action dim d, the other zeta dims left at the coarse model's output, lo_d / hi_d the 5th / 95th
   percentiles of the demo actions;
3. the copycat score on held-out demos: at action changepoints (top decile of |a_t - a_{t-1}|), the fraction
   of predictions closer to a_{t-1} than to a_t.

It prints a table and writes the pictures and a JSON report to --output-dir.

    python bc_so.py --env Hopper-v4 --seeds 1 --save-model     # likewise bc_oh.py and c2f.py
    python copycat_analysis.py --env Hopper-v4                 # reads runs/<method>/Hopper-v4/seed1.pt
    python copycat_analysis.py --env Hopper-v4 --control runs/c2f__no-coarse-action/Hopper-v4/seed1.pt   # and the capacity control
"""
import json
import os
import sys
from dataclasses import asdict, dataclass
from types import SimpleNamespace
from typing import Optional

import gymnasium as gym
import matplotlib
import mujoco
import numpy as np
import torch
import torch.nn as nn
import tyro

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the backend)

gym.logger.min_level = gym.logger.ERROR  # the paper's v4 envs are deprecated in gymnasium 1.x: keep stderr for errors
# gymnasium's HalfCheetah XML uses a compiler attribute that MuJoCo 3.x deprecates, so MuJoCo warns (and appends to
# ./MUJOCO_LOG.TXT) each time that env is made: drop that warning, print the others.
mujoco.set_mju_user_warning(lambda message: None if "settotalmass" in message else print(f"MuJoCo warning: {message}", file=sys.stderr))
METHODS = ("bc_so", "bc_oh", "c2f")
CONTROL = "c2f_no_coarse"  # the capacity control, c2f.py --no-coarse-action: C2F's network, zeros in place of zeta
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
    """C2F model written by `c2f.py --save-model` (with --coarse-output action, the default)"""
    control: Optional[str] = None
    """optional fourth model: the capacity control, `c2f.py --no-coarse-action --save-model` (do(o_hist) and the copycat score only: it reads no zeta)"""
    demos: Optional[str] = None
    """held-out demonstrations (.npz as `expert_ppo.py --make-demos` writes, read as the method files read theirs, whole); default: a fresh expert rollout from reset seed --seed (the training demos use seed 0), not cached"""
    expert: str = "experts/{env}.pt"
    """expert checkpoint that generates the held-out demos when --demos is not given"""
    num_demo_samples: int = 5000
    """held-out demo steps to generate when --demos is not given"""
    obs_noise_std: Optional[float] = None
    """std of the velocity noise on the demos' and the rollouts' observations (default: the models' training value)"""
    history: Optional[int] = None
    """frames in the history (default: the models'; it must be the BC-OH and C2F models' own)"""
    eval_episodes: int = 3
    """rollout episodes of each policy in the partially observed env"""
    zeta_quantile: float = 0.05
    """do(zeta_d) = lo_d / hi_d: the q and 1-q quantiles of the demo actions of dim d (0: their min and max)"""
    changepoint_quantile: float = 0.9
    """changepoints of the copycat score: the steps whose |a_t - a_{t-1}| is above this quantile (0.9: the top decile)"""
    output_dir: str = "analysis/{env}"
    """where the pictures and the JSON report are written"""
    seed: int = 1
    """seed of the held-out demos (not 0, the training demos' seed), of their noise and of the rollouts"""


# Copied from bc_oh.UsageError
class UsageError(Exception): ...  # bad input from the user: printed as one line on stderr, exit status 2, no traceback


# ----------------------------------------------------------------------------------------------
# Env: the partially observed setting of the paper (noisy velocities)


# Copied from bc_oh.velocity_dims
def velocity_dims(env: gym.Env, env_id: str, override=None) -> list:  # the joint velocities: where the noise goes
    obs_dim, structure = env.observation_space.shape[0], getattr(env.unwrapped, "observation_structure", None)
    if override:
        require(0 <= min(override) and max(override) < obs_dim, f"--velocity-dims must lie in [0, {obs_dim - 1}]")
        return sorted(set(override))
    if structure:  # v5 envs describe their layout: positions first, then the qvel block
        return list(range(structure["qpos"], structure["qpos"] + structure["qvel"]))
    known = {"Hopper": (5, 11), "Walker2d": (8, 17), "HalfCheetah": (8, 17), "Ant": (13, 27)}  # the v4 envs' _get_obs
    require(env_id.split("-")[0] in known, f"velocity entries of {env_id} are unknown: name them with --velocity-dims")
    return list(range(*known[env_id.split("-")[0]]))


# Copied from bc_oh.PartialObservation
class PartialObservation(gym.ObservationWrapper):  # the sensor: fresh N(0, std^2) velocity noise each step, or zeros
    def __init__(self, env: gym.Env, dims: list, std: float, hide: bool, seed: int):
        super().__init__(env)
        self.dims, self.std, self.hide, self.rng = np.asarray(dims), std, hide, np.random.default_rng(seed)

    def observation(self, obs):
        obs = np.array(obs, dtype=np.float64)
        obs[self.dims] = 0.0 if self.hide else obs[self.dims] + self.rng.normal(0.0, self.std, len(self.dims))
        return obs


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


# ----------------------------------------------------------------------------------------------
# Data: held-out expert demonstrations, noise, history


# Copied from expert_ppo.ExpertPolicy
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


# Copied from expert_ppo.load_expert
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


# Copied from expert_ppo.generate_demos
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


# Copied from expert_ppo.write_atomically
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


# Copied from bc_oh.require
def require(condition, message: str):  # refuse bad input in one line: a UsageError unless condition holds
    if not condition:
        raise UsageError(message)


# Copied from bc_oh.load_demos
def load_demos(args, env: gym.Env) -> tuple:  # (demos, meta) of --demos or `expert_ppo.py --make-demos`, checked
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    native = getattr(env.unwrapped, "frame_skip", None)
    n, rate = args.num_demo_samples or (20000 if args.env.startswith("Hopper") else 10000), args.frame_skip
    path = args.demos or f"demos/{args.env}{'' if rate == native else f'_fs{rate}'}_{n}.npz"
    make = f"python expert_ppo.py --env {args.env} --make-demos{f' --frame-skip {rate}' * (rate != native)}"
    make += f" --num-demo-samples {n}" * bool(args.num_demo_samples)
    where = f"demo file {path} not found in {os.getcwd()}"  # relative paths: the repository root holds demos/
    require(os.path.isfile(path), f"{where}: " + ("check the path" if args.demos else f"run {make}"))
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"])) if "meta" in data else {}
            demos = {key: data[key] for key in ("observations", "actions", "episode_starts") if key in data}
    except Exception as error:
        raise UsageError(f"{path} is not a readable demo file ({type(error).__name__}): see the format in README.md")
    made_for, made_at = meta.get("env_id", args.env), meta.get("frame_skip", native)  # no record: the native rate
    require(made_for == args.env, f"{path} holds demos of {made_for}: pass --env {made_for}, or demos of {args.env}")
    require(made_at == rate, f"{path} was made at frame skip {made_at}, not {rate}: pass --frame-skip {made_at}")
    for key in ("observations", "actions", "episode_starts"):
        require(key in demos, f"{path} has no {key!r} array: see the .npz format in README.md")
        require(demos[key].dtype.kind in "biuf", f"{path}: {key} hold {demos[key].dtype} values: save them as numbers")
    obs, actions, starts = demos["observations"], demos["actions"], demos["episode_starts"]
    turned = (obs_dim, act_dim) == (len(obs), len(actions))
    fix = "save them as (steps, entries), not transposed" if turned else "use demos of this env"
    need = f"{args.env} needs (N, {obs_dim}) and (N, {act_dim})"
    shapes = f"observations {obs.shape} and actions {actions.shape}, but {need}"
    require((obs.shape[1:], actions.shape[1:]) == ((obs_dim,), (act_dim,)), f"{path} holds {shapes}: {fix}")
    rows = f"observations, actions and episode_starts have {len(obs)}, {len(actions)} and {len(starts)} rows"
    require(len(obs) == len(actions) == len(starts) and starts.ndim == 1, f"{path}: {rows}: save one row per step")
    take = args.num_demo_samples or len(obs)  # with --demos: the first N steps, or all
    require(len(obs) >= take, f"{path} holds {len(obs)} steps: pass --num-demo-samples {len(obs)} or fewer")
    batch = "not more than a batch: use more, or a smaller --batch-size"
    require(take > args.batch_size, f"{path} holds {take} steps, {batch}")
    first = f" (the first {take} of its {len(obs)})" * (take < len(obs))
    obs, actions, starts = obs[:take].astype(np.float64), actions[:take].astype(np.float32), starts[:take].astype(bool)
    for key, values in (("observations", obs), ("actions", actions)):
        bad = np.unique(np.argwhere(~np.isfinite(values))[:, 0])  # each row once
        require(not len(bad), f"{path}: {key} hold non-finite values at rows {bad[:3].tolist()}: fix or drop them")
    low, high = env.action_space.low, env.action_space.high
    outside = np.unique(np.argwhere((actions < low) | (actions > high))[:, 0])
    bounds = f"lie outside the bounds [{low.min():g}, {high.max():g}]: rescale or clip them"
    require(not len(outside), f"{path}: actions of rows {outside[:3].tolist()} {bounds}")
    require(starts[0], f"{path}: episode_starts[0] is False: it is True on each episode's first step")
    step_error = ((actions[1:] - actions[:-1])[~starts[1:]] ** 2).mean(0)  # MSE(a_t-1, a_t), within episodes
    copy_error = (step_error / np.maximum(actions.var(0), 1e-12)).mean()  # / Var(a): near 0, a shortcut; near 2, none
    shortcut = f"copy error MSE(a_t-1, a_t)/Var(a) = {copy_error:.3f}"
    print(f"demos: {len(obs)} steps from {path}{first}; {shortcut} (near 0: copying the last action is a shortcut)")
    return {"observations": obs, "actions": actions, "episode_starts": starts}, meta


def heldout_demos(args, env: gym.Env, frame_skip: Optional[int]) -> dict:
    """--demos, checked as the method files check theirs (its env, rate, arrays, shapes, values), or a fresh
    expert rollout from reset seed --seed: states the policies were not trained on."""
    if args.demos is not None:  # the whole file; batch_size 1: any file of two steps or more
        rate = frame_skip or getattr(env.unwrapped, "frame_skip", None)  # the models' rate (None: the env's own)
        given = SimpleNamespace(env=args.env, demos=args.demos, num_demo_samples=None, batch_size=1, frame_skip=rate)
        try:
            return load_demos(given, env)[0]
        except UsageError as error:  # its fix "pass --frame-skip K" is the method files': here the models set the rate
            message, rate_fix, _ = str(error).partition(": pass --frame-skip")
            raise UsageError(f"{message}, the models' rate: pass --demos made at frame skip {rate}" if rate_fix else message)
    expert_path = args.expert.format(env=args.env)
    if not os.path.isfile(expert_path):
        raise UsageError(f"no expert for {args.env} at {expert_path}: pass --expert, or held-out demos with --demos")
    print(f"generating {args.num_demo_samples} held-out demonstration steps with {expert_path} (reset seed {args.seed})")
    return generate_demos(args.env, frame_skip, load_expert(expert_path, args.env), args.num_demo_samples, seed=args.seed)


# Copied from bc_oh.partially_observe
def partially_observe(observations: np.ndarray, dims: list, std: float, hide: bool, seed: int) -> np.ndarray:
    observed, rng = observations.copy(), np.random.default_rng(seed)  # the sensor's view: noise drawn once per sample
    observed[:, dims] = 0.0 if hide else observed[:, dims] + rng.normal(0.0, std, (len(observed), len(dims)))
    return observed


# Copied from bc_oh.stack_history
def stack_history(observations: np.ndarray, episode_starts: np.ndarray, history: int) -> np.ndarray:
    index = np.arange(len(observations))  # row t: [o_{t-H+1}, ..., o_t], oldest first
    first_of_episode = np.maximum.accumulate(np.where(episode_starts, index, 0))  # before it, repeat its first frame
    frames = [observations[np.maximum(index - lag, first_of_episode)] for lag in range(history - 1, -1, -1)]
    return np.concatenate(frames, axis=1)


# ----------------------------------------------------------------------------------------------
# Networks: the three policies, rebuilt from their checkpoints


# Copied from bc_oh.mlp
def mlp(in_dim: int, out_dim: int, hidden: int) -> nn.Sequential:  # the paper's three-layer MLP
    layers = [nn.Linear(in_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, out_dim)]
    return nn.Sequential(*layers)


# Copied from bc_oh.Normalizer
class Normalizer(nn.Module):  # standardises inputs with statistics of the training demos, stored with the model
    def __init__(self, inputs: torch.Tensor):
        super().__init__()
        self.register_buffer("mean", inputs.mean(0))
        self.register_buffer("std", inputs.std(0).clamp_min(1e-6))

    def forward(self, x):
        return (x - self.mean) / self.std


# Copied from bc_so.Policy with Policy->SOPolicy
class SOPolicy(nn.Module):  # BC-SO: only o_t, the last obs_dim entries of the history, into one MLP
    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, inputs: torch.Tensor):
        super().__init__()
        self.normalize = Normalizer(inputs[:, -obs_dim:])
        self.net = mlp(obs_dim, act_dim, hidden)

    def forward(self, obs_history):
        return self.net(self.normalize(obs_history[:, -self.net[0].in_features :]))  # in_features = obs_dim


# Copied from bc_oh.Policy with Policy->OHPolicy
class OHPolicy(nn.Module):  # BC-OH: the whole history, flattened, into one MLP
    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, inputs: torch.Tensor):
        super().__init__()
        self.normalize = Normalizer(inputs)
        self.net = mlp(obs_dim * history, act_dim, hidden)

    def forward(self, obs_history):
        return self.net(self.normalize(obs_history))


# Copied from c2f.Table3Policy with Table3Policy->C2FPolicy
class C2FPolicy(nn.Module):  # Policy with the flags open; at PAPER_FLAGS the same layers, order, weights and outputs
    def __init__(self, obs_dim: int, act_dim: int, inputs: torch.Tensor, args):
        super().__init__()
        frames = {"history": args.history, "current": 1}  # each model reads the whole history, or its last frame o_t
        self.normalize, self.args, hidden, fusion = Normalizer(inputs), args, args.hidden, args.fusion
        self.coarse_width, self.policy_width = obs_dim * frames[args.coarse_input], obs_dim * frames[args.policy_input]
        self.coarse = mlp(self.coarse_width, act_dim, hidden)
        fed = hidden if args.coarse_output == "feature" else act_dim  # width of what the coarse model passes on
        self.policy_first = nn.Sequential(nn.Linear(self.policy_width + fed * (fusion == "early"), hidden), nn.ReLU())
        width = act_dim if fusion == "output" else hidden  # what the policy MLP passes on (output: no last ReLU)
        self.policy_rest = nn.Sequential(nn.Linear(hidden + fed * (fusion == "middle"), hidden), nn.ReLU())
        if fusion != "penultimate":  # penultimate: BC-OH's MLP, sg(zeta) joined before its last layer (the head)
            self.policy_rest.extend([nn.Linear(hidden, width)] + [nn.ReLU()] * (fusion != "output"))
        self.head = nn.Linear(width + fed * (fusion in ("late", "penultimate", "output")), act_dim)

    def coarse_model(self, obs_history):
        feature = self.coarse[:-1](self.normalize(obs_history)[:, -self.coarse_width :])
        return self.coarse[-1](feature), feature

    def coarse_and_final(self, obs_history):
        args, (zeta, feature) = self.args, self.coarse_model(obs_history)
        fed = feature if args.coarse_output == "feature" else zeta
        fed = fed.detach() if args.stop_gradient else fed
        fed = fed if args.coarse_action else torch.zeros_like(fed)  # the capacity control: no coarse information
        join = lambda h, *stages: torch.cat([h, fed], dim=1) if args.fusion in stages else h  # noqa: E731
        h = self.policy_first(join(self.normalize(obs_history)[:, -self.policy_width :], "early"))
        h = self.policy_rest(join(h, "middle"))
        return zeta, self.head(join(h, "late", "penultimate", "output"))

    def forward(self, obs_history):
        return self.coarse_and_final(obs_history)[1]


def load_model(path: str, method: str, env_id: str, obs_dim: int, act_dim: int, control: bool = False):
    """Rebuild the policy a method script saved with --save-model; returns (policy, its training args).
    control: the model of --control, a c2f.py model trained with --no-coarse-action."""
    flag = "--control" if control else "--" + method.replace("_", "-")
    if not os.path.isfile(path):
        raise UsageError(f"{method} model {path} not found: train one with `python {method}.py --env {env_id} --seeds 1 --save-model"
                         f"{' --no-coarse-action' * control}`, or pass {flag} PATH")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
        saved_method, saved_env, saved = checkpoint["method"], checkpoint["env_id"], checkpoint["args"]
    except Exception as error:
        raise UsageError(f"{flag} {path} is not a model saved with --save-model ({type(error).__name__}): pass a seed<S>.pt written by {method}.py")
    if saved_method != method:
        raise UsageError(f"{flag} {path} is a {saved_method} model, not {method}: pass the model written by {method}.py")
    if saved_env != env_id:
        raise UsageError(f"{flag} {path} is a model of {saved_env}, not {env_id}: pass a model trained on {env_id}, or --env {saved_env}")
    if method == "c2f" and saved.get("coarse_action", True) == control:
        raise UsageError(f"{flag} {path} is a c2f model trained with{'out' * control} --no-coarse-action: pass "
                         + ("C2F's own model as --c2f" if saved.get("coarse_action", True) else "it as --control (it reads no zeta)"))
    if method == "c2f" and saved.get("coarse_output") == "feature":
        raise UsageError(f"{flag} {path} passes a feature, not an action zeta, to its policy model: do(zeta) needs a C2F model trained with --coarse-output action")
    history, hidden, inputs = saved["history"], saved["hidden"], torch.zeros(2, obs_dim * saved["history"])  # the Normalizer's statistics come from the state_dict
    if method == "bc_so":
        policy = SOPolicy(obs_dim, act_dim, history, hidden, inputs)
    elif method == "bc_oh":
        policy = OHPolicy(obs_dim, act_dim, history, hidden, inputs)
    else:
        policy = C2FPolicy(obs_dim, act_dim, inputs, SimpleNamespace(**{"coarse_action": True, **saved}))
    try:
        policy.load_state_dict(checkpoint["state_dict"])
    except RuntimeError:
        raise UsageError(f"{flag} {path}: its weights do not fit a {method} policy with history {history} on {env_id}'s {obs_dim}-d observations: re-save it with {method}.py")
    return policy.eval(), saved


def agreed(saved: dict, key: str, flag: str, readers=None, fix="pass models trained alike"):
    """The training value of `key` shared by the models in `readers` (default: all), or a clear error when they differ."""
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
    """numpy (coarse, final): zeta = pi_phi(o_t), and pi_theta(o_hist, do(zeta)) clipped to the action bounds."""

    @torch.no_grad()
    def coarse(histories: np.ndarray) -> np.ndarray:
        return policy.coarse_model(torch.as_tensor(histories, dtype=torch.float32))[0].numpy()

    @torch.no_grad()
    def final(histories: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        obs_history = torch.as_tensor(histories, dtype=torch.float32)
        fixed, feature = torch.as_tensor(zeta, dtype=torch.float32), policy.coarse_model(obs_history)[1]
        policy.coarse_model = lambda _: (fixed, feature)  # shadows the method for one call: the rest of the forward is the trained one
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
    """do(o_hist) = [o_t, ..., o_t]: every frame of each history replaced by its current (last) frame."""
    return np.tile(histories[:, -obs_dim:], histories.shape[1] // obs_dim)


def history_intervention(act, histories: np.ndarray, obs_dim: int, prev_actions: np.ndarray, scale: np.ndarray):
    """Per step: how far the action moves under do(o_hist) (mean over dims of |change| / scale), and whether
    the real history pulls it towards a_{t-1} (pi(o_hist) strictly closer to a_{t-1} than pi(do(o_hist)))."""
    factual, counterfactual = act(histories), act(repeat_current(histories, obs_dim))
    change = (np.abs(factual - counterfactual) / scale).mean(1)
    towards = distance(factual, prev_actions, scale) < distance(counterfactual, prev_actions, scale)
    return change, towards


def changepoints(actions: np.ndarray, episode_starts: np.ndarray, scale: np.ndarray, quantile: float) -> np.ndarray:
    """Steps t with a predecessor in their episode whose |a_t - a_{t-1}| (scaled) is at or above its `quantile`."""
    steps = np.flatnonzero(~episode_starts.astype(bool))
    steps = steps[steps > 0]
    jump = distance(actions[steps], actions[steps - 1], scale)
    return steps[jump >= np.quantile(jump, quantile)]


def copycat_score(predictions: np.ndarray, actions: np.ndarray, points: np.ndarray, scale: np.ndarray) -> float:
    """The fraction of the changepoints t whose prediction is closer to a_{t-1} than to a_t."""
    to_prev = distance(predictions[points], actions[points - 1], scale)
    return float(np.mean(to_prev < distance(predictions[points], actions[points], scale)))


def zeta_effect(final, histories: np.ndarray, zeta: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """CE[t, d] = |final(h_t, zeta_t with zeta_d = lo_d)_d - final(h_t, zeta_t with zeta_d = hi_d)_d|."""
    effect = np.zeros_like(zeta, dtype=np.float64)
    for d in range(zeta.shape[1]):
        low_zeta, high_zeta = zeta.copy(), zeta.copy()
        low_zeta[:, d], high_zeta[:, d] = lo[d], hi[d]
        effect[:, d] = np.abs(final(histories, low_zeta)[:, d] - final(histories, high_zeta)[:, d])
    return effect


# ----------------------------------------------------------------------------------------------
# Rollouts of each policy in the noisy env


def rollout(act, env_id: str, frame_skip: Optional[int], dims: list, std: float, hide: bool, history: int, seed: int) -> dict:
    """One episode of the deterministic policy on the partially observed env: its histories, executed
    actions, observations (the positions are noise-free) and return."""
    env = PartialObservation(make_env(env_id, frame_skip), dims, std, hide, seed)
    obs, _ = env.reset(seed=seed)
    frames = np.repeat(obs[None], history, axis=0)  # the last H frames, the first one repeated (stack_history's rule)
    record, total, done = {"histories": [], "actions": [], "observations": []}, 0.0, False
    while not done:
        histories = frames.reshape(1, -1)
        action = act(histories)[0]
        record["histories"].append(histories[0]), record["actions"].append(action), record["observations"].append(obs)
        obs, reward, terminated, truncated, _ = env.step(action)
        frames = np.concatenate([frames[1:], obs[None]])
        total, done = total + float(reward), terminated or truncated
    env.close()
    return {**{key: np.array(value) for key, value in record.items()}, "return": total}


def with_previous(episodes: list):
    """(histories, previous actions) of every step but each episode's first, over a list of rollouts."""
    histories = np.concatenate([episode["histories"][1:] for episode in episodes])
    return histories, np.concatenate([episode["actions"][:-1] for episode in episodes])


# ----------------------------------------------------------------------------------------------
# Pictures

ACTION_NAMES = {"Hopper": ["thigh", "leg", "foot"], "Walker2d": ["right thigh", "right leg", "right foot", "left thigh", "left leg", "left foot"]}
STATE_ROWS = {"Hopper": [(0, "torso height (m)"), (2, "thigh angle (rad)")], "Walker2d": [(0, "torso height (m)"), (2, "right thigh angle (rad)")]}


def plot_zeta_effect(path: str, env_id: str, effect: np.ndarray, observations: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                     episode_return: float, late_fusion: bool):
    """CE_d / (hi_d - lo_d) along one trajectory (1: the action follows zeta fully, 0: ignores it), the state beneath."""
    family = env_id.split("-")[0]
    names = ACTION_NAMES.get(family, [f"a[{d}]" for d in range(effect.shape[1])])
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(11, 6), gridspec_kw={"height_ratios": [2, 1]})
    for d in range(effect.shape[1]):
        top.plot(effect[:, d] / (hi[d] - lo[d]), lw=1, label=f"{names[d]}: do(zeta) = {lo[d]:.2f} vs {hi[d]:.2f}")
    top.set_ylabel("CE / (hi - lo)")
    if late_fusion:  # late or output fusion: one linear layer after the join, so the effect is a weight of it
        fig.text(0.01, 0.01, "late fusion: the final layer is linear in zeta, so CE / (hi - lo) = |its weight on zeta_d| wherever the "
                 "action is not clipped at its bounds (dips: clipped)", fontsize=8)
    top.set_title(f"{env_id}, C2F on its own noisy rollout (return {episode_return:.0f}): causal effect of the coarse action zeta")
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
    """Per source (held-out demos, own rollouts), the distribution of each method's per-step |change| under do(o_hist)."""
    fig, axes = plt.subplots(1, len(changes), figsize=(6 * len(changes), 4))
    for ax, (source, per_method) in zip(np.atleast_1d(axes), changes.items()):
        top = max(float(np.quantile(np.concatenate(list(per_method.values())), 0.99)), 1e-3)
        bins = np.linspace(0, top, 41)
        for method, change in per_method.items():
            ax.hist(np.minimum(change, top), bins, weights=np.full(len(change), 1 / len(change)), histtype="step", lw=1.5,
                    color=COLORS[method], label=f"{method} (mean {change.mean():.3f})")
        ax.set_yscale("log")
        ax.set_xlabel("mean |pi(o_hist) - pi(do(o_hist) = [o_t, ..., o_t])| / demo action std\n(above the 99th percentile: last bin)")
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
    if args.obs_noise_std is not None and args.obs_noise_std < 0:
        raise UsageError(f"--obs-noise-std must be >= 0, got {args.obs_noise_std}")
    if not 0 <= args.zeta_quantile < 0.5:
        raise UsageError(f"--zeta-quantile must lie in [0, 0.5), got {args.zeta_quantile}")
    if not 0 <= args.changepoint_quantile < 1:
        raise UsageError(f"--changepoint-quantile must lie in [0, 1), got {args.changepoint_quantile}")
    if args.demos is None and args.seed == 0:
        raise UsageError("--seed 0 would regenerate the training demonstrations: use another seed for held-out demos")


def run(args):
    """Load the three models (four with --control), intervene on held-out demos and on their own rollouts, report and draw."""
    check_args(args)
    env = make_env(args.env)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    low, high = env.action_space.low, env.action_space.high
    models, saved = {}, {}
    paths = {method: getattr(args, method).format(env=args.env) for method in METHODS}
    for method in METHODS:
        models[method], saved[method] = load_model(paths[method], method, args.env, obs_dim, act_dim)
    if args.control:
        paths[CONTROL] = args.control.format(env=args.env)
        models[CONTROL], saved[CONTROL] = load_model(paths[CONTROL], "c2f", args.env, obs_dim, act_dim, control=True)
    model_history = agreed(saved, "history", "--history", tuple(m for m in saved if m != "bc_so"), "pass models trained with one history length")  # BC-SO reads o_t only: any history fits it
    history = args.history or model_history
    if history != model_history:
        raise UsageError(f"--history {history} does not match the models, trained with history {model_history}: drop --history or pass {model_history}")
    std = agreed(saved, "obs_noise_std", "--obs-noise-std", fix="pass --obs-noise-std for the analysis") if args.obs_noise_std is None else args.obs_noise_std
    dims = velocity_dims(env, args.env, agreed(saved, "velocity_dims", "--velocity-dims"))
    frame_skip = agreed(saved, "frame_skip", "--frame-skip")  # None (models made before the flag): the env's own
    hide = bool(agreed(saved, "hide_velocities", "--hide-velocities"))

    demos = heldout_demos(args, env, frame_skip)
    actions, starts = demos["actions"].astype(np.float64), demos["episode_starts"]
    scale = actions.std(0).clip(1e-6)  # the expert's action scale, per dim
    lo, hi = np.quantile(actions, args.zeta_quantile, axis=0), np.quantile(actions, 1 - args.zeta_quantile, axis=0)
    histories = stack_history(partially_observe(demos["observations"], dims, std, hide, args.seed), starts, history)
    steps = np.flatnonzero(~starts)  # steps with a previous action in their episode
    points = changepoints(actions, starts, scale, args.changepoint_quantile)

    actors = {method: as_actor(model, low, high) for method, model in models.items()}
    rollouts = {method: [rollout(actors[method], args.env, frame_skip, dims, std, hide, history, 1000 * args.seed + i) for i in range(args.eval_episodes)] for method in models}
    changes, report = {"held-out demos": {}, "own rollouts": {}}, {}
    for method in models:
        change, towards = history_intervention(actors[method], histories[steps], obs_dim, actions[steps - 1], scale)
        roll_histories, roll_prev = with_previous(rollouts[method])
        roll_change, roll_towards = history_intervention(actors[method], roll_histories, obs_dim, roll_prev, scale)
        changes["held-out demos"][method], changes["own rollouts"][method] = change, roll_change
        report[method] = {
            "model": paths[method],
            "rollout_returns": [episode["return"] for episode in rollouts[method]],
            "history_change_demos": float(change.mean()), "towards_previous_demos": float(towards.mean()),
            "history_change_rollouts": float(roll_change.mean()), "towards_previous_rollouts": float(roll_towards.mean()),
            "copycat_score": copycat_score(actors[method](histories), actions, points, scale),
        }
    coarse, final = zeta_intervention(models["c2f"], low, high)
    c2f_histories = np.concatenate([episode["histories"] for episode in rollouts["c2f"]])
    effect_demos = zeta_effect(final, histories, coarse(histories), lo, hi)
    effect_rollouts = zeta_effect(final, c2f_histories, coarse(c2f_histories), lo, hi)
    first = rollouts["c2f"][0]
    zeta = {"lo": lo.tolist(), "hi": hi.tolist(), "effect_demos": effect_demos.mean(0).tolist(), "effect_rollouts": effect_rollouts.mean(0).tolist(),
            "relative_demos": (effect_demos.mean(0) / (hi - lo)).tolist(), "relative_rollouts": (effect_rollouts.mean(0) / (hi - lo)).tolist()}

    out_dir = args.output_dir.format(env=args.env)
    plot_zeta_effect(os.path.join(out_dir, "zeta_effect.png"), args.env, effect_rollouts[: len(first["actions"])], first["observations"], lo, hi, first["return"],
                     saved["c2f"]["fusion"] in ("late", "output"))
    plot_history_intervention(os.path.join(out_dir, "history_intervention.png"), args.env, changes)
    summary = {"env": args.env, "args": asdict(args), "history": history, "obs_noise_std": std, "frame_skip": frame_skip, "hide_velocities": hide, "demo_steps": len(actions),
               "changepoints": len(points), "action_std": scale.tolist(), "methods": report, "zeta": zeta}
    write_atomically(os.path.join(out_dir, "copycat_analysis.json"), lambda file: file.write(json.dumps(summary, indent=1).encode()))

    print(f"\n{args.env}: {len(actions)} held-out demo steps ({len(points)} changepoints), {args.eval_episodes} rollouts per policy, {'velocities hidden' if hide else f'noise std {std}'}, history {history}, frame skip {frame_skip or 'native'}")
    print("do(o_hist): mean |change| / action std, and the fraction of steps the history pulls towards a_{t-1}")
    print(f"{'method':>13} | {'return':>7} | {'change demos':>12} | {'towards':>7} | {'change rollouts':>15} | {'towards':>7} | {'copycat score':>13}")
    for method, row in report.items():
        print(f"{method:>13} | {np.mean(row['rollout_returns']):7.1f} | {row['history_change_demos']:12.3f} | {row['towards_previous_demos']:7.2f} | "
              f"{row['history_change_rollouts']:15.3f} | {row['towards_previous_rollouts']:7.2f} | {row['copycat_score']:13.2f}")
    print("do(zeta), c2f: CE = |pi(do(zeta_d) = lo_d) - pi(do(zeta_d) = hi_d)|_d, and CE / (hi - lo)")
    print(f"{'dim':>3} | {'lo':>6} | {'hi':>6} | {'CE demos':>8} | {'rel':>5} | {'CE rollouts':>11} | {'rel':>5}")
    for d in range(act_dim):
        print(f"{d:>3} | {lo[d]:6.2f} | {hi[d]:6.2f} | {zeta['effect_demos'][d]:8.3f} | {zeta['relative_demos'][d]:5.2f} | "
              f"{zeta['effect_rollouts'][d]:11.3f} | {zeta['relative_rollouts'][d]:5.2f}")
    print(f"pictures and report: {out_dir}/ (zeta_effect.png, history_intervention.png, copycat_analysis.json)")


if __name__ == "__main__":
    try:
        run(tyro.cli(Args))
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
