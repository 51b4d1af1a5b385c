"""The follow-the-leader arm of ``AFTIR-ArmFTL-v0`` as a batch: state, dynamics, sensing.

:class:`FTLBatch` holds ``B`` routes (a ``κ`` history each,
:class:`~aftir_rl.planning.ftl.model.Route`
with ``lead = 0``) and tip arc lengths, and steps them in one numpy pass: shift-and-copy
(:func:`ftl_kappa_batch`), batched forward kinematics, exact body clearances
(:class:`~aftir_rl.core.kernel.clearance.ClearanceGrid`), sensing rays and, optionally, the
goal-aware guide (:class:`~aftir_rl.envs.ftl.fields.FieldGuide`). No gymnasium here:
:mod:`aftir_rl.envs.ftl.env` wraps it as the single and the vector env.
"""

from __future__ import annotations

import weakref
from collections import deque

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core import kernel as core_kernel
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.kernel.clearance import clearance_grid, kernel_grid
from aftir_rl.core.tank import Tank
from aftir_rl.envs.ftl import kernel
from aftir_rl.envs.ftl.fields import LOOKAHEAD_HOPS, field_guide, raster_distance_table

__all__ = ["FTLBatch", "ftl_kappa_batch", "raster_detour_table", "RAY_DISTANCES", "NEAR_GOAL_RANGE"]

#: Directions of the sensing rays from the tip: the tip's heading, then ±x, ±y, ±z.
_RAY_AXES = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
)
#: Distances [cm] of the samples along each ray.
RAY_DISTANCES = (10.0, 25.0, 50.0)
_RAY_STEPS = np.array(RAY_DISTANCES)
#: Clearances [cm] in the observation are divided by this and clipped to [-1, 1].
_CLEAR_SCALE = 50.0


