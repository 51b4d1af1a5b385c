"""The solids of a tank (boxes, axis-aligned cylinders, spheres) and what each one knows.

Every solid carries its own geometry, which the raster, the distance, the collision scene and the
pictures ask of every kind alike (the few places that switch on ``kind``: docs/design.md §3):

- bounds, overlap with cells and point containment (:meth:`~Box.aabb`, :meth:`~Box.overlaps`,
  :meth:`~Box.contains`), which build the raster;
- its exact signed distance to points [cm] (< 0 inside), vectorised (:meth:`~Box.signed_distance`,
  :meth:`~Box.signed_distance_xyz`), one :meth:`~Box.distance_field` per kind that
  :class:`~aftir_rl.core.tank.distance.SolidStack` also evaluates on many solids stacked;
- its python-fcl collision object (:meth:`~Box.fcl_object`: a solid primitive and its pose);
- a triangle :meth:`~Box.mesh` (plotly) and :meth:`~Box.wireframe` polylines (matplotlib).

Cylinders are axis-aligned (exact overlap tests; the papers' pipes run along an axis). More:
docs/design.md §3.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import fcl
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Vec3",
    "Shape",
    "Primitive",
    "Box",
    "Cylinder",
    "Sphere",
    "Solid",
    "Mesh",
    "rotation_z_to",
]

Vec3 = tuple[float, float, float]
#: A triangle mesh: vertices ``(V, 3)`` [cm] and faces ``(F, 3)`` (vertex indices).
Mesh = tuple[NDArray[np.float64], NDArray[np.int64]]
_Array = NDArray[np.float64]

#: The 12 edges of a box, as pairs of indices into :meth:`Box.corners`.
_BOX_EDGES = (
    (0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4), (0, 4), (1, 5), (2, 6), (3, 7),
)  # fmt: skip
#: The 12 triangles of a box's faces, indices into :meth:`Box.corners`.
_BOX_FACES = (
    (0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
    (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3),
)  # fmt: skip


def rotation_z_to(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrices taking +z to ``direction`` (shape ``(..., 3)``)."""
    d = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    helper = np.where(np.abs(d[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    x = helper - np.sum(helper * d, axis=-1, keepdims=True) * d
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(d, x)
    return np.stack([x, y, d], axis=-1)


class Shape(ABC):
    """What every kind of solid shares; each defines the geometry it is made of."""

    #: The kind, as in the tank files and the scene export.
    kind: ClassVar[str]
    name: str

    @property
    def stack_key(self) -> int:
        """Solids of one kind with equal keys share a :meth:`distance_field` (a cylinder's axis)."""
        return 0

    @property
    @abstractmethod
    def distance_params(self) -> tuple[float, ...]:
        """The numbers :meth:`distance_field` takes after the coordinates."""

    @abstractmethod
    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm] of points ``(x, y, z)`` to a solid of this kind with ``params``.

        ``params`` are :attr:`distance_params`: floats for this solid, or arrays ``(S,)`` for
        ``S`` solids of the same :attr:`stack_key` at once, broadcast against the coordinates.
        """

    def signed_distance_xyz(self, x: _Array, y: _Array, z: _Array) -> _Array:
        """Signed distance [cm] of points given as coordinate arrays (< 0 inside)."""
        return self.distance_field(x, y, z, *self.distance_params)

    def signed_distance(self, points: ArrayLike) -> _Array:
        """Signed distance [cm] of points ``(..., 3)`` (< 0 inside)."""
        p = np.asarray(points, dtype=np.float64)
        return self.signed_distance_xyz(p[..., 0], p[..., 1], p[..., 2])

    @abstractmethod
    def fcl_objects(self) -> list[Any]:
        """The python-fcl ``CollisionObject`` s that make up this solid."""

    @abstractmethod
    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""

    @abstractmethod
    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""

    @abstractmethod
    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""

    @abstractmethod
    def mesh(self) -> Mesh:
        """Vertices and triangles of the surface (pictures, mesh export)."""

    @abstractmethod
    def wireframe(self) -> list[_Array]:
        """Polylines ``(V, 3)`` that outline the solid (matplotlib)."""

    @abstractmethod
    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""


class Primitive(Shape):
    """A solid that python-fcl holds as one solid primitive and its pose."""

    @abstractmethod
    def fcl_geometry(self) -> tuple[Any, Any]:
        """The python-fcl solid primitive and its ``fcl.Transform``."""

    def fcl_object(self) -> Any:
        """A python-fcl ``CollisionObject`` of this solid (a solid primitive, not a mesh)."""
        return fcl.CollisionObject(*self.fcl_geometry())

    def fcl_objects(self) -> list[Any]:
        """The solid's one python-fcl object, in a list."""
        return [self.fcl_object()]


@dataclass(frozen=True)
class Box(Primitive):
    """Solid axis-aligned box between the corners ``min`` and ``max`` [cm].

    Every kind of solid has a ``name``: what messages and collision reports call it ("" for
    none).
    """

    min: Vec3
    max: Vec3
    name: str = ""
    kind: ClassVar[str] = "box"

    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""
        return np.array(self.min), np.array(self.max)

    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        a, b = self.aabb()
        return np.all((np.minimum(hi, b) - np.maximum(lo, a)) > 0, axis=-1)

    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        a, b = self.aabb()
        return np.all((points > a) & (points < b), axis=-1)

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "box", "min": list(self.min), "max": list(self.max)}

    @cached_property
    def distance_params(self) -> tuple[float, ...]:
        """Centre and half-size, ``(cx, cy, cz, hx, hy, hz)`` [cm]."""
        lo, hi = self.min, self.max
        return (*((lo[i] + hi[i]) / 2 for i in range(3)), *((hi[i] - lo[i]) / 2 for i in range(3)))

    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm] to boxes of centre ``(cx, cy, cz)``, half-sizes ``(hx, hy, hz)``."""
        cx, cy, cz, hx, hy, hz = params
        qx, qy, qz = np.abs(x - cx) - hx, np.abs(y - cy) - hy, np.abs(z - cz) - hz
        # hypot: no overflow (and no RuntimeWarning) for points far outside
        outside = np.hypot(np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)), np.maximum(qz, 0.0))
        return outside + np.minimum(np.maximum(np.maximum(qx, qy), qz), 0.0)

    def fcl_geometry(self) -> tuple[Any, Any]:
        """An ``fcl.Box`` of the box's size at its centre."""
        lo, hi = self.aabb()
        return fcl.Box(*(hi - lo)), fcl.Transform((lo + hi) / 2)

    def corners(self) -> _Array:
        """The 8 corners ``(8, 3)``, x slowest and z fastest."""
        lo, hi = self.min, self.max
        return np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )

    def mesh(self) -> Mesh:
        """Vertices and triangles of the box's faces."""
        return self.corners(), np.array(_BOX_FACES)

    def wireframe(self) -> list[_Array]:
        """The 12 edges, each a ``(2, 3)`` polyline."""
        c = self.corners()
        return [c[[i, j]] for i, j in _BOX_EDGES]


