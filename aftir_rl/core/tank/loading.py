"""Reading tanks from YAML: ``configs/tanks/NAME.yaml`` or a path, validated key by key.

Files load into the frozen dataclasses of :mod:`aftir_rl.core.tank.geometry`; an unknown key, a
negative size, a hatch outside its baffle or an obstacle outside the box is a
:class:`~aftir_rl.core.errors.ConfigError` naming the file and the key (docs/design.md §3).
"""

from __future__ import annotations

import hashlib
import math
import re
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, cast

import numpy as np
import yaml

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.camera import Camera
from aftir_rl.core.config import (
    CONFIG_DIR,
    MAX_YAML_BYTES,
    brief,
    read_limited,
    read_yaml,
    to_float,
    to_int,
    to_vector,
)
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.files import atomic_open
from aftir_rl.core.robot import ArmSpec
from aftir_rl.core.rod import RodProperties
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank.generate import FAMILIES, generated_tank
from aftir_rl.core.tank.geometry import Panel, Tank
from aftir_rl.core.tank.parts import (
    MAX_CELLS,
    MAX_COORD,
    MAX_SECTIONS,
    MAX_TARGETS,
    parse_baffle,
    parse_baffles,
    parse_obstacles,
    parse_taper,
    parse_walls_mesh,
    positive,
    require,
    section,
)
from aftir_rl.core.tank.raster import format_point
from aftir_rl.core.tank.solids import Solid, Vec3

__all__ = [
    "TANK_DIR",
    "RUN_TANK_FILE",
    "tank_files",
    "load_tank",
    "available_tanks",
    "resolve_run_tank",
    "keep_run_tank",
    "tank_from_mapping",
    "generated_spec",
    "names_generated",
    "POOL_SPEC",
    "STREAM_SPEC",
    "MAX_COORD",
    "MAX_CELLS",
    "MAX_SECTIONS",
    "MAX_TARGETS",
]

TANK_DIR = CONFIG_DIR / "tanks"

_TOP_KEYS = {
    "name",
    "description",
    "box",
    "cell_size",
    "panel",
    "start_point",
    "baffle",
    "hatch",
    "baffles",
    "taper",
    "obstacles",
    "arm",
    "targets",
    "walls",
    "mesh",
}


def tank_from_mapping(data: Mapping[str, Any], source: str) -> Tank:
    """Build and validate a :class:`Tank` from a mapping read from YAML.

    Raises:
        ConfigError: naming ``source`` and the offending key.

    """
    src = source
    unknown = sorted(set(data) - _TOP_KEYS, key=str)
    if unknown:
        raise ConfigError(
            f"{src}: unknown key {brief(unknown[0])}; allowed keys are "
            f"{', '.join(sorted(_TOP_KEYS))}"
        )
    walls_mesh: tuple[Solid, ...] = ()
    if data.get("mesh") is None:
        lo, hi = _parse_box(data, src)
    else:
        lo, hi, solid = parse_walls_mesh(data, src)
        walls_mesh = (solid,)
    kwargs: dict[str, Any] = {"box_min": lo, "box_max": hi, "source": src}
    kwargs["name"] = str(data.get("name", Path(src).stem))
    kwargs["description"] = str(data.get("description", ""))
    walls = data.get("walls", True)
    if not isinstance(walls, bool):
        raise ConfigError(f"{src}: walls: expected true or false, got {brief(walls)}")
    kwargs["walls"] = walls
    if data.get("cell_size") is not None:
        kwargs["cell_size"] = _parse_cell_size(data["cell_size"], lo, hi, src)
    if "panel" in data:
        panel = section(data, "panel", {"center", "radius"}, src)
        centre = to_vector(panel.get("center", (0, 0, 0)), f"{src}: panel.center", limit=MAX_COORD)
        radius = positive(panel.get("radius", 12), f"{src}: panel.radius")
        kwargs["panel"] = Panel(centre, radius)  # type: ignore[arg-type]
    if "start_point" in data:
        kwargs["start_point"] = to_vector(
            data["start_point"], f"{src}: start_point", limit=MAX_COORD
        )
    kwargs["obstacles"] = walls_mesh + parse_obstacles(data, lo, hi, src)
    if data.get("baffle") is not None:
        kwargs["baffle"], kwargs["hatch"] = parse_baffle(data, lo, hi, src)
    elif data.get("hatch") is not None:
        raise ConfigError(f"{src}: hatch: a hatch needs a baffle")
    kwargs["baffles"] = parse_baffles(data, lo, hi, src)
    kwargs["taper"] = parse_taper(data, lo, hi, src)
    if "arm" in data:
        kwargs["arm"] = _parse_arm(data, src)
    kwargs["targets"] = _parse_targets(data, src)
    tank = Tank(**kwargs)
    _check_points(tank, src)
    if walls_mesh:
        _check_panel_in_walls(tank, walls_mesh[0], src)
    return tank


