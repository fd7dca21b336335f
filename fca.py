# Fighting Copycat Agents, FCA (Wen et al. 2020; paper Table 2 baseline); see README.md
"""FCA: BC-OH whose history embedding is stripped of what it says about the previous action.

An encoder G maps the flattened noisy history to an embedding e, a policy head F maps e to a_t, and an
adversary D predicts a_{t-1} from concat(e, a_t). D is conditioned on the true current action, so only
information about a_{t-1} that a_t does not already explain gets removed. The updates alternate (no
gradient reversal): D steps on MSE(D(e, a_t), a_{t-1}), then G and F step on
MSE(F(e), a_t) - w * MSE(D(e, a_t), a_{t-1}).

    python fca.py --env Hopper-v4
"""
import hashlib
import json
import multiprocessing
import os
import platform
import re
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import List, Optional

import gymnasium as gym
import mujoco
import numpy as np
import torch
import torch.nn as nn
import tyro

METHOD = "fca"


@dataclass
class Args:
    env: str = "Hopper-v4"
    """gymnasium MuJoCo env id (Hopper, HalfCheetah, Walker2d, Ant; v4 or v5)"""
    frame_skip: Optional[int] = None
    """simulator steps per action; None: the env's own, 4 for Hopper and Walker2d, 5 for HalfCheetah and Ant (episodes and rewards are rescaled to the same simulated time and return scale)"""
    seeds: List[int] = field(default_factory=lambda: [1, 2, 3])
    """training seeds, run in parallel by --workers; each seed's result is written when it ends, and a rerun keeps the seeds already done with the same settings; the score is mean ± std over them"""
    workers: Optional[int] = None
    """seeds trained at the same time, each in its own process; None: as many as the machine's cores (os.sched_getaffinity), at most one per seed; always 1 with --cuda"""
    demos: Optional[str] = None
    """demonstrations (.npz, format in README); None: roll out the expert once and cache under demos/"""
    expert: str = "experts/{env}.pt"
    """expert checkpoint used to generate demonstrations when --demos is not given"""
    num_demo_samples: Optional[int] = None
    """demonstration steps: how many to generate, or with --demos the first N of the file; None: the paper's 20000 for Hopper and 10000 otherwise (with --demos: all)"""
    obs_noise_std: float = 0.2
    """std of the Gaussian noise on the velocity entries of every observation (partial observability)"""
    hide_velocities: bool = False
    """zero the velocity entries of every observation instead of adding noise (the positions-only setting)"""
    velocity_dims: Optional[List[int]] = None
    """indices of the velocity entries, for envs not in the built-in table"""
    history: int = 2
    """frames in the observation history [o_{t-H+1}, ..., o_t]"""
    epochs: int = 1000
    """training length: one epoch is num-samples / batch-size minibatch steps, each minibatch drawn at random with replacement"""
    batch_size: int = 64
    """minibatch size"""
    learning_rate: Optional[float] = None
    """Adam learning rate, decayed linearly to zero; None: the paper's, 1e-5 for Hopper and 1e-4 otherwise"""
    eval_every: int = 100
    """evaluate every this many epochs (and after the last); a seed's score is the mean of its last 3"""
    eval_episodes: int = 10
    """episodes per evaluation, run in parallel on the partially observed env with the deterministic policy"""
    output_dir: str = "runs/{run_name}/{env}"
    """where the JSON results (and with --save-model the checkpoints) go; {run_name} is the method ({method}) plus each flag given a non-default value (e.g. c2f__fusion-early), so runs of other settings never overwrite each other's results"""
    save_model: bool = False
    """write a self-contained checkpoint per seed (weights, normalisation, args)"""
    cuda: bool = False
    """train on the GPU when there is one"""
    cuda_graph: bool = True
    """with --cuda, replay each training step as one captured CUDA graph (the fast path; it agrees with eager steps to float rounding); --no-cuda-graph for plain eager steps"""
    adversary_weight: Optional[float] = None
    """w in MSE(F(e), a_t) - w * MSE(D(e, a_t), a_{t-1}); None: the authors', 2 on Hopper (their Hopper command), 1 otherwise"""
    adversary_lr_ratio: Optional[float] = None
    """D's Adam learning rate over G's and F's (--learning-rate, decayed alike); None: the authors', 2 on Hopper, 1 otherwise"""
    encoder_hidden: int = 300
    """width of the encoder's three hidden layers and of the one hidden layer of the policy head and the adversary (the authors' 300)"""
    embedding_dim: int = 100
    """size of the history embedding e (the authors' 100)"""

    def __post_init__(self):
        if self.adversary_weight is not None and not self.adversary_weight >= 0:
            raise UsageError(f"--adversary-weight must be >= 0, got {self.adversary_weight}: 0 gives BC-OH on the FCA network")
        for name in ("adversary_lr_ratio", "encoder_hidden", "embedding_dim"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise UsageError(f"--{name.replace('_', '-')} must be positive, got {getattr(self, name)}")


# ==============================================================================================
# The method: an encoder, a policy head and an adversary that predicts a_{t-1}, trained in turns


# Copied from bc_oh.Normalizer
class Normalizer(nn.Module):
    """Standardises inputs with statistics of the training demos, stored with the model."""

    def __init__(self, inputs: torch.Tensor):
        super().__init__()
        self.register_buffer("mean", inputs.mean(0))
        self.register_buffer("std", inputs.std(0).clamp_min(1e-6))

    def forward(self, x):
        return (x - self.mean) / self.std


def head(in_dim: int, out_dim: int, hidden: int) -> nn.Sequential:
    """The authors' policy head F and adversary D: LeakyReLU(0.2) on the input, one hidden layer."""
    return nn.Sequential(nn.LeakyReLU(0.2), nn.Linear(in_dim, hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, out_dim))


def authors_init(module: nn.Module):
    """The authors' weights_init: Xavier-uniform Linear weights, zero biases, BatchNorm scales drawn from N(1, 0.02^2)."""
    if isinstance(module, nn.Linear):
        nn.init.xavier_uniform_(module.weight)
        if module.bias is not None:
            nn.init.zeros_(module.bias)
    elif isinstance(module, nn.BatchNorm1d):
        nn.init.normal_(module.weight, 1.0, 0.02)
        nn.init.zeros_(module.bias)


class Policy(nn.Module):
    """FCA: encoder G over the flattened history -> embedding e, policy head F(e) -> a_t, and the adversary
    D(e, a_t) -> a_{t-1}, used only in training. G is the authors': three hidden layers of Linear -> BatchNorm1d ->
    LeakyReLU(0.2) (the first Linear without bias). BatchNorm bounds the embedding's scale: G maximises D's error,
    and without a bound it can inflate e instead of removing what e says about a_{t-1}."""

    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, embedding_dim: int, inputs: torch.Tensor):
        super().__init__()
        self.normalize = Normalizer(inputs)
        self.encoder = nn.Sequential(nn.Linear(obs_dim * history, hidden, bias=False), nn.BatchNorm1d(hidden), nn.LeakyReLU(0.2),
                                     nn.Linear(hidden, hidden), nn.BatchNorm1d(hidden), nn.LeakyReLU(0.2),
                                     nn.Linear(hidden, hidden), nn.BatchNorm1d(hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, embedding_dim))
        self.head = head(embedding_dim, act_dim, hidden)
        self.adversary = head(embedding_dim + act_dim, act_dim, hidden)  # conditioned on the true a_t
        self.apply(authors_init)

    def embed(self, obs_history):
        return self.encoder(self.normalize(obs_history))

    def predict_previous_action(self, embedding, action):
        return self.adversary(torch.cat([embedding, action], dim=-1))

    def forward(self, obs_history):
        return self.head(self.embed(obs_history))


