"""benchmark/: the grid runner (skip, re-run, failures, expert, SLURM, bad input) and the aggregator (numbers,
refusals), with a stand-in method script that writes its result instantly: no real training here."""
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import METHOD_FILES, REPO_ROOT, assert_usage_error, plant, run_in_process, run_module

from benchmark import aggregate, run_grid
from benchmark.results import ResultError, UsageError, last_line_of, make_result, read_result, result_path, run_cli

DEMO_FILE = '''
def demo_file(env, frame_skip, num_samples):
    """The demo file the real method files load, and expert_ppo.py --make-demos writes."""
    rate = "" if frame_skip in (None, 5 if env.startswith(("Ant", "HalfCheetah")) else 4) else f"_fs{frame_skip}"
    return f"demos/{env}{rate}_{num_samples or (20000 if env.startswith('Hopper') else 10000)}.npz"
'''

FAKE_METHOD = f'''
"""Stand-in method: loads nothing but, as the method files, refuses to run without its demo file; writes a result at once.
FAKE_CRASH_SEED crashes that seed, FAKE_SILENT_SEED exits 0 without a result, FAKE_SLEEP waits that long first (its pid
in pid<seed>)."""
import argparse, json, os, sys, time
sys.path.insert(0, {str(REPO_ROOT)!r})
from benchmark.results import make_result, write_text
METHOD = "fake"
{DEMO_FILE}
parser = argparse.ArgumentParser()
for name in ("--env", "--output-dir"):
    parser.add_argument(name)
parser.add_argument("--seeds", type=int, nargs="+")
parser.add_argument("--epochs", type=int, default=1000)
parser.add_argument("--num-demo-samples", type=int)
parser.add_argument("--frame-skip", type=int)
args = parser.parse_args()
seed = args.seeds[0]
with open("calls.txt", "a") as calls:
    calls.write(f"{{args.env}} {{seed}}\\n")
if not os.path.isfile(demo_file(args.env, args.frame_skip, args.num_demo_samples)):
    sys.exit(f"error: demo file {{demo_file(args.env, args.frame_skip, args.num_demo_samples)}} not found")
if os.environ.get("FAKE_SLEEP"):
    with open(f"pid{{seed}}", "w") as file:
        file.write(str(os.getpid()))
    time.sleep(float(os.environ["FAKE_SLEEP"]))
if str(seed) == os.environ.get("FAKE_CRASH_SEED"):
    raise RuntimeError("boom")
if str(seed) != os.environ.get("FAKE_SILENT_SEED"):
    settings = dict(epochs=args.epochs, batch_size=64, obs_noise_std=0.2, history=2, learning_rate=None, num_demo_samples=args.num_demo_samples,
                    frame_skip=args.frame_skip)
    result = make_result(args.env, METHOD, dict(env=args.env, seeds=[seed], **settings), {{seed: [[1, 0.0], [2, 10.0 * seed], [3, 10.0 * seed], [4, 10.0 * seed]]}})
    write_text(f"{{args.output_dir}}/result_seeds{{seed}}.json", json.dumps(result))
'''

FAKE_EXPERT = f'''
"""Stand-in expert_ppo.py: --eval-only prints an evaluation; --make-demos writes the demo file (logged in made.txt, in
order; FAKE_DEMOS_FAIL refuses as the real one does)."""
import os
import sys
{DEMO_FILE}
env = sys.argv[sys.argv.index("--env") + 1]
if "--make-demos" in sys.argv:
    flag = lambda name: int(sys.argv[sys.argv.index(name) + 1]) if name in sys.argv else None
    path = demo_file(env, flag("--frame-skip"), flag("--num-demo-samples"))
    with open("made.txt", "a") as made:
        made.write(" ".join(sys.argv[1:]) + "\\n")
    if os.environ.get("FAKE_DEMOS_FAIL"):
        sys.exit("error: planted refusal")
    os.makedirs("demos", exist_ok=True)
    open(path, "w").close()
    print(f"generating demonstration steps -> {{path}}")
    print(f"wrote {{path}}")
    sys.exit(0)
returns = [3000.0, 3100.0, 2900.0, 3200.0]
for i, value in enumerate(returns):
    print(f"episode {{i}}: return {{value:.1f}}")
print(f"{{env}} expert: 3050.0 ± 111.8 over {{len(returns)}} episodes")
'''


@pytest.fixture
def scripts(tmp_path):
    """A scripts folder with the stand-in method `fake`, a stand-in expert_ppo.py, and expert files."""
    folder = tmp_path / "scripts"
    (folder / "experts").mkdir(parents=True)
    (folder / "fake.py").write_text(FAKE_METHOD)
    (folder / "expert_ppo.py").write_text(FAKE_EXPERT)
    for env in ("Hopper-v4", "Ant-v4"):
        (folder / "experts" / f"{env}.pt").write_bytes(b"")
    return folder


def grid(scripts, results, *args):
    """run_grid.main in this process on the stand-in scripts; returns its exit status."""
    return run_grid.main(["--scripts-dir", str(scripts), "--results-dir", str(results), *map(str, args)])


def calls(scripts) -> list:
    path = scripts / "calls.txt"
    return sorted(path.read_text().splitlines()) if path.exists() else []


def demos_made(scripts) -> list:
    """The flags of each `expert_ppo.py --make-demos` the grid ran, in order."""
    path = scripts / "made.txt"
    return path.read_text().splitlines() if path.exists() else []


# ----------------------------------------------------------------------------------------------
# The runner


