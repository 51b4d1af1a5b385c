"""Tank geometry from YAML, its raster of cubic cells, and the scene export.

A tank is an axis-aligned interior box, an access panel in the floor ``z = 0``, an optional baffle
(a slab across one horizontal axis) with a rectangular hatch, and solid obstacles (boxes, cylinders,
spheres). Files live in ``configs/tanks/NAME.yaml`` and load into frozen dataclasses; an unknown
key, a negative size, a hatch outside its baffle or an obstacle outside the box is a
:class:`~aftir_rl.errors.ConfigError` naming the file and the key (design.md §2).

The raster splits the box into cubes of ``cell_size``; a cell is *obstructed* when a solid overlaps
its cube with positive volume (a solid that only touches a face does not obstruct it). Cylinders
must be axis-aligned, which is what makes that overlap test exact; the tanks of the papers only
have pipes along an axis.

Command line::

    python -m aftir_rl.tank [--tank NAME|PATH] [--json]

prints a z-slice view of the raster, or with ``--json`` the scene export of design.md §2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.config import CONFIG_DIR, brief, read_yaml, to_float, to_int, to_vector
from aftir_rl.errors import AftirError, ConfigError, TargetError
from aftir_rl.robot import ArmSpec
from aftir_rl.safety import cli

__all__ = [
    "Box",
    "Cylinder",
    "Sphere",
    "Solid",
    "Panel",
    "Baffle",
    "Hatch",
    "Raster",
    "Tank",
    "load_tank",
    "available_tanks",
]

Vec3 = tuple[float, float, float]
TANK_DIR = CONFIG_DIR / "tanks"

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


@dataclass(frozen=True)
class Box:
    """Solid axis-aligned box [cm]."""

    min: Vec3
    max: Vec3
    name: str = ""

    def aabb(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned bounds ``(lo, hi)``."""
        return np.array(self.min), np.array(self.max)

    def overlaps(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        a, b = self.aabb()
        return np.all((np.minimum(hi, b) - np.maximum(lo, a)) > 0, axis=-1)

    def contains(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        a, b = self.aabb()
        return np.all((points > a) & (points < b), axis=-1)

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "box", "min": list(self.min), "max": list(self.max)}


@dataclass(frozen=True)
class Cylinder:
    """Solid cylinder between the centres of its end faces ``p0`` and ``p1`` [cm]."""

    p0: Vec3
    p1: Vec3
    radius: float
    name: str = ""

    @cached_property
    def axis(self) -> int:
        """Index of the coordinate axis the cylinder runs along."""
        return int(np.flatnonzero(np.array(self.p1) != np.array(self.p0))[0])

    def aabb(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned bounds ``(lo, hi)``."""
        p0, p1 = np.array(self.p0), np.array(self.p1)
        lo, hi = np.minimum(p0, p1) - self.radius, np.maximum(p0, p1) + self.radius
        lo[self.axis], hi[self.axis] = (
            min(p0[self.axis], p1[self.axis]),
            max(p0[self.axis], p1[self.axis]),
        )
        return lo, hi

    def overlaps(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        k = self.axis
        others = [i for i in range(3) if i != k]
        a0, a1 = sorted((self.p0[k], self.p1[k]))
        along = (np.minimum(hi[..., k], a1) - np.maximum(lo[..., k], a0)) > 0
        centre = np.array(self.p0)[others]
        nearest = np.clip(centre, lo[..., others], hi[..., others])
        across = np.linalg.norm(nearest - centre, axis=-1) < self.radius
        return along & across

    def contains(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        k = self.axis
        others = [i for i in range(3) if i != k]
        a0, a1 = sorted((self.p0[k], self.p1[k]))
        radial = np.linalg.norm(points[..., others] - np.array(self.p0)[others], axis=-1)
        return (points[..., k] > a0) & (points[..., k] < a1) & (radial < self.radius)

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "cylinder", "p0": list(self.p0), "p1": list(self.p1), "radius": self.radius}


@dataclass(frozen=True)
class Sphere:
    """Solid sphere [cm]."""

    center: Vec3
    radius: float
    name: str = ""

    def aabb(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned bounds ``(lo, hi)``."""
        c = np.array(self.center)
        return c - self.radius, c + self.radius

    def overlaps(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        c = np.array(self.center)
        return np.linalg.norm(np.clip(c, lo, hi) - c, axis=-1) < self.radius

    def contains(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        return np.linalg.norm(points - np.array(self.center), axis=-1) < self.radius

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "sphere", "center": list(self.center), "radius": self.radius}


Solid = Box | Cylinder | Sphere


@dataclass(frozen=True)
class Panel:
    """Circular access panel in the floor, the arm entering along +z [cm]."""

    center: Vec3 = (0.0, 0.0, 0.0)
    radius: float = 12.0


@dataclass(frozen=True)
class Baffle:
    """A wall across the tank: the slab ``position ± thickness/2`` along ``axis`` ("x" or "y")."""

    axis: str
    position: float
    thickness: float

    @property
    def index(self) -> int:
        """Coordinate index of the baffle normal."""
        return {"x": 0, "y": 1}[self.axis]


@dataclass(frozen=True)
class Hatch:
    """Rectangular opening in the baffle, ``width`` along the baffle and ``height`` in z [cm]."""

    center: Vec3
    width: float
    height: float


@dataclass(frozen=True)
class Raster:
    """The box split into cubic cells; cell ``(a, b, c)`` counts from the box minimum, 0-based.

    Attributes:
        origin: the box minimum [cm].
        cell_size: edge of a cell [cm].
        obstructed: boolean array of shape ``shape``; True where a solid overlaps the cell.

    """

    origin: Vec3
    cell_size: float
    obstructed: NDArray[np.bool_] = field(repr=False)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Number of cells along x, y, z."""
        return tuple(int(n) for n in self.obstructed.shape)  # type: ignore[return-value]

    @property
    def n_cells(self) -> int:
        """Total number of cells."""
        return int(self.obstructed.size)

    def in_bounds(self, cell: Sequence[int]) -> bool:
        """Whether ``cell`` is inside the raster."""
        return all(0 <= int(c) < n for c, n in zip(cell, self.shape))

    def point_to_cell(self, point: ArrayLike) -> tuple[int, int, int]:
        """The cell holding ``point`` [cm]; points on the box's upper faces belong to the last cell.

        Raises:
            TargetError: the point is outside the box.

        """
        p = np.asarray(point, dtype=np.float64)
        rel = (p - np.array(self.origin)) / self.cell_size
        upper = np.array(self.shape)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or np.any(rel < 0) or np.any(rel > upper):
            lo = np.array(self.origin)
            hi = lo + upper * self.cell_size
            raise TargetError(
                f"point {_fmt(p)} cm is outside the tank box {_fmt(lo)}..{_fmt(hi)} cm; "
                "give a point inside it"
            )
        cell = np.minimum(np.floor(rel).astype(int), upper - 1)
        return (int(cell[0]), int(cell[1]), int(cell[2]))

    def cell_center(self, cell: Sequence[int]) -> NDArray[np.float64]:
        """Centre of ``cell`` [cm]."""
        return np.array(self.origin) + (np.asarray(cell, dtype=np.float64) + 0.5) * self.cell_size

    def cell_bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lower and upper corners of every cell, each of shape ``shape + (3,)``."""
        idx = np.stack(np.meshgrid(*[np.arange(n) for n in self.shape], indexing="ij"), axis=-1)
        lo = np.array(self.origin) + idx * self.cell_size
        return lo, lo + self.cell_size

    def index(self, cell: Iterable[int]) -> int:
        """Flat state index ``ravel_multi_index(cell, shape)``."""
        return int(np.ravel_multi_index(tuple(int(c) for c in cell), self.shape))

    def cell(self, index: int) -> tuple[int, int, int]:
        """Cell of a flat state index."""
        a, b, c = np.unravel_index(int(index), self.shape)
        return (int(a), int(b), int(c))

    def bfs_distances(self, start: Sequence[int]) -> NDArray[np.int64]:
        """BFS steps from ``start`` through free cells (6-neighbourhood); -1 where unreachable."""
        dist = np.full(self.shape, -1, dtype=np.int64)
        start = tuple(int(c) for c in start)
        if self.obstructed[start]:
            return dist
        dist[start] = 0
        queue = deque([start])
        while queue:
            cur = queue.popleft()
            for axis in range(3):
                for step in (-1, 1):
                    nxt = list(cur)
                    nxt[axis] += step
                    t = tuple(nxt)
                    if self.in_bounds(t) and not self.obstructed[t] and dist[t] < 0:
                        dist[t] = dist[cur] + 1
                        queue.append(t)
        return dist

    def ascii(self, marks: Mapping[tuple[int, int, int], str] | None = None) -> str:
        """Z-slices of the raster, top slice first, y growing upwards in each slice.

        ``#`` is an obstructed cell, ``.`` a free one; ``marks`` puts a character on given cells.
        """
        marks = dict(marks or {})
        nx, ny, nz = self.shape
        lines = []
        for c in reversed(range(nz)):
            z0 = self.origin[2] + c * self.cell_size
            lines.append(f"z in [{z0:g}, {z0 + self.cell_size:g}) cm  (c = {c})")
            for b in reversed(range(ny)):
                row = "".join(
                    marks.get((a, b, c), "#" if self.obstructed[a, b, c] else ".")
                    for a in range(nx)
                )
                lines.append(f"  b={b:<2d} {row}")
            lines.append("       " + "".join(str(a % 10) for a in range(nx)) + "  (a)")
        return "\n".join(lines)


@dataclass(frozen=True)
class Tank:
    """A fuel tank: interior box, access panel, baffle and hatch, obstacles, and the arm for it.

    Attributes:
        name: short name (the YAML file stem).
        box_min: interior box minimum [cm].
        box_max: interior box maximum [cm].
        panel: the access panel.
        cell_size: raster cell edge [cm], or None for a tank without a raster.
        start_point: a point just inside the panel; its cell is the grid world's start [cm].
        baffle: the wall between two bays, if any.
        hatch: the opening in the baffle, if any.
        obstacles: solid obstacles (not the baffle).
        arm: the arm used in this tank.
        targets: reference targets [cm].
        walls: whether the box's faces are walls (False: open space, the box only bounds targets).
        description: one line for people.
        source: the file the tank was read from.

    """

    name: str
    box_min: Vec3
    box_max: Vec3
    panel: Panel = Panel()
    cell_size: float | None = None
    start_point: Vec3 = (0.0, 0.0, 10.0)
    baffle: Baffle | None = None
    hatch: Hatch | None = None
    obstacles: tuple[Solid, ...] = ()
    arm: ArmSpec = ArmSpec()
    targets: tuple[Vec3, ...] = ()
    walls: bool = True
    description: str = ""
    source: str = ""

    @cached_property
    def baffle_solids(self) -> tuple[Box, ...]:
        """The baffle as solid boxes around the hatch opening (empty without a baffle)."""
        if self.baffle is None:
            return ()
        k = self.baffle.index
        u = 1 - k  # the horizontal axis along the baffle
        lo, hi = list(self.box_min), list(self.box_max)
        lo[k] = self.baffle.position - self.baffle.thickness / 2
        hi[k] = self.baffle.position + self.baffle.thickness / 2
        if self.hatch is None:
            return (Box(tuple(lo), tuple(hi), "baffle"),)  # type: ignore[arg-type]
        h = self.hatch
        u0, u1 = h.center[u] - h.width / 2, h.center[u] + h.width / 2
        z0, z1 = h.center[2] - h.height / 2, h.center[2] + h.height / 2
        pieces = []
        for name, a_lo, a_hi, b_lo, b_hi in (
            ("baffle_below_hatch", lo[u], hi[u], lo[2], z0),
            ("baffle_above_hatch", lo[u], hi[u], z1, hi[2]),
            ("baffle_left_of_hatch", lo[u], u0, z0, z1),
            ("baffle_right_of_hatch", u1, hi[u], z0, z1),
        ):
            if a_hi - a_lo <= 0 or b_hi - b_lo <= 0:
                continue
            p_lo, p_hi = list(lo), list(hi)
            p_lo[u], p_hi[u], p_lo[2], p_hi[2] = a_lo, a_hi, b_lo, b_hi
            pieces.append(Box(tuple(p_lo), tuple(p_hi), name))  # type: ignore[arg-type]
        return tuple(pieces)

    @cached_property
    def fingerprint(self) -> str:
        """A digest of the geometry (box, raster, panel, start, solids): equal tanks, equal text.

        Q-table checkpoints carry it, so a table is never resumed in another tank whose raster
        has the same shape.
        """
        import hashlib

        geometry = {
            "box": [self.box_min, self.box_max], "cell_size": self.cell_size,
            "panel": [self.panel.center, self.panel.radius], "start": self.start_point,
            "solids": [s.to_json() for s in self.solids], "walls": self.walls,
        }  # fmt: skip
        text = json.dumps(geometry, sort_keys=True, default=float)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @property
    def solids(self) -> tuple[Solid, ...]:
        """Every solid inside the box: baffle pieces, then obstacles."""
        return self.baffle_solids + self.obstacles

    @cached_property
    def raster(self) -> Raster:
        """The raster of this tank.

        Raises:
            ConfigError: the tank has no ``cell_size``.

        """
        if self.cell_size is None:
            raise ConfigError(
                f"{self.source or self.name}: this tank has no cell_size, so no raster"
            )
        size = np.array(self.box_max) - np.array(self.box_min)
        shape = tuple(int(round(s / self.cell_size)) for s in size)
        empty = np.zeros(shape, dtype=bool)
        raster = Raster(self.box_min, float(self.cell_size), empty)
        lo, hi = raster.cell_bounds()
        obstructed = np.zeros(shape, dtype=bool)
        for solid in self.solids:
            obstructed |= solid.overlaps(lo, hi)
        obstructed.setflags(write=False)
        return Raster(self.box_min, float(self.cell_size), obstructed)

    @property
    def start_cell(self) -> tuple[int, int, int]:
        """The cell holding ``start_point``: where the grid world starts."""
        return self.raster.point_to_cell(self.start_point)

    @cached_property
    def reachable(self) -> NDArray[np.int64]:
        """BFS steps from the start cell to every cell, -1 where unreachable."""
        return self.raster.bfs_distances(self.start_cell)

    def contains_point(self, point: ArrayLike) -> bool:
        """Whether ``point`` [cm] lies inside the box (faces included)."""
        p = np.asarray(point, dtype=np.float64)
        return bool(np.all(p >= self.box_min) and np.all(p <= self.box_max))

    def solid_at(self, point: ArrayLike) -> Solid | None:
        """The first solid strictly containing ``point``, if any."""
        p = np.asarray(point, dtype=np.float64)
        for solid in self.solids:
            if solid.contains(p):
                return solid
        return None

    def target_cell(self, point: ArrayLike) -> tuple[int, int, int]:
        """The cell of a target point, checked to be a free cell reachable from the start.

        Raises:
            TargetError: outside the box, in an obstructed cell, or unreachable.

        """
        cell = self.raster.point_to_cell(point)
        self.check_target_cell(cell, what=f"target {_fmt(np.asarray(point, float))} cm")
        return cell

    def check_target_cell(self, cell: Sequence[int], what: str | None = None) -> None:
        """Raise :class:`TargetError` unless ``cell`` is a free cell reachable from the start."""
        cell = tuple(int(c) for c in cell)
        what = what or f"target cell {list(cell)}"
        raster = self.raster
        if len(cell) != 3 or not raster.in_bounds(cell):
            raise TargetError(
                f"{what} is outside the raster of shape {list(raster.shape)}; "
                "give a cell with 0 <= index < shape"
            )
        if raster.obstructed[cell]:
            hit = [
                s.name or type(s).__name__ for s in self.solids if _overlaps_cell(s, raster, cell)
            ]
            raise TargetError(
                f"{what} lies in obstructed cell {list(cell)} (overlapped by {', '.join(hit)}); "
                "choose a free cell (python -m aftir_rl.tank shows them as '.')"
            )
        if self.reachable[cell] < 0:
            raise TargetError(
                f"{what} lies in cell {list(cell)}, which cannot be reached from the start cell "
                f"{list(self.start_cell)} through free cells; choose a reachable cell"
            )

    def scene_dict(self) -> dict[str, Any]:
        """The scene export of design.md §2 (units cm)."""
        out: dict[str, Any] = {
            "units": "cm",
            "box": {"min": list(self.box_min), "max": list(self.box_max)},
            "panel": {"center": list(self.panel.center), "radius": self.panel.radius},
            "solids": [s.to_json() for s in self.solids],
        }
        if self.cell_size is not None:
            r = self.raster
            out["raster"] = {
                "shape": list(r.shape),
                "cell_size": r.cell_size,
                "origin": list(r.origin),
                "obstructed": [list(map(int, c)) for c in np.argwhere(r.obstructed)],
            }
        out["arm"] = {
            "section_length": self.arm.section_length,
            "max_sections": self.arm.max_sections,
            "radius": self.arm.radius,
            "theta_max": self.arm.theta_max,
        }
        return out


def _fmt(v: NDArray[np.float64]) -> str:
    return "(" + ", ".join(f"{x:g}" for x in np.atleast_1d(v)) + ")"


def _overlaps_cell(solid: Solid, raster: Raster, cell: Sequence[int]) -> bool:
    lo = np.array(raster.origin) + np.asarray(cell) * raster.cell_size
    return bool(solid.overlaps(lo, lo + raster.cell_size))


# --------------------------------------------------------------------------------------------
# Loading


def _section(data: Mapping[str, Any], key: str, allowed: Iterable[str], src: str) -> dict[str, Any]:
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


def _require(data: Mapping[str, Any], keys: Iterable[str], where: str) -> None:
    for key in keys:
        if key not in data:
            raise ConfigError(f"{where}: missing key {key!r}")


def _positive(value: Any, where: str, allow_zero: bool = False) -> float:
    x = to_float(value, where, limit=MAX_COORD)
    if x < 0 or (x == 0 and not allow_zero):
        raise ConfigError(
            f"{where}: must be {'non-negative' if allow_zero else 'positive'}, got {x:g}"
        )
    return x


def _parse_solid(item: Any, where: str) -> Solid:
    if not isinstance(item, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {brief(item)}")
    kind = item.get("type")
    kind = kind if isinstance(kind, str) else repr(type(kind))
    allowed = {
        "box": {"type", "name", "min", "max"},
        "cylinder": {"type", "name", "p0", "p1", "radius"},
        "sphere": {"type", "name", "center", "radius"},
    }
    if kind not in allowed:
        raise ConfigError(
            f"{where}: type: expected one of box, cylinder, sphere, got {brief(kind)}"
        )
    unknown = sorted(set(item) - allowed[kind], key=str)
    if unknown:
        raise ConfigError(
            f"{where}: unknown key {brief(unknown[0])} for a {kind}; allowed keys are "
            f"{', '.join(sorted(allowed[kind]))}"
        )
    _require(item, allowed[kind] - {"name"}, where)
    name = str(item.get("name", ""))
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
        return Cylinder(p0, p1, _positive(item["radius"], f"{where}: radius"), name)  # type: ignore[arg-type]
    centre = to_vector(item["center"], f"{where}: center", limit=MAX_COORD)
    return Sphere(centre, _positive(item["radius"], f"{where}: radius"), name)  # type: ignore[arg-type]


_TOP_KEYS = {
    "name", "description", "box", "cell_size", "panel", "start_point", "baffle", "hatch",
    "obstacles", "arm", "targets", "walls",
}  # fmt: skip


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
    _require(data, ["box"], src)
    box = _section(data, "box", {"min", "max"}, src)
    _require(box, ["min", "max"], f"{src}: box")
    lo, hi = (
        cast(Vec3, to_vector(box["min"], f"{src}: box.min", limit=MAX_COORD)),
        cast(Vec3, to_vector(box["max"], f"{src}: box.max", limit=MAX_COORD)),
    )
    if any(h <= lo_ for lo_, h in zip(lo, hi)):
        raise ConfigError(f"{src}: box: max must exceed min on every axis, got {lo} and {hi}")
    kwargs: dict[str, Any] = {"box_min": lo, "box_max": hi, "source": src}
    kwargs["name"] = str(data.get("name", Path(src).stem))
    kwargs["description"] = str(data.get("description", ""))
    walls = data.get("walls", True)
    if not isinstance(walls, bool):
        raise ConfigError(f"{src}: walls: expected true or false, got {brief(walls)}")
    kwargs["walls"] = walls
    if data.get("cell_size") is not None:
        cell = _positive(data["cell_size"], f"{src}: cell_size")
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
        kwargs["cell_size"] = cell
    if "panel" in data:
        panel = _section(data, "panel", {"center", "radius"}, src)
        centre = to_vector(panel.get("center", (0, 0, 0)), f"{src}: panel.center", limit=MAX_COORD)
        radius = _positive(panel.get("radius", 12), f"{src}: panel.radius")
        kwargs["panel"] = Panel(centre, radius)  # type: ignore[arg-type]
    if "start_point" in data:
        kwargs["start_point"] = to_vector(
            data["start_point"], f"{src}: start_point", limit=MAX_COORD
        )
    kwargs["obstacles"] = _parse_obstacles(data, lo, hi, src)
    if data.get("baffle") is not None:
        kwargs["baffle"], kwargs["hatch"] = _parse_baffle(data, lo, hi, src)
    elif data.get("hatch") is not None:
        raise ConfigError(f"{src}: hatch: a hatch needs a baffle")
    if "arm" in data:
        arm = _section(data, "arm", {"section_length", "max_sections", "radius", "theta_max"}, src)
        try:
            kwargs["arm"] = ArmSpec(
                section_length=to_float(
                    arm.get("section_length", 50), f"{src}: arm.section_length", limit=MAX_COORD
                ),
                max_sections=to_int(
                    arm.get("max_sections", 12), f"{src}: arm.max_sections", limit=MAX_SECTIONS
                ),
                radius=to_float(arm.get("radius", 2.5), f"{src}: arm.radius", limit=MAX_COORD),
                theta_max=to_float(arm.get("theta_max", math.pi / 2), f"{src}: arm.theta_max"),
            )
        except ValueError as exc:
            if isinstance(exc, ConfigError):
                raise
            raise ConfigError(f"{src}: arm: {exc}") from None
    targets = data.get("targets") or []
    if not isinstance(targets, list):
        raise ConfigError(f"{src}: targets: expected a list of [x, y, z], got {brief(targets)}")
    if len(targets) > MAX_TARGETS:
        raise ConfigError(f"{src}: targets: {len(targets)} targets, at most {MAX_TARGETS}")
    kwargs["targets"] = tuple(
        to_vector(t, f"{src}: targets[{i}]", limit=MAX_COORD) for i, t in enumerate(targets)
    )
    tank = Tank(**kwargs)
    _check_points(tank, src)
    return tank


def _parse_obstacles(data: Mapping[str, Any], lo: Vec3, hi: Vec3, src: str) -> tuple[Solid, ...]:
    items = data.get("obstacles") or []
    if not isinstance(items, list):
        raise ConfigError(f"{src}: obstacles: expected a list, got {brief(items)}")
    if len(items) > MAX_OBSTACLES:
        raise ConfigError(f"{src}: obstacles: {len(items)} obstacles, at most {MAX_OBSTACLES}")
    out = []
    for i, item in enumerate(items):
        solid = _parse_solid(item, f"{src}: obstacles[{i}]")
        s_lo, s_hi = solid.aabb()
        if np.any(s_lo < np.array(lo) - 1e-9) or np.any(s_hi > np.array(hi) + 1e-9):
            raise ConfigError(
                f"{src}: obstacles[{i}] ({solid.name or type(solid).__name__}) reaches outside the "
                f"box {lo}..{hi}: its bounds are {_fmt(s_lo)}..{_fmt(s_hi)}"
            )
        out.append(solid)
    return tuple(out)


def _parse_baffle(
    data: Mapping[str, Any], lo: Vec3, hi: Vec3, src: str
) -> tuple[Baffle, Hatch | None]:
    raw = _section(data, "baffle", {"axis", "position", "thickness"}, src)
    _require(raw, ["axis", "position", "thickness"], f"{src}: baffle")
    if raw["axis"] not in ("x", "y"):
        raise ConfigError(f"{src}: baffle.axis: expected 'x' or 'y', got {brief(raw['axis'])}")
    baffle = Baffle(
        raw["axis"],
        to_float(raw["position"], f"{src}: baffle.position", limit=MAX_COORD),
        _positive(raw["thickness"], f"{src}: baffle.thickness"),
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
    raw_h = _section(data, "hatch", {"center", "width", "height"}, src)
    _require(raw_h, ["center", "width", "height"], f"{src}: hatch")
    hatch = Hatch(
        to_vector(raw_h["center"], f"{src}: hatch.center", limit=MAX_COORD),  # type: ignore[arg-type]
        _positive(raw_h["width"], f"{src}: hatch.width"),
        _positive(raw_h["height"], f"{src}: hatch.height"),
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


_CACHE: dict[str, Tank] = {}


def load_tank(tank: str | Path | Tank = "b737_center") -> Tank:
    """Load a tank by name (``configs/tanks/NAME.yaml``) or by path to a YAML file.

    Loaded tanks are cached by resolved path, so envs share one raster.

    Raises:
        ConfigError: the tank does not exist or its file is malformed.

    """
    if isinstance(tank, Tank):
        return tank
    text = str(tank)
    path = Path(text)
    if not (path.suffix in (".yaml", ".yml") or path.exists()):
        path = TANK_DIR / f"{text}.yaml"
        if not path.exists():
            raise ConfigError(
                f"unknown tank {text!r}: give a YAML path or one of {', '.join(available_tanks())}"
            )
    key = str(path.resolve())
    if key not in _CACHE:
        _CACHE[key] = tank_from_mapping(read_yaml(path), str(path))
    return _CACHE[key]


# --------------------------------------------------------------------------------------------
# Command line


def _view(tank: Tank) -> str:
    raster = tank.raster
    marks = {c: "H" for c in map(tuple, np.argwhere(~raster.obstructed)) if _in_hatch(tank, c)}
    for i, t in enumerate(tank.targets):
        marks[raster.point_to_cell(t)] = str(i + 1)
    marks[tank.start_cell] = "S"
    head = [
        f"tank {tank.name}: {tank.description}".rstrip(": "),
        f"box {_fmt(np.array(tank.box_min))}..{_fmt(np.array(tank.box_max))} cm, "
        f"raster {' x '.join(map(str, raster.shape))} cells of {raster.cell_size:g} cm, "
        f"{int(raster.obstructed.sum())} obstructed",
        "legend: # obstructed  . free  S start  H hatch  1-9 reference targets",
        "",
    ]
    return "\n".join(head) + raster.ascii(marks)


def _in_hatch(tank: Tank, cell: Sequence[int]) -> bool:
    if tank.baffle is None or tank.hatch is None:
        return False
    lo = np.array(tank.raster.origin) + np.asarray(cell) * tank.raster.cell_size
    k = tank.baffle.index
    return bool(lo[k] < tank.baffle.position < lo[k] + tank.raster.cell_size)


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.tank``."""
    parser = argparse.ArgumentParser(
        prog="python -m aftir_rl.tank",
        description="Show a tank's raster as z-slices, or export its scene as JSON (units cm).",
    )
    parser.add_argument(
        "--tank", default="b737_center", help="tank name in configs/tanks or a YAML path"
    )
    parser.add_argument("--json", action="store_true", help="print the scene export as JSON")
    args = parser.parse_args(argv)
    try:
        tank = load_tank(args.tank)
        print(json.dumps(tank.scene_dict()) if args.json else _view(tank))
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
