"""The ``.npz`` checkpoints of the tabular agents: written atomically, read without unpickling.

A checkpoint holds the agent's arrays and a JSON metadata record (format, hyperparameters,
counters, the random generator's state...). :func:`write_npz` writes it to a temporary file and
renames it, so a crash never leaves half a file. :func:`read_q_table` (``aftir_rl.q_table/1``,
:class:`~aftir_rl.rl.tabular.q_table.QLearning`) and :func:`read_goal_table`
(``aftir_rl.q_table_goal/1``, :class:`~aftir_rl.rl.tabular.q_table_goal.GoalQLearning`) check
everything they read (:func:`read_npz_checkpoint`, :func:`check_hyperparameters`) and raise
:class:`~aftir_rl.core.errors.CheckpointError` with a one-line message, so that loading never passes
an unknown or unbounded value on. Reading takes at most the file (``MAX_CHECKPOINT_FILE_BYTES``)
and the arrays (``MAX_CHECKPOINT_BYTES``, views of the bytes inflated), plus the metadata's
JSON: under 400 MB, whatever the file declares.
"""

from __future__ import annotations

import io
import json
import math
import os
import random
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.archives import BoundedZip
from aftir_rl.core.config import brief, read_limited, shorten
from aftir_rl.core.errors import AftirError, CheckpointError
from aftir_rl.core.files import atomic_open

__all__ = [
    "Q_TABLE_FORMAT",
    "GOAL_TABLE_FORMAT",
    "GOAL_INTEGER_HYPERPARAMETERS",
    "MAX_CHECKPOINT_FILE_BYTES",
    "MAX_CHECKPOINT_BYTES",
    "MAX_CHECKPOINT_ENTRIES",
    "MAX_METADATA_BYTES",
    "MAX_NPY_HEADER_BYTES",
    "HYPERPARAMETER_BOUNDS",
    "npz_path",
    "write_npz",
    "read_npz_checkpoint",
    "npy_array",
    "check_number",
    "check_hyperparameters",
    "read_q_table",
    "read_goal_table",
    "random_state_to_json",
    "random_state_from_json",
]

Q_TABLE_FORMAT = "aftir_rl.q_table/1"
GOAL_TABLE_FORMAT = "aftir_rl.q_table_goal/1"
#: Integer keywords of the goal-conditioned agent, with their bounds.
GOAL_INTEGER_HYPERPARAMETERS = {"max_episode_steps": (1, 1_000_000)}

#: The largest checkpoint file read [bytes] (a 1e6-cell raster's table is 48 MB; the goal
#: tables are compressed).
MAX_CHECKPOINT_FILE_BYTES = 128_000_000
#: The most bytes a checkpoint's entries may inflate to, in all, counted as they are read.
MAX_CHECKPOINT_BYTES = 256_000_000
#: The most entries of a checkpoint (its arrays and the metadata: 2 or 3 are written).
MAX_CHECKPOINT_ENTRIES = 8
#: The longest metadata entry [bytes] (JSON in a numpy string, 4 bytes a character; a few kB
#: are written); parsed JSON may take 25 times the characters' count.
MAX_METADATA_BYTES = 1_000_000
#: The longest ``.npy`` header read [bytes] (numpy's own default).
MAX_NPY_HEADER_BYTES = 10_000

#: Bounds of the float keywords every tabular agent's constructor takes (besides ``seed``).
HYPERPARAMETER_BOUNDS: dict[str, tuple[float, float]] = {
    "learning_rate": (1e-12, 1.0),
    "gamma": (0.0, 1.0),
    "exploration_initial_eps": (0.0, 1.0),
    "exploration_final_eps": (0.0, 1.0),
    "exploration_decay": (0.0, 1.0),
    "initial_q": (-1e12, 1e12),
}

#: What reading a damaged array or metadata may raise (numpy and json each have their own).
_READ_ERRORS = (ValueError, TypeError, RecursionError)


def npz_path(path: str | os.PathLike[str]) -> Path:
    """``path`` with ``.npz`` appended if it does not end so."""
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_suffix(path.suffix + ".npz")


def write_npz(
    path: Path, arrays: dict[str, NDArray[Any]], meta: dict[str, Any], compressed: bool = False
) -> Path:
    """Write ``arrays`` and the JSON ``meta`` to the ``.npz`` file ``path`` atomically."""
    save = np.savez_compressed if compressed else np.savez
    named: dict[str, Any] = {**arrays, "metadata": np.array(json.dumps(meta))}
    with atomic_open(path, "wb") as fh:
        save(fh, **named)
    return path


