"""Files: atomic writes, bounded JSON reads, writable output folders, failed writes named.

A write goes to a temporary file beside the target and is renamed over it, so a crash or an
error mid-write leaves the old file (or none), never half of a new one. It replaces only a
regular file (keeping its mode) or nothing: a device, FIFO, socket, directory or symbolic link
at the target is refused in one line (:func:`check_output`), and :func:`check_outputs` refuses
an output that is one of the command's inputs. A full disk or an I/O
error is a :class:`WriteError` naming the file; a run directory being written keeps what it
holds then (:func:`staged_dir`). JSON read from a run directory is size-limited
(:data:`MAX_JSON_BYTES`).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from aftir_rl.core.config import read_limited, shorten
from aftir_rl.core.errors import CheckpointError, ConfigError

__all__ = [
    "DISK_ERRNOS",
    "MAX_JSON_BYTES",
    "WriteError",
    "atomic_open",
    "check_output",
    "check_outputs",
    "describe_write_error",
    "check_writable_dir",
    "staged_dir",
    "UNFINISHED",
    "unfinished_start",
    "run_file",
    "read_json",
    "write_json",
]

#: The largest JSON file read from a run directory [bytes] (a tour of 20 targets: about 20 MB).
MAX_JSON_BYTES = 64_000_000
#: The file of an unfinished run directory: the counters its training started from.
UNFINISHED = "unfinished.json"
#: The errors of a write that no retry fixes: a full disk, a full quota, a failing device.
DISK_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EIO)


class WriteError(OSError):
    """A write that failed on a full disk or a failing device, with the file it was writing.

    Attributes:
        needed: bytes it had written when it failed (it needed more), if known.
        kept: the unfinished run directory kept with what it holds (:func:`staged_dir`).
        resumable: whether ``kept`` holds a checkpoint ``--resume`` continues from.

    """

    def __init__(self, exc: OSError, path: str | os.PathLike[str], needed: int | None = None):
        super().__init__(exc.errno, exc.strerror or str(exc), str(path))
        self.needed = needed
        self.kept: Path | None = None
        self.resumable = False


def _size_text(n: float) -> str:
    """``n`` bytes as ``"512 B"``, ``"12.3 kB"``, ``"1.5 MB"``..."""
    units = ["B", "kB", "MB", "GB", "TB"]
    while n >= 1000 and len(units) > 1:
        n, units = n / 1000, units[1:]
    return f"{n:.0f} B" if units[0] == "B" else f"{n:.1f} {units[0]}"


def _free_space(path: str) -> str:
    """``", N MB free"`` on the device of ``path`` (or of its nearest existing folder), or ""."""
    where = Path(path)
    while not where.exists() and where != where.parent:
        where = where.parent
    try:
        return f"{_size_text(shutil.disk_usage(where).free)} free"
    except OSError:
        return ""


def describe_write_error(exc: OSError) -> str:
    """One line for an ``OSError``: what failed, the file, the space; where a run is kept."""
    name = f" {exc.filename}" if exc.filename else ""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        needed = getattr(exc, "needed", None)
        space = [f"it needs more than {_size_text(needed)}"] if needed else []
        free = _free_space(str(exc.filename)) if exc.filename else ""
        detail = ", ".join(space + ([free] if free else []))
        text = f"no space left on the device writing{name}" + (f" ({detail})" if detail else "")
    elif exc.errno == errno.EIO:
        text = f"input/output error writing{name}"
    else:
        return f"cannot access{name}: {exc.strerror or exc}"
    kept = getattr(exc, "kept", None)
    if kept is not None and getattr(exc, "resumable", False):
        text += f"; continue the run with --resume {kept}"
    elif kept is not None:
        text += f"; the run's logs are kept in {kept}"
    return text


_KINDS = (
    (stat.S_ISLNK, "a symbolic link"),
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
)


def check_output(path: str | os.PathLike[str]) -> int | None:
    """The mode of the regular file at ``path`` (None: nothing there) that a write may replace.

    Raises:
        ConfigError: something else is there (a device, FIFO, socket, directory or symbolic
            link), which a write would destroy.

    """
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write there ({exc.strerror or exc})") from None
    if stat.S_ISREG(info.st_mode):
        return stat.S_IMODE(info.st_mode)
    kind = next((name for test, name in _KINDS if test(info.st_mode)), "not a regular file")
    raise ConfigError(f"{path}: is {kind}, not a regular file; refusing to replace it")


def check_outputs(
    outputs: Iterable[str | os.PathLike[str] | None],
    inputs: Iterable[str | os.PathLike[str] | None],
) -> None:
    """Refuse outputs that would replace an input, another output, or a non-regular file.

    An input that is a folder (a run directory) protects every file in it (a new file there is
    fine); an input file protects itself. ``None`` entries are skipped.

    Raises:
        ConfigError: one line naming the output and what it would replace.

    """
    seen: dict[Path, str] = {}
    given = [Path(p) for p in inputs if p is not None]
    for out in (Path(p) for p in outputs if p is not None):
        check_output(out)
        where = out.resolve()
        if where in seen:
            raise ConfigError(f"{out}: given as two outputs ({seen[where]} and {out})")
        seen[where] = str(out)
        if not where.exists():
            continue
        for source in given:
            home = source.resolve()
            if where == home or (home.is_dir() and home in where.parents):
                what = "it is" if where == home else f"it is in {source}, which is"
                raise ConfigError(
                    f"{out}: {what} an input of this command; write the output elsewhere"
                )


@contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file that replaces ``path`` when the block exits without error.

    Raises:
        ConfigError: ``path`` is not a regular file (:func:`check_output`).

    """
    path = Path(path)
    keep = check_output(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes 0600; a file written in place keeps its mode, a new one gets 0666
        # less the umask (0644).
        if keep is None:
            umask = os.umask(0o022)
            os.umask(umask)
            keep = 0o666 & ~umask
        os.fchmod(fd, keep)
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as fh:
            yield fh
        os.replace(tmp, path)
    except OSError as exc:
        written = Path(tmp).stat().st_size if Path(tmp).exists() else None
        Path(tmp).unlink(missing_ok=True)
        if exc.errno in DISK_ERRNOS and not exc.filename:  # name the file it was writing
            raise WriteError(exc, path, written) from None
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: str | os.PathLike[str], data: Any, compact: bool = False) -> None:
    """Write ``data`` as indented JSON (``compact``: without spaces), atomically."""
    with atomic_open(path) as fh:
        if compact:
            json.dump(data, fh, separators=(",", ":"))
        else:
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
    final: str | os.PathLike[str],
    keep: Callable[[Path], bool] | None = None,
    start: dict[str, int] | None = None,
) -> Iterator[Path]:
    """A hidden ``.<name>.partial`` folder beside ``final``, renamed to ``final`` on success.

    A run directory is written under this name, with an :data:`UNFINISHED` file that holds
    ``start`` (the counters its training started from), so a half-written one never looks
    finished. If the block fails (Ctrl-C included) the folder is removed, unless
    ``keep(folder)`` says to keep it (it holds a checkpoint to resume from). A full disk or a
    failing device keeps it with its logs whatever ``keep`` says, and raises a
    :class:`WriteError` that says so.
    """
    final = Path(final)
    partial = final.with_name(f".{final.name}.partial")
    partial.mkdir(parents=True, exist_ok=False)
    try:
        write_json(partial / UNFINISHED, {"start": start or {}})
        yield partial
        (partial / UNFINISHED).unlink(missing_ok=True)
        partial.rename(final)
    except OSError as exc:
        if exc.errno not in DISK_ERRNOS:
            if keep is None or not keep(partial):
                shutil.rmtree(partial, ignore_errors=True)
            raise
        error = exc if isinstance(exc, WriteError) else WriteError(exc, exc.filename or partial)
        error.kept, error.resumable = partial, keep is not None and keep(partial)
        raise error from None
    except BaseException:
        if keep is None or not keep(partial):
            shutil.rmtree(partial, ignore_errors=True)
        raise