@dataclass(frozen=True)
class Cylinder(Primitive):
    """Solid cylinder between the centres of its end faces ``p0`` and ``p1`` [cm]."""

    p0: Vec3
    p1: Vec3
    radius: float
    name: str = ""
    kind: ClassVar[str] = "cylinder"

    @cached_property
    def axis(self) -> int:
        """Index of the coordinate axis the cylinder runs along."""
        return int(np.flatnonzero(np.array(self.p1) != np.array(self.p0))[0])

    @property
    def _across(self) -> list[int]:
        """The two coordinate axes across the cylinder."""
        return [i for i in range(3) if i != self.axis]

    @property
    def _span(self) -> tuple[float, float]:
        """The ends' coordinates along the axis, in increasing order."""
        a0, a1 = sorted((self.p0[self.axis], self.p1[self.axis]))
        return a0, a1

    @property
    def stack_key(self) -> int:
        """The axis: cylinders along one axis share a :meth:`distance_field`."""
        return self.axis

    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""
        p0, p1 = np.array(self.p0), np.array(self.p1)
        lo, hi = np.minimum(p0, p1) - self.radius, np.maximum(p0, p1) + self.radius
        lo[self.axis], hi[self.axis] = self._span
        return lo, hi

    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        k, others = self.axis, self._across
        a0, a1 = self._span
        along = (np.minimum(hi[..., k], a1) - np.maximum(lo[..., k], a0)) > 0
        centre = np.array(self.p0)[others]
        nearest = np.clip(centre, lo[..., others], hi[..., others])
        across = np.linalg.norm(nearest - centre, axis=-1) < self.radius
        return along & across

    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        k, others = self.axis, self._across
        a0, a1 = self._span
        radial = np.linalg.norm(points[..., others] - np.array(self.p0)[others], axis=-1)
        return (points[..., k] > a0) & (points[..., k] < a1) & (radial < self.radius)

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "cylinder", "p0": list(self.p0), "p1": list(self.p1), "radius": self.radius}

    @cached_property
    def distance_params(self) -> tuple[float, ...]:
        """Axis position across, radius, middle and half-length along: ``(u, v, r, mid, half)``."""
        u, v = (self.p0[i] for i in self._across)
        a0, a1 = self._span
        return u, v, self.radius, (a0 + a1) / 2, (a1 - a0) / 2

    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm] to cylinders along this one's axis with ``(u, v, r, mid, half)``."""
        u, v, r, mid, half = params
        coords = (x, y, z)
        i, j = self._across
        radial = np.hypot(coords[i] - u, coords[j] - v) - r
        axial = np.abs(coords[self.axis] - mid) - half
        outside = np.hypot(np.maximum(radial, 0.0), np.maximum(axial, 0.0))
        return outside + np.minimum(np.maximum(radial, axial), 0.0)

    def fcl_geometry(self) -> tuple[Any, Any]:
        """An ``fcl.Cylinder`` (along its local z) turned onto the axis, at the middle."""
        p0, p1 = np.array(self.p0, float), np.array(self.p1, float)
        return (
            fcl.Cylinder(self.radius, float(np.linalg.norm(p1 - p0))),
            fcl.Transform(rotation_z_to(p1 - p0), (p0 + p1) / 2),
        )

    def _ring(self, angles: _Array) -> _Array:
        """Offsets ``(len(angles), 3)`` from the axis to the surface at ``angles`` [rad]."""
        ring = np.zeros((len(angles), 3))
        i, j = self._across
        ring[:, i] = self.radius * np.cos(angles)
        ring[:, j] = self.radius * np.sin(angles)
        return ring

    def mesh(self, segments: int = 24) -> Mesh:
        """Vertices and triangles of the side and the end caps (``segments`` around)."""
        ring = self._ring(np.linspace(0, 2 * np.pi, segments, endpoint=False))
        p0, p1 = np.array(self.p0, float), np.array(self.p1, float)
        v = np.vstack([p0 + ring, p1 + ring, p0, p1])
        j = np.arange(segments)
        nxt = (j + 1) % segments
        side = np.vstack([np.c_[j, nxt, j + segments], np.c_[nxt, nxt + segments, j + segments]])
        caps = np.vstack(
            [
                np.c_[np.full(segments, 2 * segments), nxt, j],
                np.c_[np.full(segments, 2 * segments + 1), j + segments, nxt + segments],
            ]
        )
        return v, np.vstack([side, caps])

    def wireframe(self, lines: int = 6) -> list[_Array]:
        """``lines`` straight lines along the surface, each a ``(2, 3)`` polyline."""
        ring = self._ring(np.linspace(0, 2 * np.pi, lines, endpoint=False))
        p0, p1 = np.array(self.p0, float), np.array(self.p1, float)
        return [np.stack([p0 + off, p1 + off]) for off in ring]


