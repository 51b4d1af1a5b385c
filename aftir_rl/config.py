"""Strict YAML loading into frozen dataclasses.

HighwayEnv's ``configure()`` is a plain ``dict.update`` that silently accepts typos; here every key
must be a field of the target dataclass, and every value is converted deliberately to the field's
type (PyYAML reads ``1e-3`` as a string, so numbers are parsed by us, not by YAML).
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import math
import os
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from aftir_rl.errors import ConfigError

T = TypeVar("T")


def _shipped_config_dir() -> Path:
    """The shipped ``configs/`` folder: ``aftir_rl/configs`` inside an installed wheel.

    The repository keeps ``configs/`` at its top; the build maps it into the package as
    ``aftir_rl.configs`` (``[tool.setuptools.package-dir]``), so a wheel carries one copy of each
    file. An editable install or a source checkout has no ``aftir_rl/configs``: the repository's
    own folder is used.
    """
    shipped = importlib.resources.files("aftir_rl") / "configs"
    if shipped.is_dir():
        return Path(str(shipped))
    return Path(__file__).resolve().parent.parent / "configs"


#: Folder of the shipped configuration files (``AFTIR_RL_CONFIG_DIR`` overrides it).
CONFIG_DIR = Path(os.environ.get("AFTIR_RL_CONFIG_DIR") or _shipped_config_dir())

#: RRT-Connect's budget [s] for each colliding move of a joint trajectory (used by
#: :func:`aftir_rl.posture.trajectory.plan_trajectory`, ``train q_table``, ``bench``, ``evaluate``).
DEFAULT_BRIDGE_SECONDS = 10.0

#: Clearance [cm] the arm's surface keeps from every solid, wall, the floor outside the panel and
#: the guide, along a whole motion (``--margin`` of ``train q_table``, ``plan``, ``evaluate``,
#: ``bench``).
DEFAULT_MARGIN = 1.0


def read_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a YAML file that must hold a mapping.

    Raises:
        ConfigError: the file is missing, is not valid YAML, or does not hold a mapping.

    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the file ({exc.strerror or exc})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        raise ConfigError(f"{path}: not valid YAML{line}: {getattr(exc, 'problem', exc)}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: expected a mapping of keys to values, got {type(data).__name__}"
        )
    return data


def to_float(value: Any, where: str) -> float:
    """Convert a YAML scalar to a finite float, accepting strings such as ``"1e-3"``."""
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected a number, got {value!r}") from None
    if not math.isfinite(out):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    return out


def to_int(value: Any, where: str) -> int:
    """Convert a YAML scalar to an int; floats must be whole numbers."""
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected an integer, got {value!r}")
    try:
        number = to_float(value, where)
    except ConfigError:
        raise ConfigError(f"{where}: expected an integer, got {value!r}") from None
    if number != int(number):
        raise ConfigError(f"{where}: expected an integer, got {value!r}")
    return int(number)


def to_vector(value: Any, where: str, size: int = 3) -> tuple[float, ...]:
    """Convert a YAML list to a tuple of ``size`` floats."""
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ConfigError(f"{where}: expected a list of {size} numbers, got {value!r}")
    return tuple(to_float(v, f"{where}[{i}]") for i, v in enumerate(value))


def _convert(value: Any, annotation: Any, where: str) -> Any:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        others = [a for a in args if a is not type(None)]
        return _convert(value, others[0], where)
    if annotation is float:
        return to_float(value, where)
    if annotation is int:
        return to_int(value, where)
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected a list of {len(args)} items, got {value!r}")
        return tuple(_convert(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    return value


def from_mapping(cls: type[T], data: dict[str, Any], source: str) -> T:
    """Build the frozen dataclass ``cls`` from ``data``, rejecting unknown keys.

    Args:
        cls: a dataclass whose fields have simple annotations (float, int, bool, str, tuples).
        data: the mapping read from YAML.
        source: file name used in error messages.

    Raises:
        ConfigError: an unknown key, a missing required key or a value of the wrong type.

    """
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(
            f"{source}: unknown key {unknown[0]!r}; allowed keys are {', '.join(sorted(fields))}"
        )
    kwargs = {}
    for name, value in data.items():
        kwargs[name] = _convert(value, hints[name], f"{source}: {name}")
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    except ValueError as exc:
        raise ConfigError(f"{source}: {exc}") from None
