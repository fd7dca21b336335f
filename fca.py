# Fighting Copycat Agents, FCA (Wen et al. 2020; paper Table 2 baseline); see README.md
"""FCA: BC-OH whose history embedding is stripped of what it says about the previous action.

In turns, adversary D learns a_{t-1} from (e, a_t); encoder G (history -> e) and head F (e -> a_t) fit a_t and foil D.

    python fca.py --env Hopper-v4
"""

import json
import multiprocessing
import os
import signal
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

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
    frame_skip: int | None = None
    """simulator steps per action; None: the env's own (docs/methods.md)"""
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3])
    """training seeds, scored as mean ± std; a rerun keeps the finished ones"""
    workers: int | None = None
    """seeds trained at once, one process each; None: one per core (1 with --cuda)"""
    demos: str | None = None
    """demonstrations (.npz); None: demos/<env>_<N>.npz, made by `python expert_ppo.py --make-demos`"""
    num_demo_samples: int | None = None
    """demonstration steps; None: 20000 for Hopper, 10000 otherwise (with --demos: the whole file)"""
    obs_noise_std: float = 0.2
    """std of the Gaussian noise on the velocity entries of each observation"""
    hide_velocities: bool = False
    """zero the velocity entries instead (positions only)"""
    velocity_dims: list[int] | None = None
    """indices of the velocity entries, for envs not in the built-in table"""
    history: int = 2
    """frames in the observation history"""
    epochs: int = 1000
    """epochs of num-samples / batch-size minibatches drawn with replacement"""
    batch_size: int = 64
    """minibatch size"""
    learning_rate: float | None = None
    """Adam learning rate, decayed linearly to 0; None: 1e-5 for Hopper, 1e-4 otherwise"""
    hidden: int = 300
    """width of the hidden layers"""
    eval_every: int = 100
    """evaluate every this many epochs and after the last; the score is the mean of the last 3"""
    eval_episodes: int = 10
    """episodes per evaluation"""
    output_dir: str = "runs/{run_name}/{env}"
    """results and models; {run_name}: the method, then each flag changed from its default"""
    save_model: bool = False
    """save each seed's policy (weights, normalisation, args)"""
    cuda: bool = False
    """train on the GPU"""
    adversary_weight: float | None = None
    """w in MSE(F(e), a_t) - w * MSE(D(e, a_t), a_{t-1}); None: the authors', 2 on Hopper, 1 otherwise"""
    adversary_lr_ratio: float | None = None
    """D's learning rate over G's and F's (--learning-rate); None: the authors', 2 on Hopper (D 2e-5), 1 otherwise"""
    embedding_dim: int = 100
    """size of the history embedding e (the authors' 100)"""

    def __post_init__(self):
        weight, ratio, zero = self.adversary_weight, self.adversary_lr_ratio, "0 gives BC-OH on the FCA network"
        require(weight is None or weight >= 0, f"--adversary-weight must be >= 0, got {weight}: {zero}")
        require(ratio is None or ratio > 0, f"--adversary-lr-ratio must be positive, got {ratio}")
        require(self.embedding_dim > 0, f"--embedding-dim must be positive, got {self.embedding_dim}")


# ---- The method: its network, loss and training ----
def head(in_dim: int, out_dim: int, hidden: int) -> nn.Sequential:  # the authors' F and D: one hidden layer
    layers = [nn.LeakyReLU(0.2), nn.Linear(in_dim, hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, out_dim)]
    return nn.Sequential(*layers)


# Copied from bc_oh.Normalizer
class Normalizer(nn.Module):  # standardises inputs with statistics of the training demos, stored with the model
    def __init__(self, inputs: torch.Tensor):
        super().__init__()
        self.register_buffer("mean", inputs.mean(0))
        self.register_buffer("std", inputs.std(0).clamp_min(1e-6))

    def forward(self, x):
        return (x - self.mean) / self.std


