"""The logs of a run directory: SB3's CSV and TensorBoard logger, whose failed writes name a file.

:func:`run_logger` opens ``progress.csv`` and the TensorBoard events of a run directory. A full
disk or a failing device while writing them raises :class:`~aftir_rl.core.files.WriteError`
naming the file; when the run fails, the logger is closed without a second error.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from stable_baselines3.common.logger import KVWriter, Logger, make_output_format

from aftir_rl.core.files import DISK_ERRNOS, WriteError

__all__ = ["run_logger"]


@contextmanager
def _naming(path: Path) -> Iterator[None]:
    """Raise a disk error met inside the block as a :class:`WriteError` naming ``path``."""
    try:
        yield
    except OSError as exc:
        if exc.errno in DISK_ERRNOS and not exc.filename:
            raise WriteError(exc, path) from None
        raise


class _Named(KVWriter):
    """An output format of SB3's logger whose failed writes name its file."""

    def __init__(self, inner: KVWriter, path: Path) -> None:
        self.inner, self.path = inner, path

    def write(self, key_values: Any, key_excluded: Any, step: int = 0) -> None:
        with _naming(self.path):
            self.inner.write(key_values, key_excluded, step)

    def close(self) -> None:
        with _naming(self.path):
            self.inner.close()


def _open(kind: str, folder: Path) -> _Named:
    """SB3's ``csv`` or ``tensorboard`` output in ``folder``, wrapped by :class:`_Named`."""
    with _naming(folder):
        inner = make_output_format(kind, str(folder))
    if kind == "csv":
        return _Named(inner, folder / "progress.csv")
    events = sorted(folder.glob("events.out.tfevents.*"), key=lambda p: p.stat().st_mtime)
    return _Named(inner, events[-1] if events else folder / "events.out.tfevents")


@contextmanager
def run_logger(folder: Path) -> Iterator[Logger]:
    """SB3's logger writing ``progress.csv`` and TensorBoard events into ``folder``.

    Closed when the block ends: a failure to write the last records raises (naming the file)
    if the block succeeded, and is ignored if the block failed already.
    """
    logger = Logger(str(folder), [])
    try:
        logger.output_formats = [_open("csv", folder), _open("tensorboard", folder)]
        yield logger
    except BaseException:
        for output in logger.output_formats:
            try:
                output.close()
            except OSError:
                pass  # the disk is full or failing: the error that ended the block says so
        raise
    logger.close()
