"""Ctrl-C, SIGTERM and failing disks: a run keeps what it learnt, says so in one line, resumes.

The fast tests check the shared pieces (:mod:`aftir_rl.core.interrupts`, the command lines'
handler, atomic writes, the kept partial directory, the logger); the slow ones interrupt real
runs, in this process and in subprocesses, and fail their writes at the k-th one.
"""

from __future__ import annotations

import errno
import io
import json
import os
import random
import signal
import subprocess
import sys
import time
import weakref
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from aftir_rl.cli import train
from aftir_rl.cli.guard import cli
from aftir_rl.core import files, interrupts
from aftir_rl.core.files import WriteError, atomic_open, describe_write_error, staged_dir
from aftir_rl.rl.tabular.checkpoint import read_q_table
from aftir_rl.rl.tabular.q_table import QLearning

ROOT = Path(__file__).resolve().parents[2]
PPO_YAML = (
    "env_id: AFTIR-ArmReach-v0\nn_envs: 1\n"  # one env, not the entry's two
    "eval_freq: 100000\neval_targets: 2\ncheckpoint_freq: 64\n"
    "hyperparameters:\n  n_steps: 64\n  batch_size: 32\n"
)
TARGET = ["-50", "140", "10"]
#: What a process killed by a second Ctrl-C while it shuts down reports, besides 130.
STOPPED = (130, -signal.SIGINT)


def _q_args(logdir: Path, *more: str) -> list[str]:
    return ["q_table", "--target", *TARGET, "--logdir", str(logdir), "--no-progress", *more]


def _ppo_args(config: Path, logdir: Path, total: int, *more: str) -> list[str]:
    return [
        "ppo",
        "--config",
        str(config),
        "--total-timesteps",
        str(total),
        "--logdir",
        str(logdir),
        "--no-progress",
        *more,
    ]


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def _resume_dir(line: str) -> Path:
    """The run directory of the ``--resume DIR`` hint that ends ``line``."""
    assert "--resume " in line, line
    return Path(line.rsplit("--resume ", 1)[1].strip())


# ---------------------------------------------------------------- the shared mechanism (fast)


def test_a_signal_raises_outside_a_loop_and_only_asks_inside_one():
    interrupts.reset()
    try:
        with interrupts.deferred():
            interrupts.on_signal(signal.SIGINT, None)  # a loop polls the flag
        assert interrupts.requested()
        interrupts.reset()
        with pytest.raises(KeyboardInterrupt):
            interrupts.on_signal(signal.SIGTERM, None)  # nothing to finish: at once
    finally:
        interrupts.reset()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_cli_turns_sigint_and_sigterm_into_one_line_and_130(sig, capsys):
    before = signal.getsignal(sig)

    @cli
    def main() -> int:
        os.kill(os.getpid(), sig)
        time.sleep(5)  # interrupted at once: no loop asked to finish a step
        return 0

    @cli
    def saves() -> int:
        raise KeyboardInterrupt("the model is saved in X; continue with --resume X")

    start = time.perf_counter()
    assert main() == 130 and time.perf_counter() - start < 1
    assert _one_line(capsys.readouterr().err) == "interrupted"
    assert saves() == 130
    assert _one_line(capsys.readouterr().err).endswith("continue with --resume X")
    assert signal.getsignal(sig) is before and not interrupts.requested()


def test_a_signal_that_lands_in_a_callback_is_raised_again(capsys):
    """Python drops a KeyboardInterrupt raised in a weakref callback; the command still stops."""

    class Held:
        pass

    @cli
    def main() -> int:
        held = Held()
        ref = weakref.ref(held, lambda _: os.kill(os.getpid(), signal.SIGINT))  # noqa: F841
        del held  # the signal's handler runs inside the callback, which cannot raise
        time.sleep(5)  # the command would go on
        return 0

    start = time.perf_counter()
    assert main() == 130 and time.perf_counter() - start < 1
    err = capsys.readouterr().err
    assert _one_line(err) == "interrupted" and "Exception ignored" not in err
    assert not interrupts.requested()