class Policy(nn.Module):  # FCA: the authors' encoder G (history -> e), head F(e) -> a_t, adversary D(e, a_t) -> a_{t-1}
    def __init__(self, obs_dim: int, act_dim: int, history: int, hidden: int, embedding_dim: int, inputs: torch.Tensor):
        super().__init__()
        self.normalize = Normalizer(inputs)
        blocks = []  # G's three hidden layers; BatchNorm bounds e's scale, which G, maximising D's error, would inflate
        for i, in_dim in enumerate([obs_dim * history, hidden, hidden]):  # the first Linear without bias, as theirs
            blocks += [nn.Linear(in_dim, hidden, bias=i > 0), nn.BatchNorm1d(hidden), nn.LeakyReLU(0.2)]
        self.encoder = nn.Sequential(*blocks, nn.Linear(hidden, embedding_dim))
        self.head = head(embedding_dim, act_dim, hidden)
        self.adversary = head(embedding_dim + act_dim, act_dim, hidden)  # conditioned on the true a_t
        for module in self.modules():  # the authors' weights_init: Xavier-uniform Linear, BatchNorm N(1, 0.02^2)
            if isinstance(module, nn.Linear):
                nn.init.xavier_uniform_(module.weight)
            elif isinstance(module, nn.BatchNorm1d):
                nn.init.normal_(module.weight, 1.0, 0.02)
            if isinstance(module, (nn.Linear, nn.BatchNorm1d)) and module.bias is not None:  # and zero biases
                nn.init.zeros_(module.bias)

    def embed(self, obs_history):
        return self.encoder(self.normalize(obs_history))

    def predict_previous_action(self, embedding, action):
        return self.adversary(torch.cat([embedding, action], dim=-1))

    def forward(self, obs_history):
        return self.head(self.embed(obs_history))


def make_policy(args, obs_dim: int, act_dim: int, inputs: torch.Tensor) -> nn.Module:
    return Policy(obs_dim, act_dim, args.history, args.hidden, args.embedding_dim, inputs)


def previous_actions(actions: np.ndarray, episode_starts: np.ndarray) -> np.ndarray:  # row t: a_{t-1}
    return stack_history(actions, episode_starts, 2)[:, : actions.shape[1]]  # at a start a_t: D has nothing to remove


def adversary_step(policy: Policy, optimizer, embedding, actions, previous) -> torch.Tensor:  # a step of D; its loss
    loss = ((policy.predict_previous_action(embedding.detach(), actions) - previous) ** 2).mean()  # e held fixed
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()  # only D has gradients (e is detached), so Adam moves only D
    return loss.detach()


def encoder_policy_step(policy: Policy, optimizer, embedding, actions, previous, weight: float):  # a step of G and F
    bc_loss = ((policy.head(embedding) - actions) ** 2).mean()
    adversary_loss = ((policy.predict_previous_action(embedding, actions) - previous) ** 2).mean()
    optimizer.zero_grad()
    (bc_loss - weight * adversary_loss).backward()  # fit a_t while making a_{t-1} unpredictable for the current D
    policy.adversary.zero_grad()  # which stays as it is: this step moves G and F only
    optimizer.step()
    return bc_loss.detach(), adversary_loss.detach()


def authors_setting(env_id: str, weight: float | None, lr_ratio: float | None) -> tuple:  # (w, D's lr ratio)
    default = 2.0 if env_id.startswith("Hopper") else 1.0  # the authors' w and ratio (Hopper: w = 2, D 4e-4, G 2e-4)
    return default if weight is None else weight, default if lr_ratio is None else lr_ratio


