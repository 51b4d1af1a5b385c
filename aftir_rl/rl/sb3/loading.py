"""Loading a saved SB3 model without unpickling anything from the file.

A ``model.zip`` that people share may hold pickles that run code when SB3 loads it. Here the
model is built from our config and env (:func:`~aftir_rl.rl.sb3.config.build_model`); the
archive gives only the weights and optimizer states (``torch.load(weights_only=True)``) and the
step counters (plain JSON), and a file that needs anything more is refused with a
:class:`~aftir_rl.core.errors.CheckpointError` (:func:`load_model`, :func:`load_run`).

Sizes are counted as the bytes are read, whatever the file declares
(:class:`~aftir_rl.core.archives.BoundedZip`): the file (``MAX_MODEL_FILE_BYTES``), its
entries and the tensors (``MAX_MODEL_BYTES`` each, one ``.pth`` entry held at a time with its
re-packed copy) and ``data``'s JSON: reading a model takes under 320 MB (5 × 64 MB) besides the
model it builds, whatever the file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import GymEnv

from aftir_rl.core.archives import BoundedZip
from aftir_rl.core.config import brief, read_limited, shorten
from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.files import read_json
from aftir_rl.envs.registration import registered_env_id
from aftir_rl.rl.sb3.config import (
    ALGORITHMS,
    MAX_MODEL_BYTES,
    SB3Config,
    build_model,
    sb3_config_from_run,
)

__all__ = [
    "MAX_MODEL_FILE_BYTES",
    "MAX_MODEL_BYTES",
    "MAX_MODEL_ENTRIES",
    "MAX_PTH_RECORDS",
    "MAX_DATA_BYTES",
    "SB3_NOTES",
    "newest_model",
    "load_model",
    "load_run",
]

#: The largest model file read [bytes] (SB3 stores its entries as they are; the arm envs'
#: models are under 10 MB).
MAX_MODEL_FILE_BYTES = 64_000_000
#: The most entries of a model file (SB3 writes 6 to 8).
MAX_MODEL_ENTRIES = 16
#: The most records of one ``.pth`` file (one per tensor: about 40 for SAC's policy).
MAX_PTH_RECORDS = 1024
#: The longest ``data`` entry [bytes] (SB3 writes about 10 kB); parsed JSON may take 25 times
#: its length.
MAX_DATA_BYTES = 1_000_000
#: The entries SB3 writes besides ``data`` and the ``.pth`` files; never read.
SB3_NOTES = ("_stable_baselines3_version", "system_info.txt")

#: Counters read from a model's ``data`` (plain JSON integers); every other entry of ``data``,
#: pickled or not, is ignored: the model is built from our config and env.
_COUNTERS = ("num_timesteps", "_n_updates", "_episode_num")


#: What SB3's own pickled entries of ``data`` reference (spaces, schedules, buffers, policy
#: classes, numpy arrays). They are never unpickled; an entry that references anything else was
#: not written by SB3, and the file is refused.
_PICKLE_GLOBALS = {
    ("numpy", "dtype"),
    ("numpy", "ndarray"),
    ("numpy._core.numeric", "_frombuffer"),
    ("numpy.core.numeric", "_frombuffer"),
    ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy.random._pickle", "__generator_ctor"),
    ("numpy.random._pickle", "__bit_generator_ctor"),
    ("numpy.random._pcg64", "PCG64"),
    ("numpy.random.bit_generator", "__pyx_unpickle_SeedSequence"),
    ("numpy.random.bit_generator", "SeedSequence"),
    ("numpy.random._mt19937", "MT19937"),
    ("numpy.random._generator", "Generator"),
    ("numpy.random._pickle", "__randomstate_ctor"),
    ("numpy._core.multiarray", "scalar"),
    ("numpy.core.multiarray", "scalar"),
    ("collections", "deque"),
    ("collections", "OrderedDict"),
    ("stable_baselines3.common.utils", "FloatSchedule"),
    ("stable_baselines3.common.utils", "ConstantSchedule"),
    ("stable_baselines3.common.utils", "LinearSchedule"),
    ("stable_baselines3.common.type_aliases", "TrainFreq"),
    ("stable_baselines3.common.type_aliases", "TrainFrequencyUnit"),
}
_PICKLE_MODULES = (
    "gymnasium.spaces.",
    "stable_baselines3.common.policies",
    "stable_baselines3.common.buffers",
    "stable_baselines3.ppo.policies",
    "stable_baselines3.sac.policies",
    "stable_baselines3.td3.policies",
    "stable_baselines3.her.",
)


def _pickle_globals(raw: bytes) -> list[tuple[str, str]] | None:
    """The ``(module, name)`` pairs a pickle would import, read without running it.

    Simulates the pickle machine's stack with :mod:`pickletools` (opcodes only, nothing built);
    None when a global's name is not a literal string (then it cannot be told).
    """
    import pickletools

    unknown, mark = object(), object()
    stack: list[Any] = []
    memo: dict[int, Any] = {}
    found: list[tuple[str, str]] = []
    for op, arg, _ in pickletools.genops(raw):
        name = op.name
        if name in ("PUT", "BINPUT", "LONG_BINPUT", "MEMOIZE"):  # the stack is left as it is
            if stack:
                # typeshed: arg is Any | None; the PUT and GET opcodes always carry an int
                memo[len(memo) if name == "MEMOIZE" else int(cast(int, arg))] = stack[-1]
            continue
        if name in ("GLOBAL", "INST"):
            module, _, attr = str(arg).partition(" ")
            found.append((module, attr))
        elif name == "STACK_GLOBAL":
            if len(stack) < 2 or not all(isinstance(x, str) for x in stack[-2:]):
                return None
            found.append((stack[-2], stack[-1]))
        if any(x is pickletools.markobject for x in op.stack_before):
            while stack and stack[-1] is not mark:
                stack.pop()
            if stack:
                stack.pop()
        else:
            del stack[len(stack) - len(op.stack_before) :]
        for item in op.stack_after:
            if item is pickletools.markobject:
                stack.append(mark)
            elif isinstance(arg, str) and ("UNICODE" in name or "STRING" in name):
                stack.append(arg)
            elif name in ("GET", "BINGET", "LONG_BINGET"):
                stack.append(memo.get(int(cast(int, arg)), unknown))
            else:
                stack.append(unknown)
    return found


def _check_pickled_entries(data: dict[str, Any], path: Path) -> None:
    """Refuse a model whose ``data`` holds a pickled entry SB3 would not write (never decoded)."""
    import base64
    import binascii

    for key, item in data.items():
        if not (isinstance(item, dict) and ":serialized:" in item):
            continue
        try:
            raw = base64.b64decode(str(item[":serialized:"]).encode(), validate=True)
            found = _pickle_globals(raw)
        except (binascii.Error, ValueError, IndexError, TypeError):
            found = None
        bad = (
            None
            if found is None
            else [
                f"{m}.{n}"
                for m, n in found
                if (m, n) not in _PICKLE_GLOBALS and not m.startswith(_PICKLE_MODULES)
            ]
        )
        if found is None or bad:
            what = f"references {shorten(', '.join(bad), 80)}" if bad else "cannot be read"
            raise CheckpointError(
                f"{path}: data.{shorten(str(key), 40)} is a pickle that {what}, which SB3 does "
                "not write; refused without unpickling it"
            )


def newest_model(path: str | os.PathLike[str]) -> Path:
    """The model a path names: a ``.zip``, a run's ``model.zip``, or else its newest checkpoint.

    A run directory without ``model.zip`` (an interrupted run) gives its newest
    ``checkpoints/model_<steps>.zip``.

    Raises:
        CheckpointError: nothing to load there.

    """
    path = Path(path)
    if not path.is_dir():
        if not path.is_file():
            raise CheckpointError(
                f"{path}: no such model file; pass a run directory or a .zip model"
            )
        return path
    if (path / "model.zip").is_file():
        return path / "model.zip"
    steps = []
    for p in (path / "checkpoints").glob("model_*.zip"):
        tail = p.stem[len("model_") :]
        if tail.isdigit() and p.is_file():
            steps.append((int(tail), p))
    if not steps:
        raise CheckpointError(
            f"{path}: no model.zip and no checkpoints/model_<steps>.zip; pass a run directory "
            "of python -m aftir_rl.train ppo|sac|td3"
        )
    return max(steps)[1]


def _check_entries(entries: list[str], names: set[str], path: Path) -> None:
    """Refuse an archive without ``data`` or with an entry SB3 does not write for this algorithm.

    Besides ``data`` and :data:`SB3_NOTES`, only ``<name>.pth`` for the state dicts ``names``
    and ``pytorch_variables.pth``.
    """
    if "data" not in entries:
        raise CheckpointError(f"{path}: not an SB3 model (no data entry)")
    for name in entries:
        if name == "data" or name in SB3_NOTES:
            continue
        if not name.endswith(".pth"):
            raise CheckpointError(f"{path}: holds {brief(name)}, which SB3 does not write; refused")
        if name[: -len(".pth")] not in names and name != "pytorch_variables.pth":
            raise CheckpointError(
                f"{path}: holds {brief(name)}, which this algorithm does not save; refused"
            )


def _read_tensors(archive: BoundedZip, name: str, spent: int, path: Path) -> tuple[Any, int]:
    """The tensors of the ``.pth`` entry ``name``, and the bytes of tensors read so far.

    The entry (itself a zip archive) is inflated record by record, the records of all ``.pth``
    entries together under :data:`MAX_MODEL_BYTES` (``spent`` before this one), and torch
    reads a re-packed copy whose records are stored, each as long as its directory says: torch
    allocates what a record's directory entry declares, and would inflate a compressed one.
    ``torch.load(weights_only=True)`` builds tensors and plain containers only.
    """
    import torch

    where = f"{path}: {name}"
    raw = archive.read(name)
    with BoundedZip(
        raw, where, MAX_MODEL_BYTES, MAX_PTH_RECORDS, "tensor file", spent=spent
    ) as pth:
        del raw  # the archive holds a copy
        packed = pth.repack()
        spent = pth.budget - pth.left
    try:
        return torch.load(packed, map_location="cpu", weights_only=True), spent
    except Exception as exc:  # UnpicklingError for anything but tensors
        raise CheckpointError(
            f"{where} holds more than tensors ({shorten(str(exc), 120)}); refused without "
            "running it"
        ) from None


def _read_archive(
    path: Path, names: set[str], variables: set[str]
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """``(data, state_dicts, variables)`` of an SB3 ``.zip`` without unpickling anything.

    ``data`` is parsed as JSON; SB3's base64 cloudpickle entries in it are never decoded. Tensors
    are read with ``torch.load(weights_only=True)`` (:func:`_read_tensors`); entries SB3 does
    not write for this algorithm are refused (:func:`_check_entries`). Every size is counted as
    read, under the limits of this module's constants.
    """
    import json

    raw = read_limited(path, MAX_MODEL_FILE_BYTES, CheckpointError, "model", "loadable SB3 model")
    hint = "retrain or pass the right file"
    with BoundedZip(raw, str(path), MAX_MODEL_BYTES, MAX_MODEL_ENTRIES, "SB3 model", hint) as zf:
        _check_entries(zf.names, names, path)
        text = zf.read("data", MAX_DATA_BYTES)
        try:
            data = json.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise CheckpointError(
                f"{path}: not an SB3 model (its data is not JSON: {shorten(str(exc), 80)}); {hint}"
            ) from None
        if not isinstance(data, dict):
            raise CheckpointError(f"{path}: not an SB3 model (data is not a JSON object)")
        _check_pickled_entries(data, path)
        params, extra, spent = {}, {}, 0
        for name in sorted(n for n in zf.names if n.endswith(".pth")):
            obj, spent = _read_tensors(zf, name, spent, path)
            if name == "pytorch_variables.pth":
                if not isinstance(obj, dict) or set(obj) - variables:
                    raise CheckpointError(f"{path}: unexpected pytorch_variables; refused")
                extra = obj
            else:
                params[name[: -len(".pth")]] = obj
    return data, params, extra


def load_model(
    algo: str,
    path: str | os.PathLike[str],
    env: GymEnv | None = None,
    config: SB3Config | None = None,
    evaluation: bool | None = None,
) -> BaseAlgorithm:
    """Load a saved SB3 model without unpickling anything from the file.

    The model is built from ``config`` (default :class:`SB3Config`) and ``env`` (default: one
    instance of ``config.env_id``), so its spaces, policy class and schedules are ours; the file
    gives only the weights and optimizer states (``torch.load(weights_only=True)``) and the step
    counters (plain JSON). A file that needs anything more (pickled Python objects in its tensor
    files, entries this algorithm does not save, weights of another shape) is refused.

    Args:
        algo: ``ppo``, ``sac`` or ``td3``.
        path: a ``.zip``, or a run directory (``model.zip``, else its newest checkpoint).
        env: the (vector) env to attach; None: a new one, and a model only fit to act.
        config: the run's config (policy, hyperparameters, env id).
        evaluation: build a minimal replay buffer (default: when ``env`` is None).

    Raises:
        CheckpointError: saying what is wrong.

    """
    if not isinstance(algo, str) or algo not in ALGORITHMS:
        raise CheckpointError(
            f"unknown algorithm {brief(algo)}; use one of {', '.join(ALGORITHMS)}"
        )
    path = newest_model(path)
    config = config or SB3Config()
    if evaluation is None:
        evaluation = env is None
    if env is None:
        env_id = f"aftir_rl:{registered_env_id(config.env_id, 'config')}"
        env = gym.make(env_id, **dict(getattr(config, "env_kwargs", None) or {}))
    model = build_model(algo, config, env, seed=0, evaluation=evaluation)
    names, variables = model._get_torch_save_params()
    data, params, extra = _read_archive(path, set(names), set(variables))
    policy_kwargs = data.get("policy_kwargs", {})
    if isinstance(policy_kwargs, dict) and ":serialized:" in policy_kwargs:
        raise CheckpointError(
            f"{path}: its policy_kwargs are pickled Python objects, which are never loaded; refused"
        )
    _set_weights(model, params, path, algo, config)
    _set_extra_tensors(model, extra, path)
    _set_counters(model, data, path)
    return model


#: How to load a model whose weights do not fit the one built from a config.
_CONFIG_HINT = "load it with the config it was trained with (the run's config.json)"


def _set_weights(
    model: BaseAlgorithm, params: dict[str, Any], path: Path, algo: str, config: SB3Config
) -> None:
    """Set the archive's weights and optimizer states (``params``) on ``model``.

    Raises:
        CheckpointError: they do not fit the model built from ``config``.

    """
    try:
        model.set_parameters(params, exact_match=True, device="cpu")
    except (RuntimeError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
        raise CheckpointError(
            f"{path}: its weights do not fit a {algo.upper()} {config.policy} on "
            f"{config.env_id} with these hyperparameters ({shorten(str(exc), 160)}); "
            f"{_CONFIG_HINT}"
        ) from None


def _set_extra_tensors(model: BaseAlgorithm, extra: dict[str, Any], path: Path) -> None:
    """Copy the archive's other tensors (``log_ent_coef``...) into the model's own.

    Raises:
        CheckpointError: one is not a tensor, or not of the model's shape.

    """
    import torch

    for name, tensor in extra.items():
        if tensor is None:
            continue
        current: Any = model
        for part in name.split("."):
            current = getattr(current, part, None)
        if (
            not isinstance(tensor, torch.Tensor)
            or not isinstance(current, torch.Tensor)
            or tensor.shape != current.shape
        ):
            raise CheckpointError(f"{path}: {name} does not fit this model; {_CONFIG_HINT}")
        current.data = tensor.data.to(current.dtype)


def _set_counters(model: BaseAlgorithm, data: dict[str, Any], path: Path) -> None:
    """Set the step counters of ``data`` (plain JSON integers) on ``model``.

    Raises:
        CheckpointError: a counter is not a step count.

    """
    for key in _COUNTERS:
        value = data.get(key, 0)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 10**12:
            raise CheckpointError(f"{path}: data.{key} is not a step count; refused")
        if hasattr(model, key):
            setattr(model, key, value)


def load_run(run_dir: str | os.PathLike[str]) -> tuple[str, SB3Config, str, BaseAlgorithm]:
    """``(algo, config, env_id, model)`` of an SB3 run directory, nothing unpickled.

    ``config.json`` is read with a size limit and every key checked (:func:`sb3_config_from_run`);
    ``env_id`` is ``aftir_rl:<registered id>``; the model is ``model.zip``, or the newest
    checkpoint of an interrupted run (:func:`load_model`).

    Raises:
        CheckpointError: saying what is wrong.

    """
    run_dir = Path(run_dir)
    source = str(run_dir / "config.json")
    algo, config = sb3_config_from_run(read_json(source, "config.json"), source)
    env_id = f"aftir_rl:{registered_env_id(config.env_id, source)}"
    return algo, config, env_id, load_model(algo, run_dir, config=config)
