"""Minari datasets in and out of the demo .npz format of the method files (see docs/methods.md,
"Minari datasets").

    # The first two commands are each one line, wrapped here:
    python scripts/minari_demos.py import mujoco/hopper/expert-v0 demos/hopper_expert.npz
        --num-samples 20000
    python scripts/minari_demos.py import ~/.minari/datasets/mujoco/hopper/expert-v0
        demos/hopper_expert.npz
    python scripts/minari_demos.py export demos/Hopper-v4_20000.npz copycat/hopper/expert-v0

import: a dataset of the local Minari store (MINARI_DATASETS_PATH, else ~/.minari/datasets) or a
dataset folder -> observations, actions, episode_starts, rewards, terminations, truncations,
final_observations and meta (dataset id, env id, num_samples). export: a demo file -> a local
dataset that `minari.load_dataset(ID)` opens. Only the MuJoCo envs the method files know, at the
env's own widths. Needs `pip install -r requirements-minari.txt`; the method files do not import
minari.
"""

import contextlib
import importlib
import io
import json
import os
import re
import shutil
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import gymnasium as gym
import numpy as np

# The tooling may import the repository's benchmark package (and bc_oh.py): put the repository
# root on sys.path.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.results import OneLineParser, UsageError, run_cli, unwritable, written_atomically

# The paper's v4 envs are used on purpose: hide gymnasium's warning that they are out of date.
warnings.filterwarnings("ignore", ".*is out of date", DeprecationWarning)
KNOWN_ENVS = re.compile(r"(Hopper|HalfCheetah|Walker2d|Ant)-v[45]")
FORMAT_FIX = "see the .npz format in docs/methods.md"
DTYPES = {
    "observations": np.float64,
    "actions": np.float32,
    "episode_starts": bool,
    "rewards": np.float64,
    "terminations": bool,
    "truncations": bool,
    "final_observations": np.float64,
}


def check_env(env_id: str, obs_dim: int, act_dim: int, what: str) -> gym.Env:
    """The env made with gymnasium, after checking it is a known MuJoCo env with these widths."""
    if not KNOWN_ENVS.fullmatch(env_id or ""):
        raise UsageError(
            f"{what} is for env {env_id!r}, not a MuJoCo env the method files know: "
            "use Hopper, HalfCheetah, Walker2d or Ant, v4 or v5"
        )
    env = gym.make(env_id)
    expected = (env.observation_space.shape[0], env.action_space.shape[0])
    if (obs_dim, act_dim) != expected:
        raise UsageError(
            f"{what} has observations of width {obs_dim} and actions of width {act_dim}, "
            f"but {env_id} has {expected[0]} and {expected[1]}: "
            f"use data recorded with {env_id}'s default observation"
        )
    return env


def store_path(dataset_id=None) -> Path:
    """Where the local Minari store keeps dataset_id (the store itself without one), the store's
    folder made: a store that cannot be made is refused in one line."""
    from minari.storage.datasets_root_dir import get_dataset_path

    try:
        return get_dataset_path(dataset_id)
    except OSError as error:
        raise UsageError(
            f"cannot make the local Minari store {error.filename} ({error.strerror}): "
            "set MINARI_DATASETS_PATH to a folder you can write"
        )


def refuse_non_finite(demos: dict, what: str, fix: str):
    """Refuse a NaN or an infinity in the arrays of numbers."""
    for key in ("observations", "actions", "rewards", "final_observations"):
        bad = np.argwhere(~np.isfinite(demos[key]))
        if len(bad):
            raise UsageError(f"{what}: {key} has a non-finite value at row {bad[0][0]}: {fix}")