def train_seed(args, demos: dict, seed: int, device) -> dict:  # its evaluations [(epoch, mean return)] and policy
    torch.manual_seed(seed)
    env = make_env(args.env)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    dims = velocity_dims(env, args.env, args.velocity_dims)
    noisy = partially_observe(demos["observations"], dims, args.obs_noise_std, args.hide_velocities, seed)
    history = stack_history(noisy, demos["episode_starts"], args.history)
    inputs = torch.as_tensor(history, dtype=torch.float32, device=device)
    targets = torch.as_tensor(demos["actions"], dtype=torch.float32, device=device)
    previous = previous_actions(demos["actions"], demos["episode_starts"])
    previous = torch.as_tensor(previous, dtype=torch.float32, device=device)
    reference = ((previous - targets) ** 2).mean().item()  # D's error if it predicted a_(t-1) = a_t
    policy = make_policy(args, obs_dim, act_dim, inputs).to(device)
    weight, lr_ratio = authors_setting(args.env, args.adversary_weight, args.adversary_lr_ratio)
    d_rate = lr_ratio * args.learning_rate
    rates = f"w = {weight:g}; learning rates: G and F {args.learning_rate:g}, D {d_rate:g}"
    print(f"seed {seed} | {rates}; adversary reference: predicting a_(t-1) = a_t has error {reference:.5f}")
    g_and_f = [*policy.encoder.parameters(), *policy.head.parameters()]  # one Adam, D a parameter group of its own
    groups = [{"params": g_and_f}, {"params": policy.adversary.parameters(), "lr": d_rate}]
    optimizer = torch.optim.Adam(groups, lr=args.learning_rate, betas=(0.5, 0.999))

    def train_step(idx):  # the authors' alternating updates: the adversary D, then the encoder G and policy head F
        embedding = policy.embed(inputs[idx])  # once a step: BatchNorm's running statistics move once a step
        adversary_loss = adversary_step(policy, optimizer, embedding, targets[idx], previous[idx])
        loss, _ = encoder_policy_step(policy, optimizer, embedding, targets[idx], previous[idx], weight)
        return loss, adversary_loss

    evaluations, ms_per_step = fit(args, policy, optimizer, train_step, len(inputs), seed, device)
    return dict(evaluations=evaluations, policy=policy, obs_dim=obs_dim, act_dim=act_dim, ms_per_step=ms_per_step)


