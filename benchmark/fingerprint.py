"""Fingerprint each stage of the pinned bc_oh tiny run on this machine, in MKL's fixed mode (issue 32).

    python -m benchmark.fingerprint [--out results/fingerprints] [--compare OTHER.json] [--default-mode]
    python -m benchmark.fingerprint --compare A.json B.json     # two stored records: no run

In a temporary folder (experts/ linked in) it runs the bc_oh case of tests/test_pinned_output.py with
MKL_CBWR=COMPATIBLE (first `expert_ppo.py --make-demos` where that flag exists, else bc_oh makes its demos) plus
--save-model, and writes <out>/<cpu_vendor>_<cpu model>.json: the machine record (benchmark/machine.py); the first 16
hex digits of the sha256 of each demo array (its tobytes(), every key but "meta") and of the trained weights (one
sha256 over the tensors of the checkpoint's state_dict in sorted key order); the three evaluation returns; the printed
epoch lines. Two machines whose records agree on a stage computed it bit for bit alike; compare() names the first
stage that differs (demos -> weights -> evaluations): where the digits of two CPUs part. With --default-mode it runs
without MKL_CBWR (as the README's commands do) and writes <cpu_vendor>_<cpu model>_default.json.

A run's stages feed each other, so once one differs every later one does too. The record therefore also holds probes:
each stage again, alone, on inputs that every checkout holds bit for bit (committed files), so two machines' probes
compare each stage by itself: MuJoCo stepped open loop (no torch), the shipped expert's and a committed BC-OH policy's
forward passes on the shipped demos, that policy's closed-loop evaluation, and BC-OH trained on the shipped demos.
"""
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

# Run as a file (python benchmark/<name>.py) too: the repository root holds the benchmark package.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from benchmark.machine import MKL_VARIABLES, machine
from benchmark.results import OneLineParser, UsageError, check_writable, run_cli, write_text

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
SHIPPED_DEMOS = REPO_ROOT / "demos" / f"{ENV}_20000.npz"
SHIPPED_EXPERT = REPO_ROOT / "experts" / f"{ENV}.pt"
PROBE_POLICY = REPO_ROOT / "results" / "h3" / "native_hidden" / "runs" / "bc_oh" / ENV / "seed1.pt"
"""a committed BC-OH policy (velocities hidden; trained on an Intel Xeon): the same weights in every checkout"""
PROBE_EVALUATION = dict(episodes=10, seed=11000)
"""the policy's final evaluation in its run (seed 1, epoch 1000: --seed 10000 * 1 + 1000, its --eval-episodes 10),
whose mean its result JSON holds as that machine computed it"""
PROBES = ("libm", "mujoco", "expert_forward", "policy_forward", "policy_evaluation", "matmul", "initialization",
          "gradients", "adam_step", "training")
"""the probes in the order a run meets them: the C library's maths, the simulator, the two networks' forward passes, a
closed loop of both, then training taken apart (matrix products, initial weights and minibatches, one backward pass,
Adam steps), training"""
LAYERS = ((22, 256), (256, 256), (256, 3))
"""(inputs, outputs) of the pinned bc_oh case's Linear layers: Hopper's 2-frame history of 11, 256 units twice, 3 actions"""
MATMUL_SHAPES = {(f"{kind} {n_in}-{n_out}" if (n_in, n_out) != LAYERS[0] else kind): spec for n_in, n_out in LAYERS
                 for kind, spec in (("forward", ((64, n_in), (n_out, n_in), lambda a, b: a @ b.T)),
                                    ("grad_input", ((64, n_out), (n_out, n_in), lambda a, b: a @ b)),
                                    ("grad_weight", ((64, n_out), (64, n_in), lambda a, b: a.T @ b)))}
"""the products of each Linear layer's forward and backward pass at batch 64, as torch runs them: (shape of a, shape
of b, product); on an Intel Xeon MKL_VERBOSE=1 shows training call MKL's SGEMM with these layouts (T,N forward, N,N
for the input's gradient, N,T for the weights'), and ONEDNN_VERBOSE=1 no oneDNN primitive. The first layer's keep
their names of 2026-12-04, so records made before compare on them."""
LIBM_FUNCTIONS = ("exp", "log", "sin", "cos", "pow", "atan2", "tanh")
"""the C library's functions the libm probe calls (MuJoCo's and gymnasium's maths)"""


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
    return [run_checked(command, folder, environment) for command in case_commands(folder / "out", separate_demos)][-1]