def read_npz_checkpoint(
    path: Path, names: Sequence[str], fmt: str, what: str, hint: str
) -> tuple[dict[str, NDArray[Any]], dict[str, Any]]:
    """The arrays ``names`` and the JSON metadata of an ``.npz`` checkpoint, read safely.

    Nothing is unpickled; the file, its entries as they inflate and the metadata are read under
    the limits of this module's constants (:class:`~aftir_rl.core.archives.BoundedZip`), and the
    arrays are views of the bytes read (:func:`npy_array`). The metadata must be a mapping whose
    ``format`` is ``fmt``.

    Raises:
        CheckpointError: missing, oversized, corrupt or of another format (one line, ``hint``).

    """
    if not path.exists():
        raise CheckpointError(f"{path}: no such {what} file; {hint}")
    raw = read_limited(
        path, MAX_CHECKPOINT_FILE_BYTES, CheckpointError, f"{what} file", f"{what} checkpoint"
    )
    kind = f"{what} checkpoint"
    with BoundedZip(raw, str(path), MAX_CHECKPOINT_BYTES, MAX_CHECKPOINT_ENTRIES, kind, hint) as zf:
        missing = [n for n in (*names, "metadata") if f"{n}.npy" not in zf.names]
        if missing:
            raise CheckpointError(f"{path}: not a readable {kind} (no {missing[0]}); {hint}")
        try:
            arrays = {name: npy_array(zf.read(f"{name}.npy")) for name in names}
            meta = json.loads(npy_array(zf.read("metadata.npy", MAX_METADATA_BYTES)).item())
        except CheckpointError:  # a limit passed: said already
            raise
        except _READ_ERRORS as exc:
            raise CheckpointError(
                f"{path}: not a readable {kind} ({shorten(str(exc), 160)}); {hint}"
            ) from None
    if not isinstance(meta, dict) or meta.get("format") != fmt:
        raise CheckpointError(f"{path}: not an aftir_rl {what} checkpoint; {hint}")
    for name, array in arrays.items():  # numbers only: no strings, records or objects
        if array.dtype.kind not in "biuf":
            raise CheckpointError(f"{path}: {name} holds {array.dtype} values, not numbers; {hint}")
    return arrays, meta


def npy_array(raw: bytearray) -> NDArray[Any]:
    """The array of an ``.npy`` file's bytes: a writable view of them, its header checked first.

    Raises:
        ValueError: not an ``.npy`` file of format 1.0 or 2.0 (what ``np.save`` writes), an array
            of Python objects (never unpickled), or a header that declares more or fewer bytes
            than follow it.

    """
    fmt = np.lib.format
    head = io.BytesIO(bytes(raw[: MAX_NPY_HEADER_BYTES + 16]))
    version = fmt.read_magic(head)
    if version not in ((1, 0), (2, 0)):
        raise ValueError(f"an .npy file of format {version}, not 1.0 or 2.0")
    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
    shape, fortran, dtype = read_header(head, max_header_size=MAX_NPY_HEADER_BYTES)
    if dtype.hasobject:
        raise ValueError("an array of Python objects, which is never unpickled")
    count, offset = math.prod(shape), head.tell()
    if min(shape, default=0) < 0 or count * dtype.itemsize != len(raw) - offset:
        raise ValueError(
            f"an array of shape {brief(shape)} {dtype} over {len(raw) - offset:,} bytes of data"
        )
    array = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
    return array.reshape(shape[::-1]).T if fortran else array.reshape(shape)


def check_number(value: Any, lo: float, hi: float, where: str, integer: bool = False) -> None:
    """Refuse a ``value`` read from a checkpoint that is not a number (an integer) in bounds.

    Raises:
        CheckpointError: naming ``where``.

    """
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if ok and integer:
        ok = isinstance(value, int)
    if not ok or not (lo <= value <= hi):
        kind = "an integer" if integer else "a number"
        raise CheckpointError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")


def check_hyperparameters(
    meta: dict[str, Any], where: str, integers: dict[str, tuple[int, int]] | None = None
) -> None:
    """Check a checkpoint's ``hyperparameters`` (exactly the constructor's keywords) and counters.

    ``integers`` adds integer keywords with their bounds (e.g. the goal-conditioned agent's
    ``max_episode_steps``), so that loading never passes an unknown or unbounded keyword.

    Raises:
        CheckpointError: a missing, unknown or out-of-range value.

    """
    integers = integers or {}
    keys = [*HYPERPARAMETER_BOUNDS, *integers, "seed"]
    hyper = meta.get("hyperparameters")
    if not isinstance(hyper, dict) or set(hyper) != set(keys):
        raise CheckpointError(f"{where}: hyperparameters must hold exactly {', '.join(keys)}")
    for key, (lo, hi) in HYPERPARAMETER_BOUNDS.items():
        check_number(hyper[key], lo, hi, f"{where}: hyperparameters.{key}")
    for key, (ilo, ihi) in integers.items():
        check_number(hyper[key], ilo, ihi, f"{where}: hyperparameters.{key}", integer=True)
    if hyper["seed"] is not None:
        check_number(hyper["seed"], 0, 2**63, f"{where}: hyperparameters.seed", integer=True)
    for key in ("episodes_done", "num_timesteps"):
        check_number(meta.get(key, 0), 0, 10**15, f"{where}: {key}", integer=True)


# ---------------------------------------------------------------- aftir_rl.q_table/1


