"""Hostile inputs: malicious pickles, alias bombs, huge or NaN geometry, bad paths, Ctrl-C.

Every case must end in one line on stderr and exit 2 (130 for Ctrl-C), never run code from a
file, and never leave a run directory that looks finished.
"""

from __future__ import annotations

import base64
import io
import json
import os
import pickle
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from aftir_rl.cli import bench, evaluate, train
from aftir_rl.core.config import CONFIG_DIR
from aftir_rl.core.errors import CheckpointError, ConfigError
from aftir_rl.core.files import write_json
from aftir_rl.core.tank import load_tank
from aftir_rl.rl.sb3 import AtomicCheckpoint, load_run
from aftir_rl.rl.tabular.q_table import QLearning

REF_YAML = CONFIG_DIR / "tanks" / "b737_center.yaml"
PPO_YAML = (
    "env_id: AFTIR-ArmReach-v0\nn_envs: 1\n"  # one env, not the entry's two
    "eval_freq: 100000\neval_targets: 2\ncheckpoint_freq: 64\n"
    "hyperparameters:\n  n_steps: 64\n  batch_size: 32\n"
)


class _Payload:
    """Unpickling this writes a marker file: the proof that code ran."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').write('pwned')",))


def _payload(marker: Path) -> bytes:
    return pickle.dumps(_Payload(marker))


def test_the_payload_is_live(tmp_path):
    marker = tmp_path / "marker"
    pickle.loads(_payload(marker))
    assert marker.exists()


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    """A clean SB3 run directory: an untrained PPO saved as a training run would be."""
    from stable_baselines3 import PPO

    run = tmp_path_factory.mktemp("runs") / "ppo__AFTIR-ArmReach-v0__random__0__now"
    run.mkdir()
    model = PPO("MlpPolicy", gym.make("AFTIR-ArmReach-v0"), n_steps=64, batch_size=32, seed=0)
    model.save(run / "model.zip")
    config = {
        "env_id": "AFTIR-ArmReach-v0",
        "total_timesteps": 128,
        "n_envs": 1,
        "eval_freq": 100000,
        "eval_targets": 2,
        "checkpoint_freq": 64,
        "policy": "MlpPolicy",
        "hyperparameters": {"n_steps": 64, "batch_size": 32},
        "algo": "ppo",
        "seed": 0,
        "resume": None,
    }
    (run / "config.json").write_text(json.dumps(config))
    return run


def _copy_run(run: Path, dest: Path) -> Path:
    dest.mkdir(parents=True)
    for p in run.iterdir():
        if p.is_file():
            (dest / p.name).write_bytes(p.read_bytes())
    return dest


def _rewrite_zip(path: Path, replace: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path) as z:
        files = {n: z.read(n) for n in z.namelist()}
    files.update(replace)
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)


def _poison(run: Path, how: str, marker: Path) -> None:
    model = run / "model.zip"
    if how == "data":  # SB3 would cloudpickle.loads this entry
        with zipfile.ZipFile(model) as z:
            data = json.loads(z.read("data"))
        data["observation_space"][":serialized:"] = base64.b64encode(_payload(marker)).decode()
        _rewrite_zip(model, {"data": json.dumps(data).encode()})
    elif how == "data_new_key":  # an entry SB3 never writes
        with zipfile.ZipFile(model) as z:
            data = json.loads(z.read("data"))
        data["zz_extra"] = {":serialized:": base64.b64encode(_payload(marker)).decode()}
        _rewrite_zip(model, {"data": json.dumps(data).encode()})
    elif how == "pth_raw":  # a bare pickle as the weights
        _rewrite_zip(model, {"policy.pth": _payload(marker)})
    elif how == "pth_torch":  # a real torch archive whose data.pkl runs code
        import torch

        buffer = io.BytesIO()
        torch.save(_Payload(marker), buffer)
        _rewrite_zip(model, {"policy.pth": buffer.getvalue()})
    elif how == "extra_pth":  # a tensor file this algorithm never saves
        import torch

        buffer = io.BytesIO()
        torch.save(_Payload(marker), buffer)
        _rewrite_zip(model, {"env.pth": buffer.getvalue()})


def test_clean_run_loads_without_unpickling(ppo_run, monkeypatch):
    import cloudpickle

    def boom(*args, **kwargs):
        raise AssertionError("cloudpickle.loads ran on a file")

    monkeypatch.setattr(cloudpickle, "loads", boom)
    monkeypatch.setattr(pickle, "loads", boom)
    algo, config, env_id, model = load_run(ppo_run)
    assert algo == "ppo" and env_id == "aftir_rl:AFTIR-ArmReach-v0" and model.n_steps == 64


POISONS = ("data", "data_new_key", "pth_raw", "pth_torch", "extra_pth")


@pytest.mark.parametrize("how", POISONS)
def test_malicious_model_refused_by_evaluate_resume_and_bench(ppo_run, tmp_path, how, capsys):
    marker = tmp_path / "marker"
    run = _copy_run(ppo_run, tmp_path / "run")
    _poison(run, how, marker)
    assert evaluate.main([str(run), "--logdir", str(tmp_path / "ev")]) == 2
    assert "refused" in capsys.readouterr().err
    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML)
    rc = train.main(
        [
            "ppo",
            "--config",
            str(config),
            "--resume",
            str(run),
            "--no-progress",
            "--total-timesteps",
            "64",
            "--logdir",
            str(tmp_path / "again"),
        ]
    )
    assert rc == 2 and "refused" in capsys.readouterr().err
    assert not (tmp_path / "again").exists() or not any((tmp_path / "again").iterdir())
    assert bench.main(["--model", str(run), "--sets", "jace", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "refused" in err and len(err.strip().splitlines()) == 1
    assert not marker.exists()


@pytest.mark.slow
def test_malicious_model_one_line_in_a_subprocess(ppo_run, tmp_path):
    marker = tmp_path / "marker"
    run = _copy_run(ppo_run, tmp_path / "run")
    _poison(run, "pth_torch", marker)
    proc = subprocess.run(
        [sys.executable, "-m", "aftir_rl.evaluate", str(run), "--logdir", str(tmp_path / "ev")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and not marker.exists()
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    "change, message",
    [
        ({"env_id": "somemodule:AFTIR-ArmReach-v0"}, "env_id"),
        ({"env_id": "aftir_rl.evil:AFTIR-ArmReach-v0"}, "env_id"),
        ({"algo": "dqn"}, "algo"),
        ({"algo": ["ppo"]}, "algo"),
        ({"algo": {"ppo": 1}}, "algo"),
        ({"extra": 1}, "unknown key"),
        ({"policy": "Evil"}, "policy"),
        ({"eval_targets": 10**9}, "eval_targets"),
        ({"hyperparameters": {"n_steps": -5}}, "n_steps"),
        ({"hyperparameters": {"policy_kwargs": {"activation_fn": "os.system"}}}, "activation_fn"),
    ],
)
def test_invalid_config_json(ppo_run, tmp_path, change, message, capsys, monkeypatch):
    marker = tmp_path / "imported"
    (tmp_path / "somemodule.py").write_text(f"open({str(marker)!r}, 'w').write('x')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    run = _copy_run(ppo_run, tmp_path / "run")
    config = {**json.loads((run / "config.json").read_text()), **change}
    (run / "config.json").write_text(json.dumps(config))
    assert evaluate.main([str(run), "--logdir", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not marker.exists() and "somemodule" not in sys.modules


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", "\xff\xfe", "[" * 100_000])
def test_config_json_not_a_config(ppo_run, tmp_path, text, capsys):
    run = _copy_run(ppo_run, tmp_path / "run")
    (run / "config.json").write_bytes(text.encode("latin-1"))
    assert evaluate.main([str(run), "--logdir", str(tmp_path / "ev")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


# ------------------------------------------------------------------ Q-table checkpoints


def _q_checkpoint(path: Path, **extra) -> Path:
    env = gym.make("AFTIR-Tank-v0", target=(230, 140, 90))
    agent = QLearning(env, seed=0)
    meta = {
        "env_id": "AFTIR-Tank-v0",
        "tank": "b737_center",
        "target": [230.0, 140.0, 90.0],
        "target_cell": list(env.unwrapped.target_cell),
    }
    hyper = extra.pop("hyperparameters", None)
    agent.save(path, extra={**meta, **extra})
    if hyper is not None:  # rewrite the metadata as an attacker would
        with np.load(path) as data:
            q, m = data["q_table"], json.loads(str(data["metadata"]))
        m["hyperparameters"].update(hyper)
        np.savez(path, q_table=q, metadata=np.array(json.dumps(m)))
    return path


def test_q_table_env_id_never_imports(tmp_path, capsys, monkeypatch):
    marker = tmp_path / "imported"
    (tmp_path / "somemodule.py").write_text(f"open({str(marker)!r}, 'w').write('x')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    run = tmp_path / "run"
    run.mkdir()
    _q_checkpoint(run / "q_table.npz", env_id="somemodule:AFTIR-Tank-v0")
    assert evaluate.main([str(run), "--logdir", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err
    assert "env_id" in err and len(err.strip().splitlines()) == 1
    assert not marker.exists() and "somemodule" not in sys.modules


@pytest.mark.parametrize(
    "extra, message",
    [
        ({"hyperparameters": {"gamma": 7}}, "gamma"),
        ({"hyperparameters": {"surprise": 1}}, "hyperparameters must hold exactly"),
        ({"hyperparameters": {"learning_rate": "fast"}}, "learning_rate"),
        ({"rng_state": [3, [1, 2], None]}, "rng_state"),
        ({"episodes_done": "many"}, "episodes_done"),
        ({"tank": ["b737_center"]}, "tank"),
        ({"target": [1, 2]}, "target"),
        ({"env_id": "AFTIR-Arm-v0"}, "env_id"),
    ],
)
def test_malformed_q_table_metadata(tmp_path, extra, message):
    path = _q_checkpoint(tmp_path / "q.npz", **extra)
    with pytest.raises(CheckpointError, match=message):
        QLearning.read_checkpoint(path)


def test_q_table_from_another_tank_is_refused(tmp_path, capsys):
    path = _q_checkpoint(tmp_path / "q.npz", tank_fingerprint="0123456789abcdef")
    rc = train.main(
        [
            "q_table",
            "--target",
            "230",
            "140",
            "90",
            "--resume",
            str(path),
            "--episodes",
            "1",
            "--no-postures",
            "--no-progress",
            "--logdir",
            str(tmp_path / "runs"),
        ]
    )
    assert rc == 2 and "another tank" in capsys.readouterr().err


def test_q_table_checkpoint_records_the_tank(tmp_path):
    run = tmp_path / "runs"
    assert (
        train.main(
            [
                "q_table",
                "--target",
                "-50",
                "72",
                "90",
                "--episodes",
                "300",
                "--no-postures",
                "--no-progress",
                "--logdir",
                str(run),
            ]
        )
        == 0
    )
    (run_dir,) = run.iterdir()
    _, meta = QLearning.read_checkpoint(run_dir / "q_table.npz")
    assert meta["tank_fingerprint"] == load_tank("b737_center").fingerprint
    mode = (run_dir / "q_table.npz").stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask


# ------------------------------------------------------------------ YAML and tanks


def _tank(tmp_path: Path, text: str, name: str = "t.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _ref(old: str, new: str) -> str:
    text = REF_YAML.read_text()
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize(
    "text, message",
    [
        (_ref("box: {min: [-60, -50, 0]", "box: {min: [-1e200, -50, 0]"), "out of range"),
        (_ref("box: {min: [-60, -50, 0]", "box: {min: [-1e20, -50, 0]"), "out of range"),
        (_ref("box: {min: [-60, -50, 0]", "box: {min: [.nan, -50, 0]"), "finite"),
        (_ref("radius: 5}", "radius: 1e300}"), "out of range"),
        (_ref("start_point: [0, 0, 10]", "start_point: [0, 0, 1e200]"), "out of range"),
        (_ref("- [230, 140, 90]", "- [230, 140, 1e200]"), "out of range"),
        (_ref("cell_size: 20", "cell_size: 0.5"), "cells, more than"),
        (_ref("cell_size: 20", "cell_size: 0.1"), "cells, more than"),
        (_ref("cell_size: 20", "cell_size: 1" + "0" * 5000), "not valid YAML"),
        (_ref("max_sections: 12", "max_sections: 100000000"), "max_sections"),
        (
            "a: &a [1,1,1,1,1,1,1,1,1]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n"
            "c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\nd: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n"
            "e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\nf: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]\n"
            "g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]\nbox: {min: *g, max: *g}\n",
            "expands to more",
        ),
        ("box: " + "[" * 50_000 + "]" * 50_000, "nested too deeply"),
        ("box:\n" + "- " * 5000 + "1\n", "nested too deeply"),
        ("box: !!python/object/apply:os.system ['true']", "YAML"),
        ("1: 2\nbox: 3\n", "unknown key"),
        ("box: {min: [0, 0, 0], max: [10, 10, 10]}\nobstacles: [{type: [1]}]\n", "type"),
    ],
)
def test_hostile_tank_yaml_is_refused_fast(tmp_path, text, message):
    path = _tank(tmp_path, text)
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=message) as info:
        load_tank(path)
    assert time.perf_counter() - start < 1.5
    assert len(str(info.value)) < 600


def test_large_and_non_utf8_files(tmp_path):
    with pytest.raises(ConfigError, match="not UTF-8"):
        load_tank(_bytes(tmp_path))
    big = tmp_path / "big.yaml"
    big.write_text("description: " + "x" * 2_000_000 + "\n")
    with pytest.raises(ConfigError, match="larger than"):
        load_tank(big)
    huge = tmp_path / "huge.yaml"
    huge.write_text("box: {min: [" + ", ".join(["1"] * 20_000) + "]}\n")
    with pytest.raises(ConfigError) as info:
        load_tank(huge)
    assert len(str(info.value)) < 600


def _bytes(tmp_path: Path) -> Path:
    path = tmp_path / "latin1.yaml"
    path.write_bytes("description: caf\xe9\n".encode("latin-1"))
    return path


def test_plan_does_not_build_the_raster(tmp_path):
    from aftir_rl.planning.posture.planner import Planner

    # a tank of its own (tanks are cached by content): the reference with one more comment
    path = _tank(tmp_path, REF_YAML.read_text() + "\n# a copy\n", "ref_copy.yaml")
    tank = load_tank(path)
    assert "raster" not in tank.__dict__
    Planner(tank).plan((30.0, 0.0, 60.0))
    assert "raster" not in tank.__dict__


def test_tank_cli_one_line_and_closed_stdout(tmp_path):
    bad = _tank(tmp_path, _ref("box: {min: [-60, -50, 0]", "box: {min: [-1e200, -50, 0]"))
    proc = subprocess.run(
        [sys.executable, "-m", "aftir_rl.cli", "tank", "--tank", str(bad)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    # a reader that went away: one line, exit 2
    proc = subprocess.Popen(
        [sys.executable, "-m", "aftir_rl.cli", "tank", "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait() == 2 and "broken pipe" in err and len(err.strip().splitlines()) == 1
    # a full disk
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            [sys.executable, "-m", "aftir_rl.cli", "tank", "--json"],
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
        )
    assert proc.returncode == 2 and "no space left" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


# ------------------------------------------------------------------ command lines


@pytest.mark.parametrize(
    "yaml_text, message",
    [
        ("hyperparameters:\n  n_steps: -5\n", "n_steps"),
        ("hyperparameters:\n  learning_rate: fast\n", "learning_rate"),
        ("hyperparameters:\n  learning_rate: lin_fast\n", "learning_rate"),
        ("hyperparameters:\n  learning_rate: lin_50\n", "learning_rate"),
        ("hyperparameters:\n  gamma: 7\n", "gamma"),
        ("hyperparameters:\n  policy_kwargs: {net_arch: [100000000]}\n", "net_arch"),
        ("hyperparameters:\n  rollout_buffer_class: os.system\n", "Python object"),
        ("policy: NopePolicy\n", "policy"),
        ("n_envs: 0\n", "n_envs"),
        ("eval_targets: 0\n", "eval_targets"),
        ("total_timesteps: 1e12\n", "total_timesteps"),
        ("env_id: somemodule:AFTIR-ArmReach-v0\n", "env_id"),
    ],
)
def test_bad_sb3_config_refused_before_training(tmp_path, yaml_text, message, capsys):
    config = tmp_path / "ppo.yaml"
    config.write_text("env_id: AFTIR-ArmReach-v0\n" + yaml_text)
    start = time.perf_counter()
    rc = train.main(
        ["ppo", "--config", str(config), "--logdir", str(tmp_path / "runs"), "--no-progress"]
    )
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1
    assert time.perf_counter() - start < 5
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


@pytest.mark.parametrize("algo", ["q_table", "ppo"])
def test_bad_seed_and_logdir(tmp_path, algo, capsys):
    assert train.main([algo, "--seed", "-1", "--logdir", str(tmp_path)]) == 2
    assert "--seed" in capsys.readouterr().err
    afile = tmp_path / "file"
    afile.write_text("")
    args = ["--target", "230", "140", "90", "--episodes", "1"] if algo == "q_table" else []
    extra = ["--total-timesteps", "64"] if algo == "ppo" else []
    assert train.main([algo, *args, *extra, "--logdir", str(afile), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_evaluate_logdir_is_a_file(ppo_run, tmp_path, capsys):
    afile = tmp_path / "file"
    afile.write_text("")
    assert evaluate.main([str(ppo_run), "--logdir", str(afile)]) == 2
    err = capsys.readouterr().err
    assert "not a directory" in err and "|" not in capsys.readouterr().out


def test_atomic_writes_get_ordinary_modes(tmp_path):
    write_json(tmp_path / "a.json", {"a": 1})
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o666 & ~umask


def test_resumed_callbacks_continue_their_counters():
    class Model:
        num_timesteps = 150

    callback = AtomicCheckpoint(Path("/nonexistent"), 50)
    callback.init_callback(Model())  # type: ignore[arg-type]
    assert callback._period.next_step == 200


@pytest.mark.slow
def test_ctrl_c_saves_a_resumable_partial_run(tmp_path):
    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML.replace("checkpoint_freq: 64", "checkpoint_freq: 100000"))
    runs = tmp_path / "runs"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "aftir_rl.train",
            "ppo",
            "--config",
            str(config),
            "--total-timesteps",
            "1000000",
            "--logdir",
            str(runs),
            "--no-progress",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.time() + 60
    while time.time() < deadline and not list(runs.glob(".*.partial/progress.csv")):
        time.sleep(0.2)
    time.sleep(2)
    proc.send_signal(signal.SIGINT)
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 130
    assert err.strip().startswith("interrupted") and len(err.strip().splitlines()) == 1
    (partial,) = runs.iterdir()
    assert partial.name.startswith(".") and partial.name.endswith(".partial")
    assert not (partial / "model.zip").exists()
    (saved,) = (partial / "checkpoints").glob("model_*.zip")
    steps = int(saved.stem.split("_")[1])
    assert steps > 0
    # --resume RUN_DIR finishes that run from its checkpoint (to its --total-timesteps, here
    # 128 after it); its checkpoints follow on, no burst
    config.write_text(PPO_YAML)
    again = tmp_path / "again"
    assert (
        train.main(
            [
                "ppo",
                "--config",
                str(config),
                "--resume",
                str(partial),
                "--total-timesteps",
                str(steps + 128),
                "--logdir",
                str(again),
                "--no-progress",
            ]
        )
        == 0
    )
    (run_dir,) = again.iterdir()
    assert not run_dir.name.startswith(".") and (run_dir / "model.zip").exists()
    saved = sorted(int(p.stem.split("_")[1]) for p in (run_dir / "checkpoints").iterdir())
    assert len(saved) == 2 and saved[0] > steps
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["timesteps"] == steps + 128


@pytest.mark.parametrize("command", ["check", "evaluate", "export", "view", "rollout", "runs"])
def test_names_from_files_reach_the_terminal_as_text(tmp_path, command, capsys):
    """A run folder named with terminal escapes (retitle, bell, clear) is printed as text."""
    import importlib

    evil = tmp_path / "r\x1b]0;pwned\x07\x1b[2J\x9b"
    (evil / "x").mkdir(parents=True)
    (evil / "x" / "unfinished.json").write_text("{}")
    main = importlib.import_module(f"aftir_rl.cli.{command}").main
    output = ["-o", str(tmp_path / "out")]
    args = {"runs": [str(evil)], "export": [str(evil), *output], "rollout": [str(evil), *output]}
    code = main(args.get(command, [str(evil)]))
    out, err = capsys.readouterr()
    assert code == (0 if command == "runs" else 2) and "pwned" in out + err
    assert not set(out + err) & {"\x1b", "\x07", "\x9b"}


def test_printable_output_keeps_lines_and_progress_bars():
    from aftir_rl.core.config import printable

    assert printable("a\tb\r\nc\x1b[Ad\x08") == "a\tb\r\nc?[Ad?"
    assert printable("bar\r\x1b[A\x1b]0;t\x07", cursor_up=True) == "bar\r\x1b[A?]0;t?"
