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
import stat
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
    """``text`` on one line (:func:`one_line`), cut to ``limit`` characters with an ellipsis."""
    text = one_line(str(text))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def error_line(exc: BaseException, limit: int = MAX_MESSAGE_CHARS) -> str:
    """The first line of ``exc``'s message (its type's name if empty), :func:`shorten`-ed."""
    text = str(exc).strip()
    return shorten(text.splitlines()[0] if text else type(exc).__name__, limit)


def one_line(text: str) -> str:
    """``text`` with every run of whitespace made one space and other control characters "?"."""
    return _CONTROL.sub("?", " ".join(text.split()))


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def printable(text: str, cursor_up: bool = False) -> str:
    r"""``text`` safe for a terminal: control characters "?", but line ends and tabs.

    Kept are ``\n``, ``\r`` and ``\t`` (lines, progress bars redrawing their line) and,
    with ``cursor_up``, the ``ESC[A`` that tqdm writes between stacked bars (on stderr); every
    other C0/C1 control character (an ``ESC`` that would start a sequence retitling or clearing
    the terminal, a bell, a backspace) becomes "?".
    """
    if not cursor_up:
        return _UNPRINTABLE.sub("?", text)
    return _UNPRINTABLE_BUT_UP.sub(lambda m: m.group() if m.group() == "\x1b[A" else "?", text)


_UNPRINTABLE = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")
_UNPRINTABLE_BUT_UP = re.compile(r"\x1b\[A|" + _UNPRINTABLE.pattern)


