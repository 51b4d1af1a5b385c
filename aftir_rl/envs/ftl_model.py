"""The follow-the-leader arm of ``AFTIR-ArmFTL-v0`` as a batch: state, dynamics, sensing.

:class:`FTLBatch` holds ``B`` routes (a ``κ`` history each, :class:`~aftir_rl.motion.ftl.Route`
with ``lead = 0``) and tip arc lengths, and steps them in one numpy pass: shift-and-copy
(:func:`ftl_kappa_batch`), batched forward kinematics, exact body clearances
(:class:`~aftir_rl.envs.ftl_batch.ClearanceGrid`), sensing rays and, optionally, the goal-aware
guide (:class:`~aftir_rl.envs.ftl_batch.FieldGuide`). No gymnasium here:
:mod:`aftir_rl.envs.arm_ftl` wraps it as the single and the vector env.
"""

from __future__ import annotations

import weakref

import numpy as np
from numpy.typing import NDArray

from aftir_rl.envs.ftl_batch import (
    LOOKAHEAD_HOPS,
    clearance_grid,
    field_guide,
    raster_distance_table,
)
from aftir_rl.errors import ConfigError
from aftir_rl.motion.ftl import kappa_to_angles
from aftir_rl.robot import body_points, section_transforms
from aftir_rl.tank import Tank

__all__ = ["FTLBatch", "ftl_kappa_batch", "raster_detour_table", "RAY_DISTANCES"]

#: Directions of the sensing rays from the tip: the tip's heading, then ±x, ±y, ±z.
_RAY_AXES = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
)
#: Distances [cm] of the samples along each ray.
RAY_DISTANCES = (10.0, 25.0, 50.0)
#: Clearances [cm] in the observation are divided by this and clipped to [-1, 1].
_CLEAR_SCALE = 50.0


def ftl_kappa_batch(
    kappa: NDArray[np.float64], k: NDArray[np.int64], s: NDArray[np.float64], l: float
) -> NDArray[np.float64]:
    """Bending vectors ``(B, N, 2)`` of the arm sections for a batch of routes.

    Row ``b`` is :func:`aftir_rl.motion.ftl.ftl_postures` of ``Route(0, kappa[b, :k[b] + 1], l)``
    with the tip at arc length ``s[b]`` [cm] (the same padded interpolation, vectorised over
    routes of different lengths).

    Args:
        kappa: route ``κ`` per env, ``(B, N, 2)`` [rad]; entries past ``k`` are ignored.
        k: index of the last route section per env, ``(B,)``.
        s: tip arc length from the floor per env, ``(B,)`` [cm].
        l: section length [cm].

    """
    b, n = kappa.shape[:2]
    m = k + 1
    u = np.clip(s / l, 0.0, m.astype(np.float64))
    kk = np.minimum(np.floor(u).astype(np.int64), m)
    f = (u - kk)[:, None, None]
    rows = np.arange(b)[:, None]

    def padded(j: NDArray[np.int64]) -> NDArray[np.float64]:
        idx = j - n  # index into the route; < 0: straight padding; m: the last one repeated
        picked = kappa[rows, np.clip(np.minimum(idx, m[:, None] - 1), 0, n - 1)]
        return np.where((idx >= 0)[..., None], picked, 0.0)

    j = kk[:, None] + np.arange(n)[None, :]
    return (1.0 - f) * padded(j) + f * padded(j + 1)


def raster_detour_table(tank: Tank) -> NDArray[np.int32]:
    """Detour ``e[c, g]`` [cells] of the shortest 6-connected raster path beyond Manhattan.

    ``e = D − |c − g|₁ ≥ 0`` with ``D`` the all-pairs BFS distances of
    :func:`~aftir_rl.envs.ftl_batch.raster_distance_table` (unreachable pairs: the largest
    distance plus one). Shape ``(cells, cells)``, flat cell indices; cached with the table.
    """
    cached = _DETOUR_CACHE.get(tank)
    if cached is not None:
        return cached
    dist = raster_distance_table(tank)
    cells = np.indices(tank.raster.shape).reshape(3, -1).T
    manhattan = np.abs(cells[:, None, :] - cells[None, :, :]).sum(-1)
    detour = np.clip(dist - manhattan, 0, None).astype(np.int32)
    detour.setflags(write=False)
    _DETOUR_CACHE[tank] = detour
    return detour


_DETOUR_CACHE: weakref.WeakKeyDictionary[Tank, NDArray[np.int32]] = weakref.WeakKeyDictionary()


