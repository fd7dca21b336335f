"""benchmark/machine.py (what tells machines apart) and benchmark/fingerprint.py (where two machines' digits part).
No training run: the fingerprint functions get small hand-made inputs, and the stored record is read as written."""
import hashlib
import json
import os
import platform
import re
import subprocess
import sys

import numpy as np
import pytest
import torch
from conftest import BUDGET, FIXED_MODE, PIN_TOLERANCE, PINNED, REPO_ROOT, run_in_process

from benchmark import fingerprint, machine

CASES = {
    "nowhere": {},
    "demos": {"demos": {"observations": "0000000000000000"}, "evaluations": [0.0, 0.0, 0.0]},
    "weights": {"weights": "0000000000000000", "evaluations": [0.0, 0.0, 0.0]},
    "evaluations": {"evaluations": [5.4815069, 5.5754094, 5.7635017]},
}
"""the stage a record differs at from RECORD -> what is changed in it (later stages too, as a real run would)"""
RECORD = {"demos": {"observations": "c90a57d397331f17", "actions": "78f4566f1aca3ca1"}, "weights": "571d843f3c3f541e",
          "evaluations": [5.481506918230348, 5.57540940335334, 5.763501727743505]}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/cpuinfo and glibc are Linux's")
def test_the_machine_record_names_the_cpu_vendor_and_the_c_library_on_linux():
    record = machine.machine()
    vendor = re.search(r"^vendor_id\s*: (.*)$", open("/proc/cpuinfo").read(), re.M)
    assert record["cpu_vendor"] == (vendor[1].strip() if vendor else platform.machine()) and record["cpu_vendor"]
    if platform.machine() == "x86_64":
        assert record["cpu_vendor"] in {"GenuineIntel", "AuthenticAMD", "HygonGenuine", "CentaurHauls", "Shanghai"}
    if platform.libc_ver()[0] == "glibc":
        assert re.fullmatch(r"glibc 2\.\d+", record["libc"]), record["libc"]
    assert record["os"].startswith("Linux") and record["python"] == platform.python_version()


def test_the_machine_record_keeps_the_keys_and_values_of_the_experts_record():
    import expert_ppo

    assert expert_ppo.machine().items() <= machine.machine().items()


def test_without_cpuinfo_the_record_falls_back_to_platform(monkeypatch):
    monkeypatch.setattr(machine, "cpuinfo_field", lambda name, cpuinfo=None: None)
    record = machine.machine()
    assert (record["cpu"], record["cpu_vendor"]) == (platform.processor(), platform.machine())


def test_cpuinfo_fields_and_the_one_line_description():
    text = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R) Processor\nprocessor\t: 1\n"
    assert machine.cpuinfo_field("vendor_id", text) == "GenuineIntel"
    assert machine.cpuinfo_field("model name", text) == "Intel(R) Xeon(R) Processor"
    assert machine.cpuinfo_field("flags", text) is None
    record = {"cpu": "AMD EPYC", "cpu_vendor": "AuthenticAMD", "cpu_capability": "AVX512", "libc": "glibc 2.36",
              "MKL_CBWR": "COMPATIBLE", "MKL_ENABLE_INSTRUCTIONS": None}
    assert machine.describe(record) == "AuthenticAMD AMD EPYC, AVX512, glibc 2.36, MKL_CBWR=COMPATIBLE"
    assert machine.describe({**record, "MKL_CBWR": None, "libc": None}) == "AuthenticAMD AMD EPYC, AVX512"
    assert machine.describe({**record, "fma_avx2": False}).startswith("AuthenticAMD AMD EPYC, AVX512, no FMA/AVX2, glibc")
    assert machine.describe({**record, "fma_avx2": True}) == machine.describe(record)
    assert machine.cpu_flags(text + "flags\t\t: fpu sse2 fma avx2\n") == {"fpu", "sse2", "fma", "avx2"}
    assert machine.cpu_flags(text) == set()