def open_dataset(source: str):
    """A MinariDataset from a folder (the dataset's or its data/ folder) or an id of the local
    store."""
    import minari
    from minari.dataset.minari_dataset import parse_dataset_id

    if os.path.exists(source):
        folder = source
        if os.path.isdir(os.path.join(source, "data")):
            folder = os.path.join(source, "data")
        if not os.path.isfile(os.path.join(folder, "metadata.json")):
            raise UsageError(
                f"{source} is not a Minari dataset folder (no data/metadata.json in it): "
                "pass the folder holding data/, "
                "e.g. ~/.minari/datasets/mujoco/hopper/expert-v0, or a dataset id"
            )
    else:
        try:
            parse_dataset_id(source)
        except Exception:
            raise UsageError(
                f"{source!r} is neither a folder nor a Minari dataset id: pass a dataset folder, "
                "or an id (namespace/)name-vN, e.g. mujoco/hopper/expert-v0"
            )
        folder = os.path.join(store_path(source), "data")
        if not os.path.isdir(folder):
            raise UsageError(
                f"no Minari dataset {source!r} in the local store {store_path()}: "
                f"download it with `minari download {source}` (needs network), "
                "or pass the path of a dataset folder"
            )
    try:
        return minari.MinariDataset(folder)
    except Exception as error:
        raise UsageError(
            f"{source} is not a readable Minari dataset ({type(error).__name__}: {error}): "
            f"it may need another minari than {minari.__version__}, or download it again"
        )


def import_dataset(source: str, out: str, num_samples=None):
    # np.savez would add .npz to a name without it, and the method files look for that name.
    if not out.endswith(".npz"):
        raise UsageError(f"the demo file {out} must end in .npz, as the method files name theirs")
    if Path(out).name == ".npz":
        raise UsageError(f"the demo file {out} has no name before .npz: e.g. demos/hopper.npz")
    # Refused now, not after reading the whole dataset.
    reason = unwritable(Path(out).parent)
    if os.path.isdir(out):
        reason = f"{out} is a folder"
    if reason:
        raise UsageError(f"cannot write the demo file {out}: {reason}: pass another path")
    if num_samples is not None and num_samples < 2:
        raise UsageError(
            f"--num-samples {num_samples} is too few: the method files train on more steps "
            "than one batch, pass 2 or more, or leave it out"
        )
    dataset = open_dataset(source)
    spaces = (dataset.observation_space, dataset.action_space)
    if not all(isinstance(space, gym.spaces.Box) and len(space.shape) == 1 for space in spaces):
        raise UsageError(
            f"dataset {source} has {type(spaces[0]).__name__} observations "
            f"and {type(spaces[1]).__name__} actions: "
            "the method files need flat Box observations and actions (no Dict or Tuple spaces)"
        )
    if dataset.env_spec is None:
        raise UsageError(
            f"dataset {source} records no env spec: "
            "the method files need one of Hopper, HalfCheetah, Walker2d or Ant, v4 or v5"
        )
    env_id = dataset.env_spec.id
    env = check_env(env_id, spaces[0].shape[0], spaces[1].shape[0], f"dataset {source}")
    total = dataset.total_steps
    if total < 2:
        raise UsageError(
            f"dataset {source} holds {total} steps: the method files train on more steps "
            "than one batch, use a dataset of 2 steps or more"
        )
    if num_samples is not None and not 0 < num_samples <= total:
        raise UsageError(
            f"--num-samples {num_samples} is not within the dataset's {total} steps: "
            f"pass 1 to {total}, or leave it out"
        )
    budget = num_samples or total
    parts = []
    for episode in dataset.iterate_episodes():
        steps = min(len(episode), budget)
        truncations = np.array(episode.truncations[:steps], bool)
        # If the budget cuts this episode, its last kept step is marked truncated.
        truncations[-1:] |= steps < len(episode)
        part = {
            "observations": episode.observations[:steps],
            "actions": episode.actions[:steps],
            "episode_starts": np.arange(steps) == 0,
            "rewards": episode.rewards[:steps],
            "terminations": episode.terminations[:steps],
            "truncations": truncations,
            # The observation after the last kept step.
            "final_observations": episode.observations[steps : steps + 1],
        }
        parts.append(part)
        budget -= steps
        if budget == 0:
            break
    demos = {}
    for key, dtype in DTYPES.items():
        demos[key] = np.concatenate([part[key] for part in parts]).astype(dtype)
    fix = "the method files refuse it, use a clean dataset"
    refuse_non_finite(demos, f"dataset {source}", fix)
    spec_kwargs = dataset.env_spec.kwargs or {}
    native_frame_skip = getattr(env.unwrapped, "frame_skip", None)
    meta = {
        "env_id": env_id,
        "source": f"minari:{dataset.id}",
        "minari_dataset_id": dataset.id,
        "num_samples": len(demos["actions"]),
        "frame_skip": spec_kwargs.get("frame_skip", native_frame_skip),
    }
    # The file is written, then renamed: an interrupted run leaves no half file.
    with written_atomically(out) as tmp:
        np.savez(tmp, meta=np.array(json.dumps(meta)), **demos)
        check_with_the_method_loader(tmp, env_id, meta["frame_skip"], out)
    print(
        f"{out}: {len(demos['actions'])} steps, {len(demos['final_observations'])} episodes "
        f"of {env_id} from Minari dataset {dataset.id}"
    )


