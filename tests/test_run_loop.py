"""The seed loop every method file shares (bc_oh.run, copied into the others): a clean interrupt that stops every
process of the job, one ETA for the whole job, the line that says which seeds train and which wait, distinct seeds,
the summary's share of the expert, and the demo checks' messages."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

import bc_oh
from conftest import REPO_ROOT, assert_usage_error, fake_demos, link_experts, run_in_process, skip_evaluation, tiny_args


def live_processes(group: int) -> list:
    """The processes of a process group that still run (zombies, already ended, left out)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended while we looked
            continue
        if int(fields[2]) == group and fields[0] != "Z":
            alive.append(int(stat.parent.name))
    return alive


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table from /proc (Linux)")
@pytest.mark.parametrize("how", ["ctrl-c", "kill"])
def test_an_interrupted_job_stops_all_its_processes_and_says_what_it_kept(tmp_path, how):
    """Ctrl-C (SIGINT to the terminal's whole process group) or `kill PID` (SIGTERM to the main process only): one line
    on stderr, no traceback, and no process of the job left (the pool's workers and multiprocessing's helpers)."""
    link_experts(tmp_path)
    command = [sys.executable, str(REPO_ROOT / "bc_oh.py"), "--seeds", "1", "2", "3", "--workers", "2", "--epochs", "20000",
               "--num-demo-samples", "300", "--eval-every", "1000", "--output-dir", str(tmp_path / "out")]
    # as a terminal starts a job: Ctrl-C not ignored (a shell's background job, e.g. CI's, inherits SIGINT ignored)
    job = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                           env=dict(os.environ, PYTHONWARNINGS="ignore", PYTHONUNBUFFERED="1"),
                           preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    started = []
    for line in job.stdout:  # wait until both workers train
        started += [line] if line.startswith("seed ") and "| epoch " in line else []
        if "wait for a worker" in line:
            assert line.strip() == "seeds 1, 2 training; 3 wait for a worker"
        if len({text.split(" |")[0] for text in started}) == 2:
            break
    if how == "ctrl-c":
        os.killpg(job.pid, signal.SIGINT)
    else:
        job.send_signal(signal.SIGTERM)
    _, stderr = job.communicate(timeout=60)
    deadline = time.time() + 20
    while live_processes(job.pid) and time.time() < deadline:
        time.sleep(0.2)
    assert not live_processes(job.pid), "every process of the job has ended"
    assert job.returncode != 0 and "Traceback" not in stderr, stderr
    assert stderr.strip().splitlines() == ["interrupted: seeds none finished and kept, 1, 2, 3 lost: the same command trains only those"]


def etas(monkeypatch, capsys, seeds, workers) -> dict:
    """bc_oh.fit's printed job ETA (minutes) per seed at epoch 1 of 2, each seed halfway after 10 s (so 20 s a seed)."""
    clock = [100.0]
    monkeypatch.setattr(bc_oh.time, "time", lambda: clock[-1])
    def train_step(idx):  # one step an epoch, 10 s each
        clock.append(clock[-1] + 10.0)
        return torch.tensor(0.0)
    optimizer = torch.optim.Adam([torch.zeros(1, requires_grad=True)], lr=1e-3)
    args, found = bc_oh.Args(seeds=seeds, workers=workers, epochs=2, batch_size=8), {}
    for seed in seeds:
        bc_oh.fit(args, None, optimizer, train_step, 8, seed, torch.device("cpu"), evaluate_policy=False)
        first = capsys.readouterr().out.splitlines()[0]
        assert first.startswith(f"seed {seed} | epoch 1/2 | ")
        found[seed] = first.rsplit("| job ETA ", 1)[1]
    return found


def test_the_eta_is_the_whole_jobs_from_every_seed(monkeypatch, capsys):
    """3 seeds on 2 workers: seeds 1 and 2 see their own 10 s left and seed 3's 20 s after them; seed 3 sees only its
    own 10 s. One at a time, seed 1 has two seeds after it."""
    assert etas(monkeypatch, capsys, [1, 2, 3], 2) == {1: "0.5 min", 2: "0.5 min", 3: "0.2 min"}
    assert etas(monkeypatch, capsys, [1, 2, 3], 1)[1] == "0.8 min"


