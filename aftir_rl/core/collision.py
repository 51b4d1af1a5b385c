"""Collision checking of the arm against a tank with python-fcl, and a fast point pre-filter.

:class:`CollisionScene` builds the tank's solids once as python-fcl *solid* primitives (BVH meshes
are hollow) and checks the arm as a chain of capsules of its body radius, built once and moved
with ``setTransform``; only arm-against-tank pairs are tested. The access-panel rule
(docs/design.md §2) holds for every posture. :func:`point_clearance` is the vectorised numpy
counterpart on backbone points (:class:`~aftir_rl.core.tank.distance.TankDistance`), which the
planners use to pre-filter candidate postures before the exact fcl check of the one they return;
:meth:`CollisionScene.collides_fast` gives fcl's verdict, asking fcl only near contact.
The walls, the capsules, the precision of the check and why self-collision is not checked:
docs/design.md §3.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import fcl
import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.interrupts import held
from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.sections import posture_verdict, postures_clear
from aftir_rl.core.robot import ArmSpec, Posture, body_points
from aftir_rl.core.tank import Solid, Tank, TankDistance
from aftir_rl.core.tank.plate import ROUND_VERTICES
from aftir_rl.core.tank.solids import rotation_z_to

__all__ = [
    "CollisionScene",
    "CollisionReport",
    "point_clearance",
    "points_clear",
    "panel_violation",
]


#: Backbone samples of :meth:`CollisionScene.collides_fast` per sample of the panel rule.
_FINER = 4


@dataclass(frozen=True)
class CollisionReport:
    """Result of checking one posture.

    Attributes:
        collides: True if the arm touches a solid or wall, or breaks the panel rule.
        clearance_cm: smallest distance between the arm's body and any solid or wall [cm];
            0 or negative when they touch.
        panel_ok: whether the access-panel rule holds.
        hit: name of a solid the arm touches, "" if none.

    """

    collides: bool
    clearance_cm: float
    panel_ok: bool
    hit: str = ""


class CollisionScene:
    """A tank's solids and walls in python-fcl, and the arm as capsules moved by ``setTransform``.

    Args:
        tank: the tank.
        arm: the arm (default: the tank's).
        links_per_section: capsules per section, K.
        walls: include the box walls and floor (default: the tank's ``walls``).

    """

    def __init__(
        self,
        tank: Tank,
        arm: ArmSpec | None = None,
        links_per_section: int = 10,
        walls: bool | None = None,
    ) -> None:
        self.tank = tank
        self.arm = arm or tank.arm
        self.links_per_section = int(links_per_section)
        self.walls = tank.walls if walls is None else walls
        solids = list(tank.solids) + (tank.enclosure.slabs() if self.walls else [])
        self._names = {}
        objects = []
        for solid in solids:
            for obj in solid.fcl_objects():
                self._names[id(obj)] = solid.name or type(solid).__name__.lower()
                objects.append(obj)
        self._objects = objects  # keep the Python objects alive for the manager
        # python-fcl's meshes are hollow: an arm wholly inside one is found by its inside test
        self._hollow = [s for s in tank.solids if s.kind == "mesh"]
        self._scene = fcl.DynamicAABBTreeCollisionManager()
        self._scene.registerObjects(objects)
        self._scene.setup()
        self._arms: dict[
            int, tuple[list[fcl.CollisionObject], fcl.DynamicAABBTreeCollisionManager]
        ] = {}
        # For far_from_everything, which runs on every step of the arm env.
        bounds = [s.aabb() for s in tank.solids]
        self._solid_lo = np.array([b[0] for b in bounds]).reshape(-1, 3)
        self._solid_hi = np.array([b[1] for b in bounds]).reshape(-1, 3)
        self._box_lo = np.array(tank.box_min, dtype=np.float64)
        self._box_hi = np.array(tank.box_max, dtype=np.float64)
        self._frame = np.array(
            [*tank.panel.center, tank.panel.radius, *tank.box_min[:2], *tank.box_max],
            dtype=np.float64,
        )
        self._kernel: KernelTank | None = None  # the compiled signed distance, on first use
        self._bounds = (0.0, math.inf)

    def __getstate__(self) -> dict[str, object]:
        # fcl objects do not pickle; a copy rebuilds them (envs are pickled by vector wrappers).
        return dict(tank=self.tank, arm=self.arm, links=self.links_per_section, walls=self.walls)

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__init__(state["tank"], state["arm"], state["links"], state["walls"])  # type: ignore[misc]

    def _arm_links(
        self, n_sections: int
    ) -> tuple[list[fcl.CollisionObject], fcl.DynamicAABBTreeCollisionManager]:
        if n_sections not in self._arms:
            length = self.arm.section_length / self.links_per_section
            links = [
                fcl.CollisionObject(fcl.Capsule(self.arm.radius, length), fcl.Transform())
                for _ in range(n_sections * self.links_per_section)
            ]
            manager = fcl.DynamicAABBTreeCollisionManager()
            manager.registerObjects(links)
            manager.setup()
            self._arms[n_sections] = (links, manager)
        return self._arms[n_sections]

    def _place(self, posture: Posture) -> fcl.DynamicAABBTreeCollisionManager:
        pts = body_points(
            posture.dis, posture.theta, posture.phi, self.arm.section_length, self.links_per_section
        )
        links, manager = self._arm_links(posture.n_sections)
        chords = pts[1:] - pts[:-1]
        rotations = rotation_z_to(chords)
        centres = (pts[1:] + pts[:-1]) / 2
        for link, rot, centre in zip(links, rotations, centres):
            link.setTransform(fcl.Transform(rot, centre))
        manager.update()
        return manager

    def panel_ok(self, posture: Posture) -> bool:
        """Whether every backbone point below the floor lies inside the panel's guide."""
        pts = posture.points(self.arm.section_length, self.links_per_section * 2)
        return not bool(panel_violation(self.tank, pts[None])[0])

    def collides(self, posture: Posture) -> bool:
        """True if the arm touches a solid or wall, or breaks the panel rule."""
        return not self.panel_ok(posture) or self._touches(posture)

    def _touches(self, posture: Posture) -> bool:
        """Whether python-fcl finds a capsule of the arm touching a solid or wall."""
        data = fcl.CollisionData()
        with held():  # a Ctrl-C inside fcl's callback would be printed and lost
            self._scene.collide(self._place(posture), data, fcl.defaultCollisionCallback)
        return bool(data.result.is_collision) or bool(self._inside_hollow(posture))

    def _inside_hollow(self, posture: Posture) -> str:
        """The name of a mesh solid that holds a backbone point, "" if none."""
        if not self._hollow:
            return ""
        pts = posture.points(self.arm.section_length, self.links_per_section)
        for solid in self._hollow:
            if solid.contains(pts).any():
                return solid.name or "mesh"
        return ""

    def clearance(self, posture: Posture) -> float:
        """Smallest distance between the arm's body and any solid or wall [cm] (≤ 0 on contact)."""
        data = fcl.DistanceData()
        with held():
            self._scene.distance(self._place(posture), data, fcl.defaultDistanceCallback)
        inside = self._inside_hollow(posture)
        return min(_finite_or_inf(data.result.min_distance), 0.0 if inside else math.inf)

    def check(self, posture: Posture) -> CollisionReport:
        """Collision, clearance and panel rule of one posture, and what it hits."""
        panel = self.panel_ok(posture)
        manager = self._place(posture)
        data, dist = fcl.CollisionData(), fcl.DistanceData()
        with held():
            self._scene.collide(manager, data, fcl.defaultCollisionCallback)
            hit = self._hit_name(manager) if data.result.is_collision else ""
            self._scene.distance(manager, dist, fcl.defaultDistanceCallback)
        clearance = _finite_or_inf(dist.result.min_distance)
        inside = self._inside_hollow(posture)
        touches = bool(data.result.is_collision) or bool(inside)
        if touches:
            clearance = min(clearance, 0.0)
        return CollisionReport(touches or not panel, clearance, panel, hit or inside)

    def polyline_clearance(
        self, points: NDArray[np.float64]
    ) -> tuple[float, NDArray[np.float64], str]:
        """The clearance of a body given as a polyline ``(P, 3)`` [cm] of the arm's radius.

        For a body that is not the constant-curvature arm (the physics check's simulated rod):
        one capsule of the arm's radius along each chord, as long as the chord. Returns the
        smallest distance to any solid or wall [cm] (≤ 0 on contact), the point of the body's
        surface nearest the tank, and the name of the solid or wall it is nearest.
        """
        chords = points[1:] - points[:-1]
        lengths = np.linalg.norm(chords, axis=1)
        links = [
            fcl.CollisionObject(fcl.Capsule(self.arm.radius, float(length)), fcl.Transform(rot, c))
            for length, rot, c in zip(
                lengths, rotation_z_to(chords), (points[1:] + points[:-1]) / 2
            )
        ]
        manager = fcl.DynamicAABBTreeCollisionManager()
        manager.registerObjects(links)
        manager.setup()
        data = fcl.DistanceData(fcl.DistanceRequest(enable_nearest_points=True))
        with held():
            self._scene.distance(manager, data, fcl.defaultDistanceCallback)
        clearance = _finite_or_inf(data.result.min_distance)
        body = np.asarray(data.result.nearest_points[1], dtype=np.float64)
        if clearance <= 0:  # python-fcl says -1 and no points where they touch: the deepest
            clearance, body = 0.0, points[int(np.argmin(point_clearance(self.tank, points)))]
        if self._hollow and any(s.contains(points).any() for s in self._hollow):
            clearance = min(clearance, 0.0)
        nearest, name = math.inf, ""
        for obj in self._objects:  # which solid: the one at the smallest distance
            one = fcl.DistanceData()
            with held():
                manager.distance(obj, one, fcl.defaultDistanceCallback)
            if one.result.min_distance < nearest:
                nearest, name = one.result.min_distance, self._names[id(obj)]
        return clearance, body, name

    def _hit_name(self, manager: fcl.DynamicAABBTreeCollisionManager) -> str:
        for obj in self._objects:
            data = fcl.CollisionData()
            manager.collide(obj, data, fcl.defaultCollisionCallback)
            if data.result.is_collision:
                return self._names[id(obj)]
        return ""

    def far_from_everything(self, points: NDArray[np.float64], clear: float) -> bool:
        """Whether every point ``(P, 3)`` is farther than ``clear`` [cm] from the tank.

        Conservative and cheap: the solids are taken as their bounding boxes, and the floor as a
        plane with the panel's round opening. False only means "maybe closer".
        """
        if not _outside_boxes(np.ascontiguousarray(points), self._solid_lo, self._solid_hi, clear):
            return False
        if not self.walls:
            return True
        lo, hi = self._box_lo, self._box_hi
        if (points[:, :2] <= lo[:2] + clear).any() or (points >= hi - clear).any():
            return False
        floor = self.tank.enclosure.floor_distance_xyz(points[:, 0], points[:, 1], points[:, 2])
        return bool(np.all(floor > clear))

    def sample_margin(self, samples_per_section: int) -> float:
        """How far [cm] a point of the capsules' axes can be from the nearest backbone sample.

        A capsule's axis is a chord of the arc, within the link's sagitta of it (and a capsule of
        arc length reaches past the chord's ends by less than 0.01 cm at the defaults); any
        point of the arc is within half the sample spacing ``l/2k`` of a sample. With 0.1 cm of
        slack for rounding.
        """
        spacing = self.arm.section_length / samples_per_section
        return spacing / 2 + self._link_sagitta() + 0.1

    def collides_fast(self, posture: Posture) -> bool:
        """:meth:`collides`, with a compiled pre-check that skips python-fcl when it can.

        The same verdict, about ten times faster than :meth:`collides`. The panel rule is
        checked on the same backbone samples as :meth:`panel_ok`, ``l/2K`` apart, and the
        distances on four times as many: samples farther than radius + :meth:`sample_margin`
        from everything clear every capsule; a sample inside the tank's box nearer than the
        radius less a link's sagitta (and not that near the floor, whose opening python-fcl
        cuts square) lies in its capsule, which then touches. python-fcl decides the rest. The
        distance is the tank's exact signed distance (compiled), less what python-fcl's
        polygonal holes add (:func:`polygon_slack`). A tank with mesh solids, whose distance is
        read from a grid, or a scene built without the tank's walls is pre-checked against
        bounding boxes instead, and a posture bent past the limit goes to python-fcl.
        """
        return self.collides_joints(posture.dis, np.array(posture.theta), np.array(posture.phi))

    def collides_joints(
        self, dis: float, theta: NDArray[np.float64], phi: NDArray[np.float64]
    ) -> bool:
        """:meth:`collides_fast` of the posture ``(dis, theta, phi)`` given as float arrays.

        For callers that hold joint vectors (RRT-Connect's states): no :class:`Posture` is built
        unless python-fcl is asked.
        """
        k = 2 * self.links_per_section
        if theta.size and float(np.max(np.abs(theta))) > self.arm.theta_max:
            return self.collides(Posture(dis, theta, phi))  # the margins assume bends in limit
        if self._hollow or self.walls != self.tank.walls:
            posture = Posture(dis, theta, phi)
            pts = posture.points(self.arm.section_length, k)
            if panel_violation(self.tank, pts[None])[0]:
                return True
            if self.far_from_everything(pts, self.arm.radius + self.sample_margin(k)):
                return False
            return self._touches(posture)
        if self._kernel is None:
            self._kernel = kernel_grid(self.tank)
            clear = self.arm.radius + self.sample_margin(_FINER * k) + polygon_slack(self.tank)
            self._bounds = (self._inner_radius() - 1e-3, clear)
        verdict = posture_verdict(
            float(dis),
            theta,
            phi,
            self.arm.section_length,
            (_FINER * k, _FINER),
            self._frame,
            self._bounds,
            self._kernel,
            np.empty((theta.size * _FINER * k + 1, 3)),
        )
        return verdict < 0 or (verdict == 0 and self._touches(Posture(dis, theta, phi)))

    def _inner_radius(self) -> float:
        """The radius of a ball about any backbone point that lies inside its link's capsule.

        A capsule's axis is the chord of its link's arc, within the sagitta of every point of
        the arc.
        """
        return self.arm.radius - self._link_sagitta()

    def _link_sagitta(self) -> float:
        """How far a capsule's axis, the chord of its link, lies from the arc at most [cm]."""
        bend = self.arm.theta_max / self.links_per_section
        link = self.arm.section_length / self.links_per_section
        return link / bend * (1 - math.cos(bend / 2)) if bend > 0 else 0.0

    def collides_batch(self, dis: ArrayLike, theta: ArrayLike, phi: ArrayLike) -> NDArray[np.bool_]:
        """:meth:`collides` for postures stacked as arrays ``(B,)``, ``(B, N)``, ``(B, N)``."""
        dis, theta, phi = np.atleast_1d(dis), np.atleast_2d(theta), np.atleast_2d(phi)
        return np.array(
            [self.collides(Posture(d, t, p)) for d, t, p in zip(dis, theta, phi)], dtype=bool
        )


@njit(cache=True)
def _outside_boxes(
    points: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64], clear: float
) -> bool:
    """Whether no point ``(P, 3)`` lies inside a box ``lo[j]..hi[j]`` grown by ``clear``."""
    for i in range(points.shape[0]):
        for j in range(lo.shape[0]):
            inside = True
            for a in range(3):
                if not lo[j, a] - clear < points[i, a] < hi[j, a] + clear:
                    inside = False
                    break
            if inside:
                return False
    return True


def polygon_slack(tank: Tank) -> float:
    """How much nearer [cm] python-fcl's plates can be than the exact signed distance says.

    python-fcl holds a plate's round holes as polygons of ``ROUND_VERTICES`` corners inscribed
    in them, so its plate reaches into a hole of radius ``r`` by up to ``r (1 - cos(π/V))``.
    """
    radii = [
        max(h.width, h.height) / 2
        for s in tank.solids
        if s.kind == "plate"
        for h in s.holes  # type: ignore[attr-defined]
        if h.shape != "rect"
    ]
    return max(radii, default=0.0) * (1.0 - math.cos(math.pi / ROUND_VERTICES)) + 1e-6


def _finite_or_inf(distance: float) -> float:
    """Distance from python-fcl, which reports the largest double when nothing is there."""
    return math.inf if distance >= 1e300 else float(distance)


def panel_violation(tank: Tank, points: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per posture (points ``(B, P, 3)``): a backbone point below the floor outside the guide."""
    c = np.array(tank.panel.center)
    below = points[..., 2] < c[2]
    radial = np.hypot(points[..., 0] - c[0], points[..., 1] - c[1])
    return np.any(below & (radial > tank.panel.radius + 1e-9), axis=-1)


def point_clearance(
    tank: Tank, points: NDArray[np.float64], solids: Sequence[Solid] | None = None
) -> NDArray[np.float64]:
    """Signed distance [cm] from points ``(..., 3)`` to the nearest solid or wall (< 0 inside).

    The floor has a round opening of the panel's radius, continued below the floor as the guide
    tube (the fcl floor slab's opening is the square around that circle, so this is stricter).
    This is :attr:`Tank.distance <aftir_rl.core.tank.geometry.Tank.distance>` (built once per tank),
    or with ``solids`` a :class:`~aftir_rl.core.tank.distance.TankDistance` of those solids.
    """
    return (tank.distance if solids is None else TankDistance(tank, solids))(points)


def points_clear(tank: Tank, points: NDArray[np.float64], limit: float) -> NDArray[np.bool_]:
    """Per posture ``(B, P, 3)``: whether every point is farther than ``limit`` from the tank.

    The distances are those of :func:`point_clearance` (every solid and wall), compiled: the
    tank's clearance grid bounds them, the exact distance decides near ``limit``, and a posture
    stops at its first point that fails. Built for the planners' pre-filter on 10⁴–10⁶ points.
    """
    out = np.empty(points.shape[0], dtype=np.bool_)
    postures_clear(np.ascontiguousarray(points, dtype=np.float64), float(limit), kernel_grid(tank),
                   out)  # fmt: skip
    return out