def _parse_box(data: Mapping[str, Any], src: str) -> tuple[Vec3, Vec3]:
    """The box's corners ``(min, max)`` [cm], each larger on every axis for ``max``."""
    require(data, ["box"], src)
    box = section(data, "box", {"min", "max"}, src)
    require(box, ["min", "max"], f"{src}: box")
    lo, hi = (
        cast(Vec3, to_vector(box["min"], f"{src}: box.min", limit=MAX_COORD)),
        cast(Vec3, to_vector(box["max"], f"{src}: box.max", limit=MAX_COORD)),
    )
    if any(h <= lo_ for lo_, h in zip(lo, hi)):
        raise ConfigError(f"{src}: box: max must exceed min on every axis, got {lo} and {hi}")
    return lo, hi


def _parse_cell_size(value: Any, lo: Vec3, hi: Vec3, src: str) -> float:
    """The raster's cell size [cm]: it divides the box on every axis into few enough cells."""
    cell = positive(value, f"{src}: cell_size")
    for axis, (a, b) in enumerate(zip(lo, hi)):
        n = (b - a) / cell
        if abs(n - round(n)) > 1e-9:
            raise ConfigError(
                f"{src}: cell_size: {cell:g} does not divide the box extent {b - a:g} along "
                f"{'xyz'[axis]}"
            )
    cells = math.prod(round((b - a) / cell) for a, b in zip(lo, hi))
    if cells > MAX_CELLS:
        raise ConfigError(
            f"{src}: cell_size: {cell:g} cm splits the box into {cells:,} cells, more than the "
            f"{MAX_CELLS:,} allowed; use a larger cell_size"
        )
    return cell


def _parse_arm(data: Mapping[str, Any], src: str) -> ArmSpec:
    """The ``arm`` section (defaults for the keys it leaves out)."""
    keys = {"section_length", "max_sections", "radius", "theta_max", "limits", "camera", "rod"}
    arm = section(data, "arm", keys, src)
    try:
        return ArmSpec(
            section_length=to_float(
                arm.get("section_length", 50), f"{src}: arm.section_length", limit=MAX_COORD
            ),
            max_sections=to_int(
                arm.get("max_sections", 12), f"{src}: arm.max_sections", limit=MAX_SECTIONS
            ),
            radius=to_float(arm.get("radius", 2.5), f"{src}: arm.radius", limit=MAX_COORD),
            theta_max=to_float(arm.get("theta_max", math.pi / 2), f"{src}: arm.theta_max"),
            limits=ActuatorLimits.from_mapping(arm.get("limits"), f"{src}: arm.limits"),
            camera=Camera.from_mapping(arm.get("camera"), f"{src}: arm.camera"),
            rod=RodProperties.from_mapping(arm.get("rod"), f"{src}: arm.rod"),
        )
    except ValueError as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"{src}: arm: {exc}") from None


def _parse_targets(data: Mapping[str, Any], src: str) -> tuple[Vec3, ...]:
    """The reference targets (none when the key is missing or empty)."""
    targets = data.get("targets") or []
    if not isinstance(targets, list):
        raise ConfigError(f"{src}: targets: expected a list of [x, y, z], got {brief(targets)}")
    if len(targets) > MAX_TARGETS:
        raise ConfigError(f"{src}: targets: {len(targets)} targets, at most {MAX_TARGETS}")
    return tuple(
        cast(Vec3, to_vector(t, f"{src}: targets[{i}]", limit=MAX_COORD))
        for i, t in enumerate(targets)
    )


def _check_points(tank: Tank, src: str) -> None:
    if not tank.contains_point(tank.start_point):
        raise ConfigError(f"{src}: start_point: {tank.start_point} is outside the box")
    if tank.cell_size is not None and _start_cell_obstructed(tank):
        raise ConfigError(
            f"{src}: start_point: {tank.start_point} lies in obstructed cell "
            f"{list(tank.start_cell)}; the grid world must start in a free cell"
        )
    if abs(tank.panel.center[2] - tank.box_min[2]) > 1e-9:
        raise ConfigError(
            f"{src}: panel.center: the panel must lie in the floor z = {tank.box_min[2]:g}"
        )
    for i, target in enumerate(tank.targets):
        if not tank.contains_point(target):
            raise ConfigError(f"{src}: targets[{i}]: {target} is outside the box")
        hit = tank.solid_at(target)
        if hit is not None:
            raise ConfigError(f"{src}: targets[{i}]: {target} is inside {hit.name or 'a solid'}")