def test_runner_skips_finished_runs_and_reruns_corrupt_or_stale_ones(scripts, tmp_path, capsys):
    results = tmp_path / "runs"
    finished = plant(results, "fake", "Hopper-v4", 1, [5.0, 5.0, 5.0])
    result_path(results, "fake", "Hopper-v4", [2]).write_text('{"env": "Hopper-v4", "method": "fa')  # cut short
    plant(results, "fake", "Hopper-v4", 3, [1.0, 2.0, 3.0], epochs=2)  # other settings than asked for
    json_of_seed_1 = finished.read_text()
    wrong_seed = plant(results, "fake", "Hopper-v4", 5, [1.0])
    os.replace(wrong_seed, result_path(results, "fake", "Hopper-v4", [4]))  # claims seed 4, holds seed 5

    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "--seeds", 1, 2, 3, 4, "--dry-run") == 0
    out = capsys.readouterr().out
    assert "skip fake Hopper-v4 seed 1" in out and "grid: 4 combinations, 1 done, 3 to run" in out
    assert calls(scripts) == []  # a dry run runs nothing

    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "--seeds", 1, 2, 3, 4, "--workers", 2) == 0
    out = capsys.readouterr().out
    assert re.search(r"re-run fake Hopper-v4 seed 2: corrupt result .*result_seeds2.json: unreadable JSON", out)
    assert re.search(r"re-run fake Hopper-v4 seed 3: .* was made with other settings \(epochs 2 != 1000\)", out)
    assert re.search(r"re-run fake Hopper-v4 seed 4: corrupt result .*holds seeds \['5'\], expected \[4\]", out)
    assert calls(scripts) == ["Hopper-v4 2", "Hopper-v4 3", "Hopper-v4 4"]
    assert finished.read_text() == json_of_seed_1  # the finished run was left alone
    record = run_grid.machine()
    for seed in (2, 3, 4):
        result = read_result(result_path(results, "fake", "Hopper-v4", [seed]), "fake", "Hopper-v4", [seed])
        assert result["mean"] == 10.0 * seed and result["machine"] == record  # the runner records where it ran
    assert "machine" not in json.loads(finished.read_text())
    log = (results / "fake" / "Hopper-v4" / "seed2.log").read_text().splitlines()
    assert log[0].startswith("$ python fake.py --env Hopper-v4 --seeds 2") and json.loads(log[1].removeprefix("# machine: ")) == record
    assert demos_made(scripts) == ["--env Hopper-v4 --make-demos"]  # once, for the three runs

    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "--seeds", 1, 2, 3, 4) == 0  # all done now
    assert "4 combinations, 4 done, 0 to run" in capsys.readouterr().out and len(calls(scripts)) == 3
    assert len(demos_made(scripts)) == 1  # nothing to run: no demos made either
    # results made with --extra-args settings count as done for the same --extra-args, and only for them
    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "--seeds", 7, "--extra-args", "--epochs 2") == 0
    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "--seeds", 7, "--extra-args", "--epochs=2 --cuda", "--dry-run") == 0
    assert "1 done, 0 to run" in capsys.readouterr().out
    grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "--seeds", 7, "--dry-run")
    assert "epochs 2 != 1000" in capsys.readouterr().out


def test_a_crashing_worker_is_listed_and_the_rest_go_on(scripts, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("FAKE_CRASH_SEED", "2")
    monkeypatch.setenv("FAKE_SILENT_SEED", "3")
    results = tmp_path / "runs"
    status = grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "Ant-v4", "--seeds", 1, 2, 3, 4, "--workers", 2)
    out = capsys.readouterr().out
    assert status == 1
    assert len(calls(scripts)) == 8  # every combination ran
    failed = out.split("runs failed:")[1]
    assert "4 of 8 runs failed" in out
    for env in ("Hopper-v4", "Ant-v4"):
        assert re.search(rf"fake {env} seed 2: exit 1: RuntimeError: boom \(log: .*seed2.log\)", failed)
        assert re.search(rf"fake {env} seed 3: exited 0 but left no valid result: no result yet", failed)
        for seed in (1, 4):
            assert read_result(result_path(results, "fake", env, [seed]), "fake", env, [seed])["mean"] == 10.0 * seed
    assert "seed 1" not in failed and "seed 4" not in failed


