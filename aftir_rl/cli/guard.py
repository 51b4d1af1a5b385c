"""How every command line fails: one line on stderr and an exit status, never a traceback.

:func:`cli` wraps the ``main`` of every command line: a user error prints one line and exits 2;
Ctrl-C and SIGTERM ask the running loop to stop (:mod:`aftir_rl.core.interrupts`), then print
"interrupted" (with where the run is kept) and exit 130, a second one exits at once; a closed
or full output, or a failing disk, is one line naming the file and exit 2. Whatever a command
writes to stdout and stderr passes :func:`~aftir_rl.core.config.printable`: a name or text read
from a file cannot send the terminal a control sequence.
"""

from __future__ import annotations

import atexit
import errno
import functools
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, NoReturn, TypeVar

from aftir_rl.core import interrupts
from aftir_rl.core.config import printable, shorten
from aftir_rl.core.errors import AftirError
from aftir_rl.core.files import describe_write_error

__all__ = ["cli", "exit_with", "preload"]

F = TypeVar("F", bound=Callable[..., int])

#: The signals a command line treats as Ctrl-C.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


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


def _quiet_disk_errors(args: Any) -> None:
    """``threading.excepthook`` that keeps a thread's failed write (a log writer's) quiet.

    The main thread meets the same error at its next write and reports it in one line; any other
    error of a thread is printed as usual.
    """
    exc = args.exc_value
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EIO, errno.EDQUOT):
        return
    threading.__excepthook__(args)


def _interrupt_again(unraisable: Any) -> None:
    """``sys.unraisablehook``: a Ctrl-C that met a callback is raised again, not printed and lost.

    Any other exception Python cannot raise is printed as usual.
    """
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        for _ in range(3):  # (should the signal sent again arrive before this hook returns)
            try:
                interrupts.raise_again()
                return
            except KeyboardInterrupt:
                continue
        return
    sys.__unraisablehook__(unraisable)


@contextmanager
def _stop_signals() -> Iterator[None]:
    """Route SIGINT and SIGTERM to :func:`aftir_rl.core.interrupts.on_signal` (main thread)."""
    interrupts.reset()
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, interrupts.on_signal) for sig in STOP_SIGNALS}
    hook, threading.excepthook = threading.excepthook, _quiet_disk_errors
    unraisable, sys.unraisablehook = sys.unraisablehook, _interrupt_again
    try:
        yield
    finally:
        threading.excepthook = hook
        sys.unraisablehook = unraisable
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if interrupts.requested():  # the process ends soon: a second Ctrl-C then ends it at once
            atexit.unregister(_exit_at_once_from_now)
            atexit.register(_exit_at_once_from_now)
        interrupts.reset()  # a library call after this one (a notebook, a test) is not stopped


def preload(*modules: str) -> None:
    """Import ``modules`` (compiled code: torch, Ray) with a Ctrl-C held until they are in.

    A ``KeyboardInterrupt`` raised inside such an import may abort the process, or be taken for
    an unhandled one at exit; a long command imports them first, so that one is raised after.
    """
    with interrupts.held():
        for name in modules:
            importlib.import_module(name)


def exit_with(code: int) -> NoReturn:
    """End a command's process with ``code``: its output flushed, then Ctrl-C ignored.

    Once a command has finished and said so, a signal while the interpreter exits (atexit work,
    freeing torch and the other modules: up to a second) would kill it with SIGINT's status and
    no word, as Python puts the default handlers back first; ignored (not blocked: that holds
    for one thread only), the process exits with the status it reported. An interrupted
    command (130) runs the atexit functions and leaves without the interpreter's teardown: a
    Ctrl-C that met C code running Python (an import, a compiled library) marks the process
    to kill itself by SIGINT at the end of that teardown, and Ray's teardown may crash.
    """
    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread:
        for sig in STOP_SIGNALS:
            signal.signal(sig, signal.SIG_IGN)
    if code == 130 and main_thread:  # interrupted: Python may still die by SIGINT at its exit
        atexit._run_exitfuncs()  # Ray's shutdown, the loggers' last flush
        _flush()
        os._exit(130)
    _flush()
    sys.exit(code)