def _check_panel_in_walls(tank: Tank, walls: Solid, src: str) -> None:
    """The walls given as a mesh have the panel in their floor, with their inside above it."""
    c, r = np.array(tank.panel.center), tank.panel.radius
    ring = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    disc = c + np.c_[0.9 * r * np.cos(ring), 0.9 * r * np.sin(ring), np.zeros(16)]
    points = np.vstack([c, disc]) + [0.0, 0.0, 1.0]
    if np.any(walls.signed_distance(points) < 0.5):
        raise ConfigError(
            f"{src}: mesh: the walls do not hold the panel: the floor around "
            f"{format_point(c)} (radius {r:g} cm) must be the mesh's lowest plane, the tank's "
            "inside above it"
        )


def _start_cell_obstructed(tank: Tank) -> bool:
    """Whether a solid overlaps the start cell, without building the raster (O(solids))."""
    assert tank.cell_size is not None
    size = tank.cell_size
    lo, hi = np.array(tank.box_min), np.array(tank.box_max)
    upper = np.round((hi - lo) / size).astype(int)
    rel = (np.array(tank.start_point) - lo) / size
    cell = np.minimum(np.floor(rel).astype(int), upper - 1)
    c_lo = lo + cell * size
    return any(bool(s.overlaps(c_lo, c_lo + size)) for s in tank.solids)


def available_tanks() -> list[str]:
    """Names of the tanks shipped in ``configs/tanks``."""
    return sorted(p.stem for p in TANK_DIR.glob("*.yaml"))


#: Tanks loaded lately, by the SHA-256 of their file, newest last: the same tank read from many
#: places (every run directory's ``tank.yaml``) is one tank, with one raster; a few, so a
#: process that reads many different tanks keeps its memory bounded.
_CACHE: dict[str, Tank] = {}
_CACHE_SIZE = 4

#: The file a run directory keeps its tank in when it was trained in a tank that is not shipped.
RUN_TANK_FILE = "tank.yaml"
#: A generated tank by name: ``FAMILY:BAYS:SEED`` (:func:`generated_spec`).
_FAMILY = "(" + "|".join(FAMILIES) + ")"
_SPEC = re.compile(_FAMILY + r":([1-9][0-9]?):([0-9]{1,10})")
POOL_SPEC = re.compile(_FAMILY + r":([1-9][0-9]?):([0-9]{1,10})-([0-9]{1,10})")
#: A stream of generated wings ``FAMILY:BAYS:FIRST+``, or ``mix:FIRST+`` (families and bays
#: mixed: :func:`~aftir_rl.core.tank.generate.mixed_kind`); read by
#: :class:`~aftir_rl.envs.ftl.pool.TankStream`.
STREAM_SPEC = re.compile(r"(?:" + _FAMILY + r":([1-9][0-9]?)|mix):([0-9]{1,10})\+")


_Source = tuple[Path, bytes, dict[str, Any], list[tuple[dict[str, Any], str]]]


def _source_yaml(tank: str | Path) -> _Source | None:
    """The YAML a tank reads, its bytes, its mapping, ``(mapping, key)`` of its meshes.

    The meshes are its obstacles' and its walls'. None for a shipped name or a generator spec.
    """
    text, source = str(tank), Path(tank)
    if (text in available_tanks() or names_generated(text)) and not source.exists():
        return None
    if not (source.suffix in (".yaml", ".yml") or source.exists()):
        source = TANK_DIR / f"{text}.yaml"
    raw = read_limited(source, MAX_YAML_BYTES, ConfigError, "tank file", "tank")
    data = read_yaml(source, raw)
    meshes = [
        (o, "file")
        for o in data.get("obstacles") or []
        if isinstance(o, dict) and o.get("type") == "mesh"
    ] + ([(data, "mesh")] if data.get("mesh") is not None else [])
    return source, raw, data, meshes


def tank_files(tank: str | Path) -> list[Path]:
    """The files loading ``tank`` reads: its YAML and the meshes it names.

    None for a shipped name or a generator spec; a command refuses to write over them.
    """
    found = _source_yaml(tank)
    if found is None:
        return []
    source, _, _, meshes = found
    return [source] + [source.parent / str(item[key]) for item, key in meshes]


def keep_run_tank(tank: str | Path, run_dir: str | Path) -> str:
    """What a run directory records as its tank: a shipped name or a spec, else ``tank.yaml``.

    A tank given as a path is copied into the run directory (:data:`RUN_TANK_FILE`), with the
    mesh files it names beside it, so the run stays readable wherever it is moved and
    :func:`resolve_run_tank` never leaves it.
    """
    found = _source_yaml(tank)
    if found is None:
        return str(tank)
    source, raw, data, meshes = found
    if meshes:
        load_tank(source)  # every mesh checked before anything is copied
        for i, (item, key) in enumerate(meshes):
            name = f"tank_mesh_{i}{Path(str(item[key])).suffix.lower()}"
            shutil.copyfile(source.parent / str(item[key]), Path(run_dir) / name)
            item[key] = name
        raw = yaml.safe_dump(data, sort_keys=False).encode()
    with atomic_open(Path(run_dir) / RUN_TANK_FILE, "wb") as fh:
        fh.write(raw)
    return RUN_TANK_FILE