def test_a_killed_grid_stops_its_runs_and_starts_no_more(scripts, tmp_path):
    command = [sys.executable, "-m", "benchmark.run_grid", "--scripts-dir", str(scripts), "--results-dir", str(tmp_path / "runs"),
               "--methods", "fake", "--envs", "Hopper-v4", "--seeds", "1", "2", "3", "--workers", "2"]
    grid_process = subprocess.Popen(command, cwd=REPO_ROOT, env=dict(os.environ, FAKE_SLEEP="60"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 30
    while not all((scripts / f"pid{seed}").exists() and (scripts / f"pid{seed}").read_text() for seed in (1, 2)):
        assert time.time() < deadline and grid_process.poll() is None, "the two first runs did not start"
        time.sleep(0.1)
    grid_process.terminate()
    _, err = grid_process.communicate(timeout=20)
    assert grid_process.returncode == 130 and "interrupted: finished results are kept" in err
    for seed in (1, 2):
        with pytest.raises(ProcessLookupError):  # the runs were stopped (and reaped) with the grid
            os.kill(int((scripts / f"pid{seed}").read_text()), 0)
    assert calls(scripts) == ["Hopper-v4 1", "Hopper-v4 2"]  # seed 3 never started


def test_the_demos_are_made_once_per_env_before_the_runs_with_their_settings(scripts, tmp_path, capsys):
    alone = subprocess.run([sys.executable, "fake.py", "--env", "Ant-v4", "--seeds", "1", "--output-dir", str(tmp_path / "alone")],
                           cwd=scripts, capture_output=True, text=True)
    assert alone.returncode == 1 and "demo file demos/Ant-v4_10000.npz not found" in alone.stderr  # the stand-in needs its demos
    (scripts / "calls.txt").unlink()
    results, settings = tmp_path / "runs", "--num-demo-samples 300 --frame-skip=2"
    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "Ant-v4", "--seeds", 1, 2, "--extra-args", settings,
                "--dry-run") == 0
    out = capsys.readouterr().out
    for env in ("Ant-v4", "Hopper-v4"):
        assert f"demos {env}: (cd {scripts} && python expert_ppo.py --env {env} --make-demos --frame-skip 2 --num-demo-samples 300)" in out
    assert demos_made(scripts) == [] and calls(scripts) == []  # a dry run only lists
    assert grid(scripts, results, "--methods", "fake", "--envs", "Hopper-v4", "Ant-v4", "--seeds", 1, 2, "--extra-args", settings) == 0
    out = capsys.readouterr().out
    assert demos_made(scripts) == [f"--env {env} --make-demos --frame-skip 2 --num-demo-samples 300" for env in ("Ant-v4", "Hopper-v4")]
    assert out.index("wrote demos/Hopper-v4_fs2_300.npz") < out.index("[1/4, ")  # made before the first run ended
    for env in ("Hopper-v4", "Ant-v4"):
        for seed in (1, 2):  # every run found its demo file (the stand-in refuses without it)
            result = read_result(result_path(results, "fake", env, [seed]), "fake", env, [seed])
            assert (result["args"]["num_demo_samples"], result["args"]["frame_skip"]) == (300, 2) and result["machine"] == run_grid.machine()
    options = run_grid.parse_options(["--scripts-dir", str(scripts), "--results-dir", str(results), "--methods", "fake", "expert",
                                      "--envs", "Hopper-v4", "--extra-args=--demos=mine.npz"])
    assert run_grid.demo_commands(run_grid.combinations(options), options) == []  # the grid's own demo file: none to make
    options.extra_args = []
    assert run_grid.demo_commands([run_grid.Run("expert", "Hopper-v4", 0)], options) == []  # the expert loads no demos


def test_a_grid_whose_demos_cannot_be_made_starts_no_run(scripts, tmp_path, monkeypatch):
    monkeypatch.setenv("FAKE_DEMOS_FAIL", "1")
    with pytest.raises(UsageError, match=re.escape("could not make the demos (expert_ppo.py --env Ant-v4 --make-demos): error: planted refusal")):
        grid(scripts, tmp_path / "runs", "--methods", "fake", "--envs", "Hopper-v4", "Ant-v4", "--seeds", 1)
    assert demos_made(scripts) == ["--env Ant-v4 --make-demos"] and calls(scripts) == []  # stopped at the first env, nothing ran


def test_expert_is_evaluated_once_per_env_into_the_same_json_shape(scripts, tmp_path, capsys):
    results = tmp_path / "runs"
    assert grid(scripts, results, "--methods", "expert", "fake", "--envs", "Hopper-v4", "--seeds", 1, 2, "--expert-episodes", 4) == 0
    assert "3 combinations" in capsys.readouterr().out  # expert once, fake twice
    path = result_path(results, "expert", "Hopper-v4", [0])
    result = read_result(path, "expert", "Hopper-v4")
    assert result["scores"]["0"]["score"] == pytest.approx(3050.0)
    assert result["std"] == pytest.approx(statistics.pstdev([3000, 3100, 2900, 3200]))
    assert result["args"]["eval_episodes"] == 4
    assert grid(scripts, results, "--methods", "expert", "--envs", "Hopper-v4", "--expert-episodes", 5, "--dry-run") == 0
    assert "eval_episodes 4 != 5" in capsys.readouterr().out  # another episode count is another run


def test_expert_command_is_one_the_real_expert_ppo_accepts(scripts, tmp_path):
    """The stand-in expert_ppo.py above ignores its flags: the runner's expert command must parse with the real one's."""
    import tyro

    import expert_ppo

    options = run_grid.parse_options(["--scripts-dir", str(scripts), "--results-dir", str(tmp_path), "--methods", "expert",
                                      "--envs", "Ant-v4", "--expert-episodes", "7"])
    python, script, *flags = run_grid.command(run_grid.Run("expert", "Ant-v4", run_grid.EXPERT_SEED), options)
    assert script == "expert_ppo.py"
    args = tyro.cli(expert_ppo.Args, args=flags)  # an unknown flag would exit 2 here
    assert (args.eval_only, args.env, args.checkpoint, args.eval_episodes) == (True, "Ant-v4", "experts/Ant-v4.pt", 7)
    options.extra_args = ["--frame-skip", "2", "--num-demo-samples=300"]
    (python, script, *flags), = run_grid.demo_commands([run_grid.Run("bc_oh", "Ant-v4", 1)], options)
    args = tyro.cli(expert_ppo.Args, args=flags)
    assert script == "expert_ppo.py" and (args.make_demos, args.env, args.frame_skip, args.num_demo_samples) == (True, "Ant-v4", 2, 300)


def test_slurm_script_names_every_combination_exactly_once(scripts, tmp_path, capsys):
    results, script = tmp_path / "runs", tmp_path / "grid.sbatch"
    assert grid(scripts, results, "--methods", "fake", "expert", "--envs", "Hopper-v4", "Ant-v4", "--seeds", 1, 2, 3,
                "--workers", 4, "--slurm", script, "--extra-args", "--epochs 2") == 0
    text = script.read_text()
    tasks = re.findall(r"^  (\d+)\) one (\S+) (\S+) (\d+) ;;$", text, re.M)
    expected = {("fake", env, str(seed)) for env in ("Hopper-v4", "Ant-v4") for seed in (1, 2, 3)} | {("expert", "Hopper-v4", "0"), ("expert", "Ant-v4", "0")}
    assert [int(index) for index, *_ in tasks] == list(range(len(expected)))
    assert sorted(tuple(combination) for _, *combination in tasks) == sorted(expected)  # each once, nothing else
    assert f"#SBATCH --array=0-{len(expected) - 1}%4" in text and "--extra-args '--epochs 2'" in text
    assert calls(scripts) == [] and not list(results.rglob("*.json"))  # written, not run
    assert subprocess.run(["bash", "-n", str(script)]).returncode == 0
    # one array task runs its combination through the runner
    index = next(int(index) for index, *combination in tasks if combination == ["fake", "Ant-v4", "2"])
    task = subprocess.run(["bash", str(script)], env=dict(os.environ, SLURM_ARRAY_TASK_ID=str(index)), capture_output=True, text=True)
    assert task.returncode == 0, task.stderr
    assert calls(scripts) == ["Ant-v4 2"] and read_result(result_path(results, "fake", "Ant-v4", [2]), "fake", "Ant-v4")["args"]["epochs"] == 2


def test_a_dry_run_with_slurm_prints_the_job_and_writes_nothing(scripts, tmp_path, capsys):
    """--dry-run --slurm FILE wrote FILE (and made --results-dir) as if no --dry-run were given."""
    results = tmp_path / "runs"
    script = tmp_path / "grid.sbatch"
    args = ["--methods", "fake", "--envs", "Hopper-v4", "--seeds", 1, 2, "--slurm", script]
    assert grid(scripts, results, *args, "--dry-run") == 0
    shown = capsys.readouterr().out
    assert not script.exists() and not results.exists() and calls(scripts) == []
    assert shown.endswith(f"\n# dry run: would write {script}: a SLURM array job of 2 combinations; nothing written\n")
    # without --dry-run the same command writes the job it showed
    assert grid(scripts, results, *args) == 0
    assert shown.startswith(script.read_text())


def test_the_grid_refuses_a_missing_scripts_dir_and_an_empty_slurm_name(scripts, tmp_path):
    with pytest.raises(run_grid.UsageError, match="--scripts-dir .*nope is not a folder: pass a checkout"):
        grid(tmp_path / "nope", tmp_path / "runs", "--methods", "fake", "--envs", "Hopper-v4", "--dry-run")
    # An empty --slurm was taken as no --slurm: the whole grid ran here.
    with pytest.raises(run_grid.UsageError, match="--slurm needs the name of the file to write"):
        grid(scripts, tmp_path / "runs", "--methods", "fake", "--envs", "Hopper-v4", "--slurm", "")
    assert calls(scripts) == []


TYRO_BOX = """\
╭─ Unrecognized options ──────────────╮
│ Unrecognized options: --epoch, 1    │
│ ─────────────────────────────────── │
│ For full helptext, run bc_oh.py --help │
╰─────────────────────────────────────╯
"""
"""how a method file (tyro) refuses its flags"""


def test_a_failed_run_is_told_by_the_first_line_of_tyros_error_box():
    assert last_line_of(TYRO_BOX) == "Unrecognized options: --epoch, 1"
    assert last_line_of("training\nerror: --seeds needs distinct seeds\n") == "error: --seeds needs distinct seeds"
    assert last_line_of("a log cut after a box's top\n╰──╯\n") == "╰──╯"  # no box to read: the last line


@pytest.mark.parametrize("args, expected", [
    (["--methods", "bc_oh", "nope", "--envs", "Hopper-v4"], "unknown method 'nope': choose from"),
    (["--methods", "bc_oh", "--envs", "Hopper-v4", "Nope-v4"], "unknown env 'Nope-v4'"),
    # It was told to train an expert for these, which expert_ppo.py (CartPole) or the method files (Pendulum) refuse.
    (["--methods", "bc_oh", "--envs", "CartPole-v1"], "CartPole-v1 is not a MuJoCo env: the method files imitate MuJoCo envs"),
    (["--methods", "bc_oh", "--envs", "Pendulum-v1"], "Pendulum-v1 is not a MuJoCo env"),
    # A dry run listed seed -1 as "to run"; the real run failed on it.
    (["--methods", "bc_oh", "--envs", "Hopper-v4", "--seeds", "-1", "2", "--dry-run"], "--seeds must lie in [0, 2**32), got -1 2"),
    (["--methods", "bc_oh", "--envs", "Hopper-v4", "--extra-args", "--seeds 4"], "--extra-args sets --seeds"),
    (["--methods", "bc_oh"], "the following arguments are required: --envs"),
])
def test_bad_grid_input_is_one_line(args, expected, tmp_path):
    result = run_module("benchmark.run_grid", "--results-dir", tmp_path, *args)
    assert_usage_error(result, expected)
    assert result.returncode == 2 and not list(tmp_path.iterdir())



def refused(result, message):
    """Assert that a tool run by run_in_process refused its input with exactly `error: message`
    and exit status 2, and printed nothing else."""
    assert (result.returncode, result.stderr, result.stdout) == (2, f"error: {message}\n", "")


def grid_in_process(scripts, results, *args):
    """run_grid as its command runs (run_cli), in this process: run_in_process's result."""
    folders = ["--scripts-dir", scripts, "--results-dir", results]
    return run_in_process("benchmark/run_grid.py", *folders, *args)


@pytest.mark.parametrize("results, blocker, reason", [
    ("file/runs", "file", "is not a folder"),
    ("read_only", "read_only", "is not writable"),
    ("read_only/runs", "read_only", "is not writable"),
])
@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]])
def test_a_results_dir_that_cannot_be_written_is_refused_before_the_grid(
        scripts, tmp_path, monkeypatch, results, blocker, reason, dry_run):
    """A --results-dir under a file made the demos, then failed every run; in a read-only folder
    (a read-only mount: chmod does not stop root, so os.access, which the check asks, plays the
    OS's answer) it did the same; a dry run listed the runs as to run. Now one line before
    anything, making nothing."""
    (tmp_path / "file").write_text("")
    read_only = tmp_path / "read_only"
    read_only.mkdir()
    real_access = os.access

    def access(where, mode):
        if Path(where) == read_only:
            return False
        return real_access(where, mode)

    monkeypatch.setattr(os, "access", access)
    args = ["--methods", "fake", "--envs", "Hopper-v4", *dry_run]
    result = grid_in_process(scripts, tmp_path / results, *args)
    problem = f"{tmp_path / results} cannot hold results: {tmp_path / blocker} {reason}"
    refused(result, f"--results-dir {problem}: pass another --results-dir")
    assert demos_made(scripts) == [] and calls(scripts) == []
    assert not (read_only / "runs").exists()


