"""Build this checkout's wheel and install it outside the repository, for the slow tests.

Each test module that needs it makes its own module-scoped fixture from :func:`install_wheel`,
so pytest-xdist can run those modules on different workers.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def install_wheel(tmp: Path) -> tuple[Path, dict[str, str]]:
    """``(an empty directory outside the repository, the environment to run commands in)``.

    The wheel is installed with ``pip --target``; its copy comes first on ``sys.path``, ahead of
    the editable install of the checkout.
    """
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
    env = {**os.environ, "PYTHONPATH": str(target), "AFTIR_RL_CONFIG_DIR": ""}
    return outside, env


def run_outside(
    args: list[str], cwd: Path, env: dict[str, str]
) -> subprocess.CompletedProcess[str]:
    """Run a command in ``cwd`` with the installed wheel (10 minutes at most)."""
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
