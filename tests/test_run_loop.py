"""The seed loop every method file shares (bc_oh.run, copied into the others): a clean interrupt that stops every
process of the job, each seed's minutes left, distinct seeds, the summary's share of the expert, and the demo checks'
messages."""
import contextlib
import json
import multiprocessing
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
from conftest import METHOD_FILES, REPO_ROOT, assert_usage_error, fake_demos, link_experts, run_in_process, run_script, skip_evaluation, tiny_args


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


def ignores_ctrl_c(pid: int) -> bool:
    """Whether the process ignores SIGINT (its SigIgn mask in /proc)."""
    status = Path(f"/proc/{pid}/status").read_text().splitlines()
    ignored = next(line for line in status if line.startswith("SigIgn:"))
    return bool(int(ignored.split()[1], 16) & (1 << (signal.SIGINT - 1)))


def pool_workers(group: int) -> list:
    """The process pool's workers among a process group's live processes."""
    workers = []
    for pid in live_processes(group):
        with contextlib.suppress(OSError):  # ended while we looked
            if "spawn_main" in Path(f"/proc/{pid}/cmdline").read_text():
                workers.append(pid)
    return workers


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table from /proc (Linux)")
@pytest.mark.parametrize("how", ["ctrl-c", "kill", "worker killed", "ctrl-c while workers start", "ctrl-c twice"])
def test_an_interrupted_job_stops_all_its_processes_and_says_what_it_kept(tmp_path, how):
    """Ctrl-C (SIGINT to the terminal's whole process group) or `kill PID` (SIGTERM to the main process only): one line
    on stderr, no traceback, and no process of the job left (the pool's workers and multiprocessing's helpers). A worker
    killed from outside (the out-of-memory killer; here `kill -9`) hung multiprocessing.Pool forever: now the job stops
    its other workers and says so in one line, exit 1. A Ctrl-C while the workers import torch (before they could ignore
    it) printed their tracebacks; a second Ctrl-C during the clean exit printed one of concurrent.futures' exit hook."""
    link_experts(tmp_path)
    command = [sys.executable, str(REPO_ROOT / "bc_oh.py"), "--seeds", "1", "2", "3", "--workers", "2", "--epochs", "20000",
               "--num-demo-samples", "300", "--eval-every", "1000", "--output-dir", str(tmp_path / "out")]
    # as a terminal starts a job: Ctrl-C not ignored (a shell's background job, e.g. CI's, inherits SIGINT ignored)
    job = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                           env=dict(os.environ, PYTHONWARNINGS="ignore", PYTHONUNBUFFERED="1"),
                           preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    started = set()
    for line in job.stdout:  # wait until both workers train: each prints "seed S | training" when it starts a seed
        if how == "ctrl-c while workers start" and line.startswith("progress lines:"):
            break  # the pool starts next
        if line.startswith("seed ") and line.rstrip().endswith("| training"):
            started.add(line)
        if len(started) == 2:
            break
    if how == "ctrl-c while workers start":
        deadline = time.time() + 30
        while len(pool_workers(job.pid)) < 2 and time.time() < deadline:
            time.sleep(0.01)
        # Each worker ignores Ctrl-C from its first instruction (the old code ignored it only once torch was imported,
        # and its workers' tracebacks raced with the main process's stopping them).
        assert all(ignores_ctrl_c(pid) for pid in pool_workers(job.pid)), "a worker that takes Ctrl-C"
        while ignores_ctrl_c(job.pid) and time.time() < deadline:
            time.sleep(0.01)  # the main process ignores it while it starts the workers
        time.sleep(0.05)  # both workers are importing torch now (for a second or more)
    if how.startswith("ctrl-c"):
        os.killpg(job.pid, signal.SIGINT)
    if how == "ctrl-c twice":
        time.sleep(0.02)
        os.killpg(job.pid, signal.SIGINT)
    if how == "kill":
        job.send_signal(signal.SIGTERM)
    if how == "worker killed":
        workers = pool_workers(job.pid)
        assert len(workers) == 2
        os.kill(workers[0], signal.SIGKILL)
    try:
        _, stderr = job.communicate(timeout=60)
    finally:
        with contextlib.suppress(ProcessLookupError):  # the old code hung when a worker was killed: end it anyway
            os.killpg(job.pid, signal.SIGKILL)
    deadline = time.time() + 20
    while live_processes(job.pid) and time.time() < deadline:
        time.sleep(0.2)
    assert not live_processes(job.pid), "every process of the job has ended"
    expected = (130, "interrupted: no seed finished")
    if how == "worker killed":
        expected = (1, "a worker died (killed, out of memory or crashed): no seed finished")
    assert "Traceback" not in stderr, stderr
    assert (job.returncode, stderr.strip()) == expected