ONE_RUN = ["--methods", "fake", "--envs", "Hopper-v4"]


@pytest.mark.parametrize("args, message", [
    # The same combination twice: listed, and run side by side into the same result and log.
    (["--methods", "fake", "fake", "--envs", "Hopper-v4"],
     "--methods lists fake twice: name each once"),
    (["--methods", "fake", "--envs", "Hopper-v4", "Ant-v4", "Hopper-v4"],
     "--envs lists Hopper-v4 twice: name each once"),
    ([*ONE_RUN, "--seeds", 1, 2, 1], "--seeds lists 1 twice: name each once"),
    # A word before any flag: listed as to run, then each run refused it (Unrecognized options).
    ([*ONE_RUN, "--extra-args=epochs 2"],
     "--extra-args starts with 'epochs', not a flag: e.g. \"--epochs 2\""),
])
def test_input_every_run_would_refuse_is_one_line_before_the_grid(scripts, tmp_path, args, message):
    refused(grid_in_process(scripts, tmp_path / "runs", *args, "--dry-run"), message)


def test_a_scripts_dir_without_method_files_is_told_so(tmp_path):
    """It was told `unknown method 'bc_oh': choose from ` (nothing)."""
    result = grid_in_process(tmp_path, tmp_path / "runs", *ONE_RUN, "--dry-run")
    advice = "pass a checkout of this repository"
    refused(result, f"--scripts-dir {tmp_path} holds no method files: {advice}")


