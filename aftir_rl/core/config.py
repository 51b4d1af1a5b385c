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
import re
import reprlib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from aftir_rl.core.errors import AftirError, ConfigError

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
    return Path(__file__).resolve().parents[2] / "configs"


#: Folder of the shipped configuration files (``AFTIR_RL_CONFIG_DIR`` overrides it).
CONFIG_DIR = Path(os.environ.get("AFTIR_RL_CONFIG_DIR") or _shipped_config_dir())

#: RRT-Connect's budget [s] for each colliding move of a joint trajectory (used by
#: :func:`aftir_rl.planning.posture.trajectory.plan_trajectory`, ``train q_table``, ``bench``,
#: ``evaluate``).
DEFAULT_BRIDGE_SECONDS = 10.0

#: Clearance [cm] the arm's surface keeps from every solid, wall, the floor outside the panel and
#: the guide, along a whole motion (``--margin`` of ``train q_table``, ``plan``, ``evaluate``,
#: ``bench``).
DEFAULT_MARGIN = 1.0
#: The first seed of the targets SB3 training evaluates its runs on (seeds
#: ``EVAL_SEED .. EVAL_SEED + eval_targets − 1``).
EVAL_SEED = 12345


#: The largest YAML file read [bytes]; tanks and configs are a few kB.
MAX_YAML_BYTES = 256_000

#: The most nodes a YAML document may hold once its aliases are expanded (scalars, lists and
#: mappings each count one): an alias bomb of a few hundred bytes is refused in milliseconds.
MAX_YAML_NODES = 100_000

#: The longest error message a CLI prints [characters].
MAX_MESSAGE_CHARS = 500

_BRIEF = reprlib.Repr()
_BRIEF.maxstring, _BRIEF.maxother, _BRIEF.maxlist, _BRIEF.maxdict, _BRIEF.maxlevel = 60, 60, 6, 6, 3
_BRIEF.maxtuple, _BRIEF.maxset, _BRIEF.maxlong = 6, 6, 40


def brief(value: Any) -> str:
    """``repr(value)`` cut to a sane length, for error messages about untrusted input."""
    try:
        text = _BRIEF.repr(value)
    except Exception:  # a repr that fails must not hide the real error
        text = f"<{type(value).__name__}>"
    return shorten(text, 120)