@pytest.mark.skipif(not machine.cpu_flags(), reason="no CPU flags here (/proc/cpuinfo is Linux's)")
def test_the_machine_record_says_whether_the_cpu_has_fma_and_avx2():
    assert machine.machine()["fma_avx2"] == ({"fma", "avx2"} <= machine.cpu_flags())


GLIBC = tuple(int(part) for part in platform.libc_ver()[1].split(".")[:2]) if platform.libc_ver()[0] == "glibc" else ()


@pytest.mark.skipif(GLIBC < (2, 33) or not machine.LIBM_FMA_FLAGS <= machine.cpu_flags(),
                    reason="glibc 2.33 or later (its hwcaps names), on a CPU with FMA and AVX2, is what is hidden here")
def test_the_libm_probe_sees_glibc_choose_other_code_without_fma_and_the_pins_then_skip():
    """GLIBC_TUNABLES hides FMA from glibc alone (torch and MKL read the CPU themselves): libm's digits change, and
    the pinned tests know they no longer hold."""
    code = "import conftest as t; from benchmark import fingerprint as f; print(f.libm_probe(), t.LIBM_AS_PINNED)"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(REPO_ROOT / "tests")])}
    runs = [subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True,
                           env={**env, "GLIBC_TUNABLES": tunables}) for tunables in ("", "glibc.cpu.hwcaps=-FMA")]
    assert [run.returncode for run in runs] == [0, 0], runs[0].stderr + runs[1].stderr
    (native, pinned_here), (without_fma, pinned_there) = (run.stdout.split() for run in runs)
    assert native == fingerprint.libm_probe() and len(native) == 16 and native != without_fma
    assert (pinned_here, pinned_there) == ("True", "False")
    assert fingerprint.libm_probe(count=200) != native


def state_dict(seed=0) -> dict:
    generator = torch.Generator().manual_seed(seed)
    return {name: torch.randn(shape, generator=generator) for name, shape in
            [("net.0.weight", (4, 3)), ("net.0.bias", (4,)), ("net.2.weight", (2, 4)), ("net.2.bias", (2,))]}


def test_the_weights_fingerprint_ignores_the_dict_order_but_not_one_changed_number():
    weights = state_dict()
    reversed_order = dict(reversed(list(weights.items())))
    assert list(reversed_order) != list(weights)
    assert fingerprint.weights_fingerprint(reversed_order) == fingerprint.weights_fingerprint(weights)
    sha = hashlib.sha256()  # the definition of issue 32: one sha256 over the tensors' bytes in sorted key order
    for key in sorted(weights):
        sha.update(weights[key].numpy().tobytes())
    assert fingerprint.weights_fingerprint(weights) == sha.hexdigest()[:16]
    changed = {key: value.clone() for key, value in weights.items()}
    changed["net.2.bias"][1] = torch.nextafter(changed["net.2.bias"][1], torch.tensor(np.inf))  # one ulp
    assert fingerprint.weights_fingerprint(changed) != fingerprint.weights_fingerprint(weights)
    assert fingerprint.weights_fingerprint(state_dict(1)) != fingerprint.weights_fingerprint(weights)


def test_the_demo_fingerprints_cover_every_array_but_meta(tmp_path):
    observations, starts = np.arange(12.0).reshape(4, 3), np.array([True, False, False, True])
    np.savez(tmp_path / "d.npz", observations=observations, episode_starts=starts, meta=np.array('{"env": "x"}'))
    assert fingerprint.demo_fingerprints(tmp_path / "d.npz") == {
        "episode_starts": hashlib.sha256(starts.tobytes()).hexdigest()[:16],
        "observations": hashlib.sha256(observations.tobytes()).hexdigest()[:16]}


@pytest.mark.parametrize("stage", list(CASES))
def test_compare_names_the_first_stage_that_differs(stage):
    other = {**RECORD, **CASES[stage]}
    expected = None if stage == "nowhere" else stage
    assert fingerprint.compare(RECORD, other) == expected and fingerprint.compare(other, RECORD) == expected
    assert (stage in fingerprint.explain(RECORD, other)) == (stage != "nowhere")