def _flush() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass


def _exit_at_once(signum: int, frame: Any) -> None:
    os._exit(130)


def _exit_at_once_from_now() -> None:
    """At exit after an interrupt: another signal ends the process, not a traceback there."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, _exit_at_once)


def cli(main: F) -> F:
    """Wrap a command line's ``main``: every failure a user can cause is one line.

    - :class:`~aftir_rl.core.errors.AftirError`: ``error: <message>`` (cut to a sane length), exit
      2;
    - Ctrl-C or SIGTERM (``KeyboardInterrupt``): ``interrupted`` and the interrupted run's
      message (where it is kept, how to resume it), exit 130;
    - a closed standard output (``BrokenPipeError``): exit 2 with one line on stderr;
    - any other ``OSError`` (a full disk, a read-only or missing folder): one line naming the
      file, exit 2;
    - ``MemoryError``: one line, exit 2.
    """

    @functools.wraps(main)
    def wrapper(*args: Any, **kwargs: Any) -> int:
        _announce_compiling()
        with _stop_signals(), _printable_output():  # a second Ctrl-C exits at once too
            return _one_line_failures(main, args, kwargs)

    return wrapper  # type: ignore[return-value]


class _Printable:
    """A text stream that writes what it is given through :func:`printable` to ``stream``."""

    def __init__(self, stream: Any, cursor_up: bool) -> None:
        self._stream, self._cursor_up = stream, cursor_up

    def write(self, text: str) -> int:
        self._stream.write(printable(text, self._cursor_up))
        return len(text)

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name: str) -> Any:  # flush, fileno, isatty, encoding...
        return getattr(self._stream, name)


@contextmanager
def _printable_output() -> Iterator[None]:
    """Send stdout and stderr through :class:`_Printable` (stderr keeps tqdm's cursor-up)."""
    out, err = sys.stdout, sys.stderr
    if isinstance(out, _Printable):  # a command called by another: already wrapped
        yield
        return
    sys.stdout, sys.stderr = _Printable(out, False), _Printable(err, True)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = out, err


_ANNOUNCED: list[bool] = []


def _announce_compiling() -> None:
    """At a terminal, say so once when numba starts compiling a kernel (its cache is cold).

    The kernels compile once per install (``make install`` does it ahead); from a fresh wheel
    the first command that needs them would otherwise sit silent for a minute or two. Only at a
    terminal: piped output and tests stay as they are.
    """
    if _ANNOUNCED or not sys.stderr.isatty():
        return
    _ANNOUNCED.append(True)
    from numba.core import event

    class _Notice(event.Listener):
        said = False

        def on_start(self, ev: event.Event) -> None:
            if not self.said:
                self.said = True
                _say(
                    "compiling the package's numba kernels, once per install (about a minute "
                    "or two on 2 cores; later runs load them from the cache)..."
                )

        def on_end(self, ev: event.Event) -> None:
            pass

    event.register("numba:compile", _Notice())


def _one_line_failures(main: Callable[..., int], args: Any, kwargs: Any) -> int:
    """Run ``main``; turn what a user can cause into one line and an exit status (:func:`cli`)."""
    try:
        code = main(*args, **kwargs)
        sys.stdout.flush()  # a full or closed output fails here, not at exit
        return code
    except AftirError as exc:
        _say(f"error: {exc}")
        return 2
    except KeyboardInterrupt as exc:
        _say(f"interrupted: {exc}" if str(exc) else "interrupted")
        return 130
    except BrokenPipeError:
        _silence_stdout()
        _say("error: the output was closed (broken pipe)")
        return 2
    except OSError as exc:
        _silence_stdout()
        _say(f"error: {describe_write_error(exc)}")
        return 2
    except MemoryError:
        _say("error: out of memory; use a smaller input")
        return 2
