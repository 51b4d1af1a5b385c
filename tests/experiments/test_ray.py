"""Ray: bench/evaluate fanned out as tasks, `aftir tune` sweeps, and the serial path without Ray.

The fast tier never starts Ray (the tests that do are marked slow); tests that need the ray extra
skip where it is not installed.
"""

from __future__ import annotations

import csv
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aftir_rl.core.config import CONFIG_DIR
from aftir_rl.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]

BASE_PPO = """\
env_id: AFTIR-ArmReach-v0
total_timesteps: 256
n_envs: 1
eval_freq: 64
eval_targets: 2
checkpoint_freq: 100000
policy: MlpPolicy
hyperparameters:
  learning_rate: 3e-4
  n_steps: 64
  batch_size: 32
  n_epochs: 2
"""
SPACE_PPO = """\
hyperparameters:
  learning_rate: {loguniform: [1.0e-5, 1.0e-3]}
  n_steps: {choice: [32, 64]}
  gamma: {uniform: [0.9, 0.99]}
"""


def _python(*args: str, timeout: float = 600, **kwargs) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, cwd=ROOT, timeout=timeout, **kwargs
    )


#: Bench methods whose clearance and path come from OMPL's path simplifier, which runs for a time
#: budget: they differ between two serial runs too (their success and tip error do not).
TIMED = ("rrt_connect", "q_table+postures")


def _without_seconds(table: str) -> list[str]:
    """The rows of a bench or evaluate table less the seconds column (and TIMED's timed cells)."""
    rows = []
    for line in table.splitlines():
        if not line.startswith("| "):
            continue
        cells = line.split(" | ")
        del cells[-2]  # "s / target", before the note
        if len(cells) > 7 and cells[1] in TIMED:
            cells[5] = cells[7] = "timed"  # min clearance, path
        rows.append(" | ".join(cells))
    return rows


# ---------------------------------------------------------------- fast: no Ray started


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_kill_local_workers_ends_only_the_titles_named_under_this_process():
    from aftir_rl.experiments.distributed import kill_local_workers

    sleep = ["-c", "import time; time.sleep(60)"]
    trial = subprocess.Popen(["ray::ImplicitFunc.train", *sleep], executable=sys.executable)
    other = subprocess.Popen(["ray::DashboardAgent", *sleep], executable=sys.executable)
    try:
        deadline = time.time() + 10
        while Path(f"/proc/{trial.pid}/cmdline").read_bytes().startswith(b"ray::") is False:
            assert time.time() < deadline
            time.sleep(0.01)
        assert kill_local_workers(("ray::ImplicitFunc", "ray::IDLE")) == 1
        assert trial.wait(timeout=10) == -signal.SIGKILL
        assert other.poll() is None
        assert kill_local_workers(("ray::ImplicitFunc",), root=1) == 0  # not below init's pid
    finally:
        for proc in (trial, other):
            proc.kill()
            proc.wait()


def test_modules_import_without_ray():
    code = (
        "import sys; sys.modules['ray'] = None\n"  # `import ray` raises ImportError
        "import aftir_rl.experiments.bench, aftir_rl.cli.evaluate, "
        "aftir_rl.experiments.distributed, "
        "aftir_rl.experiments.tune, aftir_rl.cli.bench, aftir_rl.cli.tune, aftir_rl.cli.main\n"
        "print('ok')"
    )
    run = _python("-c", code)
    assert run.returncode == 0, run.stderr
    run = _python(
        "-c",
        "import aftir_rl.experiments.bench, aftir_rl.experiments.tune, sys; "
        "print('ray' in sys.modules)",
    )
    assert run.stdout.strip() == "False"


@pytest.mark.parametrize(
    "module,args",
    [
        ("aftir_rl.bench", ["--sets", "jace", "--ray", "local"]),
        ("aftir_rl.evaluate", ["runs/none", "--ray", "local"]),
        ("aftir_rl.tune", ["ppo", "--trials", "2"]),
    ],
)
def test_ray_missing_is_one_line(module, args):
    code = (
        "import sys; sys.modules['ray'] = None\n"
        f"from {module} import main\n"
        f"sys.exit(main({args!r}))"
    )
    run = _python("-c", code)
    assert run.returncode == 2
    assert run.stderr.strip().count("\n") == 0, run.stderr
    assert 'pip install "aftir_rl[ray]"' in run.stderr