def test_compare_skips_a_stage_one_record_lacks_and_explains_the_difference():
    partial = {key: value for key, value in RECORD.items() if key != "evaluations"}
    assert fingerprint.compare(partial, {**RECORD, **CASES["evaluations"]}) is None
    demos_differ = fingerprint.explain(RECORD, {**RECORD, **CASES["demos"]})
    assert demos_differ == "first stage that differs: demos (actions, observations); evaluations 1 to 1 relative; no probes in both records"
    intel_first = {**RECORD, "evaluations": [5.481507009074632, *RECORD["evaluations"][1:]]}
    assert "evaluations (the demos and weights agree; 0 to 1.7e-08 relative)" in fingerprint.explain(RECORD, intel_first)
    weights_differ = fingerprint.explain_run(RECORD, {**RECORD, "weights": "1", "evaluations": [5.5, 5.575409403353340, 5.7]})
    assert weights_differ.startswith("first stage that differs: weights (") and weights_differ.endswith("; evaluations 0 to 0.011 relative")
    assert fingerprint.relative_range([1.0, 2.0], [1.0, 2.0]) is None and fingerprint.relative_range([1.0], [1.0, 2.0]) is None


def test_the_fingerprinted_case_is_the_pinned_bc_oh_case():
    script, flags, _, _ = PINNED["bc_oh"]
    assert (fingerprint.METHOD, fingerprint.BUDGET, flags) == (script, list(map(str, BUDGET)), [])
    assert fingerprint.FIXED_MODE == FIXED_MODE
    separate, together = fingerprint.case_commands("out", True), fingerprint.case_commands("out", False)
    assert [command[1:] for command in separate[1:]] == [command[1:] for command in together] and len(together) == 1
    assert separate[0][1].endswith("expert_ppo.py") and "--make-demos" in separate[0]
    assert together[0][1].endswith("bc_oh.py") and "--save-model" in together[0]


def test_a_record_file_is_named_after_the_vendor_and_the_cpu_model(tmp_path):
    amd = {"machine": {"cpu_vendor": "AuthenticAMD", "cpu": "AMD EPYC 9R14 96-Core Processor", "MKL_CBWR": "COMPATIBLE"}}
    intel = {"machine": {"cpu_vendor": "GenuineIntel", "cpu": "Intel(R) Xeon(R) Processor"}}
    assert fingerprint.record_path(tmp_path, amd) == tmp_path / "AuthenticAMD_AMD_EPYC_9R14_96-Core_Processor.json"
    assert fingerprint.record_path(tmp_path, intel).name == "GenuineIntel_Intel_R_Xeon_R_Processor_default.json"
    fixed = {"machine": {**intel["machine"], "MKL_CBWR": "COMPATIBLE"}}
    assert fingerprint.record_path(tmp_path, fixed).name == "GenuineIntel_Intel_R_Xeon_R_Processor.json"


def test_compare_of_two_stored_records_runs_nothing(tmp_path, capsys):
    for name, record in [("a.json", RECORD), ("b.json", {**RECORD, **CASES["weights"]})]:
        (tmp_path / name).write_text(json.dumps(record))
    assert fingerprint.main(["--compare", str(tmp_path / "a.json"), str(tmp_path / "b.json")]) == 0
    assert capsys.readouterr().out.startswith("first stage that differs: weights")


@pytest.mark.parametrize("content", ["{}", "[1]"])
def test_compare_refuses_a_file_that_is_not_a_record(tmp_path, content):
    """An empty JSON object compared as "the same at every stage compared ()", and a list raised AttributeError."""
    (tmp_path / "a.json").write_text(json.dumps(RECORD))
    (tmp_path / "b.json").write_text(content)
    with pytest.raises(fingerprint.UsageError, match=r"b.json is not a fingerprint record \(none of demos, weights, evaluations\)"):
        fingerprint.main(["--compare", str(tmp_path / "a.json"), str(tmp_path / "b.json")])