def test_a_second_signal_exits_at_once():
    code = (
        "import os, signal, time\n"
        "from aftir_rl.cli.guard import cli\n"
        "from aftir_rl.core import interrupts\n"
        "@cli\n"
        "def main():\n"
        "    with interrupts.deferred():\n"
        "        print('ready', flush=True)\n"
        "        time.sleep(30)  # a step that does not end\n"
        "    return 0\n"
        "raise SystemExit(main())\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "ready"
    proc.send_signal(signal.SIGINT)
    time.sleep(0.2)
    assert proc.poll() is None  # the first asks the step to finish
    proc.send_signal(signal.SIGTERM)
    start = time.perf_counter()
    assert proc.wait(timeout=5) == 130 and time.perf_counter() - start < 1
    assert _one_line(proc.stderr.read()) == interrupts.AT_ONCE


def test_ctrl_c_is_held_back_while_workers_start_not_lost():
    from aftir_rl.rl.sb3.train import _ctrl_c_held

    previous = signal.signal(signal.SIGINT, interrupts.on_signal)
    interrupts.reset()
    try:
        with interrupts.deferred():
            with _ctrl_c_held():
                os.kill(os.getpid(), signal.SIGINT)
                child = subprocess.run(
                    ["grep", "SigBlk", "/proc/self/status"], capture_output=True, text=True
                )
            assert interrupts.requested()  # delivered (now at the latest), not lost
        if child.returncode == 0:  # Linux: the workers start with SIGINT blocked
            assert int(child.stdout.split()[1], 16) & (1 << (signal.SIGINT - 1))
    finally:
        signal.signal(signal.SIGINT, previous)
        interrupts.reset()


def test_q_learning_stops_after_the_episode_and_resumes_to_the_same_table(tmp_path, monkeypatch):
    env = gym.make("AFTIR-Tank-v0", target=(230, 72, 10))
    config = train.load_q_table_config(str(ROOT / "configs" / "q_table.yaml"))
    straight = QLearning.from_config(env, config, seed=3).learn(300)
    run = QLearning._run_episode
    calls = {"n": 0}

    def episode(self, *args):
        calls["n"] += 1
        if calls["n"] == 137:
            interrupts.on_signal(signal.SIGINT, None)  # Ctrl-C in the middle of an episode
        return run(self, *args)

    monkeypatch.setattr(QLearning, "_run_episode", episode)
    agent = QLearning.from_config(env, config, seed=3)
    interrupts.reset()
    try:
        with interrupts.deferred():
            agent.learn(300)
    finally:
        interrupts.reset()
    assert agent.episodes_done == 137  # that episode finished, no other began
    resumed = QLearning.load(agent.save(tmp_path / "q"), env).learn(300 - 137)
    assert np.array_equal(resumed.q_table, straight.q_table)
    assert resumed.num_timesteps == straight.num_timesteps


# ---------------------------------------------------------------- failing disks (fast)


def test_a_failed_atomic_write_names_the_file_and_keeps_the_old_one(tmp_path):
    path = tmp_path / "model.zip"
    path.write_bytes(b"old")
    with pytest.raises(WriteError) as info:
        with atomic_open(path, "wb") as fh:
            fh.write(b"x" * 5000)
            fh.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # no file named
    assert info.value.filename == str(path) and info.value.needed == 5000
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["model.zip"]
    line = describe_write_error(info.value)
    assert line.startswith(f"no space left on the device writing {path} (it needs more than 5.0 kB")
    eio = WriteError(OSError(errno.EIO, "Input/output error"), path)
    assert describe_write_error(eio) == f"input/output error writing {path}"


@pytest.mark.parametrize("keep", [True, False])
def test_a_run_on_a_full_disk_is_kept_with_its_logs(tmp_path, keep):
    final = tmp_path / "run"
    with pytest.raises(WriteError) as info:
        with staged_dir(final, keep=lambda p: keep) as partial:
            (partial / "progress.csv").write_text("a\n")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert info.value.kept == partial and info.value.resumable is keep
    assert (partial / "progress.csv").exists() and not final.exists()
    line = describe_write_error(info.value)
    assert (f"--resume {partial}" in line) is keep and str(partial) in line
    with pytest.raises(KeyboardInterrupt):  # anything else still removes what is not kept
        with staged_dir(tmp_path / "other") as partial:
            raise KeyboardInterrupt
    assert not partial.exists()


def test_the_run_logger_names_its_file_and_closes_quietly(tmp_path):
    from aftir_rl.rl.logs import run_logger

    with pytest.raises(WriteError) as info:
        with run_logger(tmp_path) as logger:
            csv = logger.output_formats[0].inner
            csv.file.close()
            csv.file = _Full()
            logger.record("a", 1.0)
            logger.dump(0)
    assert info.value.filename == str(tmp_path / "progress.csv")


class _Full:
    """A file on a full disk."""

    def write(self, data: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    flush = seek = readlines = write

    def close(self) -> None:
        pass


# ---------------------------------------------------------------- helpers of the slow tests


class _FailingWriter(io.BufferedWriter):
    """A file on a disk whose writes fail with ``code`` (found full, or failing)."""

    def __init__(self, fd: int, code: int) -> None:
        super().__init__(io.FileIO(fd, "w"))
        self.code = code

    def write(self, data):
        raise OSError(self.code, os.strerror(self.code))


def _fail_writes(monkeypatch, k: int, code: int, after: bool = True) -> None:
    """The k-th atomic write (and, with ``after``, every later one) fails with ``code``."""
    real, count = os, [0]

    class Os:
        def __getattr__(self, name):
            return getattr(real, name)

        @staticmethod
        def fdopen(fd, mode="r", *args, **kwargs):
            count[0] += 1
            if count[0] != k and not (after and count[0] > k):
                return real.fdopen(fd, mode, *args, **kwargs)
            fh = _FailingWriter(fd, code)
            return fh if "b" in mode else io.TextIOWrapper(fh, encoding="utf-8")

    monkeypatch.setattr(files, "os", Os())


def _stop_at(monkeypatch, cls, method: str, when) -> None:
    """Send this process SIGINT once ``when(self)`` holds, at the start of ``cls.method``."""
    real, sent = getattr(cls, method), []

    def wrapped(self, *args, **kwargs):
        if not sent and when(self):
            sent.append(1)
            os.kill(os.getpid(), signal.SIGINT)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(cls, method, wrapped)


# ---------------------------------------------------------------- command lines (slow)


@pytest.mark.slow
@pytest.mark.parametrize("k", random.Random(11).sample(range(1, 400), 2))
def test_q_table_ctrl_c_at_episode_k_resumes_to_the_same_q_table(tmp_path, monkeypatch, capsys, k):
    assert train.main(_q_args(tmp_path / "straight", "--episodes", "400", "--no-postures")) == 0
    (straight,) = (tmp_path / "straight").iterdir()
    with monkeypatch.context() as m:
        _stop_at(m, QLearning, "_run_episode", lambda agent: agent.episodes_done == k - 1)
        rc = train.main(_q_args(tmp_path / "cut", "--episodes", "400", "--no-postures"))
    assert rc == 130
    partial = _resume_dir(_one_line(capsys.readouterr().err))
    assert partial.name.startswith(".") and partial.name.endswith(".partial")
    assert read_q_table(partial / "q_table.npz")[1]["episodes_done"] == k
    # --resume alone: the checkpoint's target, the run's own episode count
    again = ["q_table", "--resume", str(partial), "--no-postures"]
    assert train.main([*again, "--logdir", str(tmp_path / "again"), "--no-progress"]) == 0
    (resumed,) = (tmp_path / "again").iterdir()
    q1, m1 = read_q_table(straight / "q_table.npz")
    q2, m2 = read_q_table(resumed / "q_table.npz")
    assert np.array_equal(q1, q2)
    assert (m1["episodes_done"], m1["num_timesteps"]) == (m2["episodes_done"], m2["num_timesteps"])


@pytest.mark.slow
@pytest.mark.parametrize("k", random.Random(12).sample(range(1, 10), 1))
def test_all_targets_ctrl_c_at_sweep_k_resumes_to_the_same_table(tmp_path, monkeypatch, capsys, k):
    from aftir_rl.rl.tabular import GoalQLearning

    args = ["q_table", "--all-targets", "--episodes", "500", "--no-progress"]
    assert train.main([*args, "--logdir", str(tmp_path / "straight")]) == 0
    (straight,) = (tmp_path / "straight").iterdir()
    with monkeypatch.context() as m:  # the config's log_interval is 50: 10 sweeps of the goals
        _stop_at(m, GoalQLearning, "_sweep", lambda agent: agent.episodes_done == 50 * (k - 1))
        assert train.main([*args, "--logdir", str(tmp_path / "cut")]) == 130
    partial = _resume_dir(_one_line(capsys.readouterr().err))
    assert partial.name.endswith(".partial")
    assert GoalQLearning.read_checkpoint(partial / "q_table_goal.npz")[2]["episodes_done"] == 50 * k
    again = [*args, "--resume", str(partial), "--logdir", str(tmp_path / "again")]
    assert train.main(again) == 0
    (resumed,) = (tmp_path / "again").iterdir()
    q1, _, m1 = GoalQLearning.read_checkpoint(straight / "q_table_goal.npz")
    q2, _, m2 = GoalQLearning.read_checkpoint(resumed / "q_table_goal.npz")
    assert np.array_equal(q1, q2)
    assert (m1["episodes_done"], m1["num_timesteps"]) == (m2["episodes_done"], m2["num_timesteps"])


@pytest.mark.slow
def test_ppo_stopped_at_a_step_resumes_to_the_same_total(tmp_path, monkeypatch, capsys):
    from aftir_rl.rl.sb3 import AtomicCheckpoint

    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML)
    k = random.Random(5).randrange(70, 440)
    with monkeypatch.context() as m:
        _stop_at(m, AtomicCheckpoint, "_on_step", lambda cb: cb.num_timesteps >= k)
        assert train.main(_ppo_args(config, tmp_path / "cut", 512)) == 130
    partial = _resume_dir(_one_line(capsys.readouterr().err))
    saved = sorted(int(p.stem[6:]) for p in (partial / "checkpoints").glob("model_*.zip"))
    assert saved[-1] == (k - 1) // 64 * 64  # as of the last update, none later
    assert train.main(_ppo_args(config, tmp_path / "again", 512, "--resume", str(partial))) == 0
    (run_dir,) = (tmp_path / "again").iterdir()
    assert json.loads((run_dir / "summary.json").read_text())["timesteps"] == 512


@pytest.mark.slow
@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
def test_ppo_on_a_failing_disk_keeps_its_last_checkpoint(tmp_path, monkeypatch, capsys, code):
    from aftir_rl.rl.sb3 import load_model, load_sb3_config

    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML)
    # writes 1 and 2 are unfinished.json and config.json, write j a checkpoint of step 64 (j - 2)
    k = random.Random(code).randrange(4, 11)
    with monkeypatch.context() as m:
        _fail_writes(m, k, code)
        assert train.main(_ppo_args(config, tmp_path / "full", 512)) == 2
    line = _one_line(capsys.readouterr().err)
    named = Path(line.split(" writing ", 1)[1].split(" ")[0].rstrip(";"))
    assert named.parent.exists() and named.name.startswith("model_")
    partial = _resume_dir(line)
    assert (partial / "progress.csv").exists() and not list(partial.rglob("*.tmp"))
    newest = max((partial / "checkpoints").glob("model_*.zip"), key=lambda p: int(p.stem[6:]))
    model = load_model("ppo", newest, config=load_sb3_config(config, "ppo"))
    assert model.num_timesteps == int(newest.stem[6:]) == (k - 3) * 64
    assert train.main(_ppo_args(config, tmp_path / "again", 512, "--resume", str(partial))) == 0
    (run_dir,) = (tmp_path / "again").iterdir()
    assert json.loads((run_dir / "summary.json").read_text())["timesteps"] == 512


