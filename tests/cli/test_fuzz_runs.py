"""Fuzzing the commands that read files a user may be handed: run directories (view, evaluate,
rollout, rank_checkpoints, check, export), tanks with their meshes (tank show) and Minari
datasets (what ``aftir train ppo --demos`` reads).

Real run directories (a Q-table run with its motion, PPO runs of ``AFTIR-ArmReach-v0`` and
``AFTIR-ArmFTL-v0`` with checkpoints) are mutated at random by :mod:`tests.fuzz` (JSON fields and
keys, FIFOs, devices, symlinks out of the run, sparse 5 GB files, truncation, flipped bytes,
zip and npz members: dropped, extra, corrupt, deflate bombs, sizes that lie) and each command
runs on every mutated copy. Every case must end in exit 0 or 2, with one line on stderr for 2,
no traceback, within :data:`tests.fuzz.CASE_SECONDS`, and the memory each case allocates must
stay under :data:`PEAK_MB`. As a user's command holds one run, a fuzzing process takes the runs of
one kind (Q-table, ArmReach, ArmFTL) and at most :data:`CHUNK` cases; the cases are split
between the kinds. ``AFTIR_FUZZ_CASES`` sets
the number of cases per command (5 in ``make test-all``, 300 in CI, 2,000 in ``make fuzz``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from aftir_rl.core.config import CONFIG_DIR
from tests.fuzz import CASE_SECONDS

pytestmark = [pytest.mark.slow, pytest.mark.fuzz]  # run by `make fuzz`, not `make test-slow`

ROOT = Path(__file__).parents[2]
CASES = int(os.environ.get("AFTIR_FUZZ_CASES", "5"))  # ``make fuzz``: 2,000
#: The most memory [MB] one case may allocate (the goal): its peak resident size less the pages
#: of mapped files (:func:`tests.fuzz.allocated_mb`; the libraries' code pages count in the
#: resident size as far as the page cache maps them, 120-230 MB for the same imports on one
#: machine). One command alone allocates about 400 MB (evaluate or rank of an ArmFTL run, torch
#: loaded); the fuzzing process also keeps what earlier cases of its kind cached (tanks, guide
#: fields: bounded caches), and hands back what they freed before each case
#: (:func:`tests.fuzz.reset_peak`). numba's kernels are compiled and cached on disk first
#: (:func:`_warm`): the compiler's memory is the first command's after installing only. A
#: bomb that is read reaches gigabytes.
PEAK_MB = 600
#: Cases per fuzzing process: a long-lived process's caches are not a command's memory.
CHUNK = 400

PPO_REACH = (
    "env_id: AFTIR-ArmReach-v0\nn_envs: 1\n"  # one env, not the entry's two
    "eval_freq: 100000\neval_targets: 2\ncheckpoint_freq: 64\n"
    "hyperparameters:\n  n_steps: 64\n  batch_size: 32\n"
)
PPO_FTL = (
    "env_id: AFTIR-ArmFTL-v0\nn_envs: 8\neval_freq: 100000\neval_targets: 2\n"
    "checkpoint_freq: 128\npolicy: MultiInputPolicy\nenv_kwargs:\n  bay: 2\n  guide: true\n"
    "hyperparameters:\n  n_steps: 16\n  batch_size: 64\n  n_epochs: 1\n"
    "  policy_kwargs:\n    net_arch: [32, 32]\n"
)


def _aftir(*args: str, bars: bool = True) -> None:
    """Run ``aftir ARGS`` (``bars``: the command draws progress bars, hidden here)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "aftir_rl.cli", *args, *(["--no-progress"] if bars else [])]
    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT, env=env, timeout=300)


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, list[list[str]]]:
    """Real run directories, made once: for each command, its kinds of run."""
    top = tmp_path_factory.mktemp("sources")
    target = ["--target", "230", "140", "90", "--episodes", "300"]
    _aftir("train", "q_table", *target, "--logdir", str(top / "q"))
    # a tank given by path: the run keeps it as tank.yaml
    (top / "mine.yaml").write_text((CONFIG_DIR / "tanks" / "b737_center.yaml").read_text())
    (top / "q_mine.yaml").write_text(f"tank: {top / 'mine.yaml'}\n")
    _aftir(
        "train",
        "q_table",
        *target,
        "--config",
        str(top / "q_mine.yaml"),
        "--no-postures",
        "--logdir",
        str(top / "q"),
    )
    for name, text in (("reach", PPO_REACH), ("ftl", PPO_FTL)):
        (top / f"{name}.yaml").write_text(text)
        config = ["--config", str(top / f"{name}.yaml"), "--total-timesteps", "256"]
        _aftir("train", "ppo", *config, "--logdir", str(top / name))
    runs = {k: [str(p) for p in (top / k).iterdir()] for k in ("q", "reach", "ftl")}
    tank = top / "tank" / "wing"  # a tank YAML that names its walls and solids as meshes
    tank.mkdir(parents=True)
    _aftir("tank", "export", "--tank", "wing:2:3", "-o", str(tank / "solids.stl"),
           "--walls", str(tank / "walls.stl"), "--yaml", str(tank / "tank.yaml"),
           bars=False)  # fmt: skip
    _aftir("dataset", "--episodes", "3", "--workers", "1", "-o", str(top / "demos" / "root"))
    timed = [r for r in runs["q"] if (Path(r) / "trajectory.json").exists()]
    _aftir("simulate", timed[0], "--every", "10")  # physics.json, for view's mutations too
    return {
        "check": [timed],
        "export": [timed],
        "tank": [[str(tank)]],
        "demos": [[str(top / "demos" / "root")]],
        "view": [runs["q"], runs["reach"], runs["ftl"]],
        "evaluate": [runs["q"], runs["reach"], runs["ftl"]],
        "rollout": [runs["reach"], runs["ftl"]],
        "rank": [runs["ftl"]],
    }


