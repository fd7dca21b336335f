"""Time the training step of method scripts: on the CPU, and on the GPU (plain eager steps, `--cuda`).

    python -m benchmark.step_time --scripts bc_oh c2f --epochs 20 [--modes cpu cuda]

Each (script, mode) runs the real script on Hopper-v4 (paper settings but --epochs, one seed, one
evaluation of one episode) and reads `ms_per_step` from its JSON result: the script's own training-loop
time per step, evaluations excluded, first epoch (warm-up) included. Prints a Markdown table. (The CUDA-graph
fast path left the method files in issue 31: docs/speed.md.)
"""
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmark.results import OneLineParser, UsageError, run_cli

REPO_ROOT = Path(__file__).resolve().parent.parent
MODES = {"cpu": [], "cuda": ["--cuda"]}
"""the flags of each mode"""


def time_step(script: str, mode: str, epochs: int, workdir: Path) -> float:
    out = workdir / f"{script}_{mode}"
    command = [sys.executable, str(REPO_ROOT / f"{script}.py"), "--env", "Hopper-v4", "--seeds", "1", "--epochs", str(epochs),
               "--eval-every", str(epochs), "--eval-episodes", "1", "--output-dir", str(out), *MODES[mode]]
    finished = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True)
    if finished.returncode != 0:
        raise UsageError(f"{' '.join(command[1:])} failed: {finished.stderr.strip().splitlines()[-1:]}")
    return json.loads((out / "result_seeds1.json").read_text())["scores"]["1"]["ms_per_step"]


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.step_time", description=__doc__.splitlines()[0])
    parser.add_argument("--scripts", nargs="+", default=["bc_oh", "c2f"])
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    parser.add_argument("--epochs", type=int, default=20)
    options = parser.parse_args(argv)
    missing = [s for s in options.scripts if not (REPO_ROOT / f"{s}.py").is_file()]
    if missing or options.epochs <= 0:
        raise UsageError(f"unknown script {missing[0]}.py" if missing else "--epochs must be positive")
    if {"eager", "graph"} & set(options.modes):
        import torch  # only to name the GPU, and to fail clearly without one

        if not torch.cuda.is_available():
            raise UsageError("the eager and graph modes need a CUDA GPU: run with --modes cpu")
        print(f"GPU: {torch.cuda.get_device_name()}")
    with tempfile.TemporaryDirectory() as tmp:
        times = {(s, m): time_step(s, m, options.epochs, Path(tmp)) for s in options.scripts for m in options.modes}
    print("| script | " + " | ".join(f"{m} ms/step" for m in options.modes) + (" | graph vs eager |" if {"eager", "graph"} <= set(options.modes) else " |"))
    print("|---" * (len(options.modes) + 1 + ({"eager", "graph"} <= set(options.modes))) + "|")
    for script in options.scripts:
        row = [f"{times[script, m]:.3f}" for m in options.modes]
        if {"eager", "graph"} <= set(options.modes):
            row.append(f"{times[script, 'eager'] / times[script, 'graph']:.1f}x")
        print(f"| {script}.py | " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    run_cli(main)
