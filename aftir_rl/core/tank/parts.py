"""Parts of a tank file: the checks every key goes through, solids, and baffles with holes.

Each parser takes the mapping read from YAML and the file's name, and returns frozen geometry
(:mod:`~aftir_rl.core.tank.solids`, :mod:`~aftir_rl.core.tank.plate`) or raises a
:class:`~aftir_rl.core.errors.ConfigError` naming the file and the key. The tank YAML:
docs/tanks.md.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, cast

import numpy as np

from aftir_rl.core.config import brief, to_float, to_vector
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank.geometry import Baffle, Hatch
from aftir_rl.core.tank.plate import HOLE_SHAPES, Hole, Plate, plane_axes
from aftir_rl.core.tank.raster import format_point
from aftir_rl.core.tank.solids import Box, Cylinder, Solid, Sphere, Vec3

__all__ = [
    "parse_walls_mesh",
    "MAX_COORD",
    "MAX_CELLS",
    "MAX_OBSTACLES",
    "MAX_TARGETS",
    "MAX_SECTIONS",
    "MAX_BAFFLES",
    "MAX_HOLES",
    "section",
    "require",
    "positive",
    "parse_solid",
    "parse_obstacles",
    "parse_baffle",
    "parse_baffles",
    "parse_taper",
]

#: Largest magnitude of any coordinate or size in a tank file [cm] (100 m): beyond, python-fcl
#: loses the precision of the arm (and crashes near 1e200).
MAX_COORD = 1e4
#: Most cells a raster may have (the reference tank has 750); 48 bytes of work memory each.
MAX_CELLS = 1_000_000
#: Most obstacles and reference targets in one tank file.
MAX_OBSTACLES = 256
MAX_TARGETS = 1000
#: Most sections of an arm (the papers use at most 12).
MAX_SECTIONS = 64
#: Most baffles (ribs) in one tank file, and holes in one baffle.
MAX_BAFFLES = 32
MAX_HOLES = 32


def section(data: Mapping[str, Any], key: str, allowed: Iterable[str], src: str) -> dict[str, Any]:
    """``data[key]`` as a dict, checked to be a mapping with only ``allowed`` keys."""
    value = data[key]
    if not isinstance(value, Mapping):
        raise ConfigError(f"{src}: {key}: expected a mapping, got {brief(value)}")
    unknown = sorted(set(value) - set(allowed), key=str)
    if unknown:
        raise ConfigError(
            f"{src}: {key}: unknown key {brief(unknown[0])}; allowed keys are "
            f"{', '.join(sorted(allowed))}"
        )
    return dict(value)


def require(data: Mapping[str, Any], keys: Iterable[str], where: str) -> None:
    """Raise :class:`ConfigError` unless ``data`` has every key."""
    for key in keys:
        if key not in data:
            raise ConfigError(f"{where}: missing key {key!r}")


def positive(value: Any, where: str, allow_zero: bool = False) -> float:
    """A finite number at most :data:`MAX_COORD`, positive (or non-negative)."""
    x = to_float(value, where, limit=MAX_COORD)
    if x < 0 or (x == 0 and not allow_zero):
        raise ConfigError(
            f"{where}: must be {'non-negative' if allow_zero else 'positive'}, got {x:g}"
        )
    return x


def parse_solid(
    item: Any, where: str, base: Path | None = None, extent: tuple[Vec3, Vec3] | None = None
) -> Solid:
    """One obstacle: a box, cylinder, sphere, or a mesh file (relative to ``base``).

    A mesh's distance grid covers ``extent`` (the tank's box) too.
    """
    if not isinstance(item, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {brief(item)}")
    kind = item.get("type")
    kind = kind if isinstance(kind, str) else repr(type(kind))
    allowed = {
        "box": {"type", "name", "min", "max"},
        "cylinder": {"type", "name", "p0", "p1", "radius"},
        "sphere": {"type", "name", "center", "radius"},
        "mesh": {"type", "name", "file"},
    }
    if kind not in allowed:
        raise ConfigError(
            f"{where}: type: expected one of box, cylinder, sphere, mesh, got {brief(kind)}"
        )
    unknown = sorted(set(item) - allowed[kind], key=str)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key {brief(unknown[0])} for a {kind}; allowed keys are "
            f"{', '.join(sorted(allowed[kind]))}"
        )
    require(item, allowed[kind] - {"name"}, where)
    name = str(item.get("name", ""))
    if kind == "mesh":
        return _parse_mesh(item["file"], name, where, base, extent)
    if kind == "box":
        lo, hi = (
            to_vector(item["min"], f"{where}: min", limit=MAX_COORD),
            to_vector(item["max"], f"{where}: max", limit=MAX_COORD),
        )
        if any(h <= lo_ for lo_, h in zip(lo, hi)):
            raise ConfigError(f"{where}: max must exceed min on every axis, got {lo} and {hi}")
        return Box(lo, hi, name)  # type: ignore[arg-type]
    if kind == "cylinder":
        p0, p1 = (
            to_vector(item["p0"], f"{where}: p0", limit=MAX_COORD),
            to_vector(item["p1"], f"{where}: p1", limit=MAX_COORD),
        )
        if sum(a != b for a, b in zip(p0, p1)) != 1:
            raise ConfigError(
                f"{where}: p0 and p1 must differ along exactly one axis (cylinders are "
                f"axis-aligned), got {p0} and {p1}"
            )
        return Cylinder(p0, p1, positive(item["radius"], f"{where}: radius"), name)  # type: ignore[arg-type]
    centre = to_vector(item["center"], f"{where}: center", limit=MAX_COORD)
    return Sphere(centre, positive(item["radius"], f"{where}: radius"), name)  # type: ignore[arg-type]


def parse_obstacles(data: Mapping[str, Any], lo: Vec3, hi: Vec3, src: str) -> tuple[Solid, ...]:
    """The ``obstacles`` list, each inside the box."""
    items = data.get("obstacles") or []
    if not isinstance(items, list):
        raise ConfigError(f"{src}: obstacles: expected a list, got {brief(items)}")
    if len(items) > MAX_OBSTACLES:
        raise ConfigError(f"{src}: obstacles: {len(items)} obstacles, at most {MAX_OBSTACLES}")
    out = []
    for i, item in enumerate(items):
        solid = parse_solid(item, f"{src}: obstacles[{i}]", Path(src).parent, (lo, hi))
        s_lo, s_hi = solid.aabb()
        if np.any(s_lo < np.array(lo) - 1e-9) or np.any(s_hi > np.array(hi) + 1e-9):
            raise ConfigError(
                f"{src}: obstacles[{i}] ({solid.name or type(solid).__name__}) reaches outside the "
                f"box {lo}..{hi}: its bounds are {format_point(s_lo)}..{format_point(s_hi)}"
            )
        out.append(solid)
    return tuple(out)


def parse_baffle(
    data: Mapping[str, Any], lo: Vec3, hi: Vec3, src: str
) -> tuple[Baffle, Hatch | None]:
    """The single ``baffle`` and its rectangular ``hatch``."""
    raw = section(data, "baffle", {"axis", "position", "thickness"}, src)
    require(raw, ["axis", "position", "thickness"], f"{src}: baffle")
    if raw["axis"] not in ("x", "y"):
        raise ConfigError(f"{src}: baffle.axis: expected 'x' or 'y', got {brief(raw['axis'])}")
    baffle = Baffle(
        raw["axis"],
        to_float(raw["position"], f"{src}: baffle.position", limit=MAX_COORD),
        positive(raw["thickness"], f"{src}: baffle.thickness"),
    )
    k = baffle.index
    if (
        not lo[k]
        < baffle.position - baffle.thickness / 2
        < baffle.position + baffle.thickness / 2
        < hi[k]
    ):
        raise ConfigError(f"{src}: baffle.position: the baffle slab must lie inside the box")
    if data.get("hatch") is None:
        return baffle, None
    raw_h = section(data, "hatch", {"center", "width", "height"}, src)
    require(raw_h, ["center", "width", "height"], f"{src}: hatch")
    hatch = Hatch(
        to_vector(raw_h["center"], f"{src}: hatch.center", limit=MAX_COORD),  # type: ignore[arg-type]
        positive(raw_h["width"], f"{src}: hatch.width"),
        positive(raw_h["height"], f"{src}: hatch.height"),
    )
    u = 1 - k
    if abs(hatch.center[k] - baffle.position) > 1e-9:
        raise ConfigError(
            f"{src}: hatch.center: the hatch is not in its baffle ({'xy'[k]} = "
            f"{hatch.center[k]:g}, the baffle is at {baffle.position:g})"
        )
    if not (
        lo[u] <= hatch.center[u] - hatch.width / 2
        and hatch.center[u] + hatch.width / 2 <= hi[u]
        and lo[2] <= hatch.center[2] - hatch.height / 2
        and hatch.center[2] + hatch.height / 2 <= hi[2]
    ):
        raise ConfigError(f"{src}: hatch: the opening reaches outside the baffle")
    return baffle, hatch


def parse_baffles(data: Mapping[str, Any], lo: Vec3, hi: Vec3, src: str) -> tuple[Plate, ...]:
    """The ``baffles`` list: plates across the box, each with its holes."""
    items = data.get("baffles") or []
    if not isinstance(items, list):
        raise ConfigError(f"{src}: baffles: expected a list, got {brief(items)}")
    if len(items) > MAX_BAFFLES:
        raise ConfigError(f"{src}: baffles: {len(items)} baffles, at most {MAX_BAFFLES}")
    return tuple(_parse_plate(item, lo, hi, f"{src}: baffles[{i}]") for i, item in enumerate(items))


def _parse_plate(item: Any, lo: Vec3, hi: Vec3, where: str) -> Plate:
    """One baffle of the ``baffles`` list."""
    raw = section({"baffle": item}, "baffle", {"name", "axis", "position", "thickness", "holes"},
                  where).copy()  # fmt: skip
    require(raw, ["axis", "position", "thickness"], where)
    if raw["axis"] not in ("x", "y", "z"):
        raise ConfigError(f"{where}: axis: expected 'x', 'y' or 'z', got {brief(raw['axis'])}")
    k = "xyz".index(raw["axis"])
    position = to_float(raw["position"], f"{where}: position", limit=MAX_COORD)
    thickness = positive(raw["thickness"], f"{where}: thickness")
    if not lo[k] < position - thickness / 2 < position + thickness / 2 < hi[k]:
        raise ConfigError(f"{where}: position: the baffle's slab must lie inside the box")
    a, b = plane_axes(k)
    plate = Plate(
        k, position, thickness, (lo[a], lo[b]), (hi[a], hi[b]), name=str(raw.get("name", ""))
    )
    holes = raw.get("holes") or []
    if not isinstance(holes, list):
        raise ConfigError(f"{where}: holes: expected a list, got {brief(holes)}")
    if len(holes) > MAX_HOLES:
        raise ConfigError(f"{where}: holes: {len(holes)} holes, at most {MAX_HOLES}")
    parsed = tuple(_parse_hole(h, plate, f"{where}: holes[{j}]") for j, h in enumerate(holes))
    for j, hole in enumerate(parsed):
        h_lo, h_hi = hole.bounds()
        for i, other in enumerate(parsed[:j]):
            o_lo, o_hi = other.bounds()
            if np.all(np.minimum(h_hi, o_hi) - np.maximum(h_lo, o_lo) > 0):
                raise ConfigError(
                    f"{where}: holes[{j}] overlaps holes[{i}] (their bounding rectangles "
                    "overlap); holes must lie apart"
                )
    return Plate(k, position, thickness, plate.lo, plate.hi, parsed, plate.name)


def _parse_hole(item: Any, plate: Plate, where: str) -> Hole:
    """One hole: its shape, its centre in the baffle, its size, inside the baffle."""
    shape = item.get("shape") if isinstance(item, Mapping) else None
    if shape not in HOLE_SHAPES:
        raise ConfigError(
            f"{where}: shape: expected one of {', '.join(HOLE_SHAPES)}, got {brief(shape)}"
        )
    size_keys = {"diameter"} if shape == "circle" else {"width", "height"}
    raw = section({"hole": item}, "hole", {"shape", "center", *size_keys}, where)
    require(raw, ["center", *size_keys], where)
    centre = to_vector(raw["center"], f"{where}: center", limit=MAX_COORD)
    k, (a, b) = plate.axis, plane_axes(plate.axis)
    if abs(centre[k] - plate.position) > 1e-9:
        raise ConfigError(
            f"{where}: center: the hole is not in its baffle ({'xyz'[k]} = {centre[k]:g}, the "
            f"baffle is at {plate.position:g})"
        )
    if shape == "circle":
        width = height = positive(raw["diameter"], f"{where}: diameter")
    else:
        width, height = (
            positive(raw["width"], f"{where}: width"),
            positive(raw["height"], f"{where}: height"),
        )
    hole = Hole(str(shape), (centre[a], centre[b]), width, height)
    h_lo, h_hi = hole.bounds()
    if np.any(h_lo < np.array(plate.lo) - 1e-9) or np.any(h_hi > np.array(plate.hi) + 1e-9):
        raise ConfigError(
            f"{where}: the hole reaches outside its baffle ({format_point(h_lo)}.."
            f"{format_point(h_hi)} in {'xyz'[a]}{'xyz'[b]}, the baffle spans "
            f"{format_point(plate.lo)}..{format_point(plate.hi)})"
        )
    return hole


def parse_walls_mesh(data: Mapping[str, Any], src: str) -> tuple[Vec3, Vec3, Solid]:
    """The walls given as a mesh (``mesh: FILE``): the box around it, and its solid.

    The mesh bounds the tank's inside; its lowest plane is the floor. The box is its bounds,
    grown to whole cells of ``cell_size`` (the floor kept), so nothing else gives one.
    """
    from aftir_rl.core.tank.meshes import MeshSolid

    for key in ("box", "taper"):
        if data.get(key) is not None:
            raise ConfigError(
                f"{src}: {key}: a tank whose walls are a mesh takes its shape from the mesh; "
                f"give mesh or {key}, not both"
            )
    if data.get("walls", True) is not True:
        raise ConfigError(f"{src}: walls: a tank whose walls are a mesh has walls")
    solid = _parse_mesh(data["mesh"], "walls", f"{src}: mesh", Path(src).parent, None)
    lo, hi = solid.aabb()
    cell = data.get("cell_size")
    if isinstance(cell, int | float) and not isinstance(cell, bool) and 0 < cell < math.inf:
        hi = lo + np.ceil((hi - lo) / cell - 1e-9) * cell
    box = (cast(Vec3, tuple(map(float, lo))), cast(Vec3, tuple(map(float, hi))))
    assert isinstance(solid, MeshSolid)
    return (*box, dataclasses.replace(solid, extent=box, walls=True))


def _parse_mesh(
    file: Any, name: str, where: str, base: Path | None, extent: tuple[Vec3, Vec3] | None
) -> Solid:
    """A mesh obstacle: the file relative to the tank file's folder, read and checked."""
    from aftir_rl.core.tank.meshes import MeshSolid, read_mesh

    if not isinstance(file, str) or not 0 < len(file) <= 255 or "\0" in file:
        raise ConfigError(f"{where}: file: expected a mesh file name, got {brief(file)}")
    folder = (base or Path(".")).resolve()
    path = folder / file
    try:
        inside = path.resolve().is_relative_to(folder)
    except (OSError, RuntimeError):  # a symlink loop
        inside = False
    if not inside:
        raise ConfigError(
            f"{where}: file: {brief(file)} leads out of the tank file's folder; keep meshes beside "
            "it or below"
        )
    verts, faces = read_mesh(path, f"{where}: file")
    return MeshSolid(verts, faces, name, file, extent)