def shorten(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` cut to ``limit`` characters, with an ellipsis where it was cut."""
    text = str(text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader (no Python objects) that refuses documents too large once expanded.

    Every alias is counted with the full size of the node it repeats, so nested aliases (the
    "billion laughs") are measured without being built.
    """

    def compose_document(self) -> Any:
        node = super().compose_document()
        sizes: dict[int, int] = {}
        # children before parents, without recursion (depth is not bounded by PyYAML)
        order, stack, seen = [], [node], set()
        while stack:
            cur = stack.pop()
            if id(cur) in seen:
                continue
            seen.add(id(cur))
            order.append(cur)
            if isinstance(cur, yaml.SequenceNode):
                stack.extend(cur.value)
            elif isinstance(cur, yaml.MappingNode):
                for k, v in cur.value:
                    stack.extend((k, v))
        for cur in reversed(order):
            if isinstance(cur, yaml.SequenceNode):
                children = cur.value
            elif isinstance(cur, yaml.MappingNode):
                children = [n for pair in cur.value for n in pair]
            else:
                children = []
            size = 1 + sum(sizes.get(id(c), 1) for c in children)
            if size > MAX_YAML_NODES:
                raise ConfigError(
                    f"the document expands to more than {MAX_YAML_NODES:,} values (repeated "
                    "aliases?); a tank or config has a few hundred"
                )
            sizes[id(cur)] = size
        return node


#: The deepest nesting read (flow brackets, or indentation and "- " in front of a line).
MAX_YAML_DEPTH = 64


def _too_deep(text: str) -> bool:
    """A cheap upper bound of the nesting, before PyYAML's recursive parser sees the text."""
    depth = 0
    for char in text:
        if char in "[{":
            depth += 1
            if depth > MAX_YAML_DEPTH:
                return True
        elif char in "]}":
            depth -= 1
    indent = re.compile(r"^[ \t\-?:]*")
    return any(
        len(indent.match(line).group()) > 4 * MAX_YAML_DEPTH  # type: ignore[union-attr]
        for line in text.splitlines()
    )


def read_limited(
    path: Path, limit: int, error: type[AftirError], what: str = "file", kind: str = "file"
) -> bytes:
    """The bytes of the file ``path``, refused when larger than ``limit``.

    Raises:
        error: "cannot read the <what>" (missing, a folder...) or "larger than ... not a <kind>".

    """
    try:
        with open(path, "rb") as fh:
            raw = fh.read(limit + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if len(raw) > limit:
        raise error(f"{path}: larger than {limit:,} bytes; not a {kind}")
    return raw


def read_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a YAML file that must hold a mapping.

    Only plain data is built (PyYAML's safe loader); the file must be UTF-8, at most
    :data:`MAX_YAML_BYTES` long and at most :data:`MAX_YAML_NODES` values once its aliases are
    expanded.

    Raises:
        ConfigError: the file is missing, too large, not UTF-8, not valid YAML, or does not hold a
            mapping.

    """
    path = Path(path)
    raw = read_limited(path, MAX_YAML_BYTES, ConfigError, "file", "tank or config")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}); save it as UTF-8") from None
    if _too_deep(text):
        raise ConfigError(f"{path}: not valid YAML: nested too deeply")
    try:
        data = yaml.load(text, Loader=_BoundedLoader)  # noqa: S506 (a SafeLoader)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        problem = shorten(str(getattr(exc, "problem", None) or exc), 200)
        raise ConfigError(f"{path}: not valid YAML{line}: {problem}") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid YAML: nested too deeply") from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. an int of 5,000 digits
        raise ConfigError(f"{path}: not valid YAML: {shorten(str(exc), 200)}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: expected a mapping of keys to values, got {type(data).__name__}"
        )
    return data


def to_float(value: Any, where: str, limit: float | None = None) -> float:
    """Convert a YAML scalar to a finite float, accepting strings such as ``"1e-3"``.

    ``limit``: the largest magnitude accepted, if any.
    """
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected a number, got {brief(value)}")
    if isinstance(value, str) and len(value) > 100:
        raise ConfigError(f"{where}: expected a number, got {brief(value)}")
    try:
        out = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}: expected a number, got {brief(value)}") from None
    if not math.isfinite(out):
        raise ConfigError(f"{where}: expected a finite number, got {brief(value)}")
    if limit is not None and abs(out) > limit:
        raise ConfigError(f"{where}: {out:g} is out of range; at most {limit:g} in magnitude")
    return out


def to_int(value: Any, where: str, limit: float | None = None) -> int:
    """Convert a YAML scalar to an int; floats must be whole numbers."""
    if isinstance(value, bool):
        raise ConfigError(f"{where}: expected an integer, got {brief(value)}")
    try:
        number = to_float(value, where)
    except ConfigError:
        raise ConfigError(f"{where}: expected an integer, got {brief(value)}") from None
    if number != int(number):
        raise ConfigError(f"{where}: expected an integer, got {brief(value)}")
    if limit is not None and abs(number) > limit:
        raise ConfigError(f"{where}: {number:g} is out of range; at most {limit:g} in magnitude")
    return int(number)


def to_vector(
    value: Any, where: str, size: int = 3, limit: float | None = None
) -> tuple[float, ...]:
    """Convert a YAML list to a tuple of ``size`` floats (each at most ``limit`` in magnitude)."""
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ConfigError(f"{where}: expected a list of {size} numbers, got {brief(value)}")
    return tuple(to_float(v, f"{where}[{i}]", limit) for i, v in enumerate(value))


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
            raise ConfigError(f"{where}: expected true or false, got {brief(value)}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {brief(value)}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {brief(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected a list of {len(args)} items, got {brief(value)}")
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
    unknown = sorted(set(data) - set(fields), key=str)
    if unknown:
        raise ConfigError(
            f"{source}: unknown key {brief(unknown[0])}; allowed keys are "
            f"{', '.join(sorted(fields))}"
        )
    kwargs = {}
    for name, value in data.items():
        kwargs[name] = _convert(value, hints[name], f"{source}: {name}")
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{source}: {shorten(str(exc), 300)}") from None
