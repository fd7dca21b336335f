"""The paper's Table 2, its Table 3 ablations (CARLA), and its MuJoCo settings (paper sections 5.1, 5.3 and 8.3).

Everything the benchmark knows about the paper lives here, in one place.
"""
import math

# Table 2: mean and std over 3 seeds of the last three evaluations; the expert has no std.
PAPER_TABLE2 = {
    "bc_so": {"Hopper": (589, 94), "Ant": (4198, 433), "HalfCheetah": (489, 77)},
    "bc_oh": {"Hopper": (628, 99), "Ant": (2922, 1266), "HalfCheetah": (639, 121)},
    "c2f": {"Hopper": (1124, 135), "Ant": (4798, 304), "HalfCheetah": (1448, 74)},
    "fca": {"Hopper": (831, 108), "Ant": (3727, 926), "HalfCheetah": (1148, 81)},
    "keyframe": {"Hopper": (696, 28), "Ant": (2930, 1321), "HalfCheetah": (1062, 127)},
    "history_dropout": {"Hopper": (539, 33), "Ant": (4069, 517), "HalfCheetah": (1215, 70)},
    "average_ensemble": {"Hopper": (504, 47), "Ant": (4659, 396), "HalfCheetah": (729, 50)},
    "dagger": {"Hopper": (2383, 294), "Ant": (4097, 418), "HalfCheetah": (1842, 10)},
    "expert": {"Hopper": (3445, None), "Ant": (5566, None), "HalfCheetah": (1941, None)},
}
"""method (file name without .py, or "expert") -> env family -> (mean, std or None)"""

PAPER_TABLE3 = {
    "c2f": (49.3, 3.6), "c2f_early": (51.4, 4.0), "c2f_middle": (49.6, 1.7), "c2f_feature": (44.8, 5.2),
    "c2f_coarse_history": (37.1, 3.4), "c2f_coarse_history_policy_current": (31.7, 5.7),
    "c2f_no_stop_gradient": (44.4, 5.5), "c2f_two_stage": (47.3, 3.8),
}
"""Table 3, the ablations on CARLA: runner variant -> (%success mean, std). The feature row is "ResNet output as ζ"
(44.8 ± 5.2): `--coarse-output feature` passes the coarse model's last hidden feature, the output of its backbone.
Table 3's shallower "ResNet Layer2 as ζ" (39.8 ± 4.0) has no flag here; the declaration in docs/regimes.md quoted
its figure. Rows run on MuJoCo only (output and penultimate fusion, no coarse action, BC-OH, BC-SO) are absent."""

METHOD_NAMES = {
    "bc_so": "BC-SO", "bc_oh": "BC-OH", "c2f": "Coarse-to-fine", "fca": "FCA", "keyframe": "KeyFrame",
    "history_dropout": "History-Dropout", "average_ensemble": "Average-Ensemble", "dagger": "DAgger 8K",
    "expert": "PPO expert",
    "c2f_output": "C2F (output fusion)",
    "c2f_middle": "C2F (middle fusion)",
    "c2f_early": "C2F (early fusion)",
    "c2f_penultimate": "C2F (penultimate fusion)",
    "c2f_feature": "C2F (feature as ζ)",
    "c2f_coarse_history": "C2F (BC-OH as π_φ and π_θ)",
    "c2f_coarse_history_policy_current": "C2F (BC-OH as π_φ, BC-SO as π_θ)",
    "c2f_no_stop_gradient": "C2F (no stop-gradient)",
    "c2f_two_stage": "C2F (two-stage)",
    "c2f_no_coarse": "C2F (no coarse action)",
}
"""the row names: Table 2's rows in the paper's order, then the C2F variants (Table 3's and ours)"""

PAPER_ENV_ORDER = ["Hopper", "Ant", "HalfCheetah"]
"""the paper's column order (env families); Walker2d was collected but never reported"""


def env_family(env_id: str) -> str:
    """"Hopper-v4" -> "Hopper": the paper names envs without a version."""
    return env_id.split("-")[0]


NATIVE_FRAME_SKIP = {"Hopper": 4, "Walker2d": 4, "HalfCheetah": 5, "Ant": 5}
"""simulator steps per action of the gymnasium MuJoCo envs (their frame_skip argument, v4 and v5)"""