@pytest.mark.slow
def test_q_table_on_a_failing_disk(tmp_path, monkeypatch, capsys):
    assert train.main(_q_args(tmp_path / "good", "--episodes", "300", "--no-postures")) == 0
    (good,) = (tmp_path / "good").iterdir()
    before = read_q_table(good / "q_table.npz")[0]
    # a full disk from the Q-table on (writes: unfinished.json, q_table.npz, path.json): the
    # resumed checkpoint is left as it was
    with monkeypatch.context() as m:
        _fail_writes(m, 2, errno.ENOSPC)
        args = _q_args(tmp_path / "full", "--resume", str(good), "--no-postures")
        assert train.main(args) == 2
    line = _one_line(capsys.readouterr().err)
    assert "no space left on the device writing" in line and "q_table.npz" in line
    assert "Traceback" not in line and np.array_equal(read_q_table(good / "q_table.npz")[0], before)
    # one failing write (path.json, after unfinished.json, a checkpoint every 50 episodes and
    # the one when learning ends): the Q-table is saved beside the logs, and resumes
    with monkeypatch.context() as m:
        _fail_writes(m, 1 + 300 // 50 + 1 + 1, errno.EIO, after=False)
        assert train.main(_q_args(tmp_path / "eio", "--episodes", "300", "--no-postures")) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("error: input/output error writing") and "path.json" in line
    partial = _resume_dir(line)
    again = ["q_table", "--resume", str(partial), "--episodes", "300", "--no-postures"]
    assert train.main([*again, "--logdir", str(tmp_path / "again"), "--no-progress"]) == 0
    (resumed,) = (tmp_path / "again").iterdir()
    assert np.array_equal(read_q_table(resumed / "q_table.npz")[0], before)


# ---------------------------------------------------------------- real signals (slow)


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
        env=env,
    )


