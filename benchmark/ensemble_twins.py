"""A control for the Average-Ensemble: two members of one kind (two BC-SO, or two BC-OH) from different seeds, averaged.

    python -m benchmark.ensemble_twins --member bc_so --env Hopper-v4 --seeds 11 12 13 --workers 2 \
        --output-dir results/ensemble_twins/runs/bc_so/Hopper-v4

average_ensemble.py averages a BC-SO and a BC-OH member, and beats each of them on Hopper. Whether that gain comes
from the two views of the history (the current frame against the whole history) or from averaging two networks at
all is what this control asks. It is average_ensemble.py itself (its flags, training, evaluation of the ensemble and
of each member, seed loop and output) with the members swapped: the first is initialised from the seed
exactly as average_ensemble.py initialises its member of that kind, so it trains to the same numbers; its twin, of
the same kind, from the seed + TWIN_SEED_OFFSET. Both see the same minibatches, as average_ensemble.py's members do.
Each result gains where it was made (`machine`, benchmark/machine.py), as the grid runner adds it.
"""
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch
import torch.nn as nn
import tyro

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import average_ensemble
from benchmark.machine import machine
from benchmark.results import UsageError, run_cli, write_text

TWIN_SEED_OFFSET = 1000
"""the twin's initialisation seed is the run's seed plus this (no run here uses a seed this large)"""
KINDS = {"bc_so": average_ensemble.CurrentFramePolicy, "bc_oh": average_ensemble.Policy}
"""the member kinds of average_ensemble.py"""


@dataclass
class Args(average_ensemble.Args):
    exp_name: str = "ensemble_twins"
    """the name of this experiment, part of the default output folder"""
    member: Literal["bc_so", "bc_oh"] = "bc_so"
    """the kind of both members: two BC-SO (the current frame) or two BC-OH (the history)"""


class TwinEnsemble(nn.Module):
    """Two members of one kind, the first initialised as average_ensemble.py's, the twin from another seed."""

    def __init__(self, kind: str, obs_dim: int, act_dim: int, history: int, hidden: int, inputs: torch.Tensor):
        super().__init__()
        seed, self.members = torch.initial_seed(), nn.ModuleDict()  # the seed train_seed gave torch.manual_seed
        for name, init_seed in ((kind, seed), (f"{kind}_twin", seed + TWIN_SEED_OFFSET)):
            torch.manual_seed(init_seed)
            self.members[name] = KINDS[kind](obs_dim, act_dim, history, hidden, inputs)

    forward = average_ensemble.AverageEnsemble.forward  # the mean action of the members


def make_policy(args, obs_dim: int, act_dim: int, inputs: torch.Tensor) -> nn.Module:
    return TwinEnsemble(args.member, obs_dim, act_dim, args.history, args.hidden, inputs)


def use_twins():  # average_ensemble.py, from now on in this process, trains and names the twins
    average_ensemble.make_policy, average_ensemble.METHOD = make_policy, "ensemble_twins"


if __name__ in ("__main__", "__mp_main__"):  # the pool's workers (spawned) import this module as their main
    use_twins()  # not when a test imports it: average_ensemble stays itself there


def main(argv=None) -> int:
    args = tyro.cli(Args, args=argv)
    use_twins()
    if args.output_dir is None:  # named here as run() names it, to find the results afterwards
        args.output_dir = f"runs/{args.env}__{args.exp_name}__{int(time.time())}"
    try:
        average_ensemble.run(args)
    except average_ensemble.UsageError as error:  # the method file's own: one line, exit 2 (run_cli)
        raise UsageError(str(error))
    for seed in args.seeds:  # where each seed was made
        path = Path(args.output_dir, f"result_seeds{seed}.json")
        result = json.loads(path.read_text())
        write_text(path, json.dumps({**result, "machine": machine()}, indent=1))
    return 0


if __name__ == "__main__":
    run_cli(main)  # also Ctrl-C or `kill` (SIGTERM) in one line, exit 130, before training too
