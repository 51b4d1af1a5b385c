"""Build this checkout's wheel and install it outside the repository, for the slow tests.

Each test module that needs it makes its own module-scoped fixture from :func:`install_wheel`,
so pytest-xdist can run those modules on different workers.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def install_wheel(tmp: Path, warm_numba: bool = False) -> tuple[Path, dict[str, str]]:
    """``(an empty directory outside the repository, the environment to run commands in)``.

    The wheel is installed with ``pip --target``; its copy comes first on ``sys.path``, ahead of
    the editable install of the checkout. ``warm_numba``: numba's cache of the checkout's kernels
    (``make install`` compiles them) is copied beside the installed modules, whose times are set
    to the checkout's so that numba takes it (it checks a module's time and size): the commands
    run without compiling. Without it the installed package compiles its kernels cold.
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
    if warm_numba:
        _copy_numba_cache(target / "aftir_rl")
    outside = tmp / "elsewhere"
    outside.mkdir()
    env = {**os.environ, "PYTHONPATH": str(target), "AFTIR_RL_CONFIG_DIR": ""}
    return outside, env


def _copy_numba_cache(installed: Path) -> None:
    package = ROOT / "aftir_rl"
    for cache in package.rglob("__pycache__/*.nb[ic]"):
        module = cache.parent.parent / (cache.name.split(".")[0] + ".py")
        there = installed / module.relative_to(package)
        if not module.is_file() or not there.is_file():
            continue
        (there.parent / "__pycache__").mkdir(exist_ok=True)
        shutil.copy2(cache, there.parent / "__pycache__" / cache.name)
        stat = module.stat()
        os.utime(there, ns=(stat.st_atime_ns, stat.st_mtime_ns))


def run_outside(
    args: list[str], cwd: Path, env: dict[str, str]
) -> subprocess.CompletedProcess[str]:
    """Run a command in ``cwd`` with the installed wheel (10 minutes at most)."""
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