def unfinished_start(path: str | os.PathLike[str]) -> dict[str, int] | None:
    """The counters an unfinished run started from, if ``path`` is or lies in one (else None).

    An unfinished run directory holds :data:`UNFINISHED` (:func:`staged_dir`): a run stopped
    by Ctrl-C, which resuming finishes. Counters that are not whole numbers are left out.
    """
    path = Path(path)
    for folder in (path, *list(path.parents)[:2]):
        if not (folder / UNFINISHED).is_file():
            continue
        try:
            data = read_json(run_file(folder, UNFINISHED), UNFINISHED)
        except (CheckpointError, OSError):
            return None
        start = data.get("start") if isinstance(data, dict) else None
        if not isinstance(start, dict):
            return None
        return {k: v for k, v in start.items() if type(v) is int and v >= 0}
    return None


def run_file(run_dir: str | os.PathLike[str], name: str) -> Path:
    """``run_dir/name``, refused if it (or a symlink on the way) leads out of ``run_dir``.

    A run directory handed over by someone else may hold a symlink to any file of this machine;
    what it names is read only when it stays inside the directory.

    Raises:
        CheckpointError: the path leaves the directory.

    """
    folder = Path(run_dir)
    path = folder / name
    try:
        inside = path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError, ValueError):  # a symlink loop, a NUL byte
        inside = False
    if not inside:
        raise CheckpointError(f"{path}: leads out of the run directory (a symlink?); refused")
    return path
