"""Fingerprint each stage of the pinned bc_oh tiny run on this machine, in MKL's fixed mode (issue 32).

    python -m benchmark.fingerprint [--out results/fingerprints] [--compare OTHER.json]
    python -m benchmark.fingerprint --compare A.json B.json     # two stored records: no run

In a temporary folder (experts/ linked in) it runs the bc_oh case of tests/test_pinned_output.py with
MKL_CBWR=COMPATIBLE (first `expert_ppo.py --make-demos` where that flag exists, else bc_oh makes its demos) plus
--save-model, and writes <out>/<cpu_vendor>_<cpu model>.json: the machine record (benchmark/machine.py); the first 16
hex digits of the sha256 of each demo array (its tobytes(), every key but "meta") and of the trained weights (one
sha256 over the tensors of the checkpoint's state_dict in sorted key order); the three evaluation returns; the printed
epoch lines. Two machines whose records agree on a stage computed it bit for bit alike; compare() names the first
stage that differs (demos -> weights -> evaluations): where the digits of two CPUs part.
"""
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmark.machine import MKL_VARIABLES, machine
from benchmark.results import OneLineParser, UsageError, run_cli, write_text

REPO_ROOT = Path(__file__).resolve().parent.parent
FIXED_MODE = {"MKL_CBWR": "COMPATIBLE"}
"""MKL's conditional numerical reproducibility, as tests/test_pinned_output.py runs the pinned cases"""
ENV, DEMO_SAMPLES = "Hopper-v4", 1000
METHOD = "bc_oh"
BUDGET = ["--env", ENV, "--seeds", "1", "--epochs", "3", "--eval-every", "1", "--eval-episodes", "2",
          "--num-demo-samples", str(DEMO_SAMPLES)]
"""the budget of tests/test_pinned_output.py (tests/test_fingerprint.py checks that they agree)"""
STAGES = ("demos", "weights", "evaluations")
"""the stages of a run in the order each feeds the next: compare() names the first that differs"""


def digest(*chunks: bytes) -> str:
    """The first 16 hex digits of the sha256 of the chunks, concatenated."""
    sha = hashlib.sha256()
    for chunk in chunks:
        sha.update(chunk)
    return sha.hexdigest()[:16]


def demo_fingerprints(path) -> dict:
    """{array name: digest of its tobytes()} for every array of a demo .npz but its "meta"."""
    import numpy as np

    with np.load(path) as demos:
        return {key: digest(demos[key].tobytes()) for key in sorted(demos) if key != "meta"}


def weights_fingerprint(state_dict: dict) -> str:
    """One digest over the tensors' bytes in sorted key order: the same for any insertion order of the dict."""
    return digest(*(state_dict[key].detach().cpu().numpy().tobytes() for key in sorted(state_dict)))


def makes_demos_separately(environment: dict) -> bool:
    """Whether expert_ppo.py has --make-demos (demonstrations made by their own step, before the method runs)."""
    shown = subprocess.run([sys.executable, str(REPO_ROOT / "expert_ppo.py"), "--help"], env=environment,
                           capture_output=True, text=True)
    return "--make-demos" in shown.stdout


def case_commands(output_dir, separate_demos: bool) -> list:
    """The commands of the pinned bc_oh case, run in order in one folder: adapt the case here."""
    python = sys.executable
    demos = [[python, str(REPO_ROOT / "expert_ppo.py"), "--env", ENV, "--make-demos", "--num-demo-samples",
              str(DEMO_SAMPLES)]] if separate_demos else []
    return [*demos, [python, str(REPO_ROOT / f"{METHOD}.py"), *BUDGET, "--save-model", "--output-dir", str(output_dir)]]


def run_case(folder: Path, environment: dict, separate_demos: bool) -> str:
    """Run the case's commands in `folder` (experts/ linked in); return what the method run printed."""
    (folder / "experts").symlink_to(REPO_ROOT / "experts", target_is_directory=True)
    for command in case_commands(folder / "out", separate_demos):
        finished = subprocess.run(command, cwd=folder, env=environment, capture_output=True, text=True)
        if finished.returncode != 0:
            last = (finished.stderr or finished.stdout).strip().splitlines()[-1:]
            raise UsageError(f"{' '.join(command[1:])} failed: {last[0] if last else f'exit {finished.returncode}'}")
    return finished.stdout


