"""What tells machines apart in a result record: the CPU, MKL's numeric mode, the C library, the OS and the versions.

    from benchmark.machine import machine, describe
    record = machine()   # {"cpu": "AMD EPYC", "cpu_vendor": "AuthenticAMD", "cpu_capability": "AVX512", ...}
    describe(record)     # 'AuthenticAMD AMD EPYC, AVX512, glibc 2.36, MKL_CBWR=COMPATIBLE'

The keys of expert_ppo.machine() (cpu, cpu_capability, MKL_CBWR, MKL_ENABLE_INSTRUCTIONS, torch, numpy, mujoco,
gymnasium) keep their meaning; cpu_vendor, cpu_family, cpu_model, fma_avx2, GLIBC_TUNABLES, libc, os and python are
added. The same command with the same record gives the same digits; which differences between records change which
digits is measured by benchmark/fingerprint.py.
"""
import os
import platform
import re
from pathlib import Path

MKL_VARIABLES = ("MKL_CBWR", "MKL_ENABLE_INSTRUCTIONS")
"""the environment variables that choose MKL's kernels (recorded as set, None when unset)"""


def cpuinfo_field(name: str, cpuinfo: str = None):
    """The first `name : value` of /proc/cpuinfo (or of the text given); None when absent (not Linux, no such field)."""
    if cpuinfo is None:
        cpuinfo = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").is_file() else ""
    found = re.search(rf"^{re.escape(name)}\s*: (.*)$", cpuinfo, re.M)
    return found[1].strip() if found else None


LIBM_FMA_FLAGS = {"fma", "avx2"}
"""on a CPU with both, glibc's libm runs its FMA code for exp, log, pow, sin, cos and most others; without them its
SSE2 code, whose last bits differ: hiding them (GLIBC_TUNABLES=glibc.cpu.hwcaps=-FMA) changes MuJoCo's trajectories
and the pinned epoch lines (results/fingerprints/README.md)"""


def cpu_flags(cpuinfo: str = None) -> set:
    """The CPU's feature flags in /proc/cpuinfo (or in the text given); empty when there are none (not Linux)."""
    return set((cpuinfo_field("flags", cpuinfo) or "").split())


def libc() -> str:
    """The C library and its version, e.g. 'glibc 2.36'; None when Python cannot tell (e.g. musl, macOS)."""
    name, version = platform.libc_ver()
    if name and version:
        return f"{name} {version}"
    try:
        return os.confstr("CS_GNU_LIBC_VERSION") or None
    except (AttributeError, ValueError, OSError):  # no confstr, or no such name on this system
        return None


def machine() -> dict:
    """Where a result was made: the same command on the same kind of CPU, with these versions, gives the same digits."""
    import gymnasium
    import mujoco
    import numpy
    import torch

    return {
        "cpu": cpuinfo_field("model name") or platform.processor(),
        "cpu_vendor": cpuinfo_field("vendor_id") or platform.machine(),
        "cpu_family": cpuinfo_field("cpu family"),  # tells CPUs of one model name apart: AMD EPYC 25 is Zen 4, 26 Zen 5
        "cpu_model": cpuinfo_field("model"),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        **{name: os.environ.get(name) for name in MKL_VARIABLES},
        "fma_avx2": LIBM_FMA_FLAGS <= flags if (flags := cpu_flags()) else None,  # None: the flags are unknown
        "GLIBC_TUNABLES": os.environ.get("GLIBC_TUNABLES"),  # can hide CPU features from glibc (None when unset)
        "libc": libc(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "torch": str(torch.__version__),
        "numpy": numpy.__version__,
        "mujoco": mujoco.__version__,
        "gymnasium": gymnasium.__version__,
    }


def describe(record: dict) -> str:
    """One line: 'AuthenticAMD AMD EPYC, AVX512, glibc 2.36, MKL_CBWR=COMPATIBLE' (the MKL variables only when set;
    'no FMA/AVX2' after the capability for a CPU that lacks them, whose libm takes other code)."""
    cpu = " ".join(str(record[key]) for key in ("cpu_vendor", "cpu") if record.get(key))
    mkl = [f"{name}={record[name]}" for name in MKL_VARIABLES if record.get(name)]
    fma = "no FMA/AVX2" if record.get("fma_avx2") is False else None
    return ", ".join(part for part in (cpu, record.get("cpu_capability"), fma, record.get("libc"), *mkl) if part)