def _wait_for(pattern: str, folder: Path, proc: subprocess.Popen, timeout: float = 60) -> None:
    deadline = time.time() + timeout
    while not list(folder.glob(pattern)):
        assert proc.poll() is None and time.time() < deadline, proc.stderr.read()
        time.sleep(0.05)


def _interrupt(proc: subprocess.Popen, *signals: int, gap: float = 0.05) -> tuple[int, float]:
    """Send ``signals`` (``gap`` apart); the exit status and the seconds from the last one."""
    for i, sig in enumerate(signals):
        if i:
            time.sleep(gap)
        proc.send_signal(sig)
    start = time.perf_counter()
    code = proc.wait(timeout=30)
    return code, time.perf_counter() - start


@pytest.mark.slow
@pytest.mark.parametrize("delay", random.Random(3).sample([0.2, 0.6, 1.0, 1.5, 2.0], 2))
def test_sigint_during_q_table_training_leaves_a_resumable_run(tmp_path, delay):
    args = ["aftir_rl.train", *_q_args(tmp_path / "runs", "--episodes", "100000")]
    proc = _start(args, tmp_path)
    _wait_for(".*.partial/progress.csv", tmp_path / "runs", proc)
    time.sleep(delay)
    code, seconds = _interrupt(proc, signal.SIGINT)
    assert code == 130 and seconds < 5
    partial = _resume_dir(_one_line(proc.stderr.read()))
    done = read_q_table(partial / "q_table.npz")[1]["episodes_done"]
    assert 0 < done < 100000
    again = ["q_table", "--resume", str(partial), "--episodes", "100000", "--no-postures"]
    assert train.main([*again, "--logdir", str(tmp_path / "again"), "--no-progress"]) == 0
    (run_dir,) = (tmp_path / "again").iterdir()
    assert read_q_table(run_dir / "q_table.npz")[1]["episodes_done"] == 100000


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_ppo_training_leaves_a_resumable_run(tmp_path, sig):
    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML.replace("checkpoint_freq: 64", "checkpoint_freq: 100000"))
    proc = _start(["aftir_rl.train", *_ppo_args(config, tmp_path / "runs", 3072)], tmp_path)
    _wait_for(".*.partial/progress.csv", tmp_path / "runs", proc)
    time.sleep(random.Random(sig).uniform(0.2, 2.0))
    code, seconds = _interrupt(proc, sig)
    assert code == 130 and seconds < 5
    partial = _resume_dir(_one_line(proc.stderr.read()))
    (saved,) = (partial / "checkpoints").glob("model_*.zip")
    assert int(saved.stem[6:]) % 64 == 0
    assert train.main(_ppo_args(config, tmp_path / "again", 3072, "--resume", str(partial))) == 0
    (run_dir,) = (tmp_path / "again").iterdir()
    assert json.loads((run_dir / "summary.json").read_text())["timesteps"] == 3072


