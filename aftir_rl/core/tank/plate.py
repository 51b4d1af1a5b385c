"""A baffle (rib) with holes: a plate across the tank with rectangular, round and oval openings.

A :class:`Plate` is the slab ``position ± thickness/2`` along one axis, spanning the rectangle
``lo..hi`` in the other two (the tank's cross-section), minus :class:`Hole` prisms through it.
Its signed distance is exact inside the material and in the holes (holes lie apart, inside the
rectangle), and never larger than the true distance elsewhere; python-fcl sees it as convex
prisms (boxes around the holes, fans of triangles between each hole and its bounding box) whose
round edges are polygons inscribed in the true ones, so it sees at most the true opening.
More: docs/tanks.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import fcl
import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.tank.solids import Mesh, Shape

__all__ = [
    "Hole",
    "Plate",
    "HOLE_SHAPES",
    "plane_axes",
    "plane_coordinates",
    "hole_distance_2d",
    "extruded_distance",
    "lift",
    "extrude",
]

_Array = NDArray[np.float64]
#: The hole shapes, by their code in :attr:`Plate.distance_params` and the compiled kernels.
HOLE_SHAPES = ("rect", "circle", "oval")
#: Vertices of a round hole's inscribed polygon (python-fcl, pictures); a multiple of 4.
ROUND_VERTICES = 48


def plane_axes(axis: int) -> tuple[int, int]:
    """The two coordinate axes in a plate across ``axis``: ``(a, b)``, in increasing order."""
    a, b = (i for i in range(3) if i != axis)
    return a, b


def hole_distance_2d(shape: Any, da: _Array, db: _Array, ha: Any, hb: Any) -> _Array:
    """Exact 2D signed distance of offsets ``(da, db)`` from holes' centres, codes ``shape``.

    ``ha, hb`` are the half-sizes; a circle has ``ha = hb`` (its radius); an oval is a stadium
    (a rectangle with half-circle ends across its shorter side). Arguments broadcast.
    """
    qa, qb = np.abs(da) - ha, np.abs(db) - hb
    rect = np.hypot(np.maximum(qa, 0.0), np.maximum(qb, 0.0)) + np.minimum(np.maximum(qa, qb), 0.0)
    circle = np.hypot(da, db) - ha
    r = np.minimum(ha, hb)
    along_a = np.hypot(np.maximum(np.abs(da) - (ha - r), 0.0), db)
    along_b = np.hypot(da, np.maximum(np.abs(db) - (hb - r), 0.0))
    oval = np.where(ha >= hb, along_a, along_b) - r
    return np.where(shape == 0, rect, np.where(shape == 1, circle, oval))


def plane_coordinates(k: Any, x: _Array, y: _Array, z: _Array) -> tuple[_Array, _Array, _Array]:
    """``(n, a, b)``: the coordinate along axis ``k`` and the two across it (:func:`plane_axes`).

    ``k`` may be an array (one axis per solid, broadcast against the coordinates).
    """
    n = np.where(k == 0, x, np.where(k == 1, y, z))
    return n, np.where(k == 0, y, x), np.where(k == 2, y, z)


def extruded_distance(flat: _Array, w: _Array) -> _Array:
    """Signed distance to a 2D region extruded: ``flat`` in its plane, ``w`` along its axis.

    ``w`` is the distance past the slab's faces (``abs(n - middle) - half``); exact when
    ``flat`` is the region's exact 2D signed distance.
    """
    outside = np.hypot(np.maximum(flat, 0.0), np.maximum(w, 0.0))
    return outside + np.minimum(np.maximum(flat, w), 0.0)


def lift(flat: _Array, axis: int, n: float) -> _Array:
    """Plane points ``(V, 2)`` (:func:`plane_axes`) at ``n`` along ``axis``, as ``(V, 3)``."""
    out = np.empty((len(flat), 3))
    a, b = plane_axes(axis)
    out[:, a], out[:, b], out[:, axis] = flat[:, 0], flat[:, 1], n
    return out


def extrude(flat: _Array, axis: int, n0: float, n1: float) -> tuple[_Array, NDArray[np.int64]]:
    """The prism over a convex polygon ``(V, 2)`` from ``n0`` to ``n1`` along ``axis``.

    Its vertices and triangles, closed (orientation as the polygon's; :func:`tank_bodies
    <aftir_rl.core.tank.meshes.tank_bodies>` turns bodies outward).
    """
    v = len(flat)
    verts = np.vstack([lift(flat, axis, n0), lift(flat, axis, n1)])
    faces = [[0, i + 1, i] for i in range(1, v - 1)]
    faces += [[v, v + i, v + i + 1] for i in range(1, v - 1)]
    for i in range(v):
        j = (i + 1) % v
        faces += [[i, j, v + j], [i, v + j, v + i]]
    return verts, np.array(faces, dtype=np.int64)


@dataclass(frozen=True)
class Hole:
    """An opening through a plate: ``shape`` rect, circle or oval, centred at ``(a, b)`` [cm].

    ``width`` runs along the plate's first in-plane axis ``a`` and ``height`` along ``b``
    (:func:`plane_axes`: y and z across x, x and z across y, x and y across z); a circle's
    width and height are its diameter.
    """

    shape: str
    center: tuple[float, float]
    width: float
    height: float

    @property
    def code(self) -> int:
        """The shape's index in :data:`HOLE_SHAPES`."""
        return HOLE_SHAPES.index(self.shape)

    def bounds(self) -> tuple[_Array, _Array]:
        """The hole's bounding rectangle ``(lo, hi)`` in plane coordinates."""
        c, h = np.array(self.center), np.array([self.width, self.height]) / 2
        return c - h, c + h

    def polygon(self) -> _Array:
        """Its outline ``(N, 2)``, counter-clockwise, inscribed in the true one."""
        ha, hb = self.width / 2, self.height / 2
        if self.shape == "rect":
            unit = np.array([[1, 0], [1, 1], [-1, 1], [-1, -1], [1, -1], [1, 0]], float)
            return np.array(self.center) + unit[1:5] * [ha, hb]
        t = np.linspace(0, 2 * np.pi, ROUND_VERTICES, endpoint=False)
        if self.shape == "circle":
            return np.array(self.center) + ha * np.c_[np.cos(t), np.sin(t)]
        # two half-circle caps, each with both its ends (where the straight sides start)
        r, m = min(ha, hb), ROUND_VERTICES // 2
        caps = []
        for side in (1.0, -1.0):
            if ha >= hb:
                u = np.linspace(-np.pi / 2, np.pi / 2, m + 1) + (side < 0) * np.pi
                centre = [side * (ha - r), 0.0]
            else:
                u = np.linspace(0.0, np.pi, m + 1) + (side < 0) * np.pi
                centre = [0.0, side * (hb - r)]
            caps.append(np.array(centre) + r * np.c_[np.cos(u), np.sin(u)])
        return np.array(self.center) + np.vstack(caps)

    def corner_fans(self) -> list[_Array]:
        """Triangles ``(T, 3, 2)`` between the outline and its bounding rectangle, by corner."""
        outline, (lo, hi) = self.polygon(), self.bounds()
        rel = outline - np.array(self.center)
        tri = []
        for sa in (1.0, -1.0):
            for sb in (1.0, -1.0):
                corner = np.array([hi[0] if sa > 0 else lo[0], hi[1] if sb > 0 else lo[1]])
                chain = outline[(rel[:, 0] * sa >= -1e-9) & (rel[:, 1] * sb >= -1e-9)]
                chain = chain[np.argsort(chain[:, 0], kind="stable")]  # monotone in a
                for p, q in zip(chain[:-1], chain[1:]):
                    u, v = p - corner, q - corner
                    area = abs(u[0] * v[1] - u[1] * v[0])
                    if area > 1e-9:
                        tri.append([corner, p, q])
        return [np.array(tri).reshape(-1, 3, 2)]


@dataclass(frozen=True)
class Plate(Shape):
    """A baffle with holes: the slab ``position ± thickness/2`` along ``axis``, ``lo..hi`` across.

    ``lo`` and ``hi`` are the rectangle's corners in the plane coordinates of
    :func:`plane_axes`; ``holes`` lie inside it and apart from each other.
    """

    axis: int
    position: float
    thickness: float
    lo: tuple[float, float]
    hi: tuple[float, float]
    holes: tuple[Hole, ...] = ()
    name: str = ""
    kind: ClassVar[str] = "plate"

    @property
    def stack_key(self) -> int:
        """Plates with as many holes share a :meth:`distance_field`."""
        return len(self.holes)

    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""
        lo, hi = np.zeros(3), np.zeros(3)
        a, b = plane_axes(self.axis)
        lo[[a, b]], hi[[a, b]] = self.lo, self.hi
        lo[self.axis] = self.position - self.thickness / 2
        hi[self.axis] = self.position + self.thickness / 2
        return lo, hi

    @cached_property
    def distance_params(self) -> tuple[float, ...]:
        """``(axis, position, half thickness, lo, hi)``, then per hole code, centre, half-sizes."""
        out = [float(self.axis), self.position, self.thickness / 2, *self.lo, *self.hi]
        for h in self.holes:
            out += [float(h.code), *h.center, h.width / 2, h.height / 2]
        return tuple(out)

    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm] to plates with ``params`` (:attr:`distance_params`)."""
        k, c, t, a0, b0, a1, b1 = params[:7]
        n, a, b = plane_coordinates(k, x, y, z)
        ca, cb, ha, hb = (a0 + a1) / 2, (b0 + b1) / 2, (a1 - a0) / 2, (b1 - b0) / 2
        flat = hole_distance_2d(0, a - ca, b - cb, ha, hb)
        for i in range(7, len(params), 5):
            shape, hca, hcb, hha, hhb = params[i : i + 5]
            flat = np.maximum(flat, -hole_distance_2d(shape, a - hca, b - hcb, hha, hhb))
        return extruded_distance(flat, np.abs(n - c) - t)

    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with boxes ``[lo, hi]`` of shape ``(..., 3)``."""
        s_lo, s_hi = self.aabb()
        overlap = np.all((np.minimum(hi, s_hi) - np.maximum(lo, s_lo)) > 0, axis=-1)
        a, b = plane_axes(self.axis)
        for h in self.holes:
            inside = np.ones(overlap.shape, dtype=bool)
            for ca in (lo[..., a], hi[..., a]):
                for cb in (lo[..., b], hi[..., b]):
                    d = hole_distance_2d(h.code, ca - h.center[0], cb - h.center[1],
                                         h.width / 2, h.height / 2)  # fmt: skip
                    inside &= d <= 1e-9
            overlap &= ~inside
        return overlap

    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie strictly inside."""
        return self.signed_distance(points) < 0

    def to_json(self) -> dict[str, Any]:
        """Scene-export form."""
        holes = [
            {"shape": h.shape, "center": list(h.center), "width": h.width, "height": h.height}
            for h in self.holes
        ]
        return {
            "type": "plate",
            "axis": "xyz"[self.axis],
            "position": self.position,
            "thickness": self.thickness,
            "min": list(self.lo),
            "max": list(self.hi),
            "holes": holes,
        }

    @cached_property
    def pieces(self) -> list[_Array]:
        """The material as convex polygons in the plane (rectangles and triangles), ``(V, 2)``."""
        boxes = [h.bounds() for h in self.holes]
        cuts_a, cuts_b = (
            sorted({self.lo[i], self.hi[i], *(float(c[i]) for box in boxes for c in box)})
            for i in (0, 1)
        )
        out: list[_Array] = []
        for a0, a1 in zip(cuts_a[:-1], cuts_a[1:]):
            for b0, b1 in zip(cuts_b[:-1], cuts_b[1:]):
                mid = np.array([(a0 + a1) / 2, (b0 + b1) / 2])
                if not any(np.all((mid > lo) & (mid < hi)) for lo, hi in boxes):
                    out.append(np.array([[a0, b0], [a1, b0], [a1, b1], [a0, b1]]))
        for h in self.holes:
            out.extend(h.corner_fans()[0])
        return out

    def _prism(self, flat: _Array) -> tuple[_Array, NDArray[np.int64]]:
        """The convex prism over a polygon ``(V, 2)`` through the plate."""
        t = self.thickness / 2
        return extrude(flat, self.axis, self.position - t, self.position + t)

    def bodies(self) -> list[tuple[_Array, NDArray[np.int64]]]:
        """Every piece's prism as a closed mesh ``(vertices, faces)``."""
        return [self._prism(flat) for flat in self.pieces]

    def fcl_objects(self) -> list[Any]:
        """python-fcl convex prisms, one per piece of :attr:`pieces` (solid, not hollow)."""
        out = []
        for flat in self.pieces:
            verts, faces = self._prism(flat)
            flat_faces = np.hstack([np.full((len(faces), 1), 3), faces]).ravel()
            out.append(fcl.CollisionObject(fcl.Convex(verts, len(faces), flat_faces)))
        return out

    def mesh(self) -> Mesh:
        """Vertices and triangles of every piece's prism (a picture's solid plate)."""
        parts = self.bodies()
        offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
        verts = np.vstack([v for v, _ in parts])
        return verts, np.vstack([f + o for (_, f), o in zip(parts, offsets)]).astype(np.int64)

    def wireframe(self) -> list[_Array]:
        """The rectangle's and the holes' outlines on both faces, closed polylines ``(V, 3)``."""
        rect = np.array([self.lo, [self.hi[0], self.lo[1]], self.hi, [self.lo[0], self.hi[1]]])
        out = []
        for outline in [rect, *(h.polygon() for h in self.holes)]:
            closed = np.vstack([outline, outline[:1]])
            for side in (-1, 1):
                out.append(lift(closed, self.axis, self.position + side * self.thickness / 2))
        return out