@pytest.mark.parametrize("slurm, message", [
    # It made --results-dir, then was told `cannot use {tmp}: Is a directory: pass another path`.
    ("{tmp}", "--slurm {tmp} is a folder: name the file to write, e.g. --slurm grid.sh"),
    # `cannot use {tmp}/file: File exists: pass another path`, naming no flag.
    ("{tmp}/file/grid.sh", "--slurm {tmp}/file/grid.sh cannot be written: "
                           "{tmp}/file is not a folder: pass another --slurm"),
])
def test_a_slurm_file_that_cannot_be_written_is_refused_before_anything(
        scripts, tmp_path, slurm, message):
    (tmp_path / "file").write_text("")
    name = slurm.format(tmp=tmp_path)
    result = grid_in_process(scripts, tmp_path / "runs", *ONE_RUN, "--slurm", name)
    refused(result, message.format(tmp=tmp_path))
    assert not (tmp_path / "runs").exists() and calls(scripts) == []


def test_a_dry_run_piped_into_head_ends_quietly(tmp_path):
    """`run_grid ... --dry-run | head`: the reader goes away early; no BrokenPipeError traceback."""
    grid = subprocess.Popen([sys.executable, "-m", "benchmark.run_grid", "--results-dir", str(tmp_path), "--dry-run",
                             "--methods", "bc_oh", "c2f", "--envs", "Hopper-v4", "Ant-v4", "--seeds", *map(str, range(1, 200))],
                            cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert grid.stdout.readline().startswith("run  bc_oh Hopper-v4 seed 1: ")
    grid.stdout.close()  # like head after its lines: the rest of the ~800-line listing meets a closed pipe
    stderr = grid.stderr.read()
    assert grid.wait(timeout=60) == 1 and stderr == ""

def test_extra_args_are_read_as_the_scripts_read_them():
    assert run_grid.explicit_settings(["--epochs", "2", "--learning-rate=1e-4", "--cuda", "--no-save-model", "--velocity-dims", "5", "6",
                                       "--demos", "None", "--tag", "x"]) == {
        "epochs": 2, "learning_rate": 1e-4, "cuda": True, "save_model": False, "velocity_dims": [5, 6], "demos": None, "tag": "x"}


# ----------------------------------------------------------------------------------------------
# Result files


@pytest.mark.parametrize("corrupt, reason", [
    (lambda r: r.pop("scores"), "missing keys scores"),
    (lambda r: r.update(method="bc_so"), "holds bc_so on Hopper-v4, expected bc_oh on Hopper-v4"),
    (lambda r: r["scores"]["1"].update(evaluations=[]), "seed 1 has no valid evaluations"),
    (lambda r: r["scores"]["1"]["evaluations"].append([9, float("nan")]), "seed 1 has no valid evaluations"),
    (lambda r: r["scores"]["1"].update(score=1.0), "is not the mean of its last three evaluations"),
    (lambda r: r.update(mean="n/a"), "mean or std is not a number"),
])
def test_partial_or_inconsistent_results_are_refused(tmp_path, corrupt, reason):
    path = plant(tmp_path, "bc_oh", "Hopper-v4", 1, [1.0, 2.0, 3.0, 4.0])
    assert read_result(path, "bc_oh", "Hopper-v4")["scores"]["1"]["score"] == 3.0  # mean of the last three
    result = json.loads(path.read_text())
    corrupt(result)
    path.write_text(json.dumps(result))
    with pytest.raises(ResultError, match=re.escape(reason)):
        read_result(path, "bc_oh", "Hopper-v4")


# ----------------------------------------------------------------------------------------------
# The aggregator


def test_aggregator_numbers_and_refusals(tmp_path, capsys):
    runs, out = tmp_path / "runs", tmp_path / "out"
    for seed, last in ((1, 100.0), (2, 200.0), (3, 600.0)):  # seed scores 100, 200, 600 (the first evaluation drops out)
        plant(runs, "bc_oh", "Hopper-v4", seed, [99999.0, last - 10, last, last + 10])
    plant(runs, "c2f", "Ant-v4", 1, [4000.0, 5000.0, 6000.0])
    expert = {"env": "Ant-v4", "seeds": [0], "checkpoint": "experts/Ant-v4.pt", "eval_episodes": 20}
    expert_path = result_path(runs, "expert", "Ant-v4", [0])
    expert_path.parent.mkdir(parents=True)
    expert_path.write_text(json.dumps({**make_result("Ant-v4", "expert", expert, {0: [[0, 5500.0]]}), "std": 42.0}))
    nonpaper = plant(runs, "bc_oh", "Hopper-v4", 4, [1.0, 1.0, 1.0], epochs=2, num_demo_samples=300)
    corrupt = result_path(runs, "c2f", "Ant-v4", [2])
    corrupt.write_text("{not json")

    assert aggregate.main(["--results-dir", str(runs), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"left out {nonpaper}: not the paper's settings (epochs 2 != 1000, num_demo_samples 300 != 20000)" in err
    assert f"left out {corrupt}: unreadable JSON" in err
    assert (out / "mujoco.csv").read_text().splitlines() == [
        "env,method,seed,score",
        "Hopper-v4,bc_oh,1,100.000", "Hopper-v4,bc_oh,2,200.000", "Hopper-v4,bc_oh,3,600.000",
        "Ant-v4,c2f,1,5000.000", "Ant-v4,expert,0,5500.000"]
    table = (out / "table2.md").read_text()
    std = statistics.pstdev([100, 200, 600])  # 216.02
    assert f"| BC-OH (`bc_oh`) | {300:.0f} ± {std:.0f} (n=3) | 628 ± 99 | — | 2922 ± 1266 |" in table
    assert "| Coarse-to-fine (`c2f`) | — | 1124 ± 135 | 5000 ± 0 (n=1) | 4798 ± 304 |" in table
    assert "| PPO expert (`expert`) | — | 3445 | 5500 ± 42 (20 ep.) | 5566 |" in table
    assert "| DAgger 8K (`dagger`) | — | 2383 ± 294 | — | 4097 ± 418 |" in table  # not run yet: shown as missing
    assert "Not at the paper's settings" not in table
    assert (out / "table2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    assert aggregate.main(["--results-dir", str(runs), "--out", str(out), "--allow-nonpaper"]) == 0
    assert "Hopper-v4,bc_oh,4,1.000" in (out / "mujoco.csv").read_text()
    table = (out / "table2.md").read_text()
    assert f"{statistics.fmean([100, 200, 600, 1]):.0f} ± {statistics.pstdev([100, 200, 600, 1]):.0f} (n=4)" in table
    assert "1 seed runs with epochs 2 != 1000, num_demo_samples 300 != 20000" in table


def test_an_expert_result_without_its_episode_count_shows_no_count(tmp_path, capsys):
    """An expert result whose args lack eval_episodes (one written by hand, or by an older runner) read "(None ep.)"."""
    runs = tmp_path / "runs"
    out = tmp_path / "out"
    expert_path = result_path(runs, "expert", "Ant-v4", [0])
    expert_path.parent.mkdir(parents=True)
    result = make_result("Ant-v4", "expert", {"env": "Ant-v4", "seeds": [0]}, {0: [[0, 5500.0]]})
    expert_path.write_text(json.dumps({**result, "std": 42.0}))
    assert aggregate.main(["--results-dir", str(runs), "--out", str(out)]) == 0
    table = (out / "table2.md").read_text()
    assert "| PPO expert (`expert`) | 5500 ± 42 | 5566 |" in table
    assert "None" not in table and capsys.readouterr().err == ""



def test_aggregator_puts_the_table_into_the_page_between_its_markers(tmp_path, capsys):
    runs, out, page = tmp_path / "runs", tmp_path / "results", tmp_path / "page.md"
    plant(runs, "c2f", "Ant-v4", 1, [4000.0, 5000.0, 6000.0])
    page.write_text("# Title\n\n<!-- table2 -->\nthe old table\n<!-- /table2 -->\n\nReading.\n")
    assert aggregate.main(["--results-dir", str(runs), "--out", str(out), "--page", str(page)]) == 0
    text = page.read_text()
    assert text.startswith("# Title\n\n<!-- table2 -->\nMade by `python -m benchmark.aggregate --results-dir ")
    assert f"--page {page}` from 1 per-seed results" in text and "the old table" not in text
    assert "| Coarse-to-fine (`c2f`) | 5000 ± 0 (n=1) | 4798 ± 304 |" in text
    assert text.endswith("\n\n![Table 2](results/table2.png)\n\n![Learning curves](results/curves.png)\n<!-- /table2 -->\n\nReading.\n")
    assert (out / "table2.md").read_text().split("\n", 2)[2].strip() in text

    page.write_text("# Title without markers\n")
    (out / "mujoco.csv").unlink()
    with pytest.raises(UsageError, match="needs one <!-- table2 --> line and, after it, one <!-- /table2 --> line"):
        aggregate.main(["--results-dir", str(runs), "--out", str(out), "--page", str(page)])
    assert not (out / "mujoco.csv").exists(), "nothing is written before the page is checked"
    with pytest.raises(UsageError, match="page .*missing.md not found"):
        aggregate.main(["--results-dir", str(runs), "--out", str(out), "--page", str(tmp_path / "missing.md")])


def test_a_bare_page_flag_writes_docs_results_md_with_links_relative_to_it(tmp_path, monkeypatch):
    """--page alone is the page the aggregator owns, docs/results.md (relative to where it runs, as --out)."""
    monkeypatch.chdir(tmp_path)
    plant(tmp_path / "runs", "c2f", "Ant-v4", 1, [4000.0, 5000.0, 6000.0])
    page = tmp_path / "docs" / "results.md"
    page.parent.mkdir()
    page.write_text("<!-- table2 -->\n<!-- /table2 -->\n")
    assert aggregate.PAGE == Path("docs/results.md")
    assert aggregate.main(["--results-dir", "runs", "--out", "results", "--page"]) == 0
    text = page.read_text()
    assert "--out results --page docs/results.md` from 1 per-seed results" in text
    assert text.endswith("\n\n![Table 2](../results/table2.png)\n\n![Learning curves](../results/curves.png)\n<!-- /table2 -->\n")


def test_docs_results_md_holds_the_committed_table2():
    """The page the aggregator owns carries its block, and the block is the committed results/table2.md (rerun
    `python -m benchmark.aggregate --page` after new runs)."""
    aggregate.page_parts(REPO_ROOT / aggregate.PAGE)  # one pair of markers
    block = (REPO_ROOT / aggregate.PAGE).read_text().split("<!-- table2 -->", 1)[1].split("<!-- /table2 -->")[0]
    table = (REPO_ROOT / "results" / "table2.md").read_text()
    assert table.split("\n", 2)[2].strip() in block
    assert "--page docs/results.md` from" in table
    assert "![Table 2](../results/table2.png)" in block and "![Learning curves](../results/curves.png)" in block


def test_aggregator_without_valid_results_is_one_line(tmp_path):
    plant(tmp_path, "bc_oh", "Hopper-v4", 1, [1.0], epochs=3)
    result = run_module("benchmark.aggregate", "--results-dir", tmp_path, "--out", tmp_path / "out")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert "not the paper's settings (epochs 3 != 1000)" in lines[0] and lines[1].startswith("error: no valid results to aggregate")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("flags, message", [
    # "no valid results ... (see above)", with nothing above
    (["--results-dir", "empty"], "no <method>/<env>/result_seeds*.json under {tmp}/empty: pass the folder "
     "python -m benchmark.run_grid wrote (--results-dir), or run it"),
    # "results folder ... not found", of a file that is there
    (["--results-dir", "file"], "results folder {tmp}/file is a file, not a folder: run python -m "
     "benchmark.run_grid first, or pass --results-dir"),
    # "cannot use ...: File exists"
    (["--out", "file/results"], "--out {tmp}/file/results cannot be written: {tmp}/file is not a "
     "folder: pass another --out"),
    # a UnicodeDecodeError traceback (the picture named for the page)
    (["--page", "table2.png"], "page {tmp}/table2.png is not text (not UTF-8): pass the markdown "
     "page to --page"),
    # "page ... not found", of a folder that is there
    (["--page", "empty"], "page {tmp}/empty is a folder: pass the markdown page itself to --page"),
])
def test_aggregator_paths_that_cannot_be_used_are_one_line(tmp_path, flags, message):
    plant(tmp_path / "runs", "c2f", "Ant-v4", 1, [4000.0, 5000.0, 6000.0])
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("not a folder\n")
    (tmp_path / "table2.png").write_bytes(b"\x89PNG\r\n\x1a\n\xff")
    paths = {"--results-dir": tmp_path / "runs", "--out": tmp_path / "out"}
    paths.update({flag: tmp_path / name for flag, name in zip(flags[::2], flags[1::2])})
    result = run_in_process("benchmark/aggregate.py", *[word for pair in paths.items() for word in pair])
    refused(result, message.format(tmp=tmp_path))
    assert not (tmp_path / "out").exists()



def test_the_speed_benchmarks_take_a_script_as_a_commit_had_it_and_refuse_what_they_cannot_time(tmp_path):
    """benchmark.baseline.script_at writes `git show <commit>:<script>.py` (HEAD: the checkout's own file); an unknown
    commit, an unknown script or a size that is not positive ends in one UsageError, before anything runs."""
    from benchmark import main_job_time, step_time
    from benchmark.baseline import BEFORE_FUSED_ADAM, script_at

    assert script_at("HEAD", "c2f", tmp_path) == REPO_ROOT / "c2f.py"
    if not (REPO_ROOT / ".git").exists():
        pytest.skip("no git history here (an unpacked archive): the baseline's file cannot be shown")
    old = script_at(BEFORE_FUSED_ADAM, "c2f", tmp_path)
    assert old == tmp_path / BEFORE_FUSED_ADAM / "c2f.py"
    assert "fused=True" not in old.read_text() and "fused=True" in (REPO_ROOT / "c2f.py").read_text()
    with pytest.raises(UsageError, match="git cannot show c2f.py at 'no-such-commit'"):
        script_at("no-such-commit", "c2f", tmp_path)
    with pytest.raises(UsageError, match="--env-now 'MKL_CBWR' is not VAR=VALUE"):
        step_time.main(["--env-now", "MKL_CBWR"])
    with pytest.raises(UsageError, match="must be positive"):
        main_job_time.main(["--repeats", "0"])


METHOD_NAMES = ", ".join(sorted(Path(name).stem for name in METHOD_FILES))
NO_TABLE3 = "commit '80062f3~1' has no c2f_table3.py: give a later commit, e.g. 8ce2c69"
"""80062f3 added c2f_table3.py; the benchmarks refuse versions before 8ce2c69 (no --workers, no ms_per_step)"""
"""how the speed benchmarks refuse a baseline that lacks the script (it was told to be no commit)"""


@pytest.mark.parametrize("args, message", [
    # expert_ppo.py ran and refused the method flags: the error was the bottom edge of tyro's box.
    (["--scripts", "expert_ppo"],
     f"--scripts expert_ppo is not a method file: choose from {METHOD_NAMES}"),
    (["--scripts", "nothing"],
     f"--scripts nothing is not a method file: choose from {METHOD_NAMES}"),
    # Its row came twice, each with both pairs.
    (["--scripts", "bc_oh", "bc_oh"], "--scripts lists bc_oh twice: name each once"),
    # git showed the staged file.
    (["--baseline", ""], "--baseline needs a commit, e.g. --baseline 8ce2c69"),
    # A version older than its timing trained, then ended in a KeyError traceback.
    (["--scripts", "bc_oh", "--baseline", "d8e24fd"],
     "bc_oh.py at d8e24fd records no ms_per_step: give a later --baseline, e.g. 8ce2c69"),
    # A script the baseline lacks (c2f_table3.py came at 80062f3) was refused after bc_oh's runs.
    (["--scripts", "bc_oh", "c2f_table3", "--baseline", "80062f3~1"], NO_TABLE3),
    # c2f.py came before the scripts timed their steps: the commit that added it was refused in turn.
    (["--scripts", "c2f", "--baseline", "d8e24fd"], "commit 'd8e24fd' has no c2f.py: give a later commit, e.g. 8ce2c69"),
])
def test_step_time_refuses_what_it_cannot_time_in_one_line_before_any_run(args, message, monkeypatch):
    from benchmark import step_time

    if "--baseline" in args and not (REPO_ROOT / ".git").exists():
        pytest.skip("no git history here (an unpacked archive)")
    # Called here, not run as a script, so that a run started before the refusal fails the test.
    monkeypatch.setattr(step_time, "start", lambda *args: pytest.fail(f"ran {args}"))
    with pytest.raises(UsageError) as refusal:
        step_time.main([*args, "--epochs", "1", "--repeats", "1"])
    assert str(refusal.value) == message


@pytest.mark.parametrize("args, message", [
    # expert_ppo.py ran and refused the method flags, told as ['╰────╯'] (its box's bottom edge).
    (["--script", "expert_ppo"],
     f"--script expert_ppo is not a method file: choose from {METHOD_NAMES}"),
    (["--script", "nothing"], f"--script nothing is not a method file: choose from {METHOD_NAMES}"),
    # Both ran, into one output folder and one row of the table.
    (["--workers", 1, 1], "--workers lists 1 twice: name each once"),
    # git showed the staged file, timed as the baseline.
    (["--baseline", ""], "--baseline needs a commit, e.g. --baseline 8ce2c69"),
    # A version older than --workers (f23377c) ran and refused the flag.
    (["--baseline", "f23377c~1"],
     "c2f.py at f23377c~1 takes no --workers: give a later --baseline, e.g. 8ce2c69"),
    (["--script", "c2f_table3", "--baseline", "80062f3~1"], NO_TABLE3),
])
def test_main_job_time_refuses_what_it_cannot_time_in_one_line_before_any_run(
        args, message, monkeypatch):
    from benchmark import baseline

    if "--baseline" in args and not (REPO_ROOT / ".git").exists():
        pytest.skip("no git history here (an unpacked archive)")
    monkeypatch.setattr(baseline, "timed_run", lambda command: pytest.fail(f"ran {command}"))
    result = run_in_process("benchmark/main_job_time.py", *args, "--epochs", 1, "--repeats", 1)
    refused(result, message)


def test_main_job_time_against_head_keeps_each_setting_apart(monkeypatch, capsys):
    """With --baseline HEAD, the baseline (HEAD at the cores' count) and the same count of --workers
    ran into one output folder and made one row of the table. Each setting is its own row now."""
    from benchmark import main_job_time

    cores = len(os.sched_getaffinity(0))
    outputs = []
    seconds = iter([10.0, 12.0])

    def timed_run(command):
        outputs.append(command[command.index("--output-dir") + 1])
        return next(seconds)

    monkeypatch.setattr(main_job_time, "timed_run", timed_run)
    monkeypatch.setattr(main_job_time, "machine_line", lambda: "a machine")
    args = ["--baseline", "HEAD", "--workers", str(cores), "--epochs", "1", "--repeats", "1"]
    assert main_job_time.main(args) == 0
    assert len(set(outputs)) == 2
    rows = capsys.readouterr().out.splitlines()[-2:]
    assert rows == [f"| this checkout | {cores} | 10.0 | 10.0 | 1.00x |",
                    f"| this checkout | {cores} | 12.0 | 12.0 | 1.20x |"]


def test_the_settings_line_gives_each_env_its_own_frame_skip():
    """Table 2's settings line named 5 for every env but Hopper; Walker2d's frame skip is 4. Each family must stand
    under the frame skip gymnasium gives it, and under the paper's learning rate and demo size for it."""
    import gymnasium as gym

    from benchmark.paper import paper_settings

    parts = dict(part.split(" ", 1) for part in aggregate.settings_text().split("; "))
    for family in ("Hopper", "Walker2d", "HalfCheetah", "Ant"):
        native = gym.make(f"{family}-v4").unwrapped.frame_skip
        wanted = {"frame_skip": native, **{name: paper_settings(f"{family}-v4")[name] for name in ("learning_rate", "num_demo_samples")}}
        for name, value in wanted.items():
            groups = dict(re.fullmatch(r"(\S+) \((.*)\)", group).groups() for group in parts[name].split(" / "))
            assert family in groups[str(value)].split(", "), (family, name, parts[name])
    assert parts["history"] == "2" and parts["obs_noise_std"] == "0.2", "a setting shared by every env is given once"


@pytest.mark.parametrize("module", sorted(path.stem for path in (REPO_ROOT / "benchmark").glob("*.py")
                                          if "__main__" in path.read_text()))
def test_a_benchmark_module_runs_as_a_file_too(module, tmp_path):
    """`python benchmark/X.py` put benchmark/ first on sys.path, so `from benchmark...` failed with a traceback; the
    docs use `python -m benchmark.X`, and both now work, from any folder."""
    result = subprocess.run([sys.executable, str(REPO_ROOT / "benchmark" / f"{module}.py"), "--help"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: "), result.stdout


def test_step_time_gives_env_now_to_todays_runs_alone(tmp_path):
    """--env-now (e.g. MKL_CBWR=COMPATIBLE with --baseline HEAD) must reach the runs of today's scripts and not the
    baseline's: start() adds it to a run's environment; a script standing in for a method file reports it."""
    from benchmark import step_time

    script = tmp_path / "reports_env.py"
    script.write_text(
        "import json, os, sys\n"
        "out = sys.argv[sys.argv.index('--output-dir') + 1]\n"
        "os.makedirs(out, exist_ok=True)\n"
        "ms = float(os.environ.get('STEP_TIME_TEST_MS', '1'))\n"
        "open(os.path.join(out, 'result_seeds1.json'), 'w').write(json.dumps({'scores': {'1': {'ms_per_step': ms}}}))\n")
    baseline = step_time.start(script, 1, tmp_path / "baseline", False, {})
    now = step_time.start(script, 1, tmp_path / "now", False, {"STEP_TIME_TEST_MS": "2.5"})
    assert step_time.ms_per_step(baseline, tmp_path / "baseline") == 1.0
    assert step_time.ms_per_step(now, tmp_path / "now") == 2.5


def test_a_failed_timing_run_is_told_by_its_error_line(tmp_path, capsys):
    """step_time told a run that failed by a list of its last line of stderr: for a method file's
    refusal, `['╰────╯']`, the bottom edge of tyro's box. Now the line inside the box names it."""
    from benchmark import step_time

    script = tmp_path / "refuses.py"
    script.write_text(f"import sys\nsys.stderr.write({TYRO_BOX!r})\nsys.exit(2)\n")
    run = step_time.start(script, 1, tmp_path / "out", False, {})
    with pytest.raises(SystemExit) as exit:
        run_cli(lambda: step_time.ms_per_step(run, tmp_path / "out"))
    flags = "--env Hopper-v4 --seeds 1 --epochs 1 --eval-every 1 --eval-episodes 1 --output-dir"
    command = f"{script} {flags} {tmp_path / 'out'}"
    refusal = f"error: {command} failed: Unrecognized options: --epoch, 1\n"
    assert (exit.value.code, capsys.readouterr().err) == (2, refusal)


def test_a_failed_job_is_told_by_its_error_line(tmp_path, capsys):
    """main_job_time (baseline.timed_run) told a run that failed by a list of its last line of
    stderr, `['╰────╯']` for a method file's refusal; now by the line inside tyro's box."""
    from benchmark.baseline import timed_run

    script = tmp_path / "refuses.py"
    script.write_text(f"import sys\nsys.stderr.write({TYRO_BOX!r})\nsys.exit(2)\n")
    with pytest.raises(SystemExit) as exit:
        run_cli(lambda: timed_run([sys.executable, str(script), "--epoch", "1"]))
    refusal = f"error: {script} --epoch 1 failed: Unrecognized options: --epoch, 1\n"
    assert (exit.value.code, capsys.readouterr().err) == (2, refusal)


def test_ctrl_c_or_kill_ends_a_tool_in_one_line(capsys):
    """The tools' run_cli (evaluate.py, watch.py, every benchmark module): Ctrl-C printed a traceback of tens of lines,
    and `kill` printed nothing and left step_time's and fingerprint's temporary folders behind. `kill` now raises
    Ctrl-C's KeyboardInterrupt inside main (so `with` blocks clean up), and both end in one line, exit status 130;
    the caller's own SIGTERM handler comes back."""
    handler_before = signal.getsignal(signal.SIGTERM)
    seen = []

    def interrupted_main():
        seen.append(signal.getsignal(signal.SIGTERM))
        raise KeyboardInterrupt

    with pytest.raises(SystemExit) as exit:
        run_cli(interrupted_main)
    assert exit.value.code == 130
    assert capsys.readouterr().err == "interrupted\n"
    assert seen == [signal.default_int_handler]
    assert signal.getsignal(signal.SIGTERM) is handler_before
