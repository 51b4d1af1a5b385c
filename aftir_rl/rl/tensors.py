"""Tensors on disk without pickles.

Nested dicts of weights written by ``torch.save`` and read back with
``torch.load(weights_only=True)`` from a re-packed archive of bounded size. RLlib runs keep
their policy and learner state this way, and so do the route policies: nothing read from such
a file runs code, and a file that declares more than :data:`MAX_STATE_BYTES` is refused before
torch allocates it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from aftir_rl.core.archives import BoundedZip
from aftir_rl.core.config import error_line, read_limited
from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.files import atomic_open

__all__ = ["MAX_RECORDS", "MAX_STATE_BYTES", "as_tensors", "load_tensors", "save_tensors"]

#: The largest weights or learner state read [bytes] (the FTL env's 2 × 256 module with Adam's
#: moments is about 2 MB; the trainer's largest networks under 50 MB).
MAX_STATE_BYTES = 256_000_000
#: The most records (tensors and the pickle) of one such file (about 60 for PPO's learner).
MAX_RECORDS = 4096


def as_tensors(value: Any) -> Any:
    """``value`` with numpy arrays and scalars as tensors and numbers (tuples as lists)."""
    import torch

    if isinstance(value, dict):
        return {k: as_tensors(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [as_tensors(v) for v in value]
    if isinstance(value, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(value))
    if isinstance(value, np.generic):
        return value.item()
    return value


def save_tensors(state: Any, path: Path) -> Path:
    """Write ``state`` (nested dicts of arrays, tensors, numbers) to ``path``, atomically."""
    import torch

    with atomic_open(path, "wb") as fh:
        torch.save(as_tensors(state), fh)
    return path


def load_tensors(path: str | os.PathLike[str], what: str) -> Any:
    """Read what :func:`save_tensors` wrote, with ``torch.load(weights_only=True)``.

    ``what`` names the file in messages ("an RLlib run's weights").

    Raises:
        CheckpointError: missing, too large, or not such a file (nothing unpickled but tensors,
            numbers, strings, lists and dicts).

    """
    import torch

    path = Path(path)
    raw = read_limited(path, MAX_STATE_BYTES, CheckpointError, what, what)
    # torch allocates what a record's directory entry declares: read a re-packed copy whose
    # records are stored, each as long as its directory says (aftir_rl.rl.sb3.loading's way)
    with BoundedZip(raw, str(path), MAX_STATE_BYTES, MAX_RECORDS, "tensor file") as archive:
        del raw
        packed = archive.repack()
    try:
        return torch.load(packed, weights_only=True, map_location="cpu")
    except Exception as exc:  # torch's unpickler raises many kinds; none may escape as a crash
        raise CheckpointError(f"{path}: not {what} ({error_line(exc, 120)})") from None
