"""The follow-the-leader arm of ``AFTIR-ArmFTL-v0`` as a batch: state, dynamics, sensing.

:class:`FTLBatch` holds ``B`` routes (a ``κ`` history each, a
:class:`~aftir_rl.planning.ftl.model.Route` with ``lead = 0``) and tip arc lengths, and steps
them in one numpy pass: shift-and-copy (:func:`ftl_kappa_batch`), batched forward kinematics,
exact body clearances (:class:`~aftir_rl.core.kernel.clearance.ClearanceGrid`), sensing rays
and, optionally, the goal-aware guide (:class:`~aftir_rl.envs.ftl.fields.FieldGuide`). No
gymnasium here: :mod:`aftir_rl.envs.ftl.env` holds it, with the reward and the target sampler,
as the single and the vector env.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core import kernel as core_kernel
from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import ConfigError, TargetError
from aftir_rl.core.kernel.clearance import clearance_grid, kernel_grid
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.envs.ftl import kernel
from aftir_rl.envs.ftl.fields import LOOKAHEAD_HOPS, field_guide

__all__ = [
    "NEAR_GOAL_RANGE",
    "RAY_DISTANCES",
    "STEER_MODES",
    "FTLBatch",
    "TaskSpec",
    "ftl_kappa_batch",
    "observation_size",
]

#: What the two steering actions may command: a change of the steered ``κ``, or ``κ`` itself.
STEER_MODES = ("increment", "target")


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _motion_free(default: Any) -> Any:
    """A task field that changes what the policy observes or aims at, never how the arm moves."""
    return dataclasses.field(default=default, metadata={"motion_free": True})


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """The tank, the arm, the task and what the policy observes (lengths in cm, angles in rad)."""

    tank: str | Path | Tank = DEFAULT_TANK
    n_sections: int | None = None
    target: Sequence[float] | None = _motion_free(None)
    bay: int | None = _motion_free(None)
    success_tolerance: float = 2.0
    margin: float = 1.0
    kappa_step: float = 0.1
    push_step: float = 5.0
    start_height: float = 10.0
    samples_per_section: int = 10
    steer: str = "increment"
    guide: bool = _motion_free(False)
    near_goal: bool = _motion_free(False)

    def __post_init__(self) -> None:
        if not isinstance(self.near_goal, bool | np.bool_):
            raise ConfigError(f"near_goal must be true or false, got {self.near_goal!r}")
        if self.steer not in STEER_MODES:
            raise ConfigError(f"steer must be 'increment' or 'target', got {self.steer!r}")
        for name in ("kappa_step", "push_step", "success_tolerance"):
            value = getattr(self, name)
            if not 0 < value < math.inf:
                raise ConfigError(f"{name} must be positive and finite, got {value}")
        if not (_number(self.margin) and 0 <= self.margin < 20):
            raise ConfigError(f"margin must be in [0, 20) cm, got {self.margin!r}")
        if self.samples_per_section < 2:
            raise ConfigError(
                f"samples_per_section must be at least 2, got {self.samples_per_section}"
            )


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

    Row ``b`` is :func:`aftir_rl.planning.ftl.model.ftl_postures` of the route
    ``Route(0, kappa[b, :k[b] + 1], l)`` with the tip at arc length ``s[b]`` [cm] (the same
    padded interpolation, vectorised over routes of different lengths).

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


#: The distance [cm] within which the ``near_goal`` columns give the target's offset itself.
NEAR_GOAL_RANGE = 10.0


def observation_size(n_sections: int, guide: bool, near_goal: bool) -> int:
    """The length of the observation vector (the columns: ``ArmFTLEnv``'s docstring).

    ``dis``, ``k``, the steered ``κ`` (2), ``θ`` per section, ``sin φ`` and ``cos φ`` per section,
    the tip (3), its heading (3), the body's clearance (1), the rays' clearances (7 × 3) and the
    heights of the last three section ends (3); the guide's 10 + 3 per lookahead point; the
    near-goal offset's 3.
    """
    size = 2 + 2 + 3 * n_sections + 3 + 3 + 1 + (len(_RAY_AXES) + 1) * len(RAY_DISTANCES) + 3
    size += 10 + 3 * len(LOOKAHEAD_HOPS) if guide else 0
    return size + (3 if near_goal else 0)


class FTLBatch:
    """State, dynamics and sensing of ``B`` FTL arms in one tank, stepped in one numpy pass.

    Built from the task spec whole: its tank (:func:`~aftir_rl.core.tank.load_tank`), arm
    (``n_sections``, default the tank arm's maximum), steps, start, margin, sensing
    (``samples_per_section``, ``guide``, ``near_goal``) and steering mode; the options are
    described in :class:`~aftir_rl.envs.ftl.env.ArmFTLEnv`. The batch also makes the goal
    space and the observation dicts both envs return.

    Args:
        task: the task spec.
        batch: ``B``.
        slack: training's ``slack`` [cm]: the margin kept is ``margin + slack`` and a success
            needs the tip within ``success_tolerance − slack``.
        goal_bounds: the goal space's corners [cm] (shared by a pool's tanks), or None: the
            tank's box grown by 1 m.

    Raises:
        ConfigError: the task does not fit the tank's arm, or the guide keeps too few fields.

    """

    def __init__(
        self,
        task: TaskSpec,
        batch: int,
        slack: float = 0.0,
        goal_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> None:
        self.tank = tank = load_tank(task.tank)
        self.arm = arm = tank.arm
        n = arm.max_sections if task.n_sections is None else int(task.n_sections)
        if not 1 <= n <= arm.max_sections:
            raise ConfigError(f"n_sections must be in 1..{arm.max_sections}, got {task.n_sections}")
        if task.push_step > arm.section_length:
            raise ConfigError(f"push_step must be at most the section length, got {task.push_step}")
        if not 0 <= task.start_height < arm.section_length:
            raise ConfigError(f"start_height must be in [0, {arm.section_length:g}) cm")
        self.n, self.b, self.k_samples = n, int(batch), int(task.samples_per_section)
        self.l = float(arm.section_length)
        self.kappa_step, self.push_step = float(task.kappa_step), float(task.push_step)
        self.start_height = float(task.start_height)
        #: The clearance the arm's surface keeps [cm]; less is a contact.
        self.margin = float(task.margin) + float(slack)
        #: The tip-to-target distance of a success [cm].
        self.success_tolerance = float(task.success_tolerance) - float(slack)
        self.s_max = self.n * self.l
        self.steer = str(task.steer)
        self.grid = clearance_grid(tank)
        self._kernel_tank = kernel_grid(tank)
        self._deep = tank.box_min[2] - tank.panel.radius - 1.0
        self.kappa = np.zeros((self.b, self.n, 2))
        self.k = np.zeros(self.b, dtype=np.int64)
        self.s = np.full(self.b, self.start_height)
        self.target = np.zeros((self.b, 3))
        if goal_bounds is None:
            goal_bounds = (np.array(tank.box_min) - 100.0, np.array(tank.box_max) + 100.0)
        #: The goal space's corners [cm].
        self.goal_bounds = goal_bounds
        #: The guide's fields, for the observation's goal-aware columns (None without them).
        self.guide = field_guide(tank, self.b) if task.guide else None
        self.guide_ids = np.zeros(self.b, dtype=np.int64)
        #: The observations' latest guide queries (every row's or some rows'), newest last: tips,
        #: targets (both ``(R, 3)``) and their distance-to-go ``(R,)``, for the reward to reuse.
        self.guide_queries: deque[
            tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
        ] = deque(maxlen=3)
        self._guide_generation = self.guide.generation if self.guide is not None else 0
        self.near_goal = bool(task.near_goal)
        #: The length of the observation vector.
        self.obs_size = observation_size(n, task.guide, self.near_goal)
        self._guide_start = observation_size(n, False, False)
        self.refresh()

    def check_target(self, target: object) -> NDArray[np.float64]:
        """``target`` as a point [cm] the tip may reach: in the tank's box, clear of surfaces.

        Raises:
            TargetError: not three finite numbers inside the box, or closer to the tank's
                surfaces than the arm's radius and the margin.

        """
        try:
            t = np.asarray(target, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            t = np.zeros(0)
        if t.shape != (3,) or not np.all(np.isfinite(t)) or not self.tank.contains_point(t):
            raise TargetError(f"target {target!r} is not a point (x, y, z) inside the tank box")
        clear = float(point_clearance(self.tank, t[None])[0])
        need = self.arm.radius + self.margin
        if clear < need:
            raise TargetError(
                f"target {target!r} lies {clear:.1f} cm from the tank's surfaces; the tip needs "
                f"at least {need:g} cm (radius + margin)"
            )
        return t

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
        contact rule reads. Below the floor the body is straight on the guide's axis (the route
        starts at the floor), where the distance does not change with depth: the base stands for
        every sample deeper than the opening's rim can reach. For every env, every array is new
        (holders of the previous ones keep them); ``rows`` are updated in place.
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
        assert self.guide is not None
        if self._guide_generation != self.guide.generation:  # the cache started again
            self.guide_ids = self.guide.field_ids(self.target)
            self._guide_generation = self.guide.generation
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
        if self.guide is not None:
            generation = self.guide.generation
            self.guide_ids[rows] = self.guide.field_ids(self.target[rows])
            if self.guide.generation != generation:  # other rows' ids are void: ask again
                self.guide_ids = self.guide.field_ids(self.target)
                self._guide_generation = self.guide.generation
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
