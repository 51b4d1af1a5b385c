"""A tank: its interior box, access panel, baffle and hatch, solid obstacles, and the arm for it.

A tank is an axis-aligned interior box, an access panel in the floor ``z = 0``, an optional baffle
(a slab across one horizontal axis) with a rectangular hatch, and solid obstacles
(:mod:`aftir_rl.core.tank.solids`). Its walls are an :class:`Enclosure`: the box's faces, the floor
open at the panel and that opening continued below the floor as the guide of the linear module.
From these a :class:`Tank` derives its raster (:mod:`aftir_rl.core.tank.raster`), its signed
distance (:class:`~aftir_rl.core.tank.distance.TankDistance`) and its scene export
(docs/design.md §5).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.config import one_line
from aftir_rl.core.errors import ConfigError, TargetError
from aftir_rl.core.robot import ArmSpec
from aftir_rl.core.tank.distance import TankDistance
from aftir_rl.core.tank.plate import Plate
from aftir_rl.core.tank.raster import Raster, format_point
from aftir_rl.core.tank.solids import Box, Solid, Vec3

__all__ = ["Panel", "Baffle", "Hatch", "Enclosure", "Tank"]

#: Thickness of the wall slabs around the box in python-fcl [cm].
WALL_THICKNESS = 50.0


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
class Enclosure:
    """The box's faces as walls; the floor is open at the access panel.

    The opening is the panel's circle, continued below the floor as the guide tube of the linear
    module (a point below the floor farther from the panel's axis than its radius is inside the
    wall).
    """

    box_min: Vec3
    box_max: Vec3
    panel: Panel

    def floor_distance_xyz(
        self, x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Signed distance [cm] to the floor with its round opening and the guide tube below."""
        c, r = self.panel.center, self.panel.radius
        radial = np.hypot(x - c[0], y - c[1])
        height = z - self.box_min[2]
        rim = np.where(height >= 0, np.hypot(r - radial, height), r - radial)
        return np.where(radial > r, height, rim)

    def signed_distance_xyz(
        self, x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Signed distance [cm] to the nearest wall, the ceiling or the floor (< 0 outside)."""
        lo, hi = self.box_min, self.box_max
        side = np.minimum(np.minimum(x - lo[0], hi[0] - x), np.minimum(y - lo[1], hi[1] - y))
        return np.minimum(np.minimum(side, hi[2] - z), self.floor_distance_xyz(x, y, z))

    def slabs(self, thickness: float = WALL_THICKNESS) -> list[Box]:
        """The walls as solid slabs outside the box; the floor's opening is the panel's square."""
        lo, hi, t = np.array(self.box_min), np.array(self.box_max), thickness
        big_lo, big_hi = lo - t, hi + t
        slabs: list[tuple[Iterable[float], Iterable[float]]] = [
            (big_lo, [lo[0], big_hi[1], big_hi[2]]),
            ([hi[0], big_lo[1], big_lo[2]], big_hi),
            ([lo[0], big_lo[1], big_lo[2]], [hi[0], lo[1], big_hi[2]]),
            ([lo[0], hi[1], big_lo[2]], [hi[0], big_hi[1], big_hi[2]]),
            ([lo[0], lo[1], hi[2]], [hi[0], hi[1], big_hi[2]]),
        ]
        c, r = np.array(self.panel.center), self.panel.radius
        z0, z1 = lo[2] - t, lo[2]
        for xa, xb, ya, yb in (
            (lo[0], c[0] - r, lo[1], hi[1]),
            (c[0] + r, hi[0], lo[1], hi[1]),
            (c[0] - r, c[0] + r, lo[1], c[1] - r),
            (c[0] - r, c[0] + r, c[1] + r, hi[1]),
        ):
            if xb > xa and yb > ya:
                slabs.append(([xa, ya, z0], [xb, yb, z1]))
        return [Box(_vec3(a), _vec3(b), "wall") for a, b in slabs]


_T = TypeVar("_T")


def _vec3(values: Iterable[float]) -> Vec3:
    x, y, z = map(float, values)
    return (x, y, z)


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
        baffles: more baffles (ribs), each a plate with any holes.
        taper: wedges along the walls where the section shrinks along the box.
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
    baffles: tuple[Plate, ...] = ()
    taper: tuple[Solid, ...] = ()
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
            "box": [self.box_min, self.box_max],
            "cell_size": self.cell_size,
            "panel": [self.panel.center, self.panel.radius],
            "start": self.start_point,
            "solids": [s.to_json() for s in self.solids],
            "walls": self.walls,
        }
        text = json.dumps(geometry, sort_keys=True, default=float)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @property
    def solids(self) -> tuple[Solid, ...]:
        """Every solid inside the box: baffle pieces, baffles with holes, taper, obstacles."""
        return self.baffle_solids + self.baffles + self.taper + self.obstacles

    @cached_property
    def dividers(self) -> tuple[tuple[int, float, float], ...]:
        """Every baffle as ``(axis, position, thickness)``, sorted by axis and position."""
        out = [(p.axis, p.position, p.thickness) for p in self.baffles]
        if self.baffle is not None:
            out.append((self.baffle.index, self.baffle.position, self.baffle.thickness))
        return tuple(sorted(out))

    def memo(self, key: str, build: Callable[[], _T]) -> _T:
        """``build()``, once per tank, kept with the tank and let go with it.

        For the caches of other layers whose values refer back to the tank (a guide, a
        clearance grid): in a weak-key dictionary such a value would keep its key, and so
        every tank a process ever met, alive.
        """
        store: dict[str, Any] = self.__dict__.setdefault("_memo", {})
        if key not in store:
            store[key] = build()
        return store[key]

    def bay(self, number: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Corners [cm] of bay ``number`` (1 nearest the low end), between consecutive baffles.

        Raises:
            ConfigError: the tank has no baffle, baffles across more than one axis, or no such
                bay.

        """
        walls = [d for d in self.dividers if d[0] != 2]
        axes = {d[0] for d in walls}
        if len(axes) != 1 or not 1 <= number <= len(walls) + 1:
            raise ConfigError(
                f"{self.source or self.name}: bay {number!r}: bays need baffles across one "
                f"horizontal axis; this tank has {len(walls) + 1 if len(axes) == 1 else 'no'} bays"
            )
        lo, hi = np.array(self.box_min, float), np.array(self.box_max, float)
        (k,) = axes
        if number > 1:
            lo[k] = walls[number - 2][1] + walls[number - 2][2] / 2
        if number <= len(walls):
            hi[k] = walls[number - 1][1] - walls[number - 1][2] / 2
        return lo, hi

    @cached_property
    def enclosure(self) -> Enclosure:
        """The box's walls, the floor open at the panel (whether they count: :attr:`walls`)."""
        return Enclosure(self.box_min, self.box_max, self.panel)

    @cached_property
    def distance(self) -> TankDistance:
        """Signed distance [cm] of points ``(..., 3)`` to the nearest solid or wall (< 0 inside).

        Built once per tank; see :class:`~aftir_rl.core.tank.distance.TankDistance`.
        """
        return TankDistance(self)

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
        self.check_target_cell(cell, what=f"target {format_point(np.asarray(point, float))} cm")
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

    def ascii(self) -> str:
        """A header and the raster's z-slices with the start, hatch and reference targets marked.

        What ``python -m aftir_rl.tank`` prints.
        """
        raster = self.raster
        marks = {c: "H" for c in map(tuple, np.argwhere(~raster.obstructed)) if self._in_hatch(c)}
        for i, t in enumerate(self.targets):
            marks[raster.point_to_cell(t)] = str(i + 1)
        marks[self.start_cell] = "S"
        head = [
            # the name and description come from a file: no control character reaches a terminal
            one_line(f"tank {self.name}: {self.description}".rstrip(": ")),
            f"box {format_point(self.box_min)}..{format_point(self.box_max)} cm, "
            f"raster {' x '.join(map(str, raster.shape))} cells of {raster.cell_size:g} cm, "
            f"{int(raster.obstructed.sum())} obstructed",
            "legend: # obstructed  . free  S start  H hole in a baffle  1-9 reference targets",
            "",
        ]
        return "\n".join(head) + raster.ascii(marks)

    def _in_hatch(self, cell: Sequence[int]) -> bool:
        """Whether a baffle's plane runs through ``cell`` (a free one there is a hole in it)."""
        lo = np.array(self.raster.origin) + np.asarray(cell) * self.raster.cell_size
        size = self.raster.cell_size
        return any(lo[k] < position < lo[k] + size for k, position, _ in self.dividers)

    def scene_dict(self) -> dict[str, Any]:
        """The scene export of docs/design.md §5 (units cm)."""
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


def _overlaps_cell(solid: Solid, raster: Raster, cell: Sequence[int]) -> bool:
    lo = np.array(raster.origin) + np.asarray(cell) * raster.cell_size
    return bool(solid.overlaps(lo, lo + raster.cell_size))
