"""Files: atomic writes, bounded JSON reads, writable output folders.

A write goes to a temporary file beside the target and is renamed over it, so a crash or an
error mid-write leaves the old file (or none), never half of a new one. JSON read from a run
directory is size-limited (:data:`MAX_JSON_BYTES`).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from aftir_rl.core.config import read_limited, shorten
from aftir_rl.core.errors import CheckpointError, ConfigError

__all__ = [
    "MAX_JSON_BYTES",
    "atomic_open",
    "check_writable_dir",
    "staged_dir",
    "read_json",
    "write_json",
]

#: The largest JSON file read from a run directory [bytes].
MAX_JSON_BYTES = 16_000_000


@contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file that replaces ``path`` when the block exits without error."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes 0600; a file written in place would get 0666 less the umask (0644).
        umask = os.umask(0o022)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: str | os.PathLike[str], data: Any) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_open(path) as fh:
        json.dump(data, fh, indent=2)
        fh.write("\n")


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


@contextmanager
def staged_dir(
    final: str | os.PathLike[str], keep: Callable[[Path], bool] | None = None
) -> Iterator[Path]:
    """A hidden ``.<name>.partial`` folder beside ``final``, renamed to ``final`` on success.

    A run directory is written under this name, so a half-written one never looks finished.
    If the block fails (Ctrl-C included) the folder is removed, unless ``keep(folder)`` says
    to keep it (e.g. it holds a checkpoint to resume from).
    """
    final = Path(final)
    partial = final.with_name(f".{final.name}.partial")
    partial.mkdir(parents=True, exist_ok=False)
    try:
        yield partial
        partial.rename(final)
    except BaseException:
        if keep is None or not keep(partial):
            shutil.rmtree(partial, ignore_errors=True)
        raise