@pytest.mark.parametrize(
    "args,message",
    [
        (["--ray", "not an address"], "use local, auto, HOST:PORT"),
        (["--workers", "2"], "--workers needs --ray local"),
        (["--ray", "local", "--workers", "0"], "--workers must be from 1"),
        (["--ray", "auto", "--workers", "2"], "a cluster has its own"),
    ],
)
def test_bad_ray_options(args, message, capsys):
    from aftir_rl.cli.bench import main

    assert main(["--sets", "jace", "--quiet", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.strip().count("\n") == 0


def test_no_cluster_at_the_address_is_one_line(capsys):
    pytest.importorskip("ray")
    import socket

    from aftir_rl.cli.bench import main

    with socket.socket() as sock:  # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    assert main(["--sets", "jace", "--quiet", "--ray", f"127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err
    assert "cannot reach a Ray cluster" in err and err.strip().count("\n") == 0


def test_tune_help_and_dispatch(capsys):
    from aftir_rl.cli.main import SUBCOMMANDS
    from aftir_rl.cli.main import main as aftir

    assert SUBCOMMANDS["tune"][0] == "aftir_rl.cli.tune"
    with pytest.raises(SystemExit) as exit_:
        aftir(["tune", "--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert "--trials" in out and "--ray" in out and "--total-timesteps" in out
    run = _python("-m", "aftir_rl.tune", "--help")
    assert run.returncode == 0 and "--logdir" in run.stdout


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_shipped_search_spaces_load(algo):
    from aftir_rl.experiments.tune import load_search_space
    from aftir_rl.rl.sb3 import entry_config

    base = entry_config(algo, "AFTIR-ArmReach-v0")
    space = load_search_space(CONFIG_DIR / "search_spaces" / f"{algo}.yaml", algo, base)
    assert {d.key for d in space} >= {"learning_rate", "batch_size", "gamma"}


@pytest.mark.parametrize(
    "text,message",
    [
        ("hyperparameters:\n  gamma: {uniform: [0.9, 1.5]}\n", "expected a number from 0 to 1"),
        ("hyperparameters:\n  learning_rate: {loguniform: [0, 1.0e-3]}\n", "LOW must be above 0"),
        ("hyperparameters:\n  gamma: {normal: [0.9, 0.1]}\n", "unknown distribution"),
        ("hyperparameters:\n  gamma: {uniform: [0.99, 0.9]}\n", "LOW must be below HIGH"),
        ("hyperparameters:\n  gamma: 0.9\n", "expected one distribution"),
        ("hyperparameters:\n  no_such: {choice: [1, 2]}\n", "unknown key 'no_such' for PPO"),
        ("hyperparameters:\n  action_noise: {choice: [1]}\n", "unknown key 'action_noise'"),
        ("hyperparameters:\n  n_steps: {choice: [64, 0]}\n", "n_steps: expected an integer from 1"),
        ("hyperparameters:\n  batch_size: {randint: [1, 64]}\n", "at least 2 for PPO"),
        ("hyperparameters:\n  n_steps: {choice: [[1, 2]]}\n", "expected a plain value"),
        ("hyperparameters:\n  n_steps: {choice: [64, 64]}\n", "repeated"),
        ("learning_rate: {loguniform: [1.0e-5, 1.0e-3]}\n", "unknown key 'learning_rate'"),
        ("hyperparameters: {}\n", "expected a mapping of 1 to 32 keys"),
    ],
)
def test_search_space_is_checked(tmp_path, text, message):
    from aftir_rl.experiments.tune import load_search_space
    from aftir_rl.rl.sb3 import entry_config

    base = entry_config("ppo", "AFTIR-ArmReach-v0")
    path = tmp_path / "space.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_search_space(path, "ppo", base)


@pytest.mark.slow  # a CLI subprocess; load_search_space's errors are checked in-process above
def test_bad_space_file_is_one_line(tmp_path):
    pytest.importorskip("ray")
    space = tmp_path / "space.yaml"
    space.write_text("hyperparameters:\n  gamma: {uniform: [0.9, 2]}\n")
    run = _python("-m", "aftir_rl.tune", "ppo", "--space", str(space), "--logdir", str(tmp_path))
    assert run.returncode == 2 and run.stderr.strip().count("\n") == 0, run.stderr
    assert "gamma" in run.stderr
    assert not list(tmp_path.glob("tune__*"))  # nothing started


def test_best_config_yaml_is_a_training_config(tmp_path):
    import dataclasses

    from aftir_rl.experiments.tune import write_config_yaml
    from aftir_rl.rl.sb3 import entry_config, load_sb3_config

    base = entry_config("ppo", "AFTIR-ArmReach-v0")
    best = dataclasses.replace(
        base, hyperparameters={**base.hyperparameters, "learning_rate": 1.234e-05, "gamma": 0.97}
    )
    path = tmp_path / "best.yaml"
    trial = {"success_rate": 0.5, "tip_error_cm": 1.0, "timesteps": 256, "run_dir": "x"}
    write_config_yaml(path, best, "ppo", trial)
    assert load_sb3_config(path, "ppo") == best


def test_a_stopped_trial_becomes_a_run_directory(tmp_path):
    from aftir_rl.experiments.tune import _finish_stopped

    run_dir = tmp_path / "ppo__AFTIR-ArmReach-v0__random__0__x"
    partial = tmp_path / f".{run_dir.name}.partial"
    partial.mkdir()
    (partial / "model.zip").write_bytes(b"zip")
    result = {"eval/success_rate": 0.25, "eval/tip_error_cm": 3.0, "timesteps": 128}
    _finish_stopped(run_dir, result, "ppo", "AFTIR-ArmReach-v0")
    assert not partial.exists() and (run_dir / "model.zip").exists()
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["stopped_early"] is True and summary["success_rate"] == 0.25
    assert summary["timesteps"] == 128 and summary["run_dir"] == str(run_dir)


# ---------------------------------------------------------------- slow: Ray started


@pytest.fixture
def local_ray():
    """One in-process Ray with 2 CPUs for the in-process tests of this module."""
    ray = pytest.importorskip("ray")
    from aftir_rl.experiments.distributed import ray_session

    with ray_session("local", 2) as r:
        yield r
    assert not ray.is_initialized()


@pytest.mark.slow
def test_failed_tasks_are_results(local_ray, tmp_path):
    from aftir_rl.experiments.bench import target_sets
    from aftir_rl.experiments.distributed import (
        TaskFailure,
        benchmark_on_ray,
        evaluate_on_ray,
        run_tasks,
    )

    out = run_tasks(divmod, [(7, 2), (1, 0), (9, 4)])
    assert out[0] == (3, 1) and out[2] == (2, 1)
    assert isinstance(out[1], TaskFailure) and out[1].error.startswith("ZeroDivisionError")

    sets = {"jace": target_sets(1)["jace"][:2]}
    rows = benchmark_on_ray(sets, {"jace": ("tga", "no_such_method")}, {"seed": 0})
    assert [r.method for r in rows] == ["tga", "no_such_method"]
    assert all(o.success for o in rows[0].outcomes)
    assert all(o.note.startswith("task failed: ") for o in rows[1].outcomes)

    broken = tmp_path / "broken_run"
    broken.mkdir()
    (broken / "model.zip").write_bytes(b"not a zip")
    (broken / "config.json").write_text("{}")
    (row,) = evaluate_on_ray([broken], None, "ftl", 1.0)
    assert row["note"].startswith("task failed: ") and row["targets"] == 0


@pytest.mark.slow
def test_bench_on_ray_gives_the_serial_table():
    pytest.importorskip("ray")
    args = ["-m", "aftir_rl.bench", "--sets", "jace", "bay1", "--n-random", "2", "--quiet"]
    serial = _python(*args)
    assert serial.returncode == 0, serial.stderr
    on_ray = _python(*args, "--ray", "local", "--workers", "2")
    assert on_ray.returncode == 0, on_ray.stderr
    rows = _without_seconds(serial.stdout)
    assert len(rows) == 1 + 4 + 7  # header, the jace and bay1 methods
    assert _without_seconds(on_ray.stdout) == rows


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """A sweep of 4 PPO trials of 256 steps on AFTIR-ArmReach-v0, on a local Ray of 2 CPUs."""
    pytest.importorskip("ray")
    tmp = tmp_path_factory.mktemp("tune")
    (tmp / "base.yaml").write_text(BASE_PPO)
    (tmp / "space.yaml").write_text(SPACE_PPO)
    run = _python(
        "-m",
        "aftir_rl.tune",
        "ppo",
        "--env",
        "AFTIR-ArmReach-v0",
        "--trials",
        "4",
        "--workers",
        "2",
        "--total-timesteps",
        "256",
        "--config",
        str(tmp / "base.yaml"),
        "--space",
        str(tmp / "space.yaml"),
        "--logdir",
        str(tmp / "runs"),
        "--quiet",
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    (folder,) = (tmp / "runs").glob("tune__ppo__AFTIR-ArmReach-v0__*")
    return tmp, folder, run.stdout


@pytest.mark.slow
def test_sweep_writes_runs_and_a_best_config(sweep):
    tmp, folder, stdout = sweep
    with open(folder / "trials.csv") as fh:
        trials = list(csv.DictReader(fh))
    assert len(trials) == 4 and not any(t["error"] for t in trials)
    for t in trials:
        run = Path(t["run_dir"])
        assert run.parent == folder and (run / "model.zip").exists()
        assert list(run.glob("events.out.tfevents.*")) and (run / "summary.json").exists()
        assert 1e-5 <= float(t["learning_rate"]) <= 1e-3 and t["n_steps"] in ("32", "64")
    assert not list(folder.glob(".*.partial"))
    assert "best config:" in stdout and (folder / "best.yaml").exists()
    # `train ppo --config best.yaml` takes it
    run = _python(
        "-m",
        "aftir_rl.train",
        "ppo",
        "--config",
        str(folder / "best.yaml"),
        "--total-timesteps",
        "64",
        "--logdir",
        str(tmp / "again"),
        "--no-progress",
    )
    assert run.returncode == 0, run.stderr[-2000:]


@pytest.mark.slow
def test_evaluate_on_ray_gives_the_serial_table(sweep):
    tmp, folder, _ = sweep
    runs = sorted(str(p) for p in folder.glob("ppo__*"))[:3]
    args = ["-m", "aftir_rl.evaluate", *runs, "--logdir", str(tmp / "eval")]
    serial = _python(*args)
    assert serial.returncode == 0, serial.stderr[-2000:]
    on_ray = _python(*args, "--ray", "local", "--workers", "2")
    assert on_ray.returncode == 0, on_ray.stderr[-2000:]
    rows = _without_seconds(serial.stdout)
    assert len(rows) == 1 + 3
    assert _without_seconds(on_ray.stdout) == rows


@pytest.mark.slow
def test_ctrl_c_ends_a_sweep_in_seconds_and_keeps_the_trial_to_resume(tmp_path):
    pytest.importorskip("ray")
    (tmp_path / "base.yaml").write_text(BASE_PPO.replace("eval_freq: 64", "eval_freq: 100000"))
    args = ["ppo", "--env", "AFTIR-ArmReach-v0", "--trials", "2", "--workers", "2"]
    args += ["--total-timesteps", "1000000", "--config", str(tmp_path / "base.yaml")]
    proc = subprocess.Popen(
        [sys.executable, "-m", "aftir_rl.tune", *args, "--logdir", str(tmp_path), "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    deadline = time.time() + 180
    while not list(tmp_path.glob("tune__*/.ppo__*.partial/progress.csv")):
        assert proc.poll() is None and time.time() < deadline, proc.stderr.read()
        time.sleep(0.1)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    start = time.perf_counter()
    code = proc.wait(timeout=60)
    seconds = time.perf_counter() - start
    err = proc.stderr.read().strip()
    # 2-5 s measured on 2 cores (Ray Tune alone waits 10 s for a trial to stop); slack for CI
    assert code == 130 and seconds < 8, (seconds, err)
    assert err.splitlines()[-1].startswith("interrupted: the sweep so far is in")
    (sweep,) = tmp_path.glob("tune__*")
    assert (sweep / "trials.csv").is_file()
    assert list(sweep.glob(".ppo__*.partial"))  # the trials, unfinished: kept to resume
    assert "Traceback" not in err
