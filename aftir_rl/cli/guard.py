"""How every command line fails: one line on stderr and an exit status, never a traceback.

:func:`cli` wraps the ``main`` of every command line: a user error prints one line and exits 2,
Ctrl-C prints "interrupted" and exits 130, a closed or full output is one line and exit 2.
"""

from __future__ import annotations

import errno
import functools
import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

from aftir_rl.core.config import shorten
from aftir_rl.core.errors import AftirError

__all__ = ["cli"]

F = TypeVar("F", bound=Callable[..., int])


def _say(line: str) -> None:
    try:
        print(shorten(line), file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr closed too: nothing more to do
        pass


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush cannot raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def cli(main: F) -> F:
    """Wrap a command line's ``main``: every failure a user can cause is one line.

    - :class:`~aftir_rl.core.errors.AftirError`: ``error: <message>`` (cut to a sane length), exit
      2;
    - ``KeyboardInterrupt`` (Ctrl-C): ``interrupted``, exit 130;
    - a closed standard output (``BrokenPipeError``): exit 2 with one line on stderr;
    - any other ``OSError`` (a full disk, a read-only or missing folder): one line, exit 2;
    - ``MemoryError``: one line, exit 2.
    """

    @functools.wraps(main)
    def wrapper(*args: Any, **kwargs: Any) -> int:
        try:
            code = main(*args, **kwargs)
            sys.stdout.flush()  # a full or closed output fails here, not at exit
            return code
        except AftirError as exc:
            _say(f"error: {exc}")
            return 2
        except KeyboardInterrupt:
            _say("interrupted")
            return 130
        except BrokenPipeError:
            _silence_stdout()
            _say("error: the output was closed (broken pipe)")
            return 2
        except OSError as exc:
            _silence_stdout()
            where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
            if exc.errno == errno.ENOSPC:
                _say(f"error: no space left on the device writing{where}")
            else:
                _say(f"error: cannot access{where}: {exc.strerror or exc}")
            return 2
        except MemoryError:
            _say("error: out of memory; use a smaller input")
            return 2

    return wrapper  # type: ignore[return-value]