@pytest.mark.parametrize("part, value", [
    ("demos", 5), ("weights", ["571d843f3c3f541e"]), ("evaluations", "5.48"), ("evaluations", [5.48, "x"]),
    ("probes", ["libm"]),
])
def test_compare_refuses_a_record_whose_parts_are_not_as_written(tmp_path, part, value):
    """A demos stage that is a number, or evaluations that are not numbers, ended in a TypeError traceback."""
    (tmp_path / "a.json").write_text(json.dumps(RECORD))
    (tmp_path / "b.json").write_text(json.dumps({**RECORD, part: value}))
    result = run_in_process("benchmark/fingerprint.py", "--compare", tmp_path / "a.json", tmp_path / "b.json")
    message = f"{tmp_path / 'b.json'} is not a fingerprint record ({part} not as this module writes them): pass one this module wrote"
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")


@pytest.mark.parametrize("content, reason", [
    (None, "No such file or directory"),
    ("{cut", "not JSON: Expecting property name enclosed in double quotes: line 1 column 2 (char 1)"),
])
def test_a_record_that_cannot_be_read_is_one_line_with_its_fix(tmp_path, content, reason):
    """It named the problem but not what to pass instead."""
    if content is not None:
        (tmp_path / "b.json").write_text(content)
    result = run_in_process("benchmark/fingerprint.py", "--compare", tmp_path / "b.json")
    message = f"cannot read the record {tmp_path / 'b.json'} ({reason}): pass one this module wrote"
    assert (result.returncode, result.stderr) == (2, f"error: {message}\n")


def test_an_out_folder_that_cannot_be_written_is_refused_before_the_run(tmp_path, monkeypatch):
    """It ran the case (a minute) and then failed to write the record."""
    (tmp_path / "a.json").write_text(json.dumps(RECORD))
    (tmp_path / "file").write_text("")
    monkeypatch.setattr(fingerprint, "measure", lambda mode: pytest.fail("measured before --out was checked"))
    with pytest.raises(fingerprint.UsageError) as refusal:
        fingerprint.main(["--compare", str(tmp_path / "a.json"), "--out", str(tmp_path / "file" / "records")])
    message = f"--out {tmp_path / 'file' / 'records'} cannot be written: {tmp_path / 'file'} is not a folder: pass another --out"
    assert str(refusal.value) == message


def test_the_stored_amd_epyc_record_is_the_pins_bit_for_bit():
    """The record made on an AMD EPYC (Zen 4) with fused Adam, the CPU and the code the pins were recorded with
    (issue 56): its run prints the pinned epoch lines and evaluations exactly."""
    record = json.loads((REPO_ROOT / "results" / "fingerprints" / "AuthenticAMD_AMD_EPYC.json").read_text())
    _, _, lines, returns = PINNED["bc_oh"]
    assert record["machine"]["MKL_CBWR"] == "COMPATIBLE" and record["machine"]["cpu_vendor"] == "AuthenticAMD"
    assert record["epoch_lines"] == lines
    assert record["evaluations"] == returns
    arrays = {"observations", "actions", "episode_starts", "rewards", "terminations", "truncations"}
    assert set(record["demos"]) == {*arrays, "final_observations"} and len(record["weights"]) == 16
    assert set(record["probes"]) == set(fingerprint.PROBES)


