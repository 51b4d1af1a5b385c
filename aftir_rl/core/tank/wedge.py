"""A wedge: a triangular prism, what a tapered tank's shrinking section is made of.

A :class:`Wedge` is a triangle in the plane across ``axis``
(:func:`~aftir_rl.core.tank.plate.plane_axes`) extruded along ``axis`` between ``lo`` and
``hi``. Its signed distance is exact (the 2D distance to a triangle, extruded); python-fcl sees a
convex prism; a raster cell is obstructed when its rectangle and the triangle overlap with
positive area (separating axes) over a positive span along ``axis``. :func:`taper_wedges` turns
a tank file's ``taper`` into wedges along the box's walls. More: docs/tanks.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import fcl
import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.tank.plate import (
    extrude,
    extruded_distance,
    lift,
    plane_axes,
    plane_coordinates,
)
from aftir_rl.core.tank.solids import Mesh, Primitive

__all__ = ["Wedge", "triangle_distance_2d", "taper_wedges", "taper_side"]

_Array = NDArray[np.float64]


def triangle_distance_2d(a: _Array, b: _Array, tri: tuple[Any, ...]) -> _Array:
    """Exact 2D signed distance of points ``(a, b)`` to triangles ``(a0, b0, a1, b1, a2, b2)``."""
    corners = [(tri[0], tri[1]), (tri[2], tri[3]), (tri[4], tri[5])]
    best = np.full(np.broadcast(a, b, *tri).shape, np.inf)
    orient = (tri[2] - tri[0]) * (tri[5] - tri[1]) - (tri[4] - tri[0]) * (tri[3] - tri[1])
    inside = np.ones(best.shape, dtype=bool)
    for i in range(3):
        (pa, pb), (qa, qb) = corners[i], corners[(i + 1) % 3]
        ea, eb = qa - pa, qb - pb
        wa, wb = a - pa, b - pb
        t = np.clip((wa * ea + wb * eb) / np.maximum(ea * ea + eb * eb, 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.hypot(wa - t * ea, wb - t * eb))
        inside &= (ea * wb - eb * wa) * orient >= 0
    return np.where(inside, -best, best)


@dataclass(frozen=True)
class Wedge(Primitive):
    """A triangle ``(a0, b0, a1, b1, a2, b2)`` across ``axis``, extruded from ``lo`` to ``hi``."""

    axis: int
    lo: float
    hi: float
    triangle: tuple[float, float, float, float, float, float]
    name: str = ""
    kind: ClassVar[str] = "wedge"

    @cached_property
    def corners(self) -> _Array:
        """The triangle's corners ``(3, 2)``."""
        return np.array(self.triangle, dtype=np.float64).reshape(3, 2)

    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""
        lo, hi = np.zeros(3), np.zeros(3)
        a, b = plane_axes(self.axis)
        lo[[a, b]], hi[[a, b]] = self.corners.min(axis=0), self.corners.max(axis=0)
        lo[self.axis], hi[self.axis] = self.lo, self.hi
        return lo, hi

    @property
    def distance_params(self) -> tuple[float, ...]:
        """``(axis, middle, half length, a0, b0, a1, b1, a2, b2)``."""
        return (float(self.axis), (self.lo + self.hi) / 2, (self.hi - self.lo) / 2, *self.triangle)

    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm] to wedges with ``params`` (:attr:`distance_params`)."""
        k, mid, half = params[:3]
        n, a, b = plane_coordinates(k, x, y, z)
        return extruded_distance(triangle_distance_2d(a, b, params[3:]), np.abs(n - mid) - half)

    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        k, (a, b) = self.axis, plane_axes(self.axis)
        along = (np.minimum(hi[..., k], self.hi) - np.maximum(lo[..., k], self.lo)) > 0
        tri = self.corners
        apart = np.zeros(along.shape, dtype=bool)
        for d, axis_lo, axis_hi in ((0, lo[..., a], hi[..., a]), (1, lo[..., b], hi[..., b])):
            apart |= (tri[:, d].max() <= axis_lo) | (tri[:, d].min() >= axis_hi)
        for i in range(3):  # the triangle's edge normals
            e = tri[(i + 1) % 3] - tri[i]
            normal = np.array([-e[1], e[0]])
            proj = tri @ normal
            box = [c0 * normal[0] + c1 * normal[1] for c0 in (lo[..., a], hi[..., a])
                   for c1 in (lo[..., b], hi[..., b])]  # fmt: skip
            box_lo, box_hi = np.minimum.reduce(box), np.maximum.reduce(box)
            apart |= (proj.max() <= box_lo) | (proj.min() >= box_hi)
        return along & ~apart

    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        return self.signed_distance(points) < 0

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "wedge", "axis": "xyz"[self.axis], "lo": self.lo, "hi": self.hi,
                "triangle": [list(c) for c in self.corners]}  # fmt: skip

    def fcl_geometry(self) -> tuple[Any, Any]:
        """An ``fcl.Convex`` prism."""
        verts, faces = self.mesh()
        flat = np.hstack([np.full((len(faces), 1), 3), faces]).ravel()
        return fcl.Convex(verts, len(faces), flat), fcl.Transform()

    def mesh(self) -> Mesh:
        """Vertices and triangles of the prism."""
        return extrude(self.corners, self.axis, self.lo, self.hi)

    def wireframe(self) -> list[_Array]:
        """The triangle at both ends, and its corners' edges along the axis."""
        ends = [lift(self.corners[[0, 1, 2, 0]], self.axis, n) for n in (self.lo, self.hi)]
        return ends + [np.stack([ends[0][i], ends[1][i]]) for i in range(3)]


def taper_wedges(lo: _Array, hi: _Array, along: int, end_lo: _Array, end_hi: _Array) -> list[Wedge]:
    """Wedges along the box's walls so its section shrinks linearly to ``end_lo..end_hi``.

    The section across ``along`` is the box's at ``lo[along]`` and ``end_lo..end_hi`` (in the
    other two coordinates, increasing order) at ``hi[along]``; each side that moves inward is
    one wedge, extruded across the whole box.
    """
    out = []
    x0, x1 = lo[along], hi[along]
    others = [i for i in range(3) if i != along]
    for j, c in enumerate(others):
        extrude_axis = others[1 - j]
        for side, wall, end in (("min", lo[c], end_lo[j]), ("max", hi[c], end_hi[j])):
            if abs(end - wall) < 1e-9:
                continue
            # the triangle in the plane of (along, c), in plane_axes order of the extrusion axis
            pts = {(x0, wall), (x1, wall), (x1, end)}
            flat = []
            for p_along, p_c in sorted(pts):
                point = {along: p_along, c: p_c}
                a, b = plane_axes(extrude_axis)
                flat += [point[a], point[b]]
            out.append(Wedge(extrude_axis, float(lo[extrude_axis]), float(hi[extrude_axis]),
                             tuple(map(float, flat)), f"taper_{'xyz'[c]}_{side}"))  # type: ignore[arg-type]  # fmt: skip
    return out


def taper_side(wedge: Wedge) -> tuple[int, int, str, float]:
    """What :func:`taper_wedges` made ``wedge`` of: ``(along, c, side, end)``.

    The box's ``side`` (``"min"`` or ``"max"``) wall across axis ``c`` reaches ``end`` at the far
    end along ``along``.
    """
    c, side = "xyz".index(wedge.name[6]), wedge.name[8:]  # its name: taper_<c>_<side>
    ends = wedge.corners[:, plane_axes(wedge.axis).index(c)]
    return 3 - c - wedge.axis, c, side, float(ends.max() if side == "min" else ends.min())