def make_policy(args, obs_dim: int, act_dim: int, inputs: torch.Tensor) -> nn.Module:
    return Policy(obs_dim, act_dim, args.history, args.encoder_hidden, args.embedding_dim, inputs)


def previous_actions(actions: np.ndarray, episode_starts: np.ndarray) -> np.ndarray:
    """Row t = a_{t-1}. At an episode start there is none: a_t itself stands in (the history rule of
    stack_history, first frame repeated), so the adversary has nothing to remove there."""
    return stack_history(actions, episode_starts, 2)[:, : actions.shape[1]]


def adversary_step(policy: Policy, optimizer, embedding, actions, previous) -> torch.Tensor:
    """One step of D on MSE(D(e, a_t), a_{t-1}), the embedding held fixed (detached); returns that loss."""
    loss = ((policy.predict_previous_action(embedding.detach(), actions) - previous) ** 2).mean()
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    return loss.detach()


def encoder_policy_step(policy: Policy, optimizer, embedding, actions, previous, weight: float):
    """One step of G and F (optimizer holds only theirs) on MSE(F(e), a_t) - w * MSE(D(e, a_t), a_{t-1}):
    fit a_t while making a_{t-1} unpredictable for the current D. Returns (BC loss, adversary loss)."""
    bc_loss = ((policy.head(embedding) - actions) ** 2).mean()
    adversary_loss = ((policy.predict_previous_action(embedding, actions) - previous) ** 2).mean()
    optimizer.zero_grad()
    (bc_loss - weight * adversary_loss).backward()
    optimizer.step()
    return bc_loss.detach(), adversary_loss.detach()


def authors_setting(env_id: str, weight: Optional[float], lr_ratio: Optional[float]) -> tuple:
    """(w, D's lr / G's lr): the flags, or the authors' values (their Hopper command: w = 2, D at 4e-4 against 2e-4)."""
    hopper = env_id.startswith("Hopper")
    return (2.0 if hopper else 1.0) if weight is None else weight, (2.0 if hopper else 1.0) if lr_ratio is None else lr_ratio


