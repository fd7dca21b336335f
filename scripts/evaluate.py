"""Evaluate a policy that a method file saved with --save-model, the CleanRL way.

    python c2f.py --env Hopper-v4 --seeds 1 --save-model --output-dir runs/c2f_hopper
    python scripts/evaluate.py runs/c2f_hopper/seed1.pt
    python scripts/evaluate.py runs/c2f_hopper/seed1.pt --episodes 20 --seed 100

The checkpoint names its method: this script imports that method file from the repository root,
rebuilds its policy with the file's own make_policy (on zero inputs of the saved shape:
load_state_dict then restores the weights and the normaliser's statistics) and runs the file's own
evaluate on the env, control rate and partial observability recorded in the checkpoint; it prints
every return and the summary line. A run's evaluation after epoch E of training seed S used
--seed 10000 * S + E with --episodes = its --eval-episodes (DAgger's final learner: three
evaluations, + 0, N and 2N episodes on, N = --eval-episodes): that seed reproduces it exactly
(on a CPU). scripts/watch.py renders saved policies to a GIF.
"""

import importlib
import math
import re
import sys
import types
import typing
from dataclasses import fields
from pathlib import Path

import numpy as np
import torch

# Tooling may import the repository's benchmark package and method files.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.results import OneLineParser, UsageError, run_cli

ROOT = Path(__file__).resolve().parent.parent
CHECKPOINT_KEYS = ("method", "env_id", "args", "obs_dim", "act_dim", "state_dict")
"""what every method file's --save-model writes"""
SAVE_FIX = "pass a seed<S>.pt that a method file wrote with --save-model"
RESAVE = "re-save it with --save-model"
POSITIVE = ("history", "epochs", "batch_size", "hidden", "eval_every", "eval_episodes")
POSITIVE += ("learning_rate", "frame_skip", "num_demo_samples", "workers")
"""the settings every method file's run() refuses unless positive and finite (None: a default)"""
WORDS = {int: "an int", float: "a number", str: "a str", bool: "True or False", type(None): "None"}
"""a type of an Args field, in words"""
RETIRED = ("expert", "cuda_graph", "velocity_dims")
"""settings the method files dropped that change neither the policy nor its evaluation (--expert:
which expert made the demos, now expert_ppo.py --make-demos; --cuda-graph: a way of training on
the GPU; --velocity-dims: None, the built-in layout, unless set, which saved_args refuses): an
older checkpoint's are ignored"""
METHOD_FILE_NAMES = ("METHOD", "Args", "make_policy", "evaluate", "make_env", "UsageError")
"""what a method file defines that this script uses"""
MAX_EPISODES = 10_000
"""the most episodes evaluated: they run at once, one env each (10**11 filled the memory)"""