def ftl_kappa_batch(
    kappa: NDArray[np.float64], k: NDArray[np.int64], s: NDArray[np.float64], l: float
) -> NDArray[np.float64]:
    """Bending vectors ``(B, N, 2)`` of the arm sections for a batch of routes.

    Row ``b`` is :func:`aftir_rl.planning.ftl.model.ftl_postures` of ``Route(0, kappa[b, :k[b] + 1],
    l)``
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
    :func:`~aftir_rl.envs.ftl.fields.raster_distance_table` (unreachable pairs: the largest
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


#: The distance [cm] within which the ``near_goal`` columns give the target's offset itself.
NEAR_GOAL_RANGE = 10.0


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
        near_goal: whether the observation ends with the target's offset at a fine scale
            (:meth:`near_goal_columns`).

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
        near_goal: bool = False,
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
        self._kernel_tank = kernel_grid(tank)
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
        #: The observations' latest guide queries (every row's or some rows'), newest last: tips,
        #: targets (both ``(R, 3)``) and their distance-to-go ``(R,)``, for the reward to reuse.
        self.guide_queries: deque[
            tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
        ] = deque(maxlen=3)
        self._guide_generation = self.fields.generation if self.fields is not None else 0
        if self.fields is not None and self.fields.capacity < 2 * self.b:
            raise ConfigError(
                f"the guide keeps {self.fields.capacity} target fields of this tank's grid, too "
                f"few for {self.b} envs; use fewer envs or guide=False"
            )
        self._guide_start = self.obs_size
        self.obs_size += 10 + 3 * len(LOOKAHEAD_HOPS) if guide else 0
        self.near_goal = bool(near_goal)
        self.obs_size += 3 if near_goal else 0
        self.refresh()

    # -- geometry
    def postures(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``dis (B,)``, ``θ (B, N)``, ``φ (B, N)`` of the current states."""
        return self.s - self.n * self.l, self.theta, self.phi

    def refresh(self, rows: NDArray[np.int64] | None = None) -> None:
        """Recompute postures, body samples, tip and clearances of every env (or of ``rows``).

        One compiled pass (:func:`aftir_rl.core.kernel.refresh`): the FTL postures
        (:func:`ftl_kappa_batch`), the backbone samples (:func:`~aftir_rl.core.robot.body_points`),
        the exact body clearance (:meth:`ClearanceGrid.row_min
        <aftir_rl.core.kernel.clearance.ClearanceGrid.row_min>`) and the rays' clearances
        (:meth:`~aftir_rl.core.kernel.clearance.ClearanceGrid.approx`); then the surface clearance
        between the samples too (:func:`aftir_rl.core.kernel.surface_clearance`), which the
        contact rule reads. Below the floor the body is
        straight on the guide's axis (the route starts at the floor), where the distance does
        not change with depth: the base stands for every sample deeper than the opening's rim
        can reach. For every env, every array is new (holders of the previous ones keep them);
        ``rows`` are updated in place.
        """
        b, n = self.b, self.n
        if rows is None:
            rows = np.arange(b)
            self.theta, self.phi = np.empty((b, n)), np.empty((b, n))
            self.points = np.empty((b, n * self.k_samples + 1, 3))
            self.heading = np.empty((b, 3))
            self.body_clearance = np.empty(b)  # surface [cm], at the samples
            self.surface_clearance = np.empty(b)  # surface [cm], between them too
            self.ray_clearance = np.empty((b, (len(_RAY_AXES) + 1) * len(RAY_DISTANCES)))
        core_kernel.refresh(
            np.asarray(rows, dtype=np.int64),
            self.kernel_arms(),
            self.l,
            self.k_samples,
            float(self.arm.radius),
            self._deep,
            (_RAY_AXES, _RAY_STEPS),
            self._kernel_tank,
        )
        core_kernel.surface_clearance(
            np.asarray(rows, dtype=np.int64),
            self.kernel_arms(),
            self.l,
            self.k_samples,
            (float(self.arm.radius), float(self.margin), self._deep),
            self._kernel_tank,
            self.surface_clearance,
        )
        self.dis = self.s - n * self.l
        self.tip = self.points[:, -1]
        self.contact = self.surface_clearance < self.margin

    def kernel_arms(self) -> core_kernel.KernelArms:
        """The batch's arrays as the compiled kernels read them (the arrays themselves)."""
        return core_kernel.KernelArms(
            *(getattr(self, name) for name in core_kernel.KernelArms._fields)
        )

    def observation(self, rows: NDArray[np.int64] | None = None) -> NDArray[np.float32]:
        """The observation vectors of every env ``(B, obs_size)``, or of ``rows``.

        With the guide, its columns follow: the way, the target and the lookahead in the frame
        the steered ``κ`` bends in, where steering towards them is simplest.
        """
        every = rows is None
        rows = np.arange(self.b) if rows is None else np.asarray(rows, dtype=np.int64)
        out = np.empty((len(rows), self.obs_size), dtype=np.float32)
        kernel.observation(
            rows,
            self.kernel_arms(),
            self.l,
            self.k_samples,
            float(self.arm.theta_max),
            _CLEAR_SCALE,
            out,
        )
        if self.guide is not None:
            # the tips as the goal space holds them (float32), so that the reward's potential,
            # asked at the observed goals, can reuse this query (:attr:`guide_queries`)
            tip = (self.tip if every else self.tip[rows]).astype(np.float32).astype(np.float64)
            target = self.target.copy() if every else self.target[rows]
            ids = self.target_fields() if every else self.target_fields()[rows]
            to_go, direction = self.guide(tip, target, ids)
            self.guide_queries.append((tip, target, to_go))
            kernel.guide_columns(
                self.steering_frames(None if every else rows),
                to_go,
                direction,
                target,
                tip,
                self.heading if every else self.heading[rows],
                self.guide.lookahead(tip, target, ids),
                out,
                self._guide_start,
            )
        if self.near_goal:
            out[:, -3:] = self.near_goal_columns(None if every else rows)
        return out

    def near_goal_columns(self, rows: NDArray[np.int64] | None = None) -> NDArray[np.float64]:
        """The target's offset from the tip at a fine scale, ``(B, 3)`` (or of ``rows``).

        ``(target − tip) / max(d, NEAR_GOAL_RANGE)`` (``d`` its length) in the frame the steered
        ``κ`` bends in: the unit way to the target beyond :data:`NEAR_GOAL_RANGE` (10 cm), and
        within it the offset itself in tenths of that range, ten times the resolution of the
        guide's ``(target − tip)/100``, where the last centimetres are decided.
        """
        offset = self.target - self.tip if rows is None else self.target[rows] - self.tip[rows]
        offset /= np.maximum(np.linalg.norm(offset, axis=1), NEAR_GOAL_RANGE)[:, None]
        return np.einsum("rji,rj->ri", self.steering_frames(rows), offset)

    def target_fields(self) -> NDArray[np.int64]:
        """The guide's field ids of the targets, ``(B,)`` (asked again after a restart)."""
        assert self.fields is not None
        if self._guide_generation != self.fields.generation:  # the cache started again
            self.guide_ids = self.fields.field_ids(self.target)
            self._guide_generation = self.fields.generation
        return self.guide_ids

    def steering_frames(self, rows: NDArray[np.int64] | None = None) -> NDArray[np.float64]:
        """Rotations ``(B, 3, 3)`` of the frames the steered sections bend in (or of ``rows``).

        The route's frame at ``k·l``: the product of the rotations of its frozen sections
        ``0..k−1`` (:func:`aftir_rl.core.kernel.steering_frames`).
        """
        kappa, k = (self.kappa, self.k) if rows is None else (self.kappa[rows], self.k[rows])
        out = np.empty((len(k), 3, 3))
        core_kernel.steering_frames(kappa, k, out)
        return out

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
        # kept as float32 values, as the goal space holds them: the observation's guide and the
        # reward ask about the same point
        self.target[rows] = np.asarray(targets, dtype=np.float32)
        if self.fields is not None:
            generation = self.fields.generation
            self.guide_ids[rows] = self.fields.field_ids(self.target[rows])
            if self.fields.generation != generation:  # other rows' ids are void: ask again
                self.guide_ids = self.fields.field_ids(self.target)
                self._guide_generation = self.fields.generation
        if refresh:
            self.refresh(None if len(rows) == self.b else rows)

    def step(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """Apply actions ``(B, 3)`` in ``[-1, 1]``; return the previous tips ``(B, 3)``."""
        prev = self.tip.copy()
        kernel.advance(
            np.ascontiguousarray(action, dtype=np.float64),
            self.kappa,
            self.k,
            self.s,
            self.steer == "target",
            self.kappa_step,
            self.push_step,
            float(self.arm.theta_max),
            self.l,
        )
        self.refresh()
        return prev