@pytest.mark.slow
def test_a_second_sigint_exits_at_once_and_leaves_the_run_unfinished(tmp_path):
    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML)
    proc = _start(["aftir_rl.train", *_ppo_args(config, tmp_path / "runs", 100000)], tmp_path)
    _wait_for(".*.partial/checkpoints/model_*.zip", tmp_path / "runs", proc)
    code, seconds = _interrupt(proc, signal.SIGINT, signal.SIGINT)
    assert code in STOPPED and seconds < 2
    (left,) = (tmp_path / "runs").iterdir()
    assert left.name.endswith(".partial") and list((left / "checkpoints").glob("model_*.zip"))
    assert "Traceback" not in proc.stderr.read()


@pytest.mark.slow
@pytest.mark.parametrize("how", ["console script", "python -m"])
@pytest.mark.parametrize("delay", random.Random(13).sample([0.05, 0.1, 0.15, 0.2, 0.3, 0.5], 2))
def test_ctrl_c_while_the_command_imports_is_one_line(tmp_path, how, delay):
    script = Path(sys.executable).parent / "aftir"
    if how == "python -m":
        args = [sys.executable, "-m", "aftir_rl.train", "q_table"]
    elif script.is_file() and "aftir_launch" in script.read_text(errors="replace"):
        args = [str(script), "train", "q_table"]
    else:
        pytest.skip("the aftir console script of this install is not aftir_launch's")
    proc = subprocess.Popen(
        [*args, "--all-targets", "--no-progress", "--logdir", str(tmp_path)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
    )  # fmt: skip
    time.sleep(delay)  # inside `import aftir_rl` (gymnasium, numpy) or just after
    code, seconds = _interrupt(proc, signal.SIGINT)
    err = proc.stderr.read()
    assert code == 130 and seconds < 5, err
    assert _one_line(err).startswith("interrupted")


@pytest.mark.slow
def test_sigint_to_bench_and_evaluate(tmp_path):
    rng = random.Random(8)
    proc = _start(["aftir_rl.bench", "--n-random", "3", "--quiet", "--rrt-seconds", "1"], tmp_path)
    time.sleep(rng.uniform(1.0, 4.0))
    code, seconds = _interrupt(proc, signal.SIGINT)
    assert code in STOPPED and seconds < 5
    assert _one_line(proc.stderr.read()) == "interrupted"
    config = tmp_path / "ppo.yaml"
    config.write_text(PPO_YAML)
    assert train.main(_ppo_args(config, tmp_path / "runs", 64)) == 0
    (run,) = (tmp_path / "runs").iterdir()
    args = [
        "aftir_rl.evaluate",
        str(run),
        "--random",
        "500",
        "--logdir",
        str(tmp_path / "eval"),
        "--no-progress",
    ]
    proc = _start(args, tmp_path)
    time.sleep(rng.uniform(1.0, 4.0))
    code, seconds = _interrupt(proc, signal.SIGINT)
    err = proc.stderr.read()
    assert code in STOPPED and seconds < 5, err
    assert _one_line(err) == "interrupted"