def test_a_repeated_seed_is_refused():
    assert_usage_error(run_in_process("bc_oh.py", "--seeds", 1, 1), "--seeds needs distinct seeds, got 1 1")


def summary(folder, monkeypatch, capsys, score, meta, **overrides) -> str:
    """The last line bc_oh.run prints, on fake demos that carry `meta`, every evaluation returning `score`."""
    path = folder / f"demos{len(list(folder.glob('demos*.npz')))}.npz"
    np.savez(path, **fake_demos(256), **({"meta": np.array(json.dumps(meta))} if meta else {}))
    skip_evaluation(monkeypatch, bc_oh, score)
    bc_oh.run(tiny_args(bc_oh, demos=str(path), output_dir=str(path.with_suffix("")), **overrides))
    return capsys.readouterr().out.splitlines()[-1]


def test_the_share_of_the_expert_reads_as_a_share_at_the_runs_own_setting(tmp_path, monkeypatch, capsys):
    meta = {"env_id": "Hopper-v4", "frame_skip": 4, "expert_return": 3000.0, "expert_frame_skip": 4}
    line = summary(tmp_path, monkeypatch, capsys, -1.0, meta)
    assert line == "Hopper-v4 bc_oh: -1.0 ± 0.0 over 1 seed, 0% of the expert's 3000"  # -0.0003: 0%, not -0%
    line = summary(tmp_path, monkeypatch, capsys, 1500.0, meta, seeds=[1, 2])
    assert line == "Hopper-v4 bc_oh: 1500.0 ± 0.0 over 2 seeds, 50% of the expert's 3000"
    fast = {**meta, "frame_skip": 1}  # demos made at frame skip 1 by the expert of frame skip 4: said so
    line = summary(tmp_path, monkeypatch, capsys, 1500.0, fast, frame_skip=1)
    assert line.endswith("50% of the expert's 3000 at its own frame skip 4")
    assert summary(tmp_path, monkeypatch, capsys, 1500.0, {}) == "Hopper-v4 bc_oh: 1500.0 ± 0.0 over 1 seed"  # no expert


def write_demos(path, observations, actions, starts):
    np.savez(path, observations=observations, actions=actions, episode_starts=starts)
    return path


@pytest.mark.parametrize("case, message", [
    ("rows", "observations, actions and episode_starts have 100, 99 and 100 rows: save one row per step"),
    ("transposed", "(11, 100) and actions (3, 100), but Hopper-v4 needs (N, 11) and (N, 3): save them as (steps, entries), not transposed"),
    ("other env", "(100, 17) and actions (100, 6), but Hopper-v4 needs (N, 11) and (N, 3): use demos of this env"),
])
def test_a_demo_file_that_does_not_fit_is_told_what_is_wrong(tmp_path, case, message):
    rng, starts = np.random.default_rng(0), np.arange(100) % 50 == 0
    obs, actions = rng.normal(size=(100, 11)), rng.uniform(-1, 1, (100, 3))
    arrays = {"rows": (obs, actions[:99], starts), "transposed": (obs.T, actions.T, starts),
              "other env": (rng.normal(size=(100, 17)), rng.uniform(-1, 1, (100, 6)), starts)}[case]
    path = write_demos(tmp_path / "demos.npz", *arrays)
    assert_usage_error(run_in_process("bc_oh.py", "--demos", path, "--epochs", 1), message)


def test_missing_demos_name_the_command_that_makes_them(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_usage_error(run_in_process("bc_oh.py", "--frame-skip", 1, "--num-demo-samples", 500),
                       f"demo file demos/Hopper-v4_fs1_500.npz not found in {tmp_path}: run python expert_ppo.py --env Hopper-v4 --make-demos "
                       "--frame-skip 1 --num-demo-samples 500")
    assert_usage_error(run_in_process("bc_oh.py", "--env", "Walker2d-v5"),
                       f"demos/Walker2d-v5_10000.npz not found in {tmp_path}: run python expert_ppo.py --env Walker2d-v5 --make-demos")
