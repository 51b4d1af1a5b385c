"""The wheel works outside the repository: configs shipped as package data, every env, the CLIs."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    tmp = tmp_path_factory.mktemp("wheel")
    wheels = tmp / "dist"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(wheels)],
        check=True,
        capture_output=True,
    )
    (wheel,) = wheels.glob("aftir_rl-*.whl")
    target = tmp / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target), wheel],
        check=True,
        capture_output=True,
    )
    outside = tmp / "elsewhere"
    outside.mkdir()
    # The wheel's copy comes first on sys.path, ahead of the editable install of the checkout.
    env = {**os.environ, "PYTHONPATH": str(target), "AFTIR_RL_CONFIG_DIR": ""}
    return outside, env


def _run(args: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


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


# --- The README's commands, run as a user would: from a fresh directory, on the wheel ----------

README = ROOT / "README.md"


def _blocks(section: str, lang: str) -> list[str]:
    """The fenced ``lang`` blocks of the README section titled ``section``."""
    text = README.read_text(encoding="utf-8")
    body = text.split(f"\n## {section}\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(rf"```{lang}\n(.*?)```", body, flags=re.S)


def _small(line: str) -> str:
    """A README command with the step and target counts made small (the rest untouched)."""
    line = line.split("  #", 1)[0].strip()
    if re.match(r"aftir train (ppo|sac|td3)\b", line):
        line = re.sub(r" --total-timesteps \d+", "", line) + " --total-timesteps 1024 --n-envs 8"
        line += " --no-progress"
    return re.sub(r"--random \d+", "--random 2", line)


def test_readme_first_steps_run_from_a_wheel(installed) -> None:
    """Every command of "First steps", in order, from a fresh directory: each exits 0."""
    cwd, env = installed
    bin_dir = cwd.parent / "bin"  # the console script, as pip would write it
    bin_dir.mkdir(exist_ok=True)
    script = bin_dir / "aftir"
    script.write_text(
        f"#!{sys.executable}\nimport sys\nfrom aftir_rl.cli.main import main\nsys.exit(main())\n"
    )
    script.chmod(0o755)
    env = {**env, "PATH": f"{bin_dir}{os.pathsep}{env['PATH']}", "OMP_NUM_THREADS": "1"}
    lines = [ln for block in _blocks("First steps", "bash") for ln in block.splitlines()]
    commands = [_small(ln) for ln in lines if ln.startswith("aftir ")]
    assert len(commands) >= 9, commands
    for command in commands:
        out = _run(["bash", "-c", command], cwd, env)
        assert out.returncode == 0, f"{command}\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}"
    assert (cwd / "view.html").stat().st_size > 100_000
    assert (cwd / "arm.gif").read_bytes()[:6] == b"GIF89a"
    assert list((cwd / "runs" / "best" / "stage1").glob("ppo__*/best/model.zip"))


def test_readme_python_examples_run_from_a_wheel(installed) -> None:
    """The README's Python examples, ``learn(100_000)`` and the like made one rollout.

    No error, and the grid world's printed line is the one the README shows.
    """
    cwd, env = installed
    for code in _blocks("The environments", "python"):
        small = re.sub(r"\.learn\(\d+_[\d_]+\)", ".learn(1)", code)
        out = _run([sys.executable, "-c", small], cwd, {**env, "OMP_NUM_THREADS": "1"})
        assert out.returncode == 0, out.stderr[-3000:]
        if "greedy_rollout" in code:
            assert out.stdout.splitlines()[0] == "True 22", out.stdout