def export_demos(path: str, dataset_id: str, env_id=None):
    import minari
    from minari.dataset.minari_dataset import parse_dataset_id

    try:
        parse_dataset_id(dataset_id)
    except Exception:
        raise UsageError(
            f"{dataset_id!r} is not a Minari dataset id: "
            "use (namespace/)name-vN, e.g. copycat/hopper/expert-v0"
        )
    where = store_path(dataset_id)
    if os.path.exists(where):
        raise UsageError(
            f"Minari dataset {dataset_id} already exists at {where}: "
            f"pick another id or version, or delete it with `minari delete {dataset_id}`"
        )
    reason = unwritable(where)
    if reason:
        raise UsageError(
            f"cannot write Minari dataset {dataset_id} into the local store: {reason}: "
            "set MINARI_DATASETS_PATH to a folder you can write"
        )
    if os.path.isdir(path):
        raise UsageError(f"demo file {path} is a folder: pass the .npz file itself")
    if not os.path.isfile(path):
        raise UsageError(
            f"demo file {path} not found: "
            "check the path (expert_ppo.py --make-demos writes demos/<env>_<N>.npz)"
        )
    try:
        with np.load(path, allow_pickle=False) as data:
            demos = {key: data[key] for key in data.files}
        meta = json.loads(str(demos.pop("meta"))) if "meta" in demos else {}
    except Exception as error:
        raise UsageError(
            f"{path} is not a readable demo file ({type(error).__name__}): {FORMAT_FIX}"
        )
    if not isinstance(meta, dict):
        raise UsageError(f"{path}: its meta is not a JSON object: {FORMAT_FIX}")
    for key in ("observations", "actions", "episode_starts"):
        if key not in demos:
            raise UsageError(f"{path} has no {key!r} array: {FORMAT_FIX}")
    for key in ("rewards", "terminations", "truncations", "final_observations"):
        if key not in demos:
            raise UsageError(
                f"{path} has no {key!r} array "
                "(made before demo files kept rewards and episode ends): make it again "
                "with `python expert_ppo.py --env <env> --make-demos`, "
                "which rolls the expert out again"
            )
    env_id = env_id or meta.get("env_id")
    if env_id is None:
        raise UsageError(f"{path} names no env in its meta: pass --env, e.g. --env Hopper-v4")
    if not isinstance(env_id, str):
        raise UsageError(
            f"{path}: the env_id in its meta is {env_id!r}, not an env id: "
            "pass --env, e.g. --env Hopper-v4"
        )
    demos = {key: np.asarray(demos[key]).astype(dtype) for key, dtype in DTYPES.items()}
    observations = demos["observations"]
    actions = demos["actions"]
    final_observations = demos["final_observations"]
    n = len(demos["actions"])
    if observations.ndim != 2 or actions.ndim != 2 or n == 0:
        raise UsageError(
            f"{path} holds observations {observations.shape} and actions {actions.shape}, "
            f"not (N, width) arrays: {FORMAT_FIX}"
        )
    env = check_env(env_id, observations.shape[1], actions.shape[1], path)
    native = getattr(env.unwrapped, "frame_skip", None)
    if meta.get("frame_skip", native) != native:
        raise UsageError(
            f"{path} was recorded at frame skip {meta['frame_skip']!r}, "
            f"but a Minari env spec records {env_id}'s own rate {native}: "
            "export demos made without --frame-skip"
        )
    per_step = ("observations", "episode_starts", "rewards", "terminations", "truncations")
    if any(len(demos[key]) != n for key in per_step):
        raise UsageError(
            f"{path}: observations, actions, episode_starts, rewards, terminations and truncations "
            f"differ in length: {FORMAT_FIX}"
        )
    refuse_non_finite(demos, path, "make the demo file again")
    demos["episode_starts"][0] = True
    bounds = [*np.flatnonzero(demos["episode_starts"]), n]
    if final_observations.shape != (len(bounds) - 1, observations.shape[1]):
        raise UsageError(
            f"{path} holds {len(final_observations)} final observations "
            f"for {len(bounds) - 1} episodes: {FORMAT_FIX}"
        )
    buffers = []
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        buffer = minari.data_collector.EpisodeBuffer(
            id=i,
            observations=np.concatenate([observations[a:b], final_observations[i : i + 1]]),
            actions=actions[a:b],
            rewards=demos["rewards"][a:b],
            terminations=demos["terminations"][a:b],
            truncations=demos["truncations"][a:b],
        )
        buffers.append(buffer)
    try:
        with warnings.catch_warnings():
            # The author, permalink and eval env are not recorded: hide the warnings that they
            # are None.
            warnings.filterwarnings("ignore", message=".*is set to None")
            file_name = os.path.basename(path)
            description = f"copycat-suite demo file {file_name}; meta: {json.dumps(meta)}"
            minari.create_dataset_from_buffers(
                dataset_id,
                buffers,
                env=env_id,
                algorithm_name=meta.get("source", "copycat-suite demos"),
                description=description,
                data_format="hdf5",
            )
    except BaseException:
        # An interrupted export leaves no half dataset that would block the id.
        shutil.rmtree(where, ignore_errors=True)
        raise
    print(f"Minari dataset {dataset_id} at {where}: {n} steps, {len(buffers)} episodes of {env_id}")


