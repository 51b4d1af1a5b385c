"""Ctrl-C and SIGTERM as a request to stop, which the long loops honour at their next step.

The command lines (:func:`aftir_rl.cli.guard.cli`) route SIGINT and SIGTERM to :func:`on_signal`.
Outside a :func:`deferred` block the first signal raises ``KeyboardInterrupt`` at once: there is
nothing to finish. Inside one (a training loop) it only sets the flag :func:`requested`; the loop
stops after its current step, saves what it has and raises ``KeyboardInterrupt`` itself. A second
signal ends the process at once (status 130), leaving any run under its ``.NAME.partial`` name.
Without the command lines' handler (a library call) the flag is never set.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["deferred", "held", "on_signal", "raise_again", "request", "requested", "reset"]

#: The line printed when a second signal ends the process at once.
AT_ONCE = "interrupted twice: stopped at once; an unfinished run stays in its .NAME.partial folder"


class _State:
    requested = False
    deferring = 0


def requested() -> bool:
    """Whether a stop was requested (a first Ctrl-C or SIGTERM) since :func:`reset`."""
    return _State.requested


def request() -> None:
    """Ask the loops to stop as a first signal would inside :func:`deferred` (never raises).

    For a process that learns of the request another way than a signal: a Ray Tune trial is
    told by its sweep (:mod:`aftir_rl.experiments.tune`).
    """
    _State.requested = True


def reset() -> None:
    """Forget a request (a command line starts)."""
    _State.requested = False


@contextmanager
def deferred() -> Iterator[None]:
    """A block whose loop polls :func:`requested`: a first signal only sets the flag there."""
    _State.deferring += 1
    try:
        yield
    finally:
        _State.deferring -= 1


@contextmanager
def held() -> Iterator[None]:
    """A block a first signal does not break into: it is raised as the block ends.

    For imports of compiled code (torch), which a ``KeyboardInterrupt`` may abort, or leave
    taken for an unhandled one. Inside a :func:`deferred` block the loop still polls it.
    """
    with deferred():
        yield
    if _State.requested and not _State.deferring:
        raise KeyboardInterrupt


def on_signal(signum: int, frame: FrameType | None) -> None:
    """Signal handler: request a stop (raise now outside :func:`deferred`); the second: exit."""
    if _State.requested:
        try:
            print(AT_ONCE, file=sys.stderr, flush=True)
        finally:
            os._exit(130)
    _State.requested = True
    if not _State.deferring:
        raise KeyboardInterrupt


def raise_again() -> None:
    """Raise a first stop again in the main thread, at its next step (never raises here).

    For a ``KeyboardInterrupt`` that :func:`on_signal` raised where Python cannot raise (a weakref
    callback, a ``__del__``, a finaliser): Python prints and drops it there, and the command would
    go on and end as if never stopped. Inside a :func:`deferred` block nothing is raised, so the
    flag the loop polls is all there is.
    """
    if not _State.requested or _State.deferring:
        return
    _State.requested = False  # on_signal, run again, takes it as the first signal it is
    # sent from another thread a moment later: a signal pending now would be raised here again
    later = threading.Timer(0.02, _send_again, (threading.main_thread().ident,))
    later.daemon = True
    later.start()


def _send_again(main: int) -> None:
    """SIGINT to the main thread, while the command's handler still takes it."""
    if signal.getsignal(signal.SIGINT) is on_signal:
        signal.pthread_kill(main, signal.SIGINT)
