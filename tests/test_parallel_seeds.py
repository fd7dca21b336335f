"""--seeds 1 2 --workers 2 trains the seeds in two processes at once (issue 22): each seed prints and scores
exactly what it does when the seeds run one after another, and the combined result holds both, in order."""

import concurrent.futures

import numpy as np

from conftest import LIBM_AS_PINNED, PINNED, assert_usage_error, fake_demos, run_in_process, skip_evaluation, tiny_args, tiny_run
import pytest


@pytest.mark.parametrize("script", ["bc_oh", "average_ensemble", "dagger"])
def test_two_workers_train_each_seed_as_one_worker_does(tmp_path, script):
    """bc_oh stands for the scripts that share its training loop; average_ensemble and dagger have their own fits. The
    runs are the pins' (conftest.tiny_run: their budget and demos, in the fixed mode), with two seeds."""
    flags = PINNED[script][1]  # dagger's small rounds; none for the others
    parallel = tiny_run(tmp_path / "two", script, [*flags, "--workers", 2], seeds=(1, 2))
    sequential = tiny_run(tmp_path / "one", script, [*flags, "--workers", 1], seeds=(1, 2))
    lines = sequential.lines
    assert all(len(lines[seed]) == len(PINNED[script][2]) for seed in (1, 2)) and lines[1] != lines[2]
    assert lines[1] == PINNED[script][2] or not LIBM_AS_PINNED  # seed 1 of two prints what seed 1 alone prints
    assert parallel.lines == lines, f"two workers printed:\n{parallel.stdout}\none worker printed:\n{sequential.stdout}"
    assert parallel.evaluations == sequential.evaluations
    combined = parallel.result
    assert list(combined["scores"]) == ["1", "2"] and combined["args"]["seeds"] == [1, 2] and combined["args"]["workers"] == 2
    assert [combined["scores"][s]["evaluations"] for s in "12"] == [sequential.evaluations[1], sequential.evaluations[2]]
    assert combined["mean"] == sequential.result["mean"]


def test_workers_must_be_positive():
    assert_usage_error(run_in_process("bc_oh.py", "--workers", 0), "--workers must be positive and finite, got 0")


def test_a_pool_worker_writes_each_printed_line_at_once(monkeypatch):
    """Unbuffered (PYTHONUNBUFFERED, as this machine and the grid runner set it), print writes a line and its newline
    in two writes, and a seed printing at the same moment can land between them (test_two_workers_train_each_seed_as_one_worker_does failed so, twice: one
    seed's line glued to another's. start_worker, the pool's initializer, makes each line one write. (The workers ignore
    Ctrl-C from their start: test_run_loop's interrupt test checks it.)"""
    import io

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

    bc_oh.start_worker()  # what the pool runs first in each worker
    print("seed 2 | training", flush=True)
    assert raw.writes[2:] == [b"seed 2 | training\n"]


@pytest.mark.parametrize("flags, cores, expected", [({}, 2, 3), ({}, 16, 3), ({"workers": 2}, 16, 2), ({"workers": 8}, 2, 3)])
def test_by_default_each_seed_has_its_own_worker(tmp_path, monkeypatch, flags, cores, expected):
    """Three seeds on two cores run as one wave of three processes by default, not two waves of two (issue 56:
    docs/speed.md measures it); --workers sets the count, at most one per seed."""
    import bc_oh

    pools = []

    class ProcessPoolExecutor:
        def __init__(self, workers, context, initializer):
            pools.append(workers)

        def submit(self, function, *job):
            future = concurrent.futures.Future()
            future.set_result(function(*job))
            return future

    monkeypatch.setattr(bc_oh, "ProcessPoolExecutor", ProcessPoolExecutor)
    monkeypatch.setattr(bc_oh.os, "cpu_count", lambda: cores)
    skip_evaluation(monkeypatch, bc_oh)
    np.savez(tmp_path / "demos.npz", **fake_demos(256))
    settings = {"seeds": [1, 2, 3], "workers": None, "demos": str(tmp_path / "demos.npz"), "output_dir": str(tmp_path / "out")}
    bc_oh.run(tiny_args(bc_oh, **{**settings, **flags}))
    assert pools == [expected]