def parse_taper(data: Mapping[str, Any], lo: Vec3, hi: Vec3, src: str) -> tuple[Solid, ...]:
    """The ``taper``: the section at the box's far end along ``along``, as wedges."""
    from aftir_rl.core.tank.wedge import taper_wedges

    if data.get("taper") is None:
        return ()
    raw = section(data, "taper", {"along", "end"}, src)
    require(raw, ["along", "end"], f"{src}: taper")
    if raw["along"] not in ("x", "y"):
        raise ConfigError(f"{src}: taper.along: expected 'x' or 'y', got {brief(raw['along'])}")
    k = "xy".index(raw["along"])
    end = section(raw, "end", {"min", "max"}, f"{src}: taper")
    require(end, ["min", "max"], f"{src}: taper.end")
    others = [i for i in range(3) if i != k]
    e_lo, e_hi = (
        np.array(to_vector(end[key], f"{src}: taper.end.{key}", size=2, limit=MAX_COORD))
        for key in ("min", "max")
    )
    box_lo, box_hi = np.array(lo)[others], np.array(hi)[others]
    if np.any(e_lo < box_lo - 1e-9) or np.any(e_hi > box_hi + 1e-9) or np.any(e_hi <= e_lo):
        raise ConfigError(
            f"{src}: taper.end: the far end's section {format_point(e_lo)}..{format_point(e_hi)} "
            f"must be non-empty and inside the box's {format_point(box_lo)}..{format_point(box_hi)}"
        )
    return tuple(taper_wedges(np.array(lo), np.array(hi), k, e_lo, e_hi))