def stage_fingerprints(folder: Path, printed: str) -> dict:
    """The fingerprints of what the case left in `folder`: its one demo file, seed1.pt, result_seeds1.json."""
    import torch

    demo_files = sorted((folder / "demos").glob("*.npz"))
    if len(demo_files) != 1:
        raise UsageError(f"expected one demo file in {folder / 'demos'}, found {len(demo_files)}")
    checkpoint = torch.load(folder / "out" / "seed1.pt", map_location="cpu", weights_only=True)
    result = json.loads((folder / "out" / "result_seeds1.json").read_text())
    return {
        "demos": demo_fingerprints(demo_files[0]),
        "weights": weights_fingerprint(checkpoint["state_dict"]),
        "evaluations": [value for _, value in result["scores"]["1"]["evaluations"]],
        "epoch_lines": re.findall(r"^seed 1 \| (epoch .*?) \| [\d.]+ ms/step", printed, re.M),
    }


def measure(mode: dict = FIXED_MODE) -> dict:
    """Run the case in a temporary folder under the environment variables `mode`; return its record."""
    environment = {**os.environ, "PYTHONWARNINGS": "ignore", "OMP_NUM_THREADS": "1", **mode}
    with tempfile.TemporaryDirectory(prefix="copycat-fingerprint-") as tmp:
        folder = Path(tmp)
        separate_demos = makes_demos_separately(environment)
        fingerprints = stage_fingerprints(folder, run_case(folder, environment, separate_demos))
    return {
        "case": [" ".join([Path(command[1]).name, *command[2:]]) for command in case_commands("out", separate_demos)],
        "machine": {**machine(), **{name: environment.get(name) for name in MKL_VARIABLES}},  # as the run had them
        **fingerprints,
    }


def record_path(out_dir, record: dict) -> Path:
    """<out_dir>/<cpu_vendor>_<cpu model>.json, the model's runs of other characters than [A-Za-z0-9.-] as one '_'."""
    name = "_".join(str(record["machine"].get(key) or "unknown") for key in ("cpu_vendor", "cpu"))
    return Path(out_dir) / f"{re.sub(r'[^A-Za-z0-9.-]+', '_', name).strip('_')}.json"


def compare(a: dict, b: dict):
    """The first stage (demos, weights, evaluations) whose fingerprints differ between two records, or None when they
    agree at every stage both hold (a stage missing from either record is not compared)."""
    return next((stage for stage in STAGES if stage in a and stage in b and a[stage] != b[stage]), None)


def explain(a: dict, b: dict) -> str:
    """compare() as one line, with what differs at that stage."""
    stage = compare(a, b)
    if stage is None:
        return f"the same at every stage compared ({', '.join(s for s in STAGES if s in a and s in b)})"
    if stage == "demos":
        arrays = sorted(key for key in {*a[stage], *b[stage]} if a[stage].get(key) != b[stage].get(key))
        return f"first stage that differs: demos ({', '.join(arrays)})"
    if stage == "evaluations" and len(a[stage]) == len(b[stage]):
        worst = max(abs(x - y) / max(abs(x), abs(y)) if x != y else 0.0 for x, y in zip(a[stage], b[stage]))
        return f"first stage that differs: evaluations (the demos and weights agree; up to {worst:.2g} relative)"
    return f"first stage that differs: {stage} ({a[stage]} vs {b[stage]})"


def read_record(path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise UsageError(f"cannot read the record {path}: {error}")


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.fingerprint", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/fingerprints", help="folder the record is written to")
    parser.add_argument("--compare", nargs="+", metavar="FILE",
                        help="a record to compare this machine's with; two: compare those, without a run")
    options = parser.parse_args(argv)
    if options.compare and len(options.compare) > 2:
        raise UsageError("--compare takes one record (compared with a new run) or two")
    if options.compare and len(options.compare) == 2:
        print(explain(*map(read_record, options.compare)))
        return 0
    other = read_record(options.compare[0]) if options.compare else None
    record = measure()
    print(json.dumps(record, indent=1))
    path = record_path(options.out, record)
    write_text(path, json.dumps(record, indent=1) + "\n")
    print(f"record: {path}")
    if other is not None:
        print(f"vs {options.compare[0]}: {explain(record, other)}")
    return 0


if __name__ == "__main__":
    run_cli(main)