def read_q_table(path: str | os.PathLike[str]) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """``(q_table, metadata)`` of a :class:`~aftir_rl.rl.tabular.q_table.QLearning` checkpoint.

    Raises:
        CheckpointError: missing, corrupt or not a Q-table checkpoint.

    """
    path = Path(path)
    hint = "retrain with `python -m aftir_rl.train q_table` or pass the right file"
    arrays, meta = read_npz_checkpoint(path, ("q_table",), Q_TABLE_FORMAT, "Q-table", hint)
    q_table = np.asarray(arrays["q_table"], dtype=np.float64)
    if q_table.ndim != 2 or not np.all(np.isfinite(q_table)):
        raise CheckpointError(f"{path}: the Q-table is malformed (shape {q_table.shape}); {hint}")
    _check_q_table_metadata(meta, f"{path}: metadata")
    return q_table, meta


def _check_q_table_metadata(meta: dict[str, Any], where: str) -> None:
    """Check every key :meth:`QLearning.load` and the command lines read from a checkpoint.

    Raises:
        CheckpointError: a missing or malformed value; an ``env_id`` that is not this package's
            grid world (nothing is ever imported from a checkpoint).

    """
    check_hyperparameters(meta, where)
    if "rng_state" in meta:
        try:
            random.Random().setstate(random_state_from_json(meta["rng_state"]))
        except (TypeError, ValueError, OverflowError):
            raise CheckpointError(f"{where}: rng_state is not a random generator's state") from None
    if "env_id" in meta:
        from aftir_rl.envs.registration import registered_env_id

        try:
            registered_env_id(meta["env_id"], where, ("AFTIR-Tank-v0",))
        except AftirError as exc:
            raise CheckpointError(str(exc)) from None
    if "tank" in meta and (not isinstance(meta["tank"], str) or not 0 < len(meta["tank"]) < 4096):
        raise CheckpointError(f"{where}: tank must be a tank name or a YAML path")
    if "tank_fingerprint" in meta and not isinstance(meta["tank_fingerprint"], str):
        raise CheckpointError(f"{where}: tank_fingerprint must be a string")
    for key, integer in (("target", False), ("target_cell", True)):
        value = meta.get(key)
        if value is None:
            continue
        if not isinstance(value, list) or len(value) != 3:
            raise CheckpointError(f"{where}: {key} must be a list of 3 numbers")
        for i, v in enumerate(value):
            check_number(v, -1e6, 1e6, f"{where}: {key}[{i}]", integer=integer)


def random_state_to_json(state: tuple[Any, ...]) -> list[Any]:
    """A :class:`random.Random` state as JSON."""
    version, internal, gauss = state
    return [version, list(internal), gauss]


def random_state_from_json(data: list[Any]) -> tuple[Any, ...]:
    """The :class:`random.Random` state of :func:`random_state_to_json`'s value.

    Raises:
        ValueError: not such a state.

    """
    if not isinstance(data, list) or len(data) != 3 or not isinstance(data[1], list):
        raise ValueError("not a random generator's state")
    version, internal, gauss = data
    if len(internal) != 625 or not all(type(v) is int for v in internal):
        raise ValueError("not a random generator's state")
    return (version, tuple(internal), gauss)


# ---------------------------------------------------------------- aftir_rl.q_table_goal/1


def read_goal_table(
    path: str | os.PathLike[str],
) -> tuple[NDArray[np.float64], NDArray[np.int64], dict[str, Any]]:
    """``(q_table, goal_cells, metadata)`` of a goal-conditioned Q-table checkpoint.

    Raises:
        CheckpointError: missing, corrupt or not a goal-conditioned Q-table checkpoint.

    """
    path = Path(path)
    hint = "retrain with aftir_rl.rl.tabular.train_all_targets or pass the right file"
    arrays, meta = read_npz_checkpoint(
        path, ("q_table", "goal_cells"), GOAL_TABLE_FORMAT, "goal Q-table", hint
    )
    q_table = np.asarray(arrays["q_table"], dtype=np.float64)
    goal_cells = np.asarray(arrays["goal_cells"])
    if not np.issubdtype(goal_cells.dtype, np.integer):
        raise CheckpointError(f"{path}: goal_cells must be integers; {hint}")
    goal_cells = goal_cells.astype(np.int64)
    where = f"{path}: metadata"
    check_hyperparameters(meta, where, GOAL_INTEGER_HYPERPARAMETERS)
    if "rng_state" in meta:
        try:
            np.random.default_rng().bit_generator.state = meta["rng_state"]
        except (TypeError, ValueError, KeyError, OverflowError):
            raise CheckpointError(f"{where}: rng_state is not a generator's state") from None
    if (
        q_table.ndim != 3
        or goal_cells.shape != (q_table.shape[1], 3)
        or not np.all(np.isfinite(q_table))
    ):
        raise CheckpointError(
            f"{path}: the goal Q-table is malformed (shape {q_table.shape}, "
            f"{len(goal_cells)} goals); {hint}"
        )
    return q_table, goal_cells, meta