def test_the_records_before_fused_adam_part_the_two_cpus_in_training_alone_within_the_pins_tolerance():
    """The Intel Xeon's and the AMD EPYC's records of 2026-12-04, made by the code before fused Adam (8ce2c69): the
    demos and every probe before training agree, the weights do not, and the evaluations part by less than the
    pins' tolerance (the measurement PIN_TOLERANCE was set from)."""
    folder = REPO_ROOT / "results" / "fingerprints" / "8ce2c69"
    intel, amd = (json.loads((folder / name).read_text()) for name in (
        "GenuineIntel_Intel_R_Xeon_R_Processor.json", "AuthenticAMD_AMD_EPYC.json"))
    assert intel["machine"]["cpu_vendor"] == "GenuineIntel" and intel["machine"]["MKL_CBWR"] == "COMPATIBLE"
    assert amd["machine"]["cpu_vendor"] == "AuthenticAMD" and amd["machine"]["MKL_CBWR"] == "COMPATIBLE"
    assert intel["epoch_lines"] == amd["epoch_lines"]
    assert intel["evaluations"] != amd["evaluations"]
    assert intel["evaluations"] == pytest.approx(amd["evaluations"], rel=PIN_TOLERANCE / 20)
    assert set(intel["probes"]) == set(fingerprint.PROBES)
    assert fingerprint.compare(intel, amd) == "weights"
    assert fingerprint.probe_differences(intel, amd).startswith(
        "probes the same: libm, mujoco, expert_forward, policy_forward, policy_evaluation; different: training")


PROBED = {"mujoco": "2dd92469f3838844", "expert_forward": "8e85f2f60e550fa6", "policy_forward": "53ec3bcfb7c8469e",
          "policy_evaluation": [554.1877473647398, 535.4060427424504],
          "training": {"weights": "571d843f3c3f541e", "evaluations": [5.5, 5.6, 5.8]}}


def test_probe_differences_name_each_probe_apart_from_the_run_s_first_stage():
    torch_differs = {**PROBED, "policy_forward": "0000000000000000", "training": {**PROBED["training"], "weights": "1"}}
    line = fingerprint.explain({**RECORD, "probes": PROBED}, {**RECORD, **CASES["demos"], "probes": torch_differs})
    assert line.startswith("first stage that differs: demos")
    assert line.endswith("probes the same: mujoco, expert_forward, policy_evaluation; different: policy_forward, training")
    one_probe = {"probes": {"mujoco": PROBED["mujoco"]}}
    assert fingerprint.probe_differences({"probes": PROBED}, one_probe) == "probes the same: mujoco; different: none"
    moved = {**PROBED, "policy_evaluation": [554.1877473647398, 535.4060427424504 * (1 + 1e-6)],
             "training": {**PROBED["training"], "evaluations": [5.5, 5.6, 5.9]}}
    assert fingerprint.probe_differences({"probes": PROBED}, {"probes": moved}).endswith(
        "different: policy_evaluation (returns 0 to 1e-06 relative), training (returns 0 to 0.017 relative)")
    assert fingerprint.probe_differences(RECORD, one_probe) == "no probes in both records"


def test_the_probes_inputs_are_committed_so_every_checkout_holds_them_bit_for_bit():
    for path in (fingerprint.SHIPPED_DEMOS, fingerprint.SHIPPED_EXPERT, fingerprint.PROBE_POLICY):
        tracked = subprocess.run(["git", "ls-files", "--error-unmatch", str(path)], cwd=REPO_ROOT, capture_output=True)
        assert tracked.returncode == 0 or not (REPO_ROOT / ".git").exists(), f"{path} is not committed"
        assert path.is_file()
    training = fingerprint.training_command("out")
    assert training[training.index("--demos") + 1] == str(fingerprint.SHIPPED_DEMOS)
    assert [flag for flag in training[2:] if flag not in ("--demos", str(fingerprint.SHIPPED_DEMOS))] == [
        *fingerprint.BUDGET, "--save-model", "--output-dir", "out"]


def test_the_mujoco_probe_repeats_exactly_and_sees_one_ulp_of_its_actions():
    digest = fingerprint.mujoco_probe(steps=200)
    assert digest == fingerprint.mujoco_probe(steps=200) and len(digest) == 16
    assert fingerprint.mujoco_probe(steps=200, amplitude=float(np.nextafter(0.5, 1.0))) != digest


