"""The README's commands, run as a user would: from a fresh directory, on the installed wheel.

The same wheel (one build, numba's cache of the checkout's kernels copied beside it) also shows
that the package works outside the repository: configs shipped as package data, every env,
``aftir plan``. (``make install`` compiles the kernels cold, from the checkout.)
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from tests.wheel_install import ROOT, install_wheel
from tests.wheel_install import run_outside as _run

pytestmark = pytest.mark.slow

README = ROOT / "README.md"


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    return install_wheel(tmp_path_factory.mktemp("wheel"), warm_numba=True)


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
        line += " --eval-episodes 2 --no-progress"
    if line.startswith("aftir dataset"):
        line = re.sub(r"--episodes \d+", "--episodes 1", line) + " --no-progress"
    if line.startswith("aftir route train"):  # three routes cloned, not 600
        line += " --routes 3 --updates 50"
    if line.startswith("aftir simulate"):  # an instant every 10 s of the motion, not every 1 s
        line += " --every 10"
    if line.startswith("python -m rl_zoo3.train"):  # one rollout of 8 envs, not the entry's 128
        line += " -n 1 --eval-freq 256 --eval-episodes 2 --n-eval-envs 1"
        line += " -params n_envs:8 batch_size:1024"  # RL Zoo's per-run override of the entry
    return re.sub(r"--random \d+", "--random 1", line)


def _commands(section: str) -> list[str]:
    """The shell commands of a README section's bash blocks, continued lines joined."""
    text = "\n".join(_blocks(section, "bash")).replace("\\\n", " ")
    return [ln for ln in text.splitlines() if ln.strip()]


def _tensorboard_tags(cwd: Path, env: dict[str, str]) -> dict[str, list[str]]:
    """``tensorboard --logdir runs`` as the README says, asked over HTTP for its scalar tags."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    args = ["tensorboard", "--logdir", "runs", "--port", str(port), "--host", "127.0.0.1"]
    server = subprocess.Popen(args, cwd=cwd, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)  # fmt: skip
    url = f"http://127.0.0.1:{port}/data/plugin/scalars/tags"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(url, timeout=5) as reply:
                    tags = json.loads(reply.read())
                if tags:
                    return {run: sorted(t) for run, t in tags.items()}
            except OSError:
                pass
            time.sleep(1)
        raise AssertionError("tensorboard served no scalars in 120 s")
    finally:
        server.terminate()
        server.wait(30)


def test_readme_first_steps_run_from_a_wheel(installed) -> None:
    """Every command of "First steps", in order, from a fresh directory: each exits 0."""
    cwd, env = installed
    bin_dir = cwd.parent / "bin"  # the console script, as pip would write it
    bin_dir.mkdir(exist_ok=True)
    script = bin_dir / "aftir"
    script.write_text(
        f"#!{sys.executable}\nimport sys\nfrom aftir_rl.cli.main import main\n"
        "if __name__ == '__main__':\n    sys.exit(main())\n"  # as pip writes it
    )
    script.chmod(0o755)
    venv_bin = Path(sys.executable).parent  # python, tensorboard
    path = os.pathsep.join([str(bin_dir), str(venv_bin), env["PATH"]])
    env = {**env, "PATH": path, "OMP_NUM_THREADS": "1"}
    hyperparams = cwd / "configs" / "hyperparams"  # what the clone's root holds
    hyperparams.mkdir(parents=True)
    shutil.copy(ROOT / "configs" / "hyperparams" / "ppo.yml", hyperparams)
    commands = [_small(line) for line in _commands("First steps")]
    assert len(commands) >= 15 and any(c.startswith("python -m rl_zoo3") for c in commands)
    for command in commands:
        out = _run(["bash", "-c", command], cwd, env)
        assert out.returncode == 0, f"{command}\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}"
    assert (cwd / "view.html").stat().st_size > 100_000
    assert (cwd / "arm.gif").read_bytes()[:6] == b"GIF89a"
    assert list((cwd / "runs" / "best" / "stage1").glob("ppo__*/best/model.zip"))
    # RL Zoo trained and evaluated (its evaluations.npz) with the README's flags
    (zoo,) = (cwd / "logs" / "ppo").glob("AFTIR-ArmFTL-v0_*")
    assert (zoo / "evaluations.npz").exists() and (zoo / "AFTIR-ArmFTL-v0.zip").exists()
    tags = _tensorboard_tags(cwd, env)
    ppo = [run for run in tags if run.startswith("ppo__AFTIR-ArmFTL-v0")]
    assert ppo and "eval/success_rate" in tags[ppo[0]], tags


def test_readme_install_and_development_commands_resolve() -> None:
    """The install line resolves (pip's dry run, in the checkout, as after ``cd aftir_rl``) and
    every ``make`` target of "Development" exists (``make -n``; CI runs them for real)."""
    pip = [sys.executable, "-m", "pip", "install", "--dry-run", "--quiet", "--report", "-"]
    (line,) = [c for c in _commands("Install") if c.startswith("pip install")]
    args = shlex.split(line.split("  #", 1)[0])[2:]
    out = subprocess.run([*pip, *args], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    report = json.loads(out.stdout)
    assert any(item["metadata"]["name"] == "aftir_rl" for item in report["install"])
    for line in _commands("Development"):
        target = line.split()[1]
        make = subprocess.run(["make", "-n", target], cwd=ROOT, capture_output=True, text=True)
        assert make.returncode == 0, f"make {target}: {make.stderr}"


def test_readme_python_examples_run_from_a_wheel(installed) -> None:
    """The README's Python examples, ``learn(100_000)`` and the like made one rollout.

    No error, and the grid world's printed line is the one the README shows.
    """
    cwd, env = installed
    for code in _blocks("The environments", "python"):
        small = re.sub(r"\.learn\(\d+_[\d_]+", ".learn(1", code)  # SB3's, not Q-learning's
        out = _run([sys.executable, "-c", small], cwd, {**env, "OMP_NUM_THREADS": "1"})
        assert out.returncode == 0, out.stderr[-3000:]
        if "greedy_rollout" in code:
            assert out.stdout.splitlines()[0] == "True 22", out.stdout


def test_wheel_makes_every_env_and_plans_from_outside_the_repo(installed) -> None:
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
    plan = [sys.executable, "-m", "aftir_rl.cli", "plan", "--target", "230", "140", "90", "--json"]
    out = _run(plan, cwd, env)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["error_cm"] < 0.01
