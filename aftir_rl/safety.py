"""Untrusted input: what a file a user receives may name, and how every command line fails.

Run directories and configs are what people share, so nothing read from them may run code or
import a module:

- an environment id read from a file (``config.json``, a checkpoint's metadata, a YAML config)
  must be one this package registers, bare (``AFTIR-Tank-v0``) or prefixed ``aftir_rl:``; Gymnasium
  would import the module before the colon of any other (:func:`registered_env_id`);
- JSON files of a run directory are read with a size limit and checked key by key
  (:func:`read_json`).

:func:`cli` wraps the ``main`` of every command line: a user error prints one line and exits 2,
Ctrl-C prints "interrupted" and exits 130, a closed or full output is one line and exit 2, never
a traceback.
"""

from __future__ import annotations

import errno
import functools
import json
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

from aftir_rl.config import read_limited, shorten
from aftir_rl.errors import AftirError, CheckpointError, ConfigError

__all__ = ["MAX_JSON_BYTES", "registered_env_id", "read_json", "cli", "check_writable_dir"]

#: The largest JSON file read from a run directory [bytes].
MAX_JSON_BYTES = 16_000_000

F = TypeVar("F", bound=Callable[..., int])


def registered_env_id(value: Any, where: str, allowed: Iterable[str] | None = None) -> str:
    """The bare id of one of this package's environments, from ``value`` read from a file.

    Accepts ``ID`` or ``aftir_rl:ID`` where ``ID`` is in ``allowed`` (default: every id
    :data:`aftir_rl.envs.ENV_IDS` registers). Anything else, a ``module:ID`` that Gymnasium would
    import above all, is a :class:`ConfigError`; nothing is imported.
    """
    from aftir_rl.envs import ENV_IDS

    ids = tuple(allowed) if allowed is not None else tuple(ENV_IDS)
    if not isinstance(value, str) or len(value) > 200:
        raise ConfigError(f"{where}: env_id must be one of {', '.join(ids)}")
    bare = value[len("aftir_rl:") :] if value.startswith("aftir_rl:") else value
    if bare not in ids:
        raise ConfigError(
            f"{where}: env_id {shorten(repr(value), 80)} is not one of {', '.join(ids)} "
            "(optionally prefixed 'aftir_rl:'); no other module is imported"
        )
    return bare


def read_json(path: str | os.PathLike[str], what: str = "file") -> Any:
    """Parse a JSON file of at most :data:`MAX_JSON_BYTES`, or raise :class:`CheckpointError`."""
    path = Path(path)
    raw = read_limited(path, MAX_JSON_BYTES, CheckpointError, what, what)
    try:
        return json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise CheckpointError(f"{path}: not a valid {what} ({shorten(str(exc), 120)})") from None


def check_writable_dir(path: str | os.PathLike[str], flag: str = "--logdir") -> Path:
    """Make ``path`` (and its parents) if needed and check it is a writable directory.

    Raises:
        ConfigError: it is a file, cannot be made, or cannot be written in.

    """
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ConfigError(f"{flag} {path}: exists and is not a directory") from None
    except OSError as exc:
        raise ConfigError(f"{flag} {path}: cannot make it ({exc.strerror or exc})") from None
    if not path.is_dir():
        raise ConfigError(f"{flag} {path}: not a directory")
    if not os.access(path, os.W_OK | os.X_OK):
        raise ConfigError(f"{flag} {path}: not writable")
    return path


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

    - :class:`~aftir_rl.errors.AftirError`: ``error: <message>`` (cut to a sane length), exit 2;
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
