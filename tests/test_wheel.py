"""The wheel works outside the repository: configs shipped as package data, every env, the CLIs."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from tests.wheel_install import install_wheel
from tests.wheel_install import run_outside as _run

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    return install_wheel(tmp_path_factory.mktemp("wheel"))


def test_wheel_makes_every_env_from_outside_the_repo(installed) -> None:
    cwd, env = installed
    code = (
        "import aftir_rl, gymnasium as gym\n"
        "from aftir_rl.core.config import CONFIG_DIR\n"
        "assert 'site' in aftir_rl.__file__, aftir_rl.__file__\n"
        "assert CONFIG_DIR.is_relative_to(aftir_rl.__path__[0]), CONFIG_DIR\n"
        "for env_id in aftir_rl.ENV_IDS:\n"
        "    e = gym.make('aftir_rl:' + env_id); e.reset(seed=0); e.close()\n"
        "print(len(aftir_rl.ENV_IDS))\n"
    )
    out = _run([sys.executable, "-c", code], cwd, env)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout) >= 3


def test_wheel_runs_train_and_plan(installed) -> None:
    cwd, env = installed
    out = _run(
        [
            sys.executable,
            "-m",
            "aftir_rl.cli",
            "plan",
            "--target",
            "230",
            "140",
            "90",
            "--json",
        ],
        cwd,
        env,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["error_cm"] < 0.01
    out = _run(
        [
            sys.executable,
            "-m",
            "aftir_rl.train",
            "q_table",
            "--target",
            "20",
            "10",
            "60",
            "--logdir",
            str(cwd / "runs"),
            "--no-progress",
        ],
        cwd,
        env,
    )
    assert out.returncode == 0, out.stderr
    (run,) = (cwd / "runs").iterdir()
    assert json.loads((run / "path.json").read_text())["target"] == [20.0, 10.0, 60.0]