def resolve_run_tank(name: object, run_dir: str | Path) -> str:
    """The tank a run directory names, as :func:`load_tank` takes it, checked before any read.

    A run may name a shipped tank (``b737_center``), a generator spec (``wing:3:7``) or a YAML file
    inside its own directory (:data:`RUN_TANK_FILE`); an absolute path, ``..``, or a symlink that
    leads out of the directory is refused unread, so a run handed over by someone else opens no
    other file.

    Raises:
        ConfigError: anything else (the message names the field, never a file's content).

    """
    shipped = available_tanks()
    if isinstance(name, str) and (name in shipped or names_generated(name)):
        return name
    folder = Path(run_dir)
    try:
        if not isinstance(name, str) or not 0 < len(name) <= 255:
            raise ValueError
        path = (folder / name).resolve()
        inside = path.is_relative_to(folder.resolve()) and path.suffix in (".yaml", ".yml")
    except (ValueError, OSError, RuntimeError):  # a NUL byte, a symlink loop
        inside = False
    if not inside:
        raise ConfigError(
            f"{folder}: the run names the tank {brief(name)}, which is neither a shipped tank "
            f"({', '.join(shipped)}) nor a YAML file inside the run directory; pass --tank"
        )
    return str(path)


def generated_spec(text: str) -> tuple[int, int, str] | None:
    """``(bays, seed, family)`` of a generator spec ``FAMILY:BAYS:SEED``, or None otherwise."""
    match = _SPEC.fullmatch(text)
    return (int(match[2]), int(match[3]), match[1]) if match else None


def names_generated(text: str) -> bool:
    """Whether ``text`` names generated tanks: ``FAMILY:BAYS:SEED``, a pool or a stream.

    A pool is ``FAMILY:BAYS:A-B``, a stream ``FAMILY:BAYS:A+`` or ``mix:A+``.
    """
    return generated_spec(text) is not None or any(
        spec.fullmatch(text) is not None for spec in (POOL_SPEC, STREAM_SPEC)
    )


def load_tank(tank: str | Path | Tank = DEFAULT_TANK) -> Tank:
    """Load a tank by name (``configs/tanks/NAME.yaml``), path, or spec ``FAMILY:BAYS:SEED``.

    A spec is :func:`~aftir_rl.core.tank.generate.generated_tank`'s tank of that family
    (``wing``, ``round``), read no file. The last few
    tanks loaded are cached by their file's content, so envs share one raster.

    Raises:
        ConfigError: the tank does not exist or its file is malformed.

    """
    if isinstance(tank, Tank):
        return tank
    text = str(tank)
    if STREAM_SPEC.fullmatch(text):
        raise ConfigError(
            f"tank {text!r} is a stream of generated wings: the batched AFTIR-ArmFTL-v0 and "
            "AFTIR-ArmRoute-v1 move along it; everything else takes one tank, wing:BAYS:SEED"
        )
    if POOL_SPEC.fullmatch(text):
        raise ConfigError(
            f"tank {text!r} is a pool of generated tanks: AFTIR-ArmFTL-v0 draws one per episode "
            "(tank=...); everything else takes one tank, wing:BAYS:SEED"
        )
    spec = generated_spec(text)
    if spec is not None:
        return _cached(text, lambda: tank_from_mapping(generated_tank(spec[2], *spec[:2]), text))
    path = Path(text)
    if not (path.suffix in (".yaml", ".yml") or path.exists()):
        path = TANK_DIR / f"{text}.yaml"
        if not path.exists():
            raise ConfigError(
                f"unknown tank {text!r}: give a YAML path or one of {', '.join(available_tanks())}"
            )
    raw = read_limited(path, MAX_YAML_BYTES, ConfigError, "file", "tank or config")
    return _cached(
        hashlib.sha256(raw).hexdigest(), lambda: tank_from_mapping(read_yaml(path, raw), str(path))
    )


def _cached(key: str, build: Callable[[], Tank]) -> Tank:
    """The tank cached under ``key``, built and cached (the newest last) when missing."""
    tank = _CACHE.pop(key, None) or build()
    _CACHE[key] = tank
    while len(_CACHE) > _CACHE_SIZE:
        del _CACHE[next(iter(_CACHE))]
    return tank