def _warm(cli: str, work: Path, runs: list[str]) -> None:
    """Build numba's on-disk caches for ``cli`` first: the compiler's memory is a one-off of the
    first command after installing (about 100 MB more), not a command's."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT), "TQDM_DISABLE": "1"}
    cmd = [sys.executable, "-m", "tests.fuzz", "warm", cli, str(work), *runs]
    work.mkdir(parents=True)
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=work, env=env, timeout=600)
    assert done.returncode == 0, done.stdout[-1000:] + done.stderr[-2000:]


def _fuzz(cli: str, seed: int, cases: int, work: Path, runs: list[str]) -> list[dict]:
    """The results of ``python -m tests.fuzz``: ``cases`` mutations of ``runs`` by ``cli``."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT), "TQDM_DISABLE": "1"}
    cmd = [sys.executable, "-m", "tests.fuzz", cli, str(seed), str(cases), str(work), *runs]
    done = subprocess.run(
        cmd, capture_output=True, text=True, cwd=work.parent, env=env, timeout=60 + cases * 12
    )
    assert done.returncode == 0, done.stderr[-2000:]
    results: list[dict] = json.loads(done.stdout.splitlines()[-1])["results"]
    return results


@pytest.mark.parametrize(
    "cli", ["view", "evaluate", "rollout", "rank", "check", "export", "tank", "demos"]
)
def test_mutated_run_directories(cli, sources, tmp_path):
    kinds = sources[cli]
    _warm(cli, tmp_path / "warm", [run for runs in kinds for run in runs])
    results = []
    for i, runs in enumerate(kinds):  # CASES in all, split between the kinds
        cases = CASES // len(kinds) + (i < CASES % len(kinds))
        got: list[dict] = []
        for k, first in enumerate(range(0, cases, CHUNK)):
            n = min(CHUNK, cases - first)
            got += _fuzz(cli, 7 + i + 100 * k, n, tmp_path / f"kind{i}_{k}", runs)
        slowest, peak = max(c["s"] for c in got), max(c["allocated"] for c in got)
        resident = max(c["resident"] for c in got)
        print(f"{cli} on {Path(runs[0]).parent.name}: {cases} cases, {slowest:.2f} s, {peak} MB "
              f"allocated, {resident} MB resident")  # fmt: skip
        results += got
    bad = []
    for case in results:
        lines = [line for line in case["stderr"].splitlines() if line.strip()]
        ok = case["code"] == 0 and not lines or case["code"] == 2 and len(lines) == 1
        # check and export: 1 is a motion that fails its check (export says so in one line)
        ok |= cli in ("check", "export") and case["code"] == 1 and len(lines) <= 1
        if not ok or "Traceback" in case["stderr"] or case["s"] > CASE_SECONDS:
            bad.append(case)
    assert not bad, json.dumps(bad[:3], indent=1)[:4000]
    peak = max(results, key=lambda c: c["allocated"])
    assert peak["allocated"] <= PEAK_MB, peak
    if CASES >= 50:  # enough cases for both kinds: some refused, some still readable
        codes = {c["code"] for c in results}
        assert {0, 2} <= codes <= ({0, 1, 2} if cli in ("check", "export") else {0, 2})