def fit(args, policy, optimizer, train_step, num_samples: int, seed: int, device, evaluate_policy=True) -> tuple:
    steps_per_epoch = num_samples // args.batch_size
    total_steps, step, evaluations, start, train_time = args.epochs * steps_per_epoch, 0, [], time.time(), 0.0
    generator = torch.Generator(device=device).manual_seed(seed)
    workers, position = args.workers or 1, args.seeds.index(seed) if seed in args.seeds else 0  # for the job's ETA:
    waves_after = (len(args.seeds) - 1) // workers - position // workers  # this seed's rest, then the waves after it
    for epoch in range(1, args.epochs + 1):
        epoch_start = time.time()
        adversary_error = torch.zeros((), device=device)  # this file's own fit: it also logs D's mean error
        for _ in range(steps_per_epoch):
            for group in optimizer.param_groups:  # each from its own initial rate, linearly to 0
                group["lr"] = group.setdefault("initial_lr", group["lr"]) * (1 - step / total_steps)
            idx = torch.randint(num_samples, (args.batch_size,), device=device, generator=generator)
            loss, adversary_loss = train_step(idx)
            adversary_error += adversary_loss / steps_per_epoch  # D's mean error over the epoch
            step += 1
        last_loss = loss.item()  # also waits for the GPU, so train_time is the true training time
        train_time += time.time() - epoch_start
        evaluating = epoch % args.eval_every == 0 or epoch == args.epochs
        if evaluate_policy and evaluating:
            policy.eval()
            returns = evaluate(policy, args, args.eval_episodes, 10_000 * seed + epoch, device)
            evaluations.append((epoch, float(np.mean(returns))))
            policy.train()
        if evaluating or epoch % max(1, args.epochs // 20) == 0:
            last = f"{evaluations[-1][1]:.1f}" if evaluations else "n/a"
            line = f"seed {seed} | epoch {epoch}/{args.epochs} | loss {last_loss:.5f}"
            line += f" | adversary error {adversary_error.item():.5f} | last eval {last}"
            eta = (time.time() - start) * (1 - epoch / args.epochs + waves_after) / (epoch / args.epochs) / 60
            print(f"{line} | {1000 * train_time / step:.2f} ms/step | job ETA {eta:.1f} min", flush=True)
    return evaluations, 1000 * train_time / step


# ---- Evaluation ----
# Copied from bc_oh.evaluate..stack_history
@torch.no_grad()
def evaluate(policy: nn.Module, args, episodes: int, seed: int, device) -> list:  # the deterministic policy's returns
    dims, skip = velocity_dims(make_env(args.env), args.env, args.velocity_dims), args.frame_skip
    noise = (args.obs_noise_std, args.hide_velocities)
    makers = [lambda i=i: PartialObservation(make_env(args.env, skip), dims, *noise, seed + i) for i in range(episodes)]
    envs = gym.vector.SyncVectorEnv(makers, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    low, high = envs.single_action_space.low, envs.single_action_space.high
    obs, _ = envs.reset(seed=seed)
    frames = np.repeat(obs[:, None], args.history, axis=1)  # [o_{t-H+1}, ..., o_t]: stack_history's first-frame rule
    returns, running = np.zeros(episodes), np.ones(episodes, bool)
    while running.any():
        inputs = torch.as_tensor(frames.reshape(episodes, -1), dtype=torch.float32, device=device)
        obs, reward, terminated, truncated, _ = envs.step(policy(inputs).cpu().numpy().clip(low, high))
        returns += reward * running
        running &= ~(terminated | truncated)  # each env plays one episode: what follows its end does not count
        frames = np.concatenate([frames[:, 1:], obs[:, None]], axis=1)
    envs.close()
    return returns.tolist()


# ---- Shared plumbing, identical in every method file (scripts/check_copies.py): seeds, env, demos ----
def run(args):  # check the input, load the demos, train each seed not yet finished (each written when it ends)
    for key in "history epochs batch_size hidden eval_every eval_episodes learning_rate frame_skip workers".split():
        value, flag = getattr(args, key, None), f"--{key.replace('_', '-')}"  # the flags every method shares
        require(value is None or value > 0, f"{flag} must be positive, got {value}: pass one, or leave it out")
    require(args.obs_noise_std >= 0, f"--obs-noise-std must be >= 0, got {args.obs_noise_std}: 0 gives no noise")
    seeds = " ".join(map(str, args.seeds)) or "none"
    require(len(set(args.seeds)) == len(args.seeds) > 0, f"--seeds needs distinct seeds, got {seeds}: e.g. 1 2 3")
    samples, batch = args.num_demo_samples, args.batch_size
    require(samples is None or samples > batch, f"--num-demo-samples must exceed --batch-size {batch}, got {samples}")
    require(not args.cuda or torch.cuda.is_available(), "--cuda, but torch sees no CUDA GPU here: drop --cuda")
    name = run_name(args)  # before the defaults are filled in: it names what the user changed
    env = make_env(args.env)
    velocity_dims(env, args.env, args.velocity_dims)  # fail early for envs of unknown layout
    args.frame_skip = args.frame_skip or getattr(env.unwrapped, "frame_skip", None)  # recorded with the results
    make_env(args.env, args.frame_skip)  # fail early for a frame skip the env cannot take
    args.learning_rate = args.learning_rate or (1e-5 if args.env.startswith("Hopper") else 1e-4)
    demos, meta = load_demos(args, env)
    output_dir = args.output_dir.format(method=METHOD, run_name=name, env=args.env)
    os.makedirs(output_dir, exist_ok=True)
    per_seed = {seed: finished_seed(output_dir, seed, args) for seed in args.seeds}
    kept, to_train = [s for s in args.seeds if per_seed[s]], [s for s in args.seeds if not per_seed[s]]
    if kept:
        print(f"seeds {', '.join(map(str, kept))}: kept their finished results in {output_dir} (delete to retrain)")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    args.workers = 1 if args.cuda else max(1, min(args.workers or cores, len(to_train)))  # the GPU: one seed at a time
    if len(to_train) > args.workers:
        waiting = ", ".join(map(str, to_train[args.workers :]))
        print(f"seeds {', '.join(map(str, to_train[: args.workers]))} training; {waiting} wait for a worker")
    jobs = [(replace(args, seeds=to_train), demos, seed, output_dir) for seed in to_train]  # the ETA counts to_train
    try:
        if args.workers == 1:
            entries = [train_and_record(*job) for job in jobs]
        else:  # spawn, not fork: torch and MuJoCo are not fork-safe
            with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
                entries = pool.starmap(train_and_record, jobs, chunksize=1)
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM (made one in __main__): leaving the pool stops its workers
        lost = [s for s in to_train if not finished_seed(output_dir, s, args)]
        done, lost = [s for s in args.seeds if s not in lost] or ["none"], lost or ["none"]
        where = f"seeds {', '.join(map(str, done))} finished and kept, {', '.join(map(str, lost))} lost"
        sys.exit(f"interrupted: {where}: the same command trains only those")
    per_seed.update(zip(to_train, entries))
    result_path, scores = write_result(output_dir, args, per_seed), [entry["score"] for entry in per_seed.values()]
    print(f"\n{'seed':>6} | {'score':>8}\n" + "\n".join(f"{s:>6} | {per_seed[s]['score']:8.1f}" for s in per_seed))
    mean, plural, skip = np.mean(scores), "s" * (len(scores) > 1), meta.get("expert_frame_skip")
    line = f"{args.env} {METHOD}: {mean:.1f} ± {np.std(scores):.1f} over {len(scores)} seed{plural}"
    if "expert_return" in meta:  # demos from elsewhere (e.g. Minari) have no expert to compare with
        share = round(mean / meta["expert_return"], 2) + 0.0  # + 0.0: a share of -0.001 reads 0%, not -0%
        rate = "" if skip == args.frame_skip else f" at its own frame skip {skip}"
        line += f", {share:.0%} of the expert's {meta['expert_return']:.0f}{rate}"
    print(f"result: {result_path}\n{line}")


def train_and_record(args, demos: dict, seed: int, output_dir: str) -> dict:
    torch.set_num_threads(1)  # small networks gain nothing from more; first: a worker starts with all the cores
    if multiprocessing.parent_process():  # a pool worker: Ctrl-C is the main process's, a printed line one write
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.stdout.reconfigure(line_buffering=True, write_through=False)  # unbuffered, print's "\n" is a write apart
    print(f"seed {seed} | training", flush=True)
    result = train_seed(args, demos, seed, torch.device("cuda" if args.cuda else "cpu"))
    score = float(np.mean([ret for _, ret in result["evaluations"][-3:]]))  # the paper: mean of the last 3
    entry = {"score": score, "evaluations": result["evaluations"], "ms_per_step": result["ms_per_step"]}
    if args.save_model:
        model = {"method": METHOD, "env_id": args.env, "args": asdict(args), "obs_dim": result["obs_dim"]}
        model.update(act_dim=result["act_dim"], state_dict=result["policy"].cpu().state_dict())
        path = os.path.join(output_dir, f"seed{seed}.pt")
        torch.save(model, f"{path}.tmp")
        os.replace(f"{path}.tmp", path)  # an interrupted run leaves no half-written checkpoint
    write_result(output_dir, args, {seed: entry})  # now: a rerun keeps this seed
    return entry


def run_name(args) -> str:  # METHOD, then each flag changed from its default that changes results (c2f__fusion-early)
    defaults, changed = type(args)(), []
    for name, value in asdict(args).items():
        if name in ("seeds", "workers", "output_dir", "save_model", "cuda") or value == getattr(defaults, name):
            continue
        flag, text = name.replace("_", "-"), "-".join(map(str, value)) if isinstance(value, list) else str(value)
        text = os.path.basename(text).removesuffix(".npz")
        changed.append(flag if value is True else f"no-{flag}" if value is False else f"{flag}-{text}")
    return "__".join([METHOD, *changed])


def finished_seed(output_dir: str, seed: int, args) -> dict | None:
    ignored = ("seeds", "workers", "output_dir", "cuda", "save_model")  # flags that change no result
    try:
        result = json.loads(Path(output_dir, f"result_seeds{seed}.json").read_text())
        (entry,) = result["scores"].values()
        recorded = {name: value for name, value in result["args"].items() if name not in ignored}
    except Exception:  # none yet, half written, or not one of ours: train the seed
        return None
    same = recorded == {name: value for name, value in asdict(args).items() if name not in ignored}
    model = os.path.join(output_dir, f"seed{seed}.pt")
    return entry if same and (os.path.isfile(model) or not args.save_model) else None


def write_result(output_dir: str, args, per_seed: dict, **more) -> str:  # result_seeds<seeds>.json: scores, mean, std
    scores, recorded = [entry["score"] for entry in per_seed.values()], {**asdict(args), "seeds": list(per_seed)}
    recorded["output_dir"] = os.path.relpath(output_dir)  # relative: no machine named
    result = dict(env=args.env, method=METHOD, args=recorded, scores=per_seed, mean=np.mean(scores), std=np.std(scores))
    path = Path(output_dir, f"result_seeds{'-'.join(map(str, per_seed))}.json")
    path.write_text(json.dumps({**result, **more}, indent=1))  # written plainly: a reader refuses a half-written file
    return str(path)


class UsageError(Exception): ...  # bad input from the user: printed as one line on stderr, exit status 2, no traceback


def require(condition, message: str):  # refuse bad input in one line: a UsageError unless condition holds
    if not condition:
        raise UsageError(message)


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


class PartialObservation(gym.ObservationWrapper):  # the sensor: fresh N(0, std^2) velocity noise each step, or zeros
    def __init__(self, env: gym.Env, dims: list, std: float, hide: bool, seed: int):
        super().__init__(env)
        self.dims, self.std, self.hide, self.rng = np.asarray(dims), std, hide, np.random.default_rng(seed)

    def observation(self, obs):
        obs = np.array(obs, dtype=np.float64)
        obs[self.dims] = 0.0 if self.hide else obs[self.dims] + self.rng.normal(0.0, self.std, len(self.dims))
        return obs


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


def partially_observe(observations: np.ndarray, dims: list, std: float, hide: bool, seed: int) -> np.ndarray:
    observed, rng = observations.copy(), np.random.default_rng(seed)  # the sensor's view: noise drawn once per sample
    observed[:, dims] = 0.0 if hide else observed[:, dims] + rng.normal(0.0, std, (len(observed), len(dims)))
    return observed


def stack_history(observations: np.ndarray, episode_starts: np.ndarray, history: int) -> np.ndarray:
    index = np.arange(len(observations))  # row t: [o_{t-H+1}, ..., o_t], oldest first
    first_of_episode = np.maximum.accumulate(np.where(episode_starts, index, 0))  # before it, repeat its first frame
    frames = [observations[np.maximum(index - lag, first_of_episode)] for lag in range(history - 1, -1, -1)]
    return np.concatenate(frames, axis=1)


gym.logger.min_level = gym.logger.ERROR  # the paper's v4 envs are deprecated in gymnasium 1.x: keep stderr for errors
# MuJoCo 3.x warns of gymnasium's HalfCheetah XML (to ./MUJOCO_LOG.TXT too) each time it is made: drop that one
mujoco.set_mju_user_warning(lambda text: "settotalmass" in text or print(f"MuJoCo warning: {text}", file=sys.stderr))


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # `kill PID` stops the job as Ctrl-C does
    try:
        run(tyro.cli(Args))
    except UsageError as error:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(2)