def check_with_the_method_loader(path, env_id: str, frame_skip, out: str):
    """The import goes through the loader of every method file (bc_oh.load_demos, here the
    tooling may import the repository's code): what a method file would refuse is refused here,
    in one line, naming the demo file out rather than its temporary path."""
    import bc_oh

    args = SimpleNamespace(
        demos=str(path), env=env_id, num_demo_samples=None, batch_size=1, frame_skip=frame_skip
    )
    try:
        # The loader prints its "demos: ..." line; hide it, as the import prints its own.
        with contextlib.redirect_stdout(io.StringIO()):
            bc_oh.load_demos(args, bc_oh.make_env(env_id))
    except bc_oh.UsageError as error:
        message = str(error).replace(str(path), out)
        raise UsageError(f"the method files would refuse this import ({message})")


def main(argv=None):
    parser = OneLineParser(
        prog="python scripts/minari_demos.py", description=__doc__.split("\n\n")[0]
    )
    commands = parser.add_subparsers(dest="command", required=True)
    importer = commands.add_parser("import", help="a Minari dataset -> a demo .npz")
    importer.add_argument(
        "source", help="dataset id in the local Minari store, or the path of a dataset folder"
    )
    importer.add_argument("out", help="the demo .npz to write (overwritten)")
    importer.add_argument(
        "--num-samples",
        type=int,
        help="keep the first N steps; the cut episode is marked truncated",
    )
    exporter = commands.add_parser(
        "export", help="a demo .npz -> a dataset in the local Minari store"
    )
    exporter.add_argument(
        "demos", help="a demo .npz with rewards, terminations, truncations and final_observations"
    )
    exporter.add_argument(
        "dataset_id", help="new dataset id, (namespace/)name-vN, e.g. copycat/hopper/expert-v0"
    )
    exporter.add_argument(
        "--env", help="env id to record (default: the env_id in the demo file's meta)"
    )
    args = parser.parse_args(argv)
    try:
        # Only a check that minari is installed: the functions that use it import it themselves.
        importlib.import_module("minari")
    except ImportError:
        raise UsageError("minari is not installed: pip install -r requirements-minari.txt")
    if args.command == "import":
        import_dataset(args.source, args.out, args.num_samples)
    else:
        export_demos(args.demos, args.dataset_id, args.env)
    return 0


if __name__ == "__main__":
    run_cli(main)
