"""--seeds 1 2 --workers 2 trains the seeds in two processes at once (issue 22): each seed prints and scores
exactly what it does when the seeds run one after another, and the combined result holds both, in order."""
import json
import re
from types import SimpleNamespace

import numpy as np

from conftest import assert_usage_error, demos_made_in, fake_demos, link_experts, run_in_process, run_script, skip_evaluation, tiny_args
import pytest
from test_pinned_output import BUDGET, FIXED_MODE, LIBM_AS_PINNED, PINNED

TWO_SEEDS = (*BUDGET[:BUDGET.index("--seeds")], *BUDGET[BUDGET.index("--seeds") + 2:], "--seeds", 1, 2)
"""test_pinned_output's tiny budget, with two seeds"""


@pytest.fixture
def fixed_mode_demos():
    """The demos of the pins, made as test_pinned_output makes them: by expert_ppo.py --make-demos in the fixed mode
    (the session's demo files are made in the default mode, whose last digits differ by CPU)."""
    return demos_made_in(FIXED_MODE, *BUDGET[:2], *BUDGET[-2:])


def tiny_run(folder, script: str, workers: int, demos) -> tuple:
    """({seed: its printed epoch lines without timings}, {seed: its JSON evaluations}, the combined JSON, stdout) of a
    run."""
    folder.mkdir()
    link_experts(folder, demos=False)
    (folder / "demos").symlink_to(demos, target_is_directory=True)
    flags = PINNED[script][1]  # dagger's small rounds; none for the others
    result = run_script(f"{script}.py", *TWO_SEEDS, *flags, "--workers", workers, "--output-dir", folder / "out", cwd=folder, env=FIXED_MODE)
    assert result.returncode == 0, result.stderr
    lines = {seed: re.findall(rf"^seed {seed} \| (.*last eval \S+(?:, \w+ \S+)*) \| [\d.]+ ms/step", result.stdout, re.M) for seed in (1, 2)}
    evaluations = {seed: json.loads((folder / "out" / f"result_seeds{seed}.json").read_text())["scores"][str(seed)]["evaluations"]
                   for seed in (1, 2)}
    return lines, evaluations, json.loads((folder / "out" / "result_seeds1-2.json").read_text()), result.stdout


@pytest.mark.parametrize("script", ["bc_oh", "average_ensemble", "dagger"])
def test_two_workers_train_each_seed_as_one_worker_does(tmp_path, script, fixed_mode_demos):
    """bc_oh stands for the scripts that share its training loop; average_ensemble and dagger have their own fits."""
    parallel_lines, parallel_evaluations, combined, parallel_out = tiny_run(tmp_path / "two", script, 2, fixed_mode_demos)
    lines, evaluations, sequential, out = tiny_run(tmp_path / "one", script, 1, fixed_mode_demos)
    assert all(len(lines[seed]) == len(PINNED[script][2]) for seed in (1, 2)) and lines[1] != lines[2]
    assert lines[1] == PINNED[script][2] or not LIBM_AS_PINNED  # seed 1 of two prints what seed 1 alone prints
    assert parallel_lines == lines, f"two workers printed:\n{parallel_out}\none worker printed:\n{out}"
    assert parallel_evaluations == evaluations
    assert list(combined["scores"]) == ["1", "2"] and combined["args"]["seeds"] == [1, 2] and combined["args"]["workers"] == 2
    assert [combined["scores"][s]["evaluations"] for s in "12"] == [evaluations[1], evaluations[2]]
    assert combined["mean"] == sequential["mean"]


def test_workers_must_be_positive():
    assert_usage_error(run_in_process("bc_oh.py", "--workers", 0), "--workers must be positive and finite, got 0")


def test_a_pool_worker_writes_each_printed_line_at_once(monkeypatch):
    """Unbuffered (PYTHONUNBUFFERED, as this machine and the grid runner set it), print writes a line and its newline
    in two writes, and a seed printing at the same moment can land between them (test_two_workers_train_each_seed_as_one_worker_does failed so, twice: one
    seed's line glued to another's. start_worker, the pool's initializer, makes each line one write and leaves Ctrl-C
    to the main process."""
    import io
    import signal

    import bc_oh

    class Writes(io.RawIOBase):
        def __init__(self):
            self.writes = []

        def writable(self):
            return True

        def write(self, data):
            self.writes.append(bytes(data))
            return len(data)

    raw = Writes()
    monkeypatch.setattr("sys.stdout", io.TextIOWrapper(raw, write_through=True))  # what PYTHONUNBUFFERED gives
    print("seed 1 | epoch 1/3", flush=True)
    assert raw.writes == [b"seed 1 | epoch 1/3", b"\n"]

    previous = signal.getsignal(signal.SIGINT)
    try:
        bc_oh.start_worker()  # what the pool runs first in each worker
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN, "Ctrl-C is the main process's"
        print("seed 2 | training", flush=True)
        assert raw.writes[2:] == [b"seed 2 | training\n"]
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("flags, cores, expected", [({}, 2, 3), ({}, 16, 3), ({"workers": 2}, 16, 2), ({"workers": 8}, 2, 3)])
def test_by_default_each_seed_has_its_own_worker(tmp_path, monkeypatch, flags, cores, expected):
    """Three seeds on two cores run as one wave of three processes by default, not two waves of two (issue 56:
    docs/speed.md measures it); --workers sets the count, at most one per seed."""
    import bc_oh

    pools = []

    class Pool:
        def __init__(self, workers, initializer):
            pools.append(workers)

        def __enter__(self):
            return self

        def __exit__(self, *exception):
            return False

        def starmap(self, function, jobs, chunksize):
            return [function(*job) for job in jobs]

    context = SimpleNamespace(Pool=Pool)
    monkeypatch.setattr(bc_oh.multiprocessing, "get_context", lambda method: context)
    monkeypatch.setattr(bc_oh.os, "cpu_count", lambda: cores)
    skip_evaluation(monkeypatch, bc_oh)
    np.savez(tmp_path / "demos.npz", **fake_demos(256))
    settings = {"seeds": [1, 2, 3], "workers": None, "demos": str(tmp_path / "demos.npz"), "output_dir": str(tmp_path / "out")}
    bc_oh.run(tiny_args(bc_oh, **{**settings, **flags}))
    assert pools == [expected]