def paper_settings(env_id: str) -> dict:
    """The settings of every Table 2 run, as Args fields of the method scripts."""
    hopper = env_family(env_id) == "Hopper"
    return {
        "epochs": 1000,
        "batch_size": 64,
        "obs_noise_std": 0.2,
        "history": 2,
        "learning_rate": 1e-5 if hopper else 1e-4,
        "num_demo_samples": 20000 if hopper else 10000,
        "frame_skip": NATIVE_FRAME_SKIP.get(env_family(env_id)),
        "hide_velocities": False,
    }


DEFAULTED = ("learning_rate", "num_demo_samples", "frame_skip")
"""fields for which the scripts take None to mean the paper's per-env default"""


def setting_differences(args: dict, wanted: dict, env_id: str) -> list:
    """Readable 'name got != wanted' for every field of `wanted` on which a run's args differ.

    None in the run's args stands for the script's default (the paper's value) for DEFAULTED fields; a
    field missing from the run's args was made before the flag existed, at what is now its default
    (the paper's setting, or a method flag's default).
    """
    defaults = {**paper_settings(env_id), **{name: value for flags in METHOD_FLAGS.values() for name, value in flags.items()}}
    differences = []
    for name, want in wanted.items():
        got = args.get(name)
        if (got is None and name in DEFAULTED) or name not in args:
            got = defaults.get(name)
        if not same_value(got, want):
            differences.append(f"{name} {got} != {want}")
    return differences


def same_value(a, b) -> bool:
    """Equality with a relative tolerance for numbers (1e-5 written as 1e-05 or 0.00001 alike)."""
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b))
    return a == b


TABLE3_FLAGS = {"fusion": "late", "coarse_output": "action", "coarse_input": "current", "policy_input": "history",
                "stop_gradient": True, "coarse_action": True, "two_stage": False}
"""c2f_table3.py's flags of Table 3's ablations and the capacity control, at their defaults (the paper's model)"""

METHOD_FLAGS = {"c2f_table3": TABLE3_FLAGS, "c2f": TABLE3_FLAGS}
"""method script -> its method flags at their defaults: a result of the script's own method must have them all
(an ablation is not the method), and a result made before a flag existed was made at its default. c2f.py has no
such flag since the ablations left it for c2f_table3.py (issue 55), but its results made before recorded them:
a c2f result must have them at their defaults (one of today's c2f.py, which lacks them, has)"""

VARIANTS = {
    "c2f_output": ("c2f_table3", {"fusion": "output"}),
    "c2f_middle": ("c2f_table3", {"fusion": "middle"}),
    "c2f_early": ("c2f_table3", {"fusion": "early"}),
    "c2f_penultimate": ("c2f_table3", {"fusion": "penultimate"}),
    "c2f_feature": ("c2f_table3", {"coarse_output": "feature"}),
    "c2f_coarse_history": ("c2f_table3", {"coarse_input": "history"}),
    "c2f_coarse_history_policy_current": ("c2f_table3", {"coarse_input": "history", "policy_input": "current"}),
    "c2f_no_stop_gradient": ("c2f_table3", {"stop_gradient": False}),
    "c2f_two_stage": ("c2f_table3", {"two_stage": True}),
    "c2f_no_coarse": ("c2f_table3", {"coarse_action": False}),
}
"""method name -> (method script, its flags): a method file run with settings that make it another method
(the Table 3 rows of c2f_table3.py, and the capacity controls); their results made before c2f_table3.py existed
were made by c2f.py and name the method "c2f" (benchmark.results.read_result accepts both)"""


def script_of(method: str) -> str:
    """The method file (without .py) that runs `method`."""
    return VARIANTS[method][0] if method in VARIANTS else method


def variant_flags(method: str) -> dict:
    """The flags that make `method` out of its script, as its command passes them ({} for a plain method file)."""
    return dict(VARIANTS[method][1]) if method in VARIANTS else {}


def variant_settings(method: str) -> dict:
    """Every method flag a result of `method` must have: its script's defaults, changed by the variant's flags."""
    return {**METHOD_FLAGS.get(script_of(method), {}), **variant_flags(method)}


def as_flags(settings: dict) -> list:
    """{"fusion": "output", "stop_gradient": False} -> ["--fusion", "output", "--no-stop-gradient"]"""
    flags = []
    for name, value in settings.items():
        flag = name.replace("_", "-")
        if isinstance(value, bool):
            flags.append(f"--{flag}" if value else f"--no-{flag}")
        else:
            flags += [f"--{flag}", str(value)]
    return flags