@dataclass(frozen=True)
class Sphere(Primitive):
    """Solid sphere [cm]."""

    center: Vec3
    radius: float
    name: str = ""
    kind: ClassVar[str] = "sphere"

    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""
        c = np.array(self.center)
        return c - self.radius, c + self.radius

    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        c = np.array(self.center)
        return np.linalg.norm(np.clip(c, lo, hi) - c, axis=-1) < self.radius

    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        return np.linalg.norm(points - np.array(self.center), axis=-1) < self.radius

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        return {"type": "sphere", "center": list(self.center), "radius": self.radius}

    @cached_property
    def distance_params(self) -> tuple[float, ...]:
        """Centre and radius, ``(cx, cy, cz, r)`` [cm]."""
        return (*self.center, self.radius)

    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm] to spheres of centre ``(cx, cy, cz)`` and radius ``r``."""
        cx, cy, cz, r = params
        return np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) - r

    def fcl_geometry(self) -> tuple[Any, Any]:
        """An ``fcl.Sphere`` at the centre."""
        return fcl.Sphere(self.radius), fcl.Transform(np.array(self.center))

    def _grid(self, n_u: int, n_v: int, closed: bool) -> _Array:
        """Surface points ``(n_u, n_v, 3)`` by longitude (closed: 2π repeated) and colatitude."""
        u = np.linspace(0, 2 * np.pi, n_u, endpoint=closed)
        uu, vv = np.meshgrid(u, np.linspace(0, np.pi, n_v), indexing="ij")
        unit = np.stack([np.cos(uu) * np.sin(vv), np.sin(uu) * np.sin(vv), np.cos(vv)], axis=-1)
        return np.array(self.center) + self.radius * unit

    def mesh(self, n_u: int = 16, n_v: int = 9) -> Mesh:
        """Vertices and triangles of a UV sphere."""
        v = self._grid(n_u, n_v, closed=False).reshape(-1, 3)
        faces = []
        for i in range(n_u):
            for j in range(n_v - 1):
                a, b = i * n_v + j, ((i + 1) % n_u) * n_v + j
                faces += [[a, b, b + 1], [a, b + 1, a + 1]]
        return v, np.array(faces)

    def wireframe(self, n_u: int = 12, n_v: int = 7) -> list[_Array]:
        """Meridians (``n_v`` points each) and parallels (closed, ``n_u`` points each)."""
        grid = self._grid(n_u, n_v, closed=True)
        return [*grid, *grid.transpose(1, 0, 2)]


#: Any solid of a tank: a box, cylinder, sphere, or a plate with holes
#: (:class:`~aftir_rl.core.tank.plate.Plate`).
Solid = Shape
