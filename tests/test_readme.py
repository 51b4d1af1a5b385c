"""The README's commands, run as a user would: from a fresh directory, on the installed wheel."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import pytest

from tests.wheel_install import ROOT, install_wheel
from tests.wheel_install import run_outside as _run

pytestmark = pytest.mark.slow

README = ROOT / "README.md"


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    return install_wheel(tmp_path_factory.mktemp("wheel"))


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
    return re.sub(r"--random \d+", "--random 1", line)


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