def test_the_progress_line_gives_the_seeds_own_minutes_left(monkeypatch, capsys):
    """4 epochs of one 12 s step each: after epoch 1, 3 epochs of 12 s are left (0.6 min); the time an evaluation
    takes counts in the epoch's time."""
    clock = [100.0]
    monkeypatch.setattr(bc_oh.time, "time", lambda: clock[-1])

    def train_step(idx):
        clock.append(clock[-1] + 12.0)
        return torch.tensor(0.25)

    skip_evaluation(monkeypatch, bc_oh, 3.0)
    optimizer = torch.optim.Adam([torch.zeros(1, requires_grad=True)], lr=1e-3)
    args = bc_oh.Args(seeds=[5], epochs=4, batch_size=8, eval_every=2, learning_rate=1e-3)
    evaluations, ms_per_step = bc_oh.fit(args, torch.nn.Linear(1, 1), optimizer, train_step, 8, 5, torch.device("cpu"))
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "seed 5 | epoch 1/4 | loss 0.25000 | last eval n/a | 12000.00 ms/step | 0.6 min left"
    assert lines[1] == "seed 5 | epoch 2/4 | loss 0.25000 | last eval 3.0 | 12000.00 ms/step | 0.4 min left"
    assert evaluations == [(2, 3.0), (4, 3.0)] and ms_per_step == 12000.0


def test_progress_lines_come_after_the_first_epoch_then_every_twentieth_of_the_run(monkeypatch, capsys):
    """A user sees the first line, with its loss and pace, after one epoch rather than after 5% of the run; then a line
    every epochs // 20 epochs, and one at each evaluation."""
    skip_evaluation(monkeypatch, bc_oh, 1.0)
    optimizer = torch.optim.Adam([torch.zeros(1, requires_grad=True)], lr=1e-3)
    args = bc_oh.Args(seeds=[1], epochs=60, batch_size=8, eval_every=25, learning_rate=1e-3)
    bc_oh.fit(args, torch.nn.Linear(1, 1), optimizer, lambda idx: torch.tensor(0.5), 8, 1, torch.device("cpu"))
    printed = [int(line.split(" | ")[1].split()[1].split("/")[0]) for line in capsys.readouterr().out.splitlines()]
    # epochs // 20 = 3; the evaluations come at epochs 25, 50 and 60.
    assert printed == sorted({1, 25, 50, *range(3, 61, 3)})


def test_the_learning_rate_decays_linearly_to_zero(monkeypatch):
    """Section 8.3: each step's rate is the initial one times the share of the steps still to come."""
    rates = []
    parameter = torch.zeros(1, requires_grad=True)
    optimizer = torch.optim.Adam([parameter], lr=1e-3)

    def train_step(idx):
        rates.append(optimizer.param_groups[0]["lr"])
        return torch.tensor(0.0)

    skip_evaluation(monkeypatch, bc_oh, 0.0)
    args = bc_oh.Args(epochs=2, batch_size=4, eval_every=2, learning_rate=1e-3)
    bc_oh.fit(args, torch.nn.Linear(1, 1), optimizer, train_step, 8, 1, torch.device("cpu"))
    assert rates == pytest.approx([1e-3, 7.5e-4, 5e-4, 2.5e-4])


def test_a_repeated_or_out_of_range_seed_is_refused():
    assert_usage_error(run_in_process("bc_oh.py", "--seeds", 1, 1), "--seeds needs distinct seeds, got [1, 1]")
    # numpy's generators refuse a negative seed, torch's one of 2**64: in a worker, with a traceback.
    assert_usage_error(run_in_process("bc_oh.py", "--seeds", 1, -1), "--seeds must lie in [0, 2**32), got [1, -1]")
    assert_usage_error(run_in_process("bc_oh.py", "--seeds", 2**32), "--seeds must lie in [0, 2**32), got [4294967296]")


def summary(folder, monkeypatch, capsys, score, meta, **overrides) -> str:
    """The last line bc_oh.run prints, on fake demos that carry `meta`, every evaluation returning `score`."""
    path = folder / f"demos{len(list(folder.glob('demos*.npz')))}.npz"
    np.savez(path, **fake_demos(256), **({"meta": np.array(json.dumps(meta))} if meta else {}))
    skip_evaluation(monkeypatch, bc_oh, score)
    bc_oh.run(tiny_args(bc_oh, demos=str(path), output_dir=str(path.with_suffix("")), **overrides))
    return capsys.readouterr().out.splitlines()[-1]