def train_seed(args, demos: dict, seed: int, device) -> dict:
    """Train one seed; returns its evaluations [(epoch, mean return)] and the trained policy."""
    torch.manual_seed(seed)
    env = make_env(args.env)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    noisy = partially_observe(demos["observations"], velocity_dims(env, args.env, args.velocity_dims), args.obs_noise_std, args.hide_velocities, seed)
    inputs = torch.as_tensor(stack_history(noisy, demos["episode_starts"], args.history), dtype=torch.float32, device=device)
    targets = torch.as_tensor(demos["actions"], dtype=torch.float32, device=device)
    previous = torch.as_tensor(previous_actions(demos["actions"], demos["episode_starts"]), dtype=torch.float32, device=device)
    print(f"seed {seed} | adversary reference: predicting a_(t-1) = a_t has error {((previous - targets) ** 2).mean().item():.5f}")
    policy = make_policy(args, obs_dim, act_dim, inputs).to(device)
    fast = device.type == "cuda" and args.cuda_graph
    weight, lr_ratio = authors_setting(args.env, args.adversary_weight, args.adversary_lr_ratio)
    print(f"seed {seed} | w = {weight:g}; learning rates: G and F {args.learning_rate:g}, D {args.learning_rate * lr_ratio:g}")
    optimizer = make_adam([*policy.encoder.parameters(), *policy.head.parameters()], args.learning_rate, fast, betas=(0.5, 0.999))
    adversary_optimizer = make_adam(policy.adversary.parameters(), args.learning_rate * lr_ratio, fast, betas=(0.5, 0.999))

    def train_step(idx):  # alternating updates, as the authors: the adversary D, then the encoder G and the policy head F
        embedding = policy.embed(inputs[idx])  # once a step: BatchNorm's running statistics move once a step
        adversary_loss = adversary_step(policy, adversary_optimizer, embedding, targets[idx], previous[idx])
        loss, _ = encoder_policy_step(policy, optimizer, embedding, targets[idx], previous[idx], weight)
        return loss, adversary_loss

    evaluations, ms_per_step = fit(args, policy, optimizer, adversary_optimizer, lr_ratio, train_step, len(inputs), seed, device, fast)
    return {"evaluations": evaluations, "policy": policy, "obs_dim": obs_dim, "act_dim": act_dim, "ms_per_step": ms_per_step}


