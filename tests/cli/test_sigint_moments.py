"""Ctrl-C at random moments of every long command: exit 130 within 5 s, one line, resumable.

For each of ``train q_table``, ``train ppo``, ``bench``, ``evaluate`` and ``tune``, a reference
run goes uninterrupted and is timed; then ``AFTIR_SIGINT_MOMENTS`` runs (20 in ``make fuzz``;
none in ``make test-all``, which samples moments in ``test_interrupts.py``) get one SIGINT
each, at a moment drawn at random over that whole time, from the interpreter's start to its
end. Each must exit 130 within :data:`EXIT_SECONDS` with one line on stderr (or 0 if it had
already finished), leave no half-written output, and the run it names with ``--resume`` must
end where the reference did: the same Q-table (same seed), the same number of PPO steps, a
sweep's trial resumed to its steps.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from aftir_rl.rl.tabular.checkpoint import read_q_table

pytestmark = [pytest.mark.slow, pytest.mark.fuzz]  # run by `make fuzz`, not `make test-slow`

ROOT = Path(__file__).resolve().parents[2]
MOMENTS = int(os.environ.get("AFTIR_SIGINT_MOMENTS", "0"))  # ``make fuzz``: 20
#: The longest a command may take to exit after Ctrl-C [s].
EXIT_SECONDS = 5.0
PPO_YAML = (
    "env_id: AFTIR-ArmReach-v0\nn_envs: 1\neval_freq: 100000\neval_targets: 2\n"
    "checkpoint_freq: 64\nhyperparameters:\n  n_steps: 64\n  batch_size: 32\n  n_epochs: 2\n"
)
PPO_STEPS = 3072
Q_ARGS = ["--target", "-50", "140", "10", "--episodes", "20000", "--seed", "3"]
COMMANDS = {
    "q_table": ["aftir_rl.train", "q_table", *Q_ARGS, "--logdir", "{out}"],
    "ppo": ["aftir_rl.train", "ppo", "--config", "{tmp}/ppo.yaml", "--logdir", "{out}"],
    "bench": ["aftir_rl.bench", "--sets", "jace", "--n-random", "1", "--rrt-seconds", "1"],
    "evaluate": [
        "aftir_rl.evaluate", "{run}", "--random", "100", "--logdir", "{out}", "--no-progress"
    ],
    "tune": [
        "aftir_rl.tune", "ppo", "--env", "AFTIR-ArmReach-v0", "--trials", "2", "--workers", "2",
        "--total-timesteps", "2048", "--config", "{tmp}/ppo.yaml", "--logdir", "{out}",
    ],
}  # fmt: skip
MORE = {
    "q_table": ["--no-progress"],
    "ppo": ["--total-timesteps", str(PPO_STEPS), "--no-progress"],
    "bench": ["--bridge-seconds", "1", "--json", "{tmp}/bench.json", "--quiet"],
    "tune": ["--quiet"],
}


def _args(name: str, tmp: Path, out: Path, run: Path | None = None) -> list[str]:
    fill = {"tmp": str(tmp), "out": str(out), "run": str(run)}
    return [a.format(**fill) for a in [*COMMANDS[name], *MORE.get(name, [])]]


def _python(args: list[str], cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", *args],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=cwd, env=env,
    )  # fmt: skip


def _only(folder: Path, pattern: str = "*") -> Path:
    (found,) = folder.glob(pattern)
    return found


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, tuple[float, Path]]:
    """Every command run once, uninterrupted: its seconds and its output folder."""
    tmp = tmp_path_factory.mktemp("reference")
    (tmp / "ppo.yaml").write_text(PPO_YAML)
    done: dict[str, tuple[float, Path]] = {}
    for name in COMMANDS:
        out = tmp / name
        start = time.perf_counter()
        proc = _python(_args(name, tmp, out, run=done.get("ppo", (0, tmp))[1]), tmp)
        assert proc.wait(timeout=600) == 0, proc.stderr.read()
        seconds = time.perf_counter() - start
        done[name] = (seconds, _only(out) if name in ("q_table", "ppo") else out)
    return done


def _resume(kind: str, partial: Path, tmp: Path, out: Path) -> Path:
    """``train KIND --resume PARTIAL`` as the hint says, nothing more; the finished run."""
    args = ["aftir_rl.train", kind, "--resume", str(partial), "--logdir", str(out), "--no-progress"]
    proc = _python(args, tmp)
    assert proc.wait(timeout=600) == 0, proc.stderr.read()
    return _only(out)


def _check_resumed(kind: str, partial: Path, tmp: Path, ref: Path) -> None:
    resumed = _resume(kind, partial, tmp, tmp / "again")
    if kind == "q_table":
        table, meta = read_q_table(resumed / "q_table.npz")
        assert np.array_equal(table, read_q_table(ref / "q_table.npz")[0])
        assert meta["episodes_done"] == 20000
    else:
        assert json.loads((resumed / "summary.json").read_text())["timesteps"] == PPO_STEPS


def _check_left(name: str, line: str, out: Path, tmp: Path, ref: Path) -> None:
    """What an interrupted ``name`` left in ``out`` is whole and resumes as the reference."""
    if name in ("q_table", "ppo"):
        if "--resume " in line:
            _check_resumed(name, Path(line.rsplit("--resume ", 1)[1].strip()), tmp, ref)
        else:  # stopped before training began: nothing, or nothing but an empty folder
            assert not out.exists() or not any(out.rglob("*.npz")) and not any(out.rglob("*.zip"))
    elif name == "bench":  # the JSON is whole or absent
        written = tmp / "bench.json"
        assert not written.exists() or json.loads(written.read_text())
    elif name == "tune":
        trials = sorted(out.glob("tune__*/.ppo__*.partial"))
        if trials and list(trials[0].glob("checkpoints/model_*.zip")):
            resumed = _resume("ppo", trials[0], tmp, tmp / "again")
            steps = json.loads((resumed / "summary.json").read_text())["timesteps"]
            assert steps == 2048


@pytest.mark.parametrize("name", list(COMMANDS))
@pytest.mark.parametrize("moment", range(MOMENTS))
def test_ctrl_c_at_a_random_moment(name, moment, reference, tmp_path):
    seconds, ref = reference[name]
    at = random.Random(f"{name}-{moment}").uniform(0.0, seconds)
    (tmp_path / "ppo.yaml").write_text(PPO_YAML)
    out = tmp_path / "out"
    proc = _python(_args(name, tmp_path, out, run=reference["ppo"][1]), tmp_path)
    time.sleep(at)
    proc.send_signal(signal.SIGINT)
    start = time.perf_counter()
    code = proc.wait(timeout=60)
    took = time.perf_counter() - start
    err = proc.stderr.read()
    print(f"{name} at {at:.2f} s of {seconds:.1f}: exit {code} after {took:.2f} s")
    lines = err.strip().splitlines()
    if code == 0:  # it had finished, and says nothing more
        assert not lines, (at, err)
        return
    assert code == 130 and took < EXIT_SECONDS and len(lines) == 1, (at, code, took, err)
    assert lines[0].startswith("interrupted") and "Traceback" not in err
    _check_left(name, lines[0], out, tmp_path, ref)