def read_checkpoint(path) -> dict:
    """The checkpoint at `path`, checked to be one --save-model writes (torch only: imports no
    method file)."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(
            f"checkpoint {path} not found: {SAVE_FIX}, e.g. runs/Hopper-v4__bc_oh__<time>/seed1.pt"
        )
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:
        raise UsageError(
            f"{path} is not a readable checkpoint ({type(error).__name__}): "
            "the file is damaged or no torch file; "
            f"re-save it with --save-model, or {SAVE_FIX}"
        )
    if isinstance(checkpoint, dict):
        missing = [key for key in CHECKPOINT_KEYS if key not in checkpoint]
    else:
        missing = ["method"]
    if missing:
        hint = ""
        if isinstance(checkpoint, dict) and "actor" in checkpoint:
            hint = " (an expert: expert_ppo.py --help shows how to evaluate it)"
        raise UsageError(
            f"{path} is not a model saved with --save-model: "
            f"it has no {missing[0]!r}{hint}; {SAVE_FIX}"
        )
    for key in ("obs_dim", "act_dim"):
        if not fits(checkpoint[key], int) or checkpoint[key] <= 0:
            raise UsageError(
                f"{path}: its {key} {checkpoint[key]!r} is not a positive int: {RESAVE}"
            )
    method = checkpoint["method"]
    if not isinstance(method, str) or not re.fullmatch(r"[a-z][a-z0-9_]*", method):
        raise UsageError(
            f"{path} names the method {method!r}, not a method file's name: {SAVE_FIX}"
        )
    if not isinstance(checkpoint["args"], dict) or not isinstance(checkpoint["state_dict"], dict):
        raise UsageError(
            f"{path} holds no args and weights as --save-model writes them: {SAVE_FIX}"
        )
    return checkpoint


def method_module(method: str, path):
    """The method file ROOT/<method>.py, imported (the method files are self-contained modules)."""
    if (ROOT / "benchmark" / f"{method}.py").is_file():
        # A benchmark module's variant (ensemble_twins): not a method file this script can import.
        raise UsageError(
            f"{path} was saved by benchmark/{method}.py, whose models this script does not replay"
        )
    if not (ROOT / f"{method}.py").is_file():
        raise UsageError(
            f"{path} was saved by {method}.py, which is not in {ROOT}: "
            f"evaluate it in a checkout that has {method}.py, or {SAVE_FIX}"
        )
    module = importlib.import_module(method)
    if not all(hasattr(module, name) for name in METHOD_FILE_NAMES):
        raise UsageError(
            f"{method}.py (named by {path}) is not a method file "
            f"with Args, make_policy and evaluate: {SAVE_FIX}"
        )
    return module


def fits(value, kind) -> bool:
    """Whether `value` is of the type `kind` of an Args field: int, float, str, bool, X | None,
    list[int] or Literal[...] (an int is a float too, a bool is neither)."""
    origin = typing.get_origin(kind)
    options = typing.get_args(kind)
    if origin is typing.Literal:
        return value in options
    if origin in (typing.Union, types.UnionType):
        return any(fits(value, option) for option in options)
    if origin is list:
        return isinstance(value, list) and all(fits(item, options[0]) for item in value)
    if isinstance(value, bool) and kind is not bool:
        return False
    if kind is float:
        return isinstance(value, (int, float))
    return isinstance(value, kind)


def in_words(kind) -> str:
    """The type `kind` of an Args field, in words: "an int or None"."""
    origin = typing.get_origin(kind)
    options = typing.get_args(kind)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(option) for option in options)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(in_words(option) for option in options)
    if origin is list:
        return f"a list of {options[0].__name__} values"
    return WORDS.get(kind, str(kind))


def check_values(module, values: dict, path):
    """Refuse a saved setting that the method file would refuse as a flag: of another type than
    its Args field, a size not positive and finite, a noise std below 0 or not finite."""
    kinds = typing.get_type_hints(module.Args)
    for name, value in values.items():
        if not fits(value, kinds[name]):
            wanted = in_words(kinds[name])
        elif name in POSITIVE and value is not None and not 0 < value < math.inf:
            wanted = "positive and finite"
        elif name == "obs_noise_std" and not 0 <= value < math.inf:
            wanted = ">= 0 and finite"
        else:
            continue
        raise UsageError(f"{path}: its args hold {name} {value!r}, which is not {wanted}: {RESAVE}")


def saved_args(module, checkpoint: dict, path):
    """The method file's Args with the checkpoint's values (settings the file added since keep
    their defaults, RETIRED ones it no longer has are dropped)."""
    if checkpoint["args"].get("velocity_dims"):
        raise UsageError(
            f"{path} was trained with --velocity-dims, which the method files no longer have: "
            "evaluate it with the version of its method file that saved it"
        )
    known = {field.name for field in fields(module.Args)}
    unknown = sorted(set(checkpoint["args"]) - known - set(RETIRED), key=str)
    method = checkpoint["method"]
    if unknown:
        raise UsageError(
            f"{path} records the setting {unknown[0]!r}, "
            f"which this {method}.py does not have: "
            f"it was saved by another version of {method}.py; evaluate it with that version"
        )
    values = {name: value for name, value in checkpoint["args"].items() if name in known}
    check_values(module, values, path)
    return module.Args(**values)


def load_policy(path):
    """(method module, policy in eval mode on the CPU, its Args) for a checkpoint written by
    --save-model."""
    checkpoint = read_checkpoint(path)
    method = checkpoint["method"]
    # c2f.py held Table 3's settings until c2f_table3.py took them (issue 55). Its older models
    # (the shipped results/h3 ones) record them: c2f_table3.py, c2f.py at its defaults, loads them.
    if method == "c2f" and "fusion" in checkpoint["args"]:
        method = "c2f_table3"
    module = method_module(method, path)
    try:
        args = saved_args(module, checkpoint, path)
        # Make the checkpoint's env at its control rate, or fail with one clear line.
        env = module.make_env(args.env, args.frame_skip)
        # And an env whose velocity entries the method knows: its sensor needs them.
        module.velocity_dims(env, args.env)
    except module.UsageError as error:
        raise UsageError(f"{path}: {error}")
    obs_dim = env.observation_space.shape[0]
    act_dim = env.action_space.shape[0]
    env.close()
    if (checkpoint["obs_dim"], checkpoint["act_dim"]) != (obs_dim, act_dim):
        raise UsageError(
            f"{path} was trained on observations of width {checkpoint['obs_dim']} "
            f"and actions of width {checkpoint['act_dim']}, "
            f"but {args.env} here has {obs_dim} and {act_dim}: "
            "use the gymnasium version it was trained with"
        )
    # Only the shape matters: the normaliser's statistics come from the state_dict.
    inputs = torch.zeros(2, obs_dim * args.history)
    policy = module.make_policy(args, obs_dim, act_dim, inputs)
    try:
        policy.load_state_dict(checkpoint["state_dict"])
    except (RuntimeError, TypeError) as error:
        lines = str(error).splitlines()
        if len(lines) > 1:
            first = lines[1].strip()
        else:
            first = type(error).__name__
        raise UsageError(
            f"{path}: its weights do not fit the {method} policy its args describe ({first}): "
            f"re-save it with this {method}.py"
        )
    for name, tensor in policy.state_dict().items():
        if tensor.is_floating_point() and not torch.isfinite(tensor).all():
            raise UsageError(f"{path}: its weights hold non-finite values ({name}): re-train it")
    # Use one thread, as the method files train and evaluate: the same digits.
    torch.set_num_threads(1)
    return module, policy.eval(), args


def describe(args) -> str:
    """The partial observability and control rate a policy acts under, in words."""
    if args.hide_velocities:
        sensor = "velocities hidden"
    else:
        sensor = f"velocity noise std {args.obs_noise_std}"
    return f"{args.env}, {sensor}, frame skip {args.frame_skip}, history {args.history}"


def positive(text: str) -> int:
    value = int(text)
    if value <= 0:
        raise ValueError(text)
    return value


def non_negative(text: str) -> int:
    value = int(text)
    if value < 0:
        raise ValueError(text)
    return value


def main(argv=None):
    parser = OneLineParser(prog="python scripts/evaluate.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", help="a seed<S>.pt written by a method file's --save-model")
    parser.add_argument(
        "--episodes",
        type=positive,
        help="episodes, run in parallel (default: the run's --eval-episodes)",
    )
    parser.add_argument(
        "--seed",
        type=non_negative,
        default=0,
        help="seed of the first episode (episode i: seed + i, its env and its sensor noise)",
    )
    options = parser.parse_args(argv)
    if options.episodes is not None and options.episodes > MAX_EPISODES:
        raise UsageError(
            f"--episodes {options.episodes} is more than {MAX_EPISODES}, the most evaluated "
            f"(one env each, all at once): pass --episodes {MAX_EPISODES} or less"
        )
    module, policy, args = load_policy(options.checkpoint)
    episodes = options.episodes or args.eval_episodes
    if episodes > MAX_EPISODES:
        raise UsageError(
            f"{options.checkpoint}: its args hold eval_episodes {episodes}, more than "
            f"{MAX_EPISODES}, the most evaluated (one env each, all at once): "
            f"pass --episodes {MAX_EPISODES} or less"
        )
    noun = "episode"
    if episodes > 1:
        noun = "episodes"
    print(
        f"{module.METHOD} from {options.checkpoint} on {describe(args)}: "
        f"{episodes} {noun} from --seed {options.seed}"
    )
    returns = module.evaluate(policy, args, episodes, options.seed, torch.device("cpu"))
    for i, value in enumerate(returns):
        # The repr prints every digit, to compare with a run's JSON.
        print(f"episode {i + 1} | seed {options.seed + i} | return {value!r}")
    mean = np.mean(returns)
    std = np.std(returns)
    print(f"{args.env} {module.METHOD}: {mean:.1f} ± {std:.1f} over {episodes} {noun}")
    return 0


if __name__ == "__main__":
    run_cli(main)