# (fit is this file's own: it decays the adversary's learning rate too, and logs the adversary's mean error)
def fit(args, policy: nn.Module, optimizer, adversary_optimizer, lr_ratio: float, train_step, num_samples: int, seed: int, device, fast: bool) -> tuple:
    """Run train_step(minibatch indices) for --epochs, both learning rates decayed linearly to zero; evaluate every --eval-every
    epochs and after the last. Returns ([(epoch, mean return)], ms per training step)."""
    steps_per_epoch = num_samples // args.batch_size
    total_steps, step, evaluations, start, train_time = args.epochs * steps_per_epoch, 0, [], time.time(), 0.0
    generator = torch.Generator(device=device).manual_seed(seed)
    idx = torch.zeros(args.batch_size, dtype=torch.long, device=device)  # the minibatch's indices, a fixed buffer
    step_fn = CudaGraphStep(lambda: train_step(idx), enabled=fast)
    for epoch in range(1, args.epochs + 1):
        epoch_start, adversary_error = time.time(), torch.zeros((), device=device)
        for _ in range(steps_per_epoch):
            set_learning_rate(optimizer, args.learning_rate * (1 - step / total_steps))  # linear decay
            set_learning_rate(adversary_optimizer, lr_ratio * args.learning_rate * (1 - step / total_steps))
            idx.copy_(torch.randint(num_samples, (args.batch_size,), device=device, generator=generator))
            loss, adversary_loss = step_fn()
            adversary_error += adversary_loss / steps_per_epoch
            step += 1
        last_loss = loss.item()  # also waits for the GPU, so train_time is the true training time
        train_time += time.time() - epoch_start
        if epoch % args.eval_every == 0 or epoch == args.epochs:
            policy.eval()
            evaluations.append((epoch, float(np.mean(evaluate(policy, args, args.eval_episodes, 10_000 * seed + epoch, device)))))
            policy.train()
        if epoch % args.eval_every == 0 or epoch == args.epochs or epoch % max(1, args.epochs // 20) == 0:
            later_seeds = len(args.seeds) - 1 - args.seeds.index(seed) if seed in args.seeds else 0
            waves = later_seeds // (args.workers or 1)  # the later seeds run --workers at a time
            eta = (time.time() - start) / epoch * (args.epochs - epoch + waves * args.epochs) / 60  # for the whole run
            last = f"{evaluations[-1][1]:.1f}" if evaluations else "n/a"
            print(f"seed {seed} | epoch {epoch}/{args.epochs} | loss {last_loss:.5f} | adversary error {adversary_error.item():.5f} | "
                  f"last eval {last} | {1000 * train_time / step:.2f} ms/step | ETA {eta:.1f} min", flush=True)
    return evaluations, 1000 * train_time / step


# ==============================================================================================
# Evaluation


# Copied from bc_oh.evaluate
@torch.no_grad()
def evaluate(policy: nn.Module, args, episodes: int, seed: int, device) -> list:
    """Returns of `episodes` parallel episodes of the deterministic policy on the partially observed env."""
    probe = make_env(args.env, args.frame_skip)
    dims, low, high = velocity_dims(probe, args.env, args.velocity_dims), probe.action_space.low, probe.action_space.high
    probe.close()
    envs = gym.vector.SyncVectorEnv(
        [lambda i=i: PartialObservation(make_env(args.env, args.frame_skip), dims, args.obs_noise_std, args.hide_velocities, seed + i)
         for i in range(episodes)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    obs, _ = envs.reset(seed=seed)
    frames = np.repeat(obs[:, None], args.history, axis=1)  # per env [o_{t-H+1}, ..., o_t], the first frame repeated (stack_history's rule)
    returns, running = np.zeros(episodes), np.ones(episodes, bool)
    while running.any():
        inputs = torch.as_tensor(frames.reshape(episodes, -1), dtype=torch.float32, device=device)
        action = policy(inputs).cpu().numpy().clip(low, high)
        obs, reward, terminated, truncated, _ = envs.step(action)
        returns += reward * running
        running &= ~(terminated | truncated)  # each env plays exactly one episode: what follows its end does not count
        frames = np.concatenate([frames[:, 1:], obs[:, None]], axis=1)
    envs.close()
    return returns.tolist()


# ==============================================================================================
# Shared plumbing, identical in every method file (each "# Copied from" block is checked by
# scripts/check_copies.py): the seed loop, the partially observed env, demos, history, fast GPU path


# Copied from bc_oh.run
def run(args):
    """Check the input, get the demos, train every seed (writing its result when it ends), report."""
    check_common_args(args)
    name = run_name(args)  # before the defaults are filled in: it names what the user changed
    env = make_env(args.env)
    velocity_dims(env, args.env, args.velocity_dims)  # fail early for envs of unknown layout
    args.frame_skip = args.frame_skip or getattr(env.unwrapped, "frame_skip", None)  # recorded in results and checkpoints
    make_env(args.env, args.frame_skip)  # fail early for a frame skip the env cannot take
    if args.learning_rate is None:
        args.learning_rate = 1e-5 if args.env.startswith("Hopper") else 1e-4
    torch.set_num_threads(1)  # these small networks gain nothing from more threads, and runs can share a machine
    demos = load_or_generate_demos(args, env)
    output_dir = args.output_dir.format(method=METHOD, run_name=name, env=args.env)
    per_seed, to_train = {}, []
    for seed in args.seeds:
        seed_path = os.path.join(output_dir, f"result_seeds{seed}.json")
        per_seed[seed] = finished_seed(seed_path, args)
        if per_seed[seed]:
            print(f"seed {seed}: kept its finished result {seed_path}, made with these settings (delete it to train the seed again)")
        else:
            to_train.append(seed)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    args.workers = 1 if args.cuda else max(1, min(args.workers or cores, len(to_train)))  # the GPU: one seed at a time
    if args.workers == 1:
        entries = [train_and_record(args, demos, seed, output_dir) for seed in to_train]
    else:  # spawn, not fork: torch and MuJoCo are not fork-safe (and macOS has no fork default)
        with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
            entries = pool.starmap(train_and_record, [(args, demos, seed, output_dir) for seed in to_train], chunksize=1)
    per_seed.update(zip(to_train, entries))
    result_path = os.path.join(output_dir, f"result_seeds{'-'.join(map(str, args.seeds))}.json")
    write_result(result_path, args, output_dir, per_seed)
    print(f"\n{'seed':>6} | {'score':>8}")
    for seed, entry in per_seed.items():
        print(f"{seed:>6} | {entry['score']:8.1f}")
    print(f"result: {result_path}")
    print(summary_line(args, [entry["score"] for entry in per_seed.values()]))


# Copied from bc_oh.train_and_record
def train_and_record(args, demos: dict, seed: int, output_dir: str) -> dict:
    """Train one seed, write its model (with --save-model) and its result_seeds<seed>.json; returns its entry of the
    result. run calls it in this process, or in a worker process of its pool (--workers)."""
    torch.set_num_threads(1)  # first: a worker process starts with torch's default of all the cores
    device = torch.device("cuda" if args.cuda else "cpu")
    result = train_seed(args, demos, seed, device)
    score = float(np.mean([ret for _, ret in result["evaluations"][-3:]]))  # the paper: mean of the last 3
    entry = {"score": score, "evaluations": result["evaluations"], "ms_per_step": result["ms_per_step"]}
    if args.save_model:
        checkpoint = {"method": METHOD, "env_id": args.env, "args": asdict(args), "obs_dim": result["obs_dim"],
                      "act_dim": result["act_dim"], "state_dict": result["policy"].cpu().state_dict()}
        write_atomically(os.path.join(output_dir, f"seed{seed}.pt"), lambda file: torch.save(checkpoint, file))
    write_result(os.path.join(output_dir, f"result_seeds{seed}.json"), args, output_dir, {seed: entry})  # now: an interrupted run keeps this seed
    sys.stdout.flush()  # a worker's prints reach the terminal before the pool ends it
    return entry


# Copied from bc_oh.run_name
def run_name(args) -> str:
    """{run_name} in --output-dir: METHOD, then every flag given a value other than its default
    (e.g. c2f__fusion-early__no-stop-gradient), so runs of other settings never overwrite each other's results.
    Flags that change no result (seeds, where results go, the device) are left out."""
    defaults, changed = type(args)(), []
    for name, value in asdict(args).items():
        if name in ("seeds", "workers", "output_dir", "save_model", "cuda", "cuda_graph") or value == getattr(defaults, name):
            continue
        flag = name.replace("_", "-")
        text = "-".join(map(str, value)) if isinstance(value, list) else os.path.basename(str(value)).removesuffix(".npz").removesuffix(".pt")
        changed.append(flag if value is True else f"no-{flag}" if value is False else f"{flag}-{text}")
    return "__".join([METHOD, *changed])


# Copied from bc_oh.finished_seed
def finished_seed(path: str, args) -> Optional[dict]:
    """The entry of the one seed in the result at path, if an earlier run wrote it with these same settings (and
    with --save-model, its model): a rerun of an interrupted command trains only the seeds it had not finished."""
    ignored = ("seeds", "workers", "output_dir", "cuda", "cuda_graph", "save_model")
    try:
        with open(path) as file:
            result = json.load(file)
        (entry,) = result["scores"].values()
        recorded = {name: value for name, value in result["args"].items() if name not in ignored}
    except Exception:  # none yet, or not one of ours: train the seed
        return None
    same = recorded == {name: value for name, value in asdict(args).items() if name not in ignored}
    model_kept = not args.save_model or os.path.isfile(os.path.join(os.path.dirname(path), f"seed{result['args']['seeds'][0]}.pt"))
    return entry if same and model_kept else None


# Copied from bc_oh.write_result
def write_result(path: str, args, output_dir: str, per_seed: dict, **more):
    """Write the JSON result of the seeds in per_seed (atomically), with their mean and std and where it was made."""
    scores = [entry["score"] for entry in per_seed.values()]
    recorded = {**asdict(args), "seeds": list(per_seed), "output_dir": os.path.relpath(output_dir)}  # relative: no machine named
    summary = {"env": args.env, "method": METHOD, "args": recorded, "scores": per_seed, "mean": float(np.mean(scores)),
               "std": float(np.std(scores)), **more, "machine": machine()}
    write_atomically(path, lambda file: file.write(json.dumps(summary, indent=1).encode()))


# Copied from bc_oh.summary_line
def summary_line(args, scores: list) -> str:
    """Mean ± std over the seeds, and its share of the shipped expert's return (recorded by expert_ppo.py --ship-to)."""
    line = f"{args.env} {METHOD}: {np.mean(scores):.1f} ± {np.std(scores):.1f} over {len(scores)} seed{'s' * (len(scores) > 1)}"
    try:
        expert = float(torch.load(args.expert.format(env=args.env), map_location="cpu", weights_only=True)["eval_return"])
    except Exception:  # no expert file (own demos), or one without a recorded return: no share to give
        return line
    return f"{line}, {np.mean(scores) / expert:.0%} of the expert's {expert:.0f}"


# Copied from bc_oh.UsageError
class UsageError(Exception):
    """Bad input from the user: printed as one line on stderr, exit status 2, no traceback."""


# Copied from bc_oh.check_common_args
def check_common_args(args):
    """Reject bad values of the arguments every method shares, before anything slow happens."""
    for name in ("history", "epochs", "batch_size", "hidden", "eval_every", "eval_episodes", "frame_skip", "learning_rate", "workers"):
        if getattr(args, name, None) is not None and not getattr(args, name) > 0:
            raise UsageError(f"--{name.replace('_', '-')} must be positive, got {getattr(args, name)}: pass a positive value, or leave it out for its default")
    if args.obs_noise_std < 0:
        raise UsageError(f"--obs-noise-std must be >= 0, got {args.obs_noise_std}: pass 0 for noise-free observations")
    if not args.seeds:
        raise UsageError("--seeds needs at least one seed: e.g. --seeds 1 2 3")
    if args.num_demo_samples is not None and args.num_demo_samples <= args.batch_size:
        raise UsageError(f"--num-demo-samples must exceed --batch-size ({args.batch_size}), got {args.num_demo_samples}: pass more samples or a smaller batch")
    if args.cuda and not torch.cuda.is_available():
        raise UsageError("--cuda, but torch sees no CUDA GPU here (torch.cuda.is_available() is False): drop --cuda to train on the CPU")


# Copied from bc_oh.velocity_dims
def velocity_dims(env: gym.Env, env_id: str, override=None) -> list:
    """Indices of the joint velocities in the observation, where the paper adds its noise."""
    obs_dim = env.observation_space.shape[0]
    if override:
        if min(override) < 0 or max(override) >= obs_dim:
            raise UsageError(f"--velocity-dims must lie in [0, {obs_dim - 1}] for {env_id}")
        return sorted(set(override))
    structure = getattr(env.unwrapped, "observation_structure", None)
    if structure:  # v5 envs describe their layout
        start = structure["qpos"]  # positions come first, then the qvel block
        return list(range(start, start + structure["qvel"]))
    # the v4 envs' qvel block, from their _get_obs in gymnasium/envs/mujoco/<env>_v4.py
    known = {"Hopper": (5, 11), "Walker2d": (8, 17), "HalfCheetah": (8, 17), "Ant": (13, 27)}
    family = env_id.split("-")[0]
    if family not in known:
        raise UsageError(f"velocity entries of {env_id} are unknown: name them with --velocity-dims")
    return list(range(*known[family]))


# Copied from bc_oh.PartialObservation
class PartialObservation(gym.ObservationWrapper):
    """The policy's sensor: fresh N(0, std^2) noise on the velocity entries of every observation, or
    with hide, those entries zeroed (positions only)."""

    def __init__(self, env: gym.Env, dims: list, std: float, hide: bool, seed: int):
        super().__init__(env)
        self.dims, self.std, self.hide, self.rng = np.asarray(dims), std, hide, np.random.default_rng(seed)

    def observation(self, obs):
        obs = np.array(obs, dtype=np.float64)
        if self.hide:
            obs[self.dims] = 0.0
        else:
            obs[self.dims] += self.rng.normal(0.0, self.std, len(self.dims))
        return obs


# Copied from bc_oh.make_env
def make_env(env_id: str, frame_skip: Optional[int] = None) -> gym.Env:
    """gym.make with a clear error for unknown ids and non-continuous action spaces. A frame_skip other
    than the env's own K0 stretches the time limit by K0 / frame_skip and scales every reward by
    frame_skip / K0: an episode covers the same simulated time and returns keep their usual scale."""
    try:
        env = gym.make(env_id)
    except Exception as error:  # gymnasium raises several error types for unknown or broken ids
        raise UsageError(f"cannot make env {env_id!r} ({error}): use a gymnasium MuJoCo id such as Hopper-v4")
    if not isinstance(env.action_space, gym.spaces.Box):
        raise UsageError(f"env {env_id!r} has a {type(env.action_space).__name__} action space: imitation here needs continuous actions")
    native = getattr(env.unwrapped, "frame_skip", None)
    if frame_skip is None or frame_skip == native:
        return env
    if native is None:
        raise UsageError(f"env {env_id!r} is not a MuJoCo env: --frame-skip needs one, leave it out")
    env = gym.make(env_id, max_episode_steps=round(env.spec.max_episode_steps * native / frame_skip))
    env.unwrapped.frame_skip = frame_skip  # MuJoCo envs step the simulator frame_skip times per action; dt follows
    return gym.wrappers.TransformReward(env, lambda reward: reward * frame_skip / native)


# Copied from expert_ppo.ExpertPolicy
class ExpertPolicy(nn.Module):
    """The deterministic expert: frozen obs normalisation, mean action of the actor, clipped to bounds."""

    def __init__(self, checkpoint: dict):
        super().__init__()
        obs_dim, act_dim, hidden = checkpoint["obs_shape"][0], checkpoint["action_shape"][0], checkpoint["hidden"]
        self.net = nn.Sequential(nn.Linear(obs_dim, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh(), nn.Linear(hidden, act_dim))
        self.net.load_state_dict(checkpoint["actor"])
        for name in ("obs_mean", "obs_var", "action_low", "action_high"):
            self.register_buffer(name, checkpoint[name].float())

    @torch.no_grad()
    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        obs = obs[..., : len(self.obs_mean)]  # re-targeted to a wider observation (Ant-v5's contact forces): its leading entries
        obs = ((obs - self.obs_mean) / torch.sqrt(self.obs_var + 1e-8)).clamp(-10.0, 10.0)
        return torch.maximum(torch.minimum(self.net(obs), self.action_high), self.action_low)


# Copied from expert_ppo.load_expert
def load_expert(path: str, env_id: str) -> ExpertPolicy:
    """Load an expert checkpoint written by expert_ppo.py, checking that it is one and fits env_id."""
    if not os.path.isfile(path):
        raise UsageError(f"expert checkpoint {path} not found: train one with `python expert_ppo.py --env {env_id}`, or give the path of one")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
        policy, trained_on = ExpertPolicy(checkpoint), checkpoint["env_id"]
    except Exception as error:
        raise UsageError(f"{path} is not a readable expert checkpoint ({type(error).__name__}): re-copy it or re-train with expert_ppo.py")
    if trained_on != env_id:
        raise UsageError(f"{path} is an expert for {trained_on}, not {env_id}: pass the checkpoint made for {env_id}")
    return policy.eval()


# Copied from bc_oh.generate_demos
def generate_demos(env_id: str, frame_skip: Optional[int], expert: ExpertPolicy, num_samples: int, seed: int = 0) -> dict:
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
    return {"observations": np.array(observations, np.float64), "actions": np.array(actions, np.float32), "episode_starts": np.array(starts),
            "rewards": np.array(rewards, np.float64), "terminations": np.array(terminations), "truncations": np.array(truncations),
            "final_observations": np.array(final_observations, np.float64)}


# Copied from bc_oh.demo_meta
def demo_meta(path: str) -> dict:
    """The JSON meta of a demo file: env_id, source, expert_sha256, num_samples, seed, frame_skip ({} if none)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return json.loads(str(data["meta"])) if "meta" in data else {}
    except Exception:
        return {}


# Copied from bc_oh.load_or_generate_demos
def load_or_generate_demos(args, env: gym.Env) -> dict:
    """The demos of --demos, or the rollout of --expert cached under demos/, made again when the cache was
    recorded at another frame skip or by another expert file (its meta holds the expert's SHA-256)."""
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    num_samples = args.num_demo_samples or (20000 if args.env.startswith("Hopper") else 10000)
    native = getattr(env.unwrapped, "frame_skip", None)  # env is made at the env's own rate
    frame_skip = args.frame_skip or native  # a demo file without the record was made at the native rate
    path = args.demos or f"demos/{args.env}{'' if frame_skip == native else f'_fs{frame_skip}'}_{num_samples}.npz"
    expert_path = args.expert.format(env=args.env)
    if args.demos is None and os.path.isfile(expert_path):
        with open(expert_path, "rb") as file:
            expert_sha256 = hashlib.sha256(file.read()).hexdigest()
        if (demo_meta(path).get("expert_sha256"), demo_meta(path).get("frame_skip", native)) != (expert_sha256, frame_skip):
            print(f"generating {num_samples} demonstration steps with {expert_path} -> {path}")
            demos = generate_demos(args.env, frame_skip, load_expert(expert_path, args.env), num_samples)
            meta = json.dumps({"env_id": args.env, "source": expert_path, "expert_sha256": expert_sha256, "num_samples": num_samples,
                               "seed": 0, "frame_skip": frame_skip})
            write_atomically(path, lambda file: np.savez(file, meta=np.array(meta), **demos))
    if not os.path.isfile(path) and args.demos:
        raise UsageError(f"demo file {path} not found: check the path, or drop --demos to roll out the expert")
    if not os.path.isfile(path):
        raise UsageError(f"no expert for {args.env} at {os.path.abspath(expert_path)} (--expert is relative to the working directory, and the "
                         "repository's experts are in its experts/ folder): run from the repository root, pass --expert PATH or --demos, "
                         f"or train one with `python expert_ppo.py --env {args.env}`")
    recorded_env = demo_meta(path).get("env_id")
    if recorded_env and recorded_env != args.env:
        raise UsageError(f"{path} holds demos of {recorded_env}, not {args.env}: pass --env {recorded_env}, or demos of {args.env}")
    recorded_rate = demo_meta(path).get("frame_skip", native)  # a file without the record was made at the native rate
    if recorded_rate != frame_skip:
        raise UsageError(f"{path} was recorded at frame skip {recorded_rate}, this run is at {frame_skip}: pass --frame-skip {recorded_rate} or demos of this rate")
    meaning = {"observations": "o_t per step, (N, obs_dim)", "actions": "the expert's a_t, (N, act_dim)", "episode_starts": "True where an episode starts, (N,)"}
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in meaning if key not in data]
            demos = {key: data[key] for key in meaning if key in data}
    except Exception as error:
        fix = "delete it to regenerate" if args.demos is None else "save the arrays with np.savez, as plain numeric arrays"
        raise UsageError(f"{path} is not a readable demo file ({type(error).__name__}: {error}): see the .npz format in README.md, or {fix}")
    if missing:
        raise UsageError(f"{path} has no {missing[0]!r} array ({meaning[missing[0]]}): see the .npz format in README.md")
    n = len(demos["actions"]) if demos["actions"].ndim else 0
    if demos["observations"].shape != (n, obs_dim) or demos["actions"].shape != (n, act_dim) or demos["episode_starts"].shape != (n,):
        raise UsageError(f"{path} holds observations {demos['observations'].shape} and actions {demos['actions'].shape}, but {args.env} needs (N, {obs_dim}) and (N, {act_dim}): use demos of this env")
    if args.demos and args.num_demo_samples:  # the Minari import's rule: the first N steps
        if args.num_demo_samples > n:
            raise UsageError(f"--num-demo-samples {args.num_demo_samples}, but {path} holds {n} steps: pass at most {n}, or leave it out for all")
        print(f"--num-demo-samples {args.num_demo_samples}: the first {args.num_demo_samples} of the {n} steps in {path}")
        demos, n = {key: value[:args.num_demo_samples] for key, value in demos.items()}, args.num_demo_samples
    if n <= args.batch_size:
        raise UsageError(f"{path} holds {n} samples, fewer than one batch of {args.batch_size}: use more demos or a smaller --batch-size")
    for key, dtype in (("observations", np.float64), ("actions", np.float32)):  # any real dtype converts
        if not (np.issubdtype(demos[key].dtype, np.integer) or np.issubdtype(demos[key].dtype, np.floating) or demos[key].dtype == bool):
            raise UsageError(f"{path}: {key} hold {demos[key].dtype} values, not real numbers: save them as floats")
        demos[key] = demos[key].astype(dtype)
        bad = np.argwhere(~np.isfinite(demos[key]))
        if len(bad):
            raise UsageError(f"{path}: {key} has the non-finite value {demos[key][tuple(bad[0])]} at row {bad[0][0]}, column {bad[0][1]}: fix or drop that step")
    low, high = env.action_space.low, env.action_space.high
    outside = np.argwhere((demos["actions"] < low) | (demos["actions"] > high))
    if len(outside):
        row, column = outside[0]
        raise UsageError(f"{path}: actions[{row}, {column}] = {demos['actions'][row, column]:g} lies outside {args.env}'s bounds "
                         f"[{low[column]:g}, {high[column]:g}]: clip or rescale the actions to the env's action space")
    demos["episode_starts"] = demos["episode_starts"].astype(bool)
    if not demos["episode_starts"][0]:
        raise UsageError(f"{path}: episode_starts[0] is False, but the first step starts an episode: episode_starts is True on each "
                         "episode's first step (done flags, True on the last step, shifted by one give this: use [True] + dones[:-1])")
    print(f"demos: {n} steps from {path}; copy error MSE(a_t-1, a_t)/Var(a) = {copy_error(demos['actions'], demos['episode_starts']):.3f} "
          "(near 0 means copying the last action is a shortcut)")
    return demos


# Copied from bc_oh.copy_error
def copy_error(actions: np.ndarray, episode_starts: np.ndarray) -> float:
    """MSE(a_{t-1}, a_t) / Var(a) within episodes, mean over action dims: near 0, copying the previous
    action predicts the expert well (a copycat shortcut exists); near 2, it is no better than chance."""
    same_episode = ~episode_starts[1:]
    step_error = ((actions[1:] - actions[:-1])[same_episode] ** 2).mean(0)
    return float((step_error / np.maximum(actions.var(0), 1e-12)).mean())


# Copied from bc_oh.partially_observe
def partially_observe(observations: np.ndarray, dims: list, std: float, hide: bool, seed: int) -> np.ndarray:
    """The demos as the policy's sensor saw them: noise on the velocity entries drawn once per sample
    (a noisy sensor at collection time), or with hide, those entries zeroed."""
    observed = observations.copy()
    if hide:
        observed[:, dims] = 0.0
    else:
        observed[:, dims] += np.random.default_rng(seed).normal(0.0, std, (len(observed), len(dims)))
    return observed


# Copied from bc_oh.stack_history
def stack_history(observations: np.ndarray, episode_starts: np.ndarray, history: int) -> np.ndarray:
    """Row t = [o_{t-H+1}, ..., o_t] (oldest first); before an episode's first frame, repeat that frame."""
    index = np.arange(len(observations))
    first_of_episode = np.maximum.accumulate(np.where(episode_starts, index, 0))
    frames = [observations[np.maximum(index - lag, first_of_episode)] for lag in range(history - 1, -1, -1)]
    return np.concatenate(frames, axis=1)


# Copied from bc_oh.machine
def machine() -> dict:
    """Where a result was made: the same command on the same kind of CPU, with these versions, prints the same digits."""
    cpus = open("/proc/cpuinfo").read() if os.path.isfile("/proc/cpuinfo") else ""
    cpu = re.search(r"^model name\s*: (.*)$", cpus, re.M)
    return {"cpu": cpu[1] if cpu else platform.processor(), "cpu_capability": torch.backends.cpu.get_cpu_capability(),
            "MKL_CBWR": os.environ.get("MKL_CBWR"), "MKL_ENABLE_INSTRUCTIONS": os.environ.get("MKL_ENABLE_INSTRUCTIONS"),
            "torch": str(torch.__version__), "numpy": np.__version__, "mujoco": mujoco.__version__, "gymnasium": gym.__version__}


# Copied from bc_oh.write_atomically
def write_atomically(path: str, write):
    """Call write(file) on a temporary file, then rename: an interrupted run leaves no half file."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, "wb") as file:
            write(file)
        os.replace(tmp, path)
    finally:  # after an interruption, remove the half-written temporary file
        if os.path.exists(tmp):
            os.remove(tmp)


# Copied from bc_oh.make_adam
def make_adam(params, lr: float, fast: bool, **kwargs) -> torch.optim.Adam:
    """Adam; a step captured in a CUDA graph needs its state on the GPU (capturable) and a tensor lr."""
    return torch.optim.Adam(params, lr=torch.tensor(lr, device="cuda") if fast else lr, capturable=fast, **kwargs)


# Copied from bc_oh.set_learning_rate
def set_learning_rate(optimizer: torch.optim.Optimizer, lr: float):
    """Set the lr in place: a CUDA graph reads a tensor lr from its fixed address at every replay."""
    for group in optimizer.param_groups:
        if torch.is_tensor(group["lr"]):
            group["lr"].fill_(lr)
        else:
            group["lr"] = lr


# Copied from bc_oh.CudaGraphStep
class CudaGraphStep:
    """The fast GPU path (--cuda): launching the dozens of tiny kernels of a step costs more than running
    them, so the step (reading fixed tensors only) is captured once in a CUDA graph and replayed."""

    def __init__(self, step, enabled: bool, warmup: int = 3):
        self.step, self.enabled, self.warmup, self.graph, self.output = step, enabled, warmup, None, None

    def __call__(self):
        if not self.enabled:
            return self.step()
        if self.graph is None:
            stream = torch.cuda.Stream()  # capture needs a few ordinary steps on a side stream first
            stream.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(stream):
                output = self.step() if self.warmup > 0 else None
            torch.cuda.current_stream().wait_stream(stream)
            if self.warmup > 0:
                self.warmup -= 1
                return output
            self.graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(self.graph):
                self.output = self.step()
        self.graph.replay()
        return self.output


gym.logger.min_level = gym.logger.ERROR  # the paper's v4 envs are deprecated in gymnasium 1.x: keep stderr for errors
# gymnasium's HalfCheetah XML uses a compiler attribute that MuJoCo 3.x deprecates, so MuJoCo warns (and appends to
# ./MUJOCO_LOG.TXT) each time that env is made: drop that warning, print the others.
mujoco.set_mju_user_warning(lambda message: None if "settotalmass" in message else print(f"MuJoCo warning: {message}", file=sys.stderr))


if __name__ == "__main__":
    try:
        run(tyro.cli(Args))
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