def test_the_summary_gives_the_share_of_the_expert_when_the_demos_name_one(tmp_path, monkeypatch, capsys):
    meta = {"env_id": "Hopper-v4", "frame_skip": 4, "expert_return": 3000.0, "expert_frame_skip": 4}
    line = summary(tmp_path, monkeypatch, capsys, 1500.0, meta, seeds=[1, 2])
    assert line == "Hopper-v4 bc_oh: score 1500.0 ± 0.0 (mean ± std over 2 seeds), 50% of the expert's 3000"
    assert summary(tmp_path, monkeypatch, capsys, 1500.0, {}) == "Hopper-v4 bc_oh: score 1500.0 ± 0.0 (mean ± std over 1 seed)"  # no expert
    # A null or zero expert return (demos made elsewhere) crashed, or printed inf%, after every seed had trained.
    for unknown in (None, 0.0):
        line = summary(tmp_path, monkeypatch, capsys, 1500.0, {**meta, "expert_return": unknown})
        assert line == "Hopper-v4 bc_oh: score 1500.0 ± 0.0 (mean ± std over 1 seed)"


def test_an_output_dir_that_cannot_be_made_is_refused_in_one_line(tmp_path):
    rng = np.random.default_rng(0)
    path = write_demos(tmp_path / "demos.npz", rng.normal(size=(100, 11)), rng.uniform(-1, 1, (100, 3)), np.arange(100) % 50 == 0)
    (tmp_path / "afile").write_text("")
    for output_dir, problem in ((tmp_path / "afile", "File exists"), (tmp_path / "afile" / "run", "Not a directory")):
        result = run_in_process("bc_oh.py", "--demos", path, "--output-dir", output_dir, "--epochs", 1)
        assert_usage_error(result, f"cannot make {output_dir} ({problem}): pass another --output-dir")


def test_an_output_dir_that_cannot_be_written_is_refused_before_training(tmp_path, monkeypatch):
    """A read-only folder (a read-only mount; chmod does not stop root) trained every seed, then raised at the first
    result file. The OS's answer is played here by os.access, which the check asks."""
    rng = np.random.default_rng(0)
    path = write_demos(tmp_path / "demos.npz", rng.normal(size=(100, 11)), rng.uniform(-1, 1, (100, 3)), np.arange(100) % 50 == 0)
    read_only = tmp_path / "read_only"
    read_only.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda where, mode: real_access(where, mode) and Path(where) != read_only)
    result = run_in_process("bc_oh.py", "--demos", path, "--output-dir", read_only, "--epochs", 1)
    assert_usage_error(result, f"cannot write in {read_only}: pass another --output-dir")
    assert "seed 1 | training" not in result.stdout


def write_demos(path, observations, actions, starts):
    np.savez(path, observations=observations, actions=actions, episode_starts=starts)
    return path


@pytest.mark.parametrize("case, message", [
    ("rows", "demos.npz: the arrays need one row per step each, episode_starts 1-D"),
    ("2-D starts", "demos.npz: the arrays need one row per step each, episode_starts 1-D"),
    ("transposed", "(11, 100) and actions (3, 100), but Hopper-v4 needs (N, 11) and (N, 3): use demos of this env"),
    ("other env", "(100, 17) and actions (100, 6), but Hopper-v4 needs (N, 11) and (N, 3): use demos of this env"),
])
def test_a_demo_file_that_does_not_fit_is_told_what_is_wrong(tmp_path, case, message):
    rng, starts = np.random.default_rng(0), np.arange(100) % 50 == 0
    obs, actions = rng.normal(size=(100, 11)), rng.uniform(-1, 1, (100, 3))
    arrays = {"rows": (obs, actions[:99], starts), "2-D starts": (obs, actions, starts[:, None]), "transposed": (obs.T, actions.T, starts),
              "other env": (rng.normal(size=(100, 17)), rng.uniform(-1, 1, (100, 6)), starts)}[case]
    path = write_demos(tmp_path / "demos.npz", *arrays)
    assert_usage_error(run_in_process("bc_oh.py", "--demos", path, "--epochs", 1), message)