def test_the_policy_probes_repeat_exactly_and_depend_on_the_rows():
    first, again = fingerprint.policy_probes(rows=30, episodes=1, seed=0), fingerprint.policy_probes(rows=30, episodes=1, seed=0)
    assert first == again and set(first) == {"expert_forward", "policy_forward", "policy_evaluation"}
    assert len(first["policy_evaluation"]) == 1 and np.isfinite(first["policy_evaluation"][0])
    fewer = fingerprint.policy_probes(rows=29, episodes=1, seed=0)
    assert fewer["expert_forward"] != first["expert_forward"] and fewer["policy_forward"] != first["policy_forward"]


def test_the_training_step_probes_repeat_exactly_and_see_the_rows_and_the_steps():
    first = fingerprint.training_step_probes(rows=32, steps=2)
    assert first == fingerprint.training_step_probes(rows=32, steps=2)
    assert set(first) == {"initialization", "gradients", "adam_step"} and set(first["adam_step"]) == {"after 1", "after 2"}
    assert set(first["gradients"]) == {"loss", *(f"net.{i}.{p}" for i in (0, 2, 4) for p in ("weight", "bias"))}
    fewer = fingerprint.training_step_probes(rows=31, steps=3)
    assert all(fewer["gradients"][key] != value for key, value in first["gradients"].items())
    assert fewer["initialization"]["normalizer"] != first["initialization"]["normalizer"]
    assert fewer["initialization"]["minibatches"] == first["initialization"]["minibatches"]
    assert fewer["adam_step"]["after 1"] != first["adam_step"]["after 1"] and "after 3" in fewer["adam_step"]


def test_the_matmul_probe_covers_each_linear_layer_s_three_products():
    digests = fingerprint.matmul_probe()
    first, rest = {"forward", "grad_input", "grad_weight"}, {"256-256", "256-3"}
    assert set(digests) == first | {f"{kind} {layer}" for kind in first for layer in rest}
    assert len(set(digests.values())) == 9 and digests == fingerprint.matmul_probe()


def test_a_probe_of_named_parts_is_compared_on_the_parts_both_records_hold():
    older = {"probes": {"matmul": {"forward": "1", "grad_input": "2"}}}
    newer = {"probes": {"matmul": {"forward": "1", "grad_input": "2", "forward 256-3": "3"}}}
    assert fingerprint.probe_differences(older, newer) == "probes the same: matmul; different: none"
    moved = {"probes": {"matmul": {**newer["probes"]["matmul"], "grad_input": "9"}}}
    assert fingerprint.probe_differences(older, moved) == "probes the same: none; different: matmul (grad_input)"
    renamed = {"probes": {"matmul": {"forward 22-256": "1"}}}
    assert fingerprint.probe_differences(older, renamed) == "probes the same: none; different: matmul"


def test_a_probe_of_named_parts_names_the_parts_that_differ():
    a = {"probes": {"gradients": {"net.0.weight": "1", "net.4.bias": "2", "loss": "3"}, "libm": "x"}}
    b = {"probes": {"gradients": {"net.0.weight": "9", "net.4.bias": "2", "loss": "8"}, "libm": "x"}}
    assert fingerprint.probe_differences(a, b) == "probes the same: libm; different: gradients (net.0.weight, loss)"


def test_the_probe_s_evaluation_is_the_one_its_run_recorded():
    """PROBE_EVALUATION is the final evaluation of the probe policy's run: its epoch and episodes, and its mean is what
    recorded_evaluation compares with."""
    run = json.loads((fingerprint.PROBE_POLICY.parent / "result_seeds1.json").read_text())
    epoch, mean = run["scores"]["1"]["evaluations"][-1]
    assert fingerprint.PROBE_EVALUATION == {"episodes": run["args"]["eval_episodes"], "seed": 10_000 * 1 + epoch}
    line = fingerprint.recorded_evaluation({"probes": {"policy_evaluation": [mean - 1.0, mean + 1.0]}})
    assert line.startswith(f"{mean!r} here, {mean!r} recorded by its run (Intel") and line.endswith(": 0 relative")