def run_checked(command: list, cwd, environment: dict, name: str = "") -> str:
    """What `command` printed; its last line of error as a UsageError if it failed."""
    finished = subprocess.run(command, cwd=cwd, env=environment, capture_output=True, text=True)
    if finished.returncode != 0:
        last = (finished.stderr or finished.stdout).strip().splitlines()[-1:]
        raise UsageError(f"{name or ' '.join(command[1:])} failed: {last[0] if last else f'exit {finished.returncode}'}")
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


def libm_probe(count: int = 2000, library: str = None) -> str:
    """Digest of the C library's exp, log, sin, cos, pow, atan2 and tanh, called directly (ctypes), on `count` fixed
    arguments in [-20, 20]: which code the library picks for this CPU (glibc: FMA or SSE2) shows in their last bits."""
    import ctypes
    import ctypes.util

    import numpy as np

    libm = ctypes.CDLL(library or ctypes.util.find_library("m") or "libm.so.6")
    xs, values = np.linspace(-20.0, 20.0, count) + 1e-3 * np.sin(np.arange(count)), []
    for name in LIBM_FUNCTIONS:
        function, two = getattr(libm, name), name in ("pow", "atan2")
        function.restype, function.argtypes = ctypes.c_double, [ctypes.c_double] * (1 + two)
        if two:
            values += [function(abs(x) + 0.1, x / 7) for x in xs]
        else:
            values += [function(abs(x) + 1e-3 if name == "log" else x) for x in xs]
    return digest(np.array(values).tobytes())


def mujoco_probe(steps: int = 1000, amplitude: float = 0.5) -> str:
    """Digest of Hopper's observations and rewards under a fixed open-loop action sequence: MuJoCo (and the C
    library's maths) alone, no torch. It falls often, so contacts and resets are in it."""
    import gymnasium as gym
    import numpy as np

    gym.logger.min_level = gym.logger.ERROR  # the v4 envs' deprecation warning
    env = gym.make(ENV)
    obs, _ = env.reset(seed=0)
    chunks, low, high = [obs.tobytes()], env.action_space.low, env.action_space.high
    for t in range(steps):
        action = np.clip(amplitude * np.sin(0.05 * t + np.arange(len(low))), low, high)
        obs, reward, terminated, truncated, _ = env.step(action)
        chunks += [obs.tobytes(), np.float64(reward).tobytes()]
        if terminated or truncated:
            obs, _ = env.reset(seed=t)
            chunks.append(obs.tobytes())
    env.close()
    return digest(*chunks)