def test_missing_demos_of_fewer_steps_name_the_shipped_file_too(tmp_path, monkeypatch):
    """At the env's own rate, fewer steps than the paper's: the first steps of the shipped file will do, when it is
    there (only v4 files ship: Hopper-v5's hint named a file that did not exist)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "demos").mkdir()
    (tmp_path / "demos" / "Hopper-v4_20000.npz").symlink_to(REPO_ROOT / "demos" / "Hopper-v4_20000.npz")
    assert_usage_error(run_in_process("bc_oh.py", "--num-demo-samples", 500),
                       "--num-demo-samples 500 --make-demos, or the shipped file's first steps: "
                       "--demos demos/Hopper-v4_20000.npz --num-demo-samples 500")
    result = run_in_process("bc_oh.py", "--env", "Hopper-v5", "--num-demo-samples", 500)
    assert_usage_error(result, "python expert_ppo.py --env Hopper-v5 --frame-skip 4 --num-demo-samples 500 --make-demos")
    assert result.stderr.strip().endswith("--make-demos"), "no shipped file to name"


def test_the_progress_lines_say_what_their_numbers_are(tmp_path, monkeypatch, capsys):
    """Before training, one line names the loss each file prints (C2F's is Eq. 2) and the evaluation; the table's
    header names the score."""
    import c2f

    for module, loss in ((bc_oh, "MSE to the expert's actions"), (c2f, "MSE(coarse action zeta, a_t) + MSE(final action, a_t), Eq. 2's two losses summed")):
        path = tmp_path / f"{module.METHOD}.npz"
        np.savez(path, **fake_demos(256))
        skip_evaluation(monkeypatch, module, 4.0)
        module.run(tiny_args(module, demos=str(path), output_dir=str(tmp_path / module.METHOD)))
        out = capsys.readouterr().out.splitlines()
        assert f"progress lines: loss = {loss}; last eval = the mean return of the latest evaluation" in out
        assert "  seed | score (mean return of the last 3 evaluations, or all if fewer)" in out


def test_missing_demos_name_the_command_that_makes_them(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_usage_error(run_in_process("bc_oh.py", "--frame-skip", 1, "--num-demo-samples", 500),
                       f"demo file demos/Hopper-v4_fs1_500.npz not found in {tmp_path}: make it: "
                       "python expert_ppo.py --env Hopper-v4 --frame-skip 1 --num-demo-samples 500 --make-demos")
    assert_usage_error(run_in_process("bc_oh.py", "--env", "Walker2d-v5"),
                       f"demos/Walker2d-v5_10000.npz not found in {tmp_path}: make it: "
                       "python expert_ppo.py --env Walker2d-v5 --frame-skip 4 --num-demo-samples 10000 --make-demos")
    # A path the user gave: expert_ppo.py would not write it, so no command is named.
    result = run_in_process("bc_oh.py", "--demos", "mine.npz")
    assert result.stderr.strip() == f"error: demo file mine.npz not found in {tmp_path}: check --demos"


@pytest.mark.parametrize("script", METHOD_FILES)
def test_an_interrupt_while_the_demos_load_is_one_line(tmp_path, monkeypatch, script):
    """Ctrl-C (or `kill`, which __main__ turns into Ctrl-C) in the second before the seeds start, while the env and
    the demos load, printed a KeyboardInterrupt traceback."""
    np.savez(tmp_path / "demos.npz", **fake_demos(256))

    def interrupted_load(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "load", interrupted_load)
    out = tmp_path / "out"
    try:
        result = run_in_process(script, "--demos", tmp_path / "demos.npz", "--output-dir", out)
    except KeyboardInterrupt:
        pytest.fail("the interrupt came out of the command as a traceback")
    assert (result.returncode, result.stderr) == (130, "interrupted\n")
    assert not out.exists(), "nothing was written"


def test_the_run_stops_its_own_workers_only_not_its_callers_child_processes(tmp_path, monkeypatch):
    """run() ends by terminating the pool's workers at once (their own exit takes seconds); a program that calls run()
    keeps the child processes it started itself."""
    skip_evaluation(monkeypatch, bc_oh)
    np.savez(tmp_path / "demos.npz", **fake_demos(256))
    child = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(60,))
    child.start()
    try:
        bc_oh.run(tiny_args(bc_oh, demos=str(tmp_path / "demos.npz"), output_dir=str(tmp_path / "out")))
        child.join(timeout=1)  # a terminated child ends within this second
        assert child.is_alive()
    finally:
        child.terminate()


def test_a_seed_that_fails_lets_the_others_run_to_their_end(tmp_path):
    """A seed that raises (a bug) ends the job with its traceback, but only after the other seeds have run to their end
    and written their results: a first version of the process pool cancelled them (executor.map), and its cleanup then
    killed the seeds in flight. A spawned worker does not see a test's monkeypatch, so seed 2 fails in a copy of
    bc_oh.py here."""
    link_experts(tmp_path)
    source = (REPO_ROOT / "bc_oh.py").read_text()
    seed_start = "    torch.manual_seed(seed)\n"
    assert source.count(seed_start) == 1
    failing = source.replace(seed_start, seed_start + "    if seed == 2:\n        raise RuntimeError('seed 2 fails')\n")
    (tmp_path / "bc_oh_seed2_fails.py").write_text(failing)
    result = run_script(tmp_path / "bc_oh_seed2_fails.py", "--seeds", 1, 2, 3, "--workers", 2, "--epochs", 2, "--eval-every", 1,
                        "--eval-episodes", 2, "--num-demo-samples", 300, "--output-dir", "out", cwd=tmp_path)
    assert result.returncode == 1 and "RuntimeError: seed 2 fails" in result.stderr
    written = sorted(path.name for path in (tmp_path / "out").glob("*.json"))
    assert written == ["result_seeds1.json", "result_seeds3.json"], "seeds 1 and 3 ran to their end, no combined result"
