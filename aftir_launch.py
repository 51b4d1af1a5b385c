"""The ``aftir`` console scripts: Ctrl-C is one line from the command's first moment.

Importing :mod:`aftir_rl` takes a fraction of a second (gymnasium, numpy); a Ctrl-C or SIGTERM
in it would print Python's traceback. These entry points install a handler before that import:
nothing has started yet, so it prints ``interrupted`` and exits 130 at once. Each command's own
handler (:mod:`aftir_rl.cli.guard`: stop after the current step, save, say how to resume)
replaces it while the command runs. This module lives outside the package because importing
anything inside it runs the package's ``__init__`` first, and that ``__init__`` cannot take the
signals itself for a console script: a program that merely imports the package looks the same
to it, and must keep its own handlers. Under ``python -m aftir_rl...`` it can tell (``sys.argv``
is ``["-m"]`` while the module is located), and calls :func:`take_signals` from here.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
from types import FrameType


def _stopped(signum: int, frame: FrameType | None) -> None:
    try:
        sys.stderr.write("interrupted\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


def take_signals() -> None:
    """Until a command installs its own handler, Ctrl-C and SIGTERM print one line, exit 130."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stopped)


def _run(module: str) -> int:
    take_signals()
    code: int = importlib.import_module(module).main()
    importlib.import_module("aftir_rl.cli.guard").exit_with(code)  # Ctrl-C ignored from here
    return code


def aftir() -> int:
    """``aftir``: :func:`aftir_rl.cli.main.main`."""
    return _run("aftir_rl.cli.main")


def train() -> int:
    """``aftir-train``: :func:`aftir_rl.cli.train.main`."""
    return _run("aftir_rl.cli.train")


def tank() -> int:
    """``aftir-tank``: :func:`aftir_rl.cli.tank.main`."""
    return _run("aftir_rl.cli.tank")