def load_probe_policy() -> tuple:
    """PROBE_POLICY as scripts/evaluate.py loads it: (its method file's module, the policy, its run's args)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("evaluate", REPO_ROOT / "scripts" / "evaluate.py")
    evaluate = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(evaluate)  # puts the repository root on sys.path: the method files import
    return evaluate.load_policy(PROBE_POLICY)


def policy_probes(rows: int = 1000, episodes: int = PROBE_EVALUATION["episodes"], seed=PROBE_EVALUATION["seed"]) -> dict:
    """The forward passes of the shipped expert and of PROBE_POLICY on the first `rows` states of the shipped demos
    (as one batch, and the first 20 one at a time, as a rollout feeds them), and PROBE_POLICY's evaluation returns
    over `episodes` episodes from `seed` (scripts/evaluate.py's loading and the method file's own evaluate)."""
    import numpy as np
    import torch

    module, policy, args = load_probe_policy()
    import expert_ppo

    expert = expert_ppo.load_expert(str(SHIPPED_EXPERT), ENV)
    with np.load(SHIPPED_DEMOS) as demos:
        observations, starts = demos["observations"][:rows], demos["episode_starts"][:rows]
    histories = module.stack_history(observations, starts, args.history)

    def forward(net, inputs) -> str:
        inputs = torch.as_tensor(inputs, dtype=torch.float32)
        with torch.no_grad():
            one_by_one = [net(inputs[i : i + 1]).numpy().tobytes() for i in range(min(20, len(inputs)))]
            return digest(net(inputs).numpy().tobytes(), *one_by_one)

    returns = module.evaluate(policy, args, episodes, seed, torch.device("cpu"))
    return {"expert_forward": forward(expert, observations), "policy_forward": forward(policy, histories),
            "policy_evaluation": returns}


def matmul_probe() -> dict:
    """{product: digest} of the matrix products in MATMUL_SHAPES on fixed float32 inputs (numpy's seeded generator):
    MKL's sgemm, with each transpose a Linear layer's training asks of it."""
    import numpy as np
    import torch

    rng, digests = np.random.default_rng(0), {}
    for name, (shape_a, shape_b, product) in MATMUL_SHAPES.items():
        a, b = (torch.as_tensor(rng.standard_normal(shape, dtype=np.float32)) for shape in (shape_a, shape_b))
        digests[name] = digest(product(a, b).numpy().tobytes())
    return digests


def training_step_probes(rows: int = 64, steps: int = 10) -> dict:
    """Training taken apart: the initial weights and input statistics of a policy the method makes after
    torch.manual_seed(1) on those steps, and the minibatch indices a seeded generator draws; then, from PROBE_POLICY's weights on the first `rows` shipped demo
    steps (velocities as recorded), one MSE loss and its gradients, {parameter: digest}, and the weights after 1 and
    after `steps` Adam steps (the method's loss and optimizer, a fixed learning rate, the same minibatch each step)."""
    import numpy as np
    import torch

    module, policy, args = load_probe_policy()
    with np.load(SHIPPED_DEMOS) as demos:
        histories = module.stack_history(demos["observations"][:rows], demos["episode_starts"][:rows], args.history)
        targets = torch.as_tensor(demos["actions"][:rows], dtype=torch.float32)
    inputs, weights = torch.as_tensor(histories, dtype=torch.float32), {}
    torch.manual_seed(1)
    fresh = module.make_policy(args, histories.shape[1] // args.history, targets.shape[1], inputs)
    indices = torch.randint(20000, (100, 64), generator=torch.Generator().manual_seed(1))
    initialization = {"weights": weights_fingerprint(dict(fresh.named_parameters())),
                      "normalizer": weights_fingerprint(dict(fresh.named_buffers())),  # torch's mean and std
                      "minibatches": digest(indices.numpy().tobytes())}
    optimizer = torch.optim.Adam(policy.parameters(), lr=1e-4, fused=True)  # as the method files (issue 56)
    for step in range(1, steps + 1):
        loss = torch.nn.functional.mse_loss(policy(inputs), targets)
        optimizer.zero_grad()
        loss.backward()
        if step == 1:
            gradients = {name: digest(p.grad.numpy().tobytes()) for name, p in policy.named_parameters()}
            gradients["loss"] = digest(loss.detach().numpy().tobytes())
        optimizer.step()
        if step in (1, steps):
            weights[f"after {step}"] = weights_fingerprint(dict(policy.named_parameters()))
    return {"initialization": initialization, "gradients": gradients, "adam_step": weights}


PROBE_CODE = "import json; from benchmark import fingerprint as f; print(json.dumps({'libm': f.libm_probe(), " \
             "'mujoco': f.mujoco_probe(), **f.policy_probes(), 'matmul': f.matmul_probe(), " \
             "**f.training_step_probes()}))"
"""run in a fresh process, so that the mode's environment variables are set before MKL starts"""


def training_command(output_dir) -> list:
    """The pinned case's training, on the shipped demos' first 1000 steps instead of demos made on this machine."""
    return [sys.executable, str(REPO_ROOT / f"{METHOD}.py"), *BUDGET, "--demos", str(SHIPPED_DEMOS), "--save-model",
            "--output-dir", str(output_dir)]


def run_probes(folder: Path, environment: dict) -> dict:
    """The probes' record, run under `environment` (training writes into `folder`)."""
    printed = run_checked([sys.executable, "-c", PROBE_CODE], REPO_ROOT, environment, name="the probes")
    probes = json.loads(printed.strip().splitlines()[-1])
    run_checked(training_command(folder / "shipped"), folder, environment)
    import torch

    checkpoint = torch.load(folder / "shipped" / "seed1.pt", map_location="cpu", weights_only=True)
    result = json.loads((folder / "shipped" / "result_seeds1.json").read_text())
    evaluations = [value for _, value in result["scores"]["1"]["evaluations"]]
    probes["training"] = {"weights": weights_fingerprint(checkpoint["state_dict"]), "evaluations": evaluations}
    return probes


def measure(mode: dict = FIXED_MODE) -> dict:
    """Run the case in a temporary folder under the environment variables `mode` (empty: MKL's default mode, no
    MKL_CBWR); return its record."""
    dropped = () if mode else ("MKL_CBWR",)  # the default mode: as a shell without it runs the README's commands
    environment = {name: value for name, value in os.environ.items() if name not in dropped}
    environment.update(PYTHONWARNINGS="ignore", OMP_NUM_THREADS="1", **mode)
    with tempfile.TemporaryDirectory(prefix="copycat-fingerprint-") as tmp:
        folder = Path(tmp)
        separate_demos = makes_demos_separately(environment)
        fingerprints = stage_fingerprints(folder, run_case(folder, environment, separate_demos))
        fingerprints["probes"] = run_probes(folder, environment)
    return {
        "case": [" ".join([Path(command[1]).name, *command[2:]]) for command in case_commands("out", separate_demos)],
        "machine": {**machine(), **{name: environment.get(name) for name in MKL_VARIABLES}},  # as the run had them
        **fingerprints,
    }


def record_path(out_dir, record: dict) -> Path:
    """<out_dir>/<cpu_vendor>_<cpu model>.json, the model's runs of other characters than [A-Za-z0-9.-] as one '_';
    _default before .json for a record made without MKL_CBWR."""
    name = "_".join(str(record["machine"].get(key) or "unknown") for key in ("cpu_vendor", "cpu"))
    name += "_default" * (record["machine"].get("MKL_CBWR") is None)
    return Path(out_dir) / f"{re.sub(r'[^A-Za-z0-9.-]+', '_', name).strip('_')}.json"


def compare(a: dict, b: dict):
    """The first stage (demos, weights, evaluations) whose fingerprints differ between two records, or None when they
    agree at every stage both hold (a stage missing from either record is not compared)."""
    return next((stage for stage in STAGES if stage in a and stage in b and a[stage] != b[stage]), None)


def relative_range(xs: list, ys: list):
    """'X to Y relative': the least and the most relative difference of two equally long lists of numbers that differ;
    None when they are equal or cannot be paired."""
    if not (isinstance(xs, list) and isinstance(ys, list) and len(xs) == len(ys) and xs != ys):
        return None
    gaps = [abs(x - y) / max(abs(x), abs(y)) if x != y else 0.0 for x, y in zip(xs, ys)]
    return f"{min(gaps):.2g} to {max(gaps):.2g} relative"


def probe_differences(a: dict, b: dict) -> str:
    """Which probes two records agree on and which they do not (probes missing from either are not compared), with how
    far the returns of a differing probe that holds some lie apart."""
    both = [name for name in PROBES if name in a.get("probes", {}) and name in b.get("probes", {})]
    if not both:
        return "no probes in both records"
    same = [name for name in both if agree(a["probes"][name], b["probes"][name])]
    differ = []
    for name in (name for name in both if name not in same):
        x, y = a["probes"][name], b["probes"][name]
        gap = relative_range(*((x.get("evaluations"), y.get("evaluations")) if isinstance(x, dict) else (x, y)))
        parts = [key for key in x if key in y and x[key] != y[key]] if isinstance(x, dict) and "evaluations" not in x \
            and isinstance(y, dict) else []  # a probe of named parts: name the parts that differ
        differ.append(f"{name} (returns {gap})" if gap else f"{name} ({', '.join(parts)})" if parts else name)
    return f"probes the same: {', '.join(same) or 'none'}; different: {', '.join(differ) or 'none'}"


def agree(x, y) -> bool:
    """Two fingerprints of one probe agree: equal, or for a probe of named parts, equal on every part both hold (a
    record made before a probe grew a part is compared on the parts it has)."""
    if isinstance(x, dict) and isinstance(y, dict) and "evaluations" not in x:
        common = [key for key in x if key in y]
        return bool(common) and all(x[key] == y[key] for key in common)
    return x == y


def explain(a: dict, b: dict) -> str:
    """compare() as one line, with what differs at that stage, then the probes."""
    return f"{explain_run(a, b)}; {probe_differences(a, b)}"


def explain_run(a: dict, b: dict) -> str:
    """compare() as words, with what differs at that stage (and how far the evaluations then lie apart)."""
    stage = compare(a, b)
    if stage is None:
        return f"the same at every stage compared ({', '.join(s for s in STAGES if s in a and s in b)})"
    gap = relative_range(a.get("evaluations"), b.get("evaluations"))
    if stage == "evaluations" and gap:
        return f"first stage that differs: evaluations (the demos and weights agree; {gap})"
    if stage == "demos":
        arrays = sorted(key for key in {*a[stage], *b[stage]} if a[stage].get(key) != b[stage].get(key))
        line = f"first stage that differs: demos ({', '.join(arrays)})"
    else:
        line = f"first stage that differs: {stage} ({a[stage]} vs {b[stage]})"
    return f"{line}; evaluations {gap}" if gap and stage != "evaluations" else line


def recorded_evaluation(record: dict) -> str:
    """The probe policy's final evaluation here against the one its run recorded (another machine, the default mode)."""
    import numpy as np

    run = json.loads((PROBE_POLICY.parent / "result_seeds1.json").read_text())
    recorded, here = run["scores"]["1"]["evaluations"][-1][1], float(np.mean(record["probes"]["policy_evaluation"]))
    where = f"{run['machine']['cpu']}, MKL_CBWR={run['machine'].get('MKL_CBWR')}"
    return f"{here!r} here, {recorded!r} recorded by its run ({where}): {abs(here - recorded) / recorded:.2g} relative"


RECORD_TYPES = {"demos": dict, "weights": str, "evaluations": list, "probes": dict}
"""the JSON type of each part of a record that compare() and probe_differences() read"""


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def read_record(path) -> dict:
    """A record this module wrote: a JSON object with at least one stage (an empty one would compare as "the same")."""
    try:
        record = json.loads(Path(path).read_text())
    except OSError as error:
        reason = error.strerror or str(error)
    except ValueError as error:  # JSONDecodeError, UnicodeDecodeError
        reason = f"not JSON: {error}"
    else:
        reason = None
    if reason is not None:
        raise UsageError(f"cannot read the record {path} ({reason}): pass one this module wrote")
    if not isinstance(record, dict) or not any(stage in record for stage in STAGES):
        raise UsageError(f"{path} is not a fingerprint record (none of {', '.join(STAGES)}): pass one this module wrote")
    wrong = [name for name, kind in RECORD_TYPES.items()
             if name in record and not isinstance(record[name], kind)]
    evaluations = record.get("evaluations")
    if isinstance(evaluations, list) and not all(map(is_number, evaluations)):
        wrong.append("evaluations")
    if wrong:  # compared as written, a part of another shape ended in a traceback
        shapes = ", ".join(wrong)
        raise UsageError(f"{path} is not a fingerprint record ({shapes} not as this module writes "
                         "them): pass one this module wrote")
    return record


def main(argv=None) -> int:
    parser = OneLineParser(prog="python -m benchmark.fingerprint", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/fingerprints", help="folder the record is written to")
    parser.add_argument("--compare", nargs="+", metavar="FILE",
                        help="a record to compare this machine's with; two: compare those, without a run")
    parser.add_argument("--default-mode", action="store_true", help="run without MKL_CBWR (MKL picks its kernels)")
    options = parser.parse_args(argv)
    if options.compare and len(options.compare) > 2:
        raise UsageError("--compare takes one record (compared with a new run) or two")
    if options.compare and len(options.compare) == 2:
        print(explain(*map(read_record, options.compare)))
        return 0
    other = read_record(options.compare[0]) if options.compare else None
    check_writable(Path(options.out), "--out")  # before the run, not after it
    record = measure({} if options.default_mode else FIXED_MODE)
    print(json.dumps(record, indent=1))
    path = record_path(options.out, record)
    write_text(path, json.dumps(record, indent=1) + "\n")
    print(f"record: {path}\nthe committed policy's final evaluation: {recorded_evaluation(record)}")
    if other is not None:
        print(f"vs {options.compare[0]}: {explain(record, other)}")
    return 0


if __name__ == "__main__":
    run_cli(main)