#: The deepest nesting read: lists and mappings inside each other, aliases followed.
MAX_YAML_DEPTH = 64
_TOO_DEEP = f"not valid YAML: nested too deeply (more than {MAX_YAML_DEPTH} levels)"


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader (no Python objects) that refuses what a tank or config never holds.

    A document larger than :data:`MAX_YAML_NODES` values or deeper than :data:`MAX_YAML_DEPTH`
    once its aliases are expanded (measured on the composed nodes, without building them), an
    alias inside its own anchor, and a key given twice in one mapping.
    """

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._keys_checked: set[int] = set()

    def compose_node(self, parent: Any, index: Any) -> Any:
        # PyYAML composes recursively: stop at the limit, long before Python's recursion limit
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH + 1:
                raise ConfigError(_TOO_DEEP)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def compose_document(self) -> Any:
        node = super().compose_document()
        _measure(node)
        return node

    def flatten_mapping(self, node: Any) -> None:
        # the first call sees the mapping as written; merging ("<<") then changes node.value
        if id(node) not in self._keys_checked:
            self._keys_checked.add(id(node))
            self._check_unique_keys(node)
        super().flatten_mapping(node)

    def _check_unique_keys(self, node: yaml.MappingNode) -> None:
        lines: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key, line = self.construct_object(key_node, deep=True), key_node.start_mark.line + 1
            try:
                first = lines.get(key)
            except TypeError:  # an unhashable key: PyYAML refuses it when building the mapping
                continue
            if first is not None:
                raise ConfigError(
                    f"duplicate key {brief(key)} on line {line} (first on line {first}); give "
                    "each key once"
                )
            lines[key] = line


def _children(node: Any) -> list[Any]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _measure(root: Any) -> None:
    """Refuse a composed document too large, too deep or recursive once its aliases are followed.

    Iterative (no recursion however deep), each node visited once: a repeated alias counts the
    size and depth of the node it repeats.
    """
    sizes: dict[int, int] = {}
    depths: dict[int, int] = {}
    open_nodes: set[int] = set()  # entered, not finished: the path from the root
    stack: list[tuple[Any, bool]] = [(root, False)]
    while stack:
        node, finished = stack.pop()
        key, children = id(node), _children(node)
        if finished:
            open_nodes.discard(key)
            sizes[key] = 1 + sum(sizes[id(c)] for c in children)
            collection = isinstance(node, yaml.CollectionNode)
            depths[key] = collection + max((depths[id(c)] for c in children), default=0)
            if sizes[key] > MAX_YAML_NODES:
                raise ConfigError(
                    f"the document expands to more than {MAX_YAML_NODES:,} values (repeated "
                    "aliases?); a tank or config has a few hundred"
                )
            if depths[key] > MAX_YAML_DEPTH:
                raise ConfigError(_TOO_DEEP)
        elif key in open_nodes:
            raise ConfigError("not valid YAML: an alias inside its own anchor (a recursive value)")
        elif key not in sizes:
            open_nodes.add(key)
            stack.append((node, True))
            stack.extend((c, False) for c in children)


def read_limited(
    path: Path, limit: int, error: type[AftirError], what: str = "file", kind: str = "file"
) -> bytes:
    """The bytes of the regular file ``path``, refused when larger than ``limit``.

    Opened without blocking (a FIFO with no writer does not hang) and checked before any read:
    a FIFO, a device, a socket or a folder is refused, as is a file whose size is above
    ``limit``; at most ``limit + 1`` bytes are read (a file that grows meanwhile is refused).

    Raises:
        error: "cannot read the <what>" (missing, not a regular file...) or "larger than ...
            not a <kind>".

    """
    flags = os.O_RDONLY
    for name in ("O_NONBLOCK", "O_NOCTTY", "O_CLOEXEC", "O_BINARY"):
        flags |= getattr(os, name, 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    try:
        mode, size = _regular_size(fd)
        if mode:
            raise error(f"{path}: cannot read the {what}: not a regular file ({mode})")
        if size > limit:
            raise error(f"{path}: larger than {limit:,} bytes; not a {kind}")
        chunks, left = [], limit + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    raw = b"".join(chunks)
    if len(raw) > limit:
        raise error(f"{path}: larger than {limit:,} bytes; not a {kind}")
    return raw


def _regular_size(fd: int) -> tuple[str, int]:
    """``("", size)`` for a regular file, else ``(what it is, 0)`` ("a folder", "a FIFO"...)."""
    info = os.fstat(fd)
    if stat.S_ISREG(info.st_mode):
        return "", info.st_size
    kinds = (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    )
    return next((name for test, name in kinds if test(info.st_mode)), "a special file"), 0


def read_yaml(path: str | os.PathLike[str], raw: bytes | None = None) -> dict[str, Any]:
    """Read a YAML file that must hold a mapping (``raw``: its bytes, if read already).

    Only plain data is built (PyYAML's safe loader); the file must be a regular file of UTF-8
    text, at most :data:`MAX_YAML_BYTES` long, :data:`MAX_YAML_NODES` values and
    :data:`MAX_YAML_DEPTH` levels deep once its aliases are expanded, each key of a mapping once.

    Raises:
        ConfigError: the file is missing, too large, not UTF-8, not valid YAML, or does not hold a
            mapping (one line, naming the file).

    """
    path = Path(path)
    if raw is None:
        raw = read_limited(path, MAX_YAML_BYTES, ConfigError, "file", "tank or config")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}); save it as UTF-8") from None
    try:
        data = yaml.load(text, Loader=_BoundedLoader)  # noqa: S506 (a SafeLoader)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML{_yaml_problem(exc, text)}") from None
    except RecursionError:
        raise ConfigError(f"{path}: {_TOO_DEEP}") from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. an int of 5,000 digits
        raise ConfigError(f"{path}: not valid YAML: {shorten(str(exc), 200)}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: expected a mapping of keys to values, got {type(data).__name__}"
        )
    return data


def _yaml_problem(exc: yaml.YAMLError, text: str) -> str:
    """`` (line N): <problem>`` of PyYAML's error, on one line."""
    where = getattr(exc, "problem_mark", None)
    line = where.line + 1 if where is not None else None
    if isinstance(exc, yaml.reader.ReaderError) and isinstance(exc.character, int):
        line = text.count("\n", 0, exc.position) + 1
        problem = f"unacceptable character #x{exc.character:04x}: {exc.reason}"  # no newline
    else:
        problem = str(getattr(exc, "problem", None) or exc)
    return (f" (line {line})" if line else "") + f": {shorten(problem, 200)}"


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


def numbers_from_mapping(cls: type[T], data: Any, where: str, what: str, limit: float) -> T:
    """The frozen dataclass ``cls`` of numbers from a YAML mapping of ``what`` (None: defaults).

    Unknown keys are refused; every value is a finite number of at most ``limit``; ``cls``
    checks the rest and raises :class:`ConfigError`, which gets ``where`` in front.
    """
    if data is None:
        return cls()
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a mapping of {what}, got {brief(data)}")
    known = {item.name for item in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(str(key) for key in data if key not in known)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key {brief(unknown[0])}; known: {', '.join(sorted(known))}"
        )
    values = {key: to_float(value, f"{where}.{key}", limit) for key, value in data.items()}
    try:
        return cls(**values)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