class FTLBatch:
    """State and dynamics of ``B`` FTL arms in one tank, stepped in one numpy pass.

    Args:
        tank: the tank.
        n_sections: arm sections ``N``.
        batch: ``B``.
        samples_per_section: backbone samples per section for contact and clearance.
        kappa_step: largest change of the steered ``κ`` per step [rad].
        push_step: largest insertion or retraction per step [cm].
        start_height: the tip's height above the floor at reset [cm].
        margin: clearance the arm's surface keeps; less is a contact [cm].
        success_tolerance: tip-to-target distance of a success [cm].
        shaping: the reward's potential term: ``""`` (none), ``"raster"`` (the raster's detour)
            or ``"field"`` (the guide field's detour).
        guide: whether the observation holds the goal-dependent guide (see :class:`ArmFTLEnv`).
        steer: ``"increment"`` (actions change the steered ``κ``) or ``"target"`` (they name the
            bend ``κ`` approaches at ``kappa_step`` per component and step).

    """

    def __init__(
        self,
        tank: Tank,
        n_sections: int,
        batch: int,
        samples_per_section: int,
        kappa_step: float,
        push_step: float,
        start_height: float,
        margin: float,
        success_tolerance: float,
        shaping: str,
        guide: bool = False,
        steer: str = "increment",
    ) -> None:
        self.tank, self.arm = tank, tank.arm
        self.n, self.b, self.k_samples = int(n_sections), int(batch), int(samples_per_section)
        self.l = float(self.arm.section_length)
        self.kappa_step, self.push_step = float(kappa_step), float(push_step)
        self.start_height, self.margin = float(start_height), float(margin)
        self.success_tolerance, self.shaping = float(success_tolerance), str(shaping)
        self.s_max = self.n * self.l
        self.steer = str(steer)
        self.detour = raster_detour_table(tank) if shaping == "raster" else None
        self.grid = clearance_grid(tank)
        self._deep = tank.box_min[2] - tank.panel.radius - 1.0
        self.kappa = np.zeros((self.b, self.n, 2))
        self.k = np.zeros(self.b, dtype=np.int64)
        self.s = np.full(self.b, self.start_height)
        self.target = np.zeros((self.b, 3))
        self.obs_size = 14 + 3 * self.n + (len(_RAY_AXES) + 1) * len(RAY_DISTANCES)
        #: The guide's fields, for the observation or the ``"field"`` shaping.
        self.fields = field_guide(tank) if guide or shaping == "field" else None
        self.guide = self.fields if guide else None
        self.guide_ids = np.zeros(self.b, dtype=np.int64)
        self._guide_generation = self.fields.generation if self.fields is not None else 0
        if self.fields is not None and self.fields.capacity < 2 * self.b:
            raise ConfigError(
                f"the guide keeps {self.fields.capacity} target fields of this tank's grid, too "
                f"few for {self.b} envs; use fewer envs or guide=False"
            )
        self.obs_size += 10 + 3 * len(LOOKAHEAD_HOPS) if guide else 0
        self.refresh()

    # -- geometry
    def postures(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``dis (B,)``, ``θ (B, N)``, ``φ (B, N)`` of the current states."""
        theta, phi = kappa_to_angles(ftl_kappa_batch(self.kappa, self.k, self.s, self.l))
        return self.s - self.n * self.l, theta, phi

    def refresh(self) -> None:
        """Recompute postures, body samples, tip and clearances of every env."""
        dis, theta, phi = self.postures()
        pts = body_points(dis, theta, phi, self.l, self.k_samples)  # (B, N·K + 1, 3)
        tip = pts[:, -1]
        heading = tip - pts[:, -2]
        heading /= np.maximum(np.linalg.norm(heading, axis=-1, keepdims=True), 1e-12)
        axes = np.concatenate(
            [heading[:, None, :], np.broadcast_to(_RAY_AXES, (self.b,) + _RAY_AXES.shape)], 1
        )
        rays = tip[:, None, None, :] + axes[:, :, None, :] * np.asarray(RAY_DISTANCES)[:, None]
        self.theta, self.phi, self.dis = theta, phi, dis
        self.points, self.tip, self.heading = pts, tip, heading
        # Below the floor the body is straight on the guide's axis (the route starts at the
        # floor), where the distance does not change with depth: the base stands for every
        # sample deeper than the opening's rim can reach.
        use = pts[..., 2] > self._deep
        use[:, 0] = True
        self.body_clearance = self.grid.row_min(pts, use) - self.arm.radius  # surface [cm]
        self.ray_clearance = self.grid.approx(rays.reshape(self.b, -1, 3))
        self.contact = self.body_clearance < self.margin

    def observation(self) -> NDArray[np.float32]:
        """The goal-free observation vector of every env, ``(B, obs_size)``."""
        lead = self.kappa[np.arange(self.b), self.k] / self.arm.theta_max
        parts = [
            (self.dis / self.s_max)[:, None],
            (self.k / self.n)[:, None],
            lead,
            self.theta / self.arm.theta_max,
            np.sin(self.phi),
            np.cos(self.phi),
            self.tip / 100.0,
            self.heading,
            np.clip(self.body_clearance / 10.0, -1.0, 1.0)[:, None],
            np.clip(self.ray_clearance / _CLEAR_SCALE, -1.0, 1.0),
            self.points[:, self.k_samples :: self.k_samples, 2][:, -3:] / 100.0,
        ]
        if self.guide is not None:
            to_go, direction = self.guide(self.tip, self.target, self.target_fields())
            to_go = np.minimum(to_go, 1000.0)
            # in the frame the steered κ bends in, where steering towards them is simplest
            frame = self.steering_frames()
            ahead = self.guide.lookahead(self.tip, self.target, self.guide_ids) - self.tip[:, None]
            ahead /= np.maximum(np.linalg.norm(ahead, axis=-1, keepdims=True), 1e-9)
            parts += [
                (to_go / 100.0)[:, None],
                np.einsum("bji,bj->bi", frame, direction),
                np.einsum("bji,bj->bi", frame, self.target - self.tip) / 100.0,
                np.einsum("bji,bj->bi", frame, self.heading),
                np.einsum("bji,bhj->bhi", frame, ahead).reshape(self.b, -1),
            ]
        return np.concatenate(parts, axis=1).astype(np.float32)

    def target_fields(self) -> NDArray[np.int64]:
        """The guide's field ids of the targets, ``(B,)`` (asked again after a restart)."""
        assert self.fields is not None
        if self._guide_generation != self.fields.generation:  # the cache started again
            self.guide_ids = self.fields.field_ids(self.target)
            self._guide_generation = self.fields.generation
        return self.guide_ids

    def steering_frames(self) -> NDArray[np.float64]:
        """Rotations ``(B, 3, 3)`` of the frames the steered sections bend in.

        The route's frame at ``k·l``: the product of the rotations of its frozen sections
        ``0..k−1``.
        """
        theta, phi = kappa_to_angles(self.kappa)
        ends = section_transforms(theta, phi, self.l)[..., :3, :3]
        frame = np.broadcast_to(np.eye(3), (self.b, 3, 3)).copy()
        for j in range(int(self.k.max(initial=0))):
            frozen = (j < self.k)[:, None, None]
            frame = np.where(frozen, frame @ ends[:, j], frame)
        return frame

    # -- dynamics
    def reset_rows(
        self, rows: NDArray[np.int64], targets: NDArray[np.float64], refresh: bool = True
    ) -> None:
        """Straighten the arms of ``rows``, tip ``start_height`` above the floor; set targets.

        With ``refresh=False`` the geometry is recomputed by the next :meth:`step` (given a zero
        action for those rows, it leaves them where they are).
        """
        self.kappa[rows] = 0.0
        self.k[rows] = 0
        self.s[rows] = self.start_height
        self.target[rows] = targets
        if self.fields is not None:
            generation = self.fields.generation
            self.guide_ids[rows] = self.fields.field_ids(self.target[rows])
            if self.fields.generation != generation:  # other rows' ids are void: ask again
                self.guide_ids = self.fields.field_ids(self.target)
                self._guide_generation = self.fields.generation
        if refresh:
            self.refresh()

    def step(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """Apply actions ``(B, 3)`` in ``[-1, 1]``; return the previous tips ``(B, 3)``."""
        prev = self.tip.copy()
        rows = np.arange(self.b)
        lead = self.kappa[rows, self.k]
        limit = self.arm.theta_max
        if self.steer == "target":
            want = action[:, :2] * limit
            norm = np.hypot(want[:, 0], want[:, 1])
            want *= np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)[:, None]
            steered = lead + np.clip(want - lead, -self.kappa_step, self.kappa_step)
        else:
            steered = lead + action[:, :2] * self.kappa_step
            norm = np.hypot(steered[:, 0], steered[:, 1])
            steered *= np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)[:, None]
        self.kappa[rows, self.k] = steered
        self.s = np.clip(self.s + action[:, 2] * self.push_step, 0.0, self.s_max)
        new_k = np.minimum(np.floor(self.s / self.l).astype(np.int64), self.n - 1)
        grow = new_k > self.k  # push_step <= l: at most one new section
        self.kappa[rows[grow], new_k[grow]] = self.kappa[rows[grow], self.k[grow]]
        self.k = new_k
        self.refresh()
        return prev
