"""``AFTIR-ArmFTL-v0``: the whole arm deployed by follow-the-leader, goal-conditioned, batched.

The agent drives the follow-the-leader (FTL) model of :mod:`aftir_rl.motion.ftl`: it steers the
bending vector ``κ = (θ cos φ, θ sin φ)`` [rad] of the route section the tip is tracing and pushes
or pulls the linear module; the body follows the traced route. The env state is a route as that
module defines it (:class:`~aftir_rl.motion.ftl.Route` with ``lead = 0``: bending starts at the
floor), i.e. a ``κ`` history, plus the tip's arc length ``s`` [cm] along it:

- route sections ``0..k−1`` are frozen, section ``k = min(⌊s / l⌋, N − 1)`` is the one being
  traced and the only one the agent steers;
- when a push carries ``s`` past ``(k + 1)·l`` the steered ``κ`` is frozen and the new leading
  section starts as a copy of it (shift-and-copy); a pull below ``k·l`` retracts along the route
  and the previous section becomes the steered one again;
- the posture is :func:`~aftir_rl.motion.ftl.ftl_postures` of that route at ``s``
  (:func:`ftl_kappa_batch` is the same formula over a batch of routes; the tests compare the
  two), so at whole-section stages the body lies exactly on the route.

**Collision** is the numpy signed distance of :func:`~aftir_rl.collision.point_clearance` on
``samples_per_section`` backbone samples per section (5 cm apart at the default 10), batched over
envs; no python-fcl in the step. *Contact* is a sample whose surface clearance (distance minus the
arm's radius) is below ``margin`` (1 cm; the panel guide below the floor counts as a wall). Between
two samples ``δ`` apart the backbone can come closer than the samples by at most ``δ/2`` (2.5 cm at
the default sampling); the check is on the samples, as stated.

**Goal-conditioned** (Gymnasium-Robotics / panda-gym): observations are
``Dict(observation, achieved_goal, desired_goal)``; ``achieved_goal`` is the tip and
``desired_goal`` the target, both in cm. ``observation`` holds no goal (HER relabels goals), only
the arm and what it senses: see :class:`ArmFTLEnv`. :meth:`ArmFTLEnv.compute_reward` is
vectorised and the step reward *is* its value on the step's own goal, so SB3's
``HerReplayBuffer`` relabels with the same function. It needs the step's ``info`` (the previous tip
and the contact flag): give HER ``replay_buffer_kwargs={"copy_info_dict": True}``; without infos
it raises :class:`~aftir_rl.errors.AftirError` rather than returning a different reward.

**Reward** (per step, ``d`` = distance from tip to target [cm])::

    r = (d_prev − d) / 10  +  shaping · (Φ(tip) − Φ(tip_prev))  +  10·success  −  10·contact

The progress term is itself potential-based (``Φ = −d/10``, γ = 1). The switchable shaping term
(Ng, Harada & Russell 1999, with γ = 1 as for the progress term; the optimal policy of the
undiscounted episodic task is unchanged) is grounded in the grid world: ``Φ(p) = −cell · e(p, g)
/ 10``, where ``e`` is the *detour* of the shortest 6-connected path through the tank's raster
(the BFS that Q-learning is checked against, :meth:`aftir_rl.tank.Raster.bfs_distances`) from
the tip's cell to the target's cell beyond the Manhattan distance of the two cells. ``e`` is 0
wherever nothing blocks the straight way, so ``(d_prev − d)/10 + ΔΦ`` is the progress along
``d + cell·e``, a distance-to-go through the hatch: for a bay-2 target a tip in bay 1 is paid for
moving towards the hatch and up to its height, which the Euclidean term alone punishes. The
all-pairs raster distances are computed once per tank (numpy relaxation, < 0.5 s) and looked up,
so the term costs nothing per step and HER can relabel it. Measured with and without: see
``benchmarks/bench_arm_ftl.py`` and the README.

**Batched.** :class:`ArmFTLVectorEnv` (``gym.make_vec(..., vectorization_mode=
"vector_entry_point")``) steps ``num_envs`` arms in one numpy pass; both classes share
:class:`FTLBatch`, so a vector env seeded ``seed`` gives row ``i`` exactly the transitions of a
single env seeded ``seed + i`` under the same actions.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from aftir_rl.collision import point_clearance
from aftir_rl.envs.ftl_batch import bay_region, clearance_grid, draw_targets, field_guide
from aftir_rl.errors import AftirError, ConfigError, InvalidActionError, TargetError
from aftir_rl.motion.ftl import kappa_to_angles
from aftir_rl.robot import Posture, body_points, section_transforms
from aftir_rl.tank import Tank, TankDistance, load_tank

__all__ = [
    "ArmFTLEnv",
    "ArmFTLVectorEnv",
    "FTLBatch",
    "ftl_kappa_batch",
    "raster_detour_table",
    "TankDistance",
]

#: Reward of a success and penalty of a contact.
SUCCESS_REWARD = 10.0
CONTACT_PENALTY = 10.0
#: Progress reward per cm of distance-to-go.
PROGRESS_PER_CM = 0.1
#: Directions of the sensing rays from the tip: the tip's heading, then ±x, ±y, ±z.
_RAY_AXES = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
)
#: Distances [cm] of the samples along each ray.
RAY_DISTANCES = (10.0, 25.0, 50.0)
#: Clearances [cm] in the observation are divided by this and clipped to [-1, 1].
_CLEAR_SCALE = 50.0


# ---------------------------------------------------------------------------------------------
# the model, batched (no gymnasium)


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


_DETOUR_CACHE: dict[int, NDArray[np.int32]] = {}


def raster_detour_table(tank: Tank) -> NDArray[np.int32]:
    """Detour ``e[c, g]`` [cells] of the shortest 6-connected raster path beyond Manhattan.

    ``D[c, g]`` is the BFS distance through free cells (:meth:`~aftir_rl.tank.Raster.bfs_distances`
    from every cell at once); an obstructed end cell (a free point can lie in a cell a solid only
    partly fills) counts as one step from its nearest free neighbour. ``e = D − |c − g|₁ ≥ 0``;
    unreachable pairs get the largest finite detour. Shape ``(cells, cells)``, flat cell indices.
    Computed once per tank.
    """
    key = id(tank)
    if key in _DETOUR_CACHE:
        return _DETOUR_CACHE[key]
    raster = tank.raster
    shape = raster.shape
    free = ~raster.obstructed
    n = raster.n_cells
    big = np.int32(10 * n)
    dist = np.full((n,) + shape, big, dtype=np.int32)
    dist.reshape(n, n)[np.arange(n), np.arange(n)] = 0
    moves = [(axis, step) for axis in range(3) for step in (-1, 1)]

    def neighbour_min(d: NDArray[np.int32]) -> NDArray[np.int32]:
        best = np.full_like(d, big)
        for axis, step in moves:
            src = [slice(None)] * 4
            dst = [slice(None)] * 4
            src[axis + 1] = slice(max(0, -step), shape[axis] - max(0, step))
            dst[axis + 1] = slice(max(0, step), shape[axis] - max(0, -step))
            best[tuple(dst)] = np.minimum(best[tuple(dst)], d[tuple(src)])
        return best

    for _ in range(4 * sum(shape)):
        new = np.where(free[None], np.minimum(dist, neighbour_min(dist) + 1), dist)
        if np.array_equal(new, dist):
            break
        dist = new
    dist = np.where(free[None], dist, np.minimum(dist, neighbour_min(dist) + 1))
    flat = dist.reshape(n, n)
    flat = np.minimum(flat, flat.T)  # obstructed sources: from either end
    cells = np.indices(shape).reshape(3, -1).T
    manhattan = np.abs(cells[:, None, :] - cells[None, :, :]).sum(-1)
    detour = np.clip(flat - manhattan, 0, None)
    finite = detour[flat < big]
    detour = np.where(flat < big, detour, finite.max() if finite.size else 0).astype(np.int32)
    detour.setflags(write=False)
    _DETOUR_CACHE[key] = detour
    return detour


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
        shaping: whether the raster-detour potential term is in the reward.
        guide: whether the observation holds the goal-dependent guide (see :class:`ArmFTLEnv`).

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
        shaping: bool,
        guide: bool = False,
    ) -> None:
        self.tank, self.arm = tank, tank.arm
        self.n, self.b, self.k_samples = int(n_sections), int(batch), int(samples_per_section)
        self.l = float(self.arm.section_length)
        self.kappa_step, self.push_step = float(kappa_step), float(push_step)
        self.start_height, self.margin = float(start_height), float(margin)
        self.success_tolerance, self.shaping = float(success_tolerance), bool(shaping)
        self.s_max = self.n * self.l
        self.detour = raster_detour_table(tank) if shaping else None
        self.distance = tank.distance
        self.grid = clearance_grid(tank)
        self._deep = tank.box_min[2] - tank.panel.radius - 1.0
        self.kappa = np.zeros((self.b, self.n, 2))
        self.k = np.zeros(self.b, dtype=np.int64)
        self.s = np.full(self.b, self.start_height)
        self.target = np.zeros((self.b, 3))
        self.obs_size = 14 + 3 * self.n + (len(_RAY_AXES) + 1) * len(RAY_DISTANCES)
        self.guide = field_guide(tank) if guide else None
        self.guide_ids = np.zeros(self.b, dtype=np.int64)
        self.obs_size += 10 if guide else 0
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
            to_go, direction = self.guide(self.tip, self.target, self.guide_ids)
            to_go = np.minimum(to_go, 1000.0)
            # in the frame the steered κ bends in, where steering towards them is simplest
            frame = self.steering_frames()
            parts += [
                (to_go / 100.0)[:, None],
                np.einsum("bji,bj->bi", frame, direction),
                np.einsum("bji,bj->bi", frame, self.target - self.tip) / 100.0,
                np.einsum("bji,bj->bi", frame, self.heading),
            ]
        return np.concatenate(parts, axis=1).astype(np.float32)

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
        if self.guide is not None:
            self.guide_ids[rows] = self.guide.field_ids(self.target[rows])
        if refresh:
            self.refresh()

    def step(self, action: NDArray[np.float64]) -> NDArray[np.float64]:
        """Apply actions ``(B, 3)`` in ``[-1, 1]``; return the previous tips ``(B, 3)``."""
        prev = self.tip.copy()
        rows = np.arange(self.b)
        steered = self.kappa[rows, self.k] + action[:, :2] * self.kappa_step
        norm = np.hypot(steered[:, 0], steered[:, 1])
        limit = self.arm.theta_max
        steered *= np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)[:, None]
        self.kappa[rows, self.k] = steered
        self.s = np.clip(self.s + action[:, 2] * self.push_step, 0.0, self.s_max)
        new_k = np.minimum(np.floor(self.s / self.l).astype(np.int64), self.n - 1)
        grow = new_k > self.k  # push_step <= l: at most one new section
        self.kappa[rows[grow], new_k[grow]] = self.kappa[rows[grow], self.k[grow]]
        self.k = new_k
        self.refresh()
        return prev


def _distance(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Euclidean distance over the last axis, in float64 (goals are stored as float32)."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.sqrt(np.einsum("...i,...i->...", diff, diff))


def _info_arrays(info: Any, size: int) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Previous tips ``(size, 3)`` and contact flags ``(size,)`` from one dict or many."""
    try:
        if isinstance(info, Mapping):
            prev = np.asarray(info["prev_achieved_goal"], dtype=np.float64).reshape(-1, 3)
            contact = np.asarray(info["contact"], dtype=bool).reshape(-1)
        else:
            items = list(np.asarray(info, dtype=object).reshape(-1))
            prev = np.array([i["prev_achieved_goal"] for i in items], dtype=np.float64)
            contact = np.array([bool(i["contact"]) for i in items])
    except (KeyError, TypeError) as exc:
        raise AftirError(
            f"compute_reward needs the step's info (missing {exc}); with SB3's HerReplayBuffer "
            "pass replay_buffer_kwargs={'copy_info_dict': True}"
        ) from None
    prev = np.broadcast_to(prev, (size, 3)) if len(prev) == 1 else prev
    contact = np.broadcast_to(contact, (size,)) if len(contact) == 1 else contact
    return prev, contact


class _GoalReward:
    """The reward, terminations and goal spaces shared by the single and the vector env."""

    batch: FTLBatch
    tank: Tank

    def compute_reward(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.float64] | float:
        """The step reward for tips ``achieved_goal`` and targets ``desired_goal`` [cm].

        Vectorised over leading axes. ``info`` is the step's info dict (``prev_achieved_goal``,
        ``contact``), or a sequence / object array of them, one per row (HER's relabelling).
        """
        a = np.asarray(achieved_goal, dtype=np.float64)
        g = np.asarray(desired_goal, dtype=np.float64)
        shape = np.broadcast_shapes(a.shape, g.shape)[:-1]
        a2 = np.broadcast_to(a, shape + (3,)).reshape(-1, 3)
        g2 = np.broadcast_to(g, shape + (3,)).reshape(-1, 3)
        prev, contact = _info_arrays(info, len(a2))
        d = _distance(a2, g2)
        d_prev = _distance(prev, g2)
        reward = PROGRESS_PER_CM * (d_prev - d)
        if self.batch.shaping:
            reward += PROGRESS_PER_CM * self._cells(prev, g2) - PROGRESS_PER_CM * self._cells(
                a2, g2
            )
        success = (d < self.batch.success_tolerance) & ~contact
        reward = reward + SUCCESS_REWARD * success - CONTACT_PENALTY * contact
        out = reward.reshape(shape)
        return float(out) if out.ndim == 0 else out

    def _cells(self, p: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """``cell · e(p, g)`` [cm]: the raster detour from ``p``'s cell to ``g``'s."""
        raster = self.tank.raster
        shape = np.array(raster.shape)
        origin = np.array(raster.origin)

        def flat(x: NDArray[np.float64]) -> NDArray[np.int64]:
            c = np.clip(np.floor((x - origin) / raster.cell_size).astype(np.int64), 0, shape - 1)
            return (c[:, 0] * shape[1] + c[:, 1]) * shape[2] + c[:, 2]

        assert self.batch.detour is not None
        return raster.cell_size * self.batch.detour[flat(p), flat(g)].astype(np.float64)

    def compute_terminated(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.bool_] | bool:
        """Success (tip within tolerance, no contact) or contact, vectorised like the reward."""
        a = np.asarray(achieved_goal, dtype=np.float64)
        g = np.asarray(desired_goal, dtype=np.float64)
        shape = np.broadcast_shapes(a.shape, g.shape)[:-1]
        d = _distance(
            np.broadcast_to(a, shape + (3,)).reshape(-1, 3),
            np.broadcast_to(g, shape + (3,)).reshape(-1, 3),
        )
        _, contact = _info_arrays(info, len(d))
        out = ((d < self.batch.success_tolerance) | contact).reshape(shape)
        return bool(out) if out.ndim == 0 else out

    def _goal_space(self) -> spaces.Box:
        lo = np.array(self.tank.box_min) - 100.0
        hi = np.array(self.tank.box_max) + 100.0
        return spaces.Box(lo.astype(np.float32), hi.astype(np.float32), (3,), np.float32)

    def _goal_clip(self, points: NDArray[np.float64]) -> NDArray[np.float32]:
        """Points as the goal space holds them: clipped to its bounds, float32."""
        lo = np.array(self.tank.box_min) - 100.0
        hi = np.array(self.tank.box_max) + 100.0
        return np.clip(points, lo, hi).astype(np.float32)


def _check_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    options = dict(options or {})
    unknown = sorted(set(options) - {"target"})
    if unknown:
        raise ConfigError(f"unknown reset option {unknown[0]!r}; use 'target'")
    return options


class _Setup:
    """Argument checking and derived settings shared by the single and the vector env."""

    def _setup(
        self,
        tank: str | Path | Tank,
        n_sections: int | None,
        batch: int,
        target: Sequence[float] | None,
        bay: int | None,
        target_clearance: float,
        success_tolerance: float,
        margin: float,
        kappa_step: float,
        push_step: float,
        start_height: float,
        samples_per_section: int,
        shaping: bool,
        guide: bool = False,
    ) -> None:
        self.tank = load_tank(tank)
        arm = self.tank.arm
        n = arm.max_sections if n_sections is None else int(n_sections)
        if not 1 <= n <= arm.max_sections:
            raise ConfigError(f"n_sections must be in 1..{arm.max_sections}, got {n_sections}")
        for name, value in (
            ("kappa_step", kappa_step),
            ("push_step", push_step),
            ("success_tolerance", success_tolerance),
        ):
            if not 0 < value < math.inf:
                raise ConfigError(f"{name} must be positive and finite, got {value}")
        if push_step > arm.section_length:
            raise ConfigError(f"push_step must be at most the section length, got {push_step}")
        if not 0 <= margin < 20 or not 0 <= target_clearance < 100:
            raise ConfigError("margin must be in [0, 20) cm and target_clearance in [0, 100) cm")
        if samples_per_section < 2:
            raise ConfigError(f"samples_per_section must be at least 2, got {samples_per_section}")
        if not 0 <= start_height < arm.section_length:
            raise ConfigError(f"start_height must be in [0, {arm.section_length:g}) cm")
        self.region = bay_region(self.tank, bay)
        self.bay = bay
        self.target_clearance = float(target_clearance)
        self.batch = FTLBatch(
            self.tank,
            n,
            batch,
            samples_per_section,
            kappa_step,
            push_step,
            start_height,
            margin,
            success_tolerance,
            shaping,
            guide,
        )
        self.start_tip = np.array([0.0, 0.0, float(start_height)])
        self.fixed_target = None if target is None else self._check_target(target)

    def _check_target(self, target: Any) -> NDArray[np.float64]:
        try:
            t = np.asarray(target, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            t = np.zeros(0)
        if t.shape != (3,) or not np.all(np.isfinite(t)) or not self.tank.contains_point(t):
            raise TargetError(f"target {target!r} is not a point (x, y, z) inside the tank box")
        clear = float(point_clearance(self.tank, t[None])[0])
        need = self.tank.arm.radius + self.batch.margin
        if clear < need:
            raise TargetError(
                f"target {target!r} lies {clear:.1f} cm from the tank's surfaces; the tip needs "
                f"at least {need:g} cm (radius + margin)"
            )
        return t

    def _spaces(self) -> tuple[spaces.Box[np.float32], spaces.Dict]:
        action = spaces.Box(-1.0, 1.0, (3,), np.float32)
        goal = self._goal_space()  # type: ignore[attr-defined]
        obs = spaces.Dict(
            {
                "observation": spaces.Box(-10.0, 10.0, (self.batch.obs_size,), np.float32),
                "achieved_goal": goal,
                "desired_goal": goal,
            }
        )
        return action, obs

    def _obs_dict(self, rows: slice | NDArray[np.int64]) -> dict[str, NDArray[np.float32]]:
        b = self.batch
        return {
            "observation": np.clip(b.observation()[rows], -10.0, 10.0),
            "achieved_goal": self._goal_clip(b.tip[rows]),  # type: ignore[attr-defined]
            "desired_goal": b.target[rows].astype(np.float32),
        }

    def _check_action(self, action: Any, shape: tuple[int, ...] | None) -> NDArray[np.float64]:
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != shape or not np.all(np.isfinite(a)):
            raise InvalidActionError(
                f"invalid action of shape {a.shape}: expected {shape} finite values in [-1, 1]"
            )
        return np.clip(a, -1.0, 1.0)


class ArmFTLEnv(_Setup, _GoalReward, gym.Env[dict[str, NDArray[np.float32]], NDArray[np.float32]]):
    """The whole arm, deployed through the panel by follow-the-leader, reaching targets.

    ## Description
    The AFTIR arm (``n_sections`` sections, default the tank's maximum, 12 × 50 cm in the
    reference tank) on its linear module. The agent steers the section the tip is tracing and
    pushes or pulls the module; the body follows the traced route (module docstring). The task:
    bring the tip within ``success_tolerance`` of a target anywhere free in the tank (both bays
    by default), through the hatch for bay-2 targets, without contact.

    ## Action Space
    ``Box(-1, 1, (3,), float32)``: the change of the steered ``κ`` (two components, scaled by
    ``kappa_step`` [rad], ``|κ|`` clipped to ``θ_max``) and the insertion (scaled by
    ``push_step`` [cm], ``s`` clipped to ``[0, N·l]``).

    ## Observation Space
    ``Dict``: ``achieved_goal`` (tip) and ``desired_goal`` (target), ``Box(float32, (3,))`` in cm
    (the tank box grown by 100 cm); ``observation``, ``Box(-10, 10, float32)``: ``dis/(N·l)``,
    ``k/N``, the steered ``κ/θ_max``, every section's ``θ/θ_max``, ``sin φ``, ``cos φ``, the tip
    (cm/100), its heading, the body's surface clearance (cm/10, clipped to ±1), the clearance at
    10, 25 and 50 cm along 7 rays from the tip (heading, ±x, ±y, ±z; cm/50, clipped to ±1) and
    the heights of the last three section ends (cm/100).

    ## Starting State
    Straight, the tip ``start_height`` (10 cm) above the floor.

    ## Rewards
    Progress ``(d_prev − d)/10`` [per cm], the raster-detour potential term when ``shaping``,
    ``+10`` on success, ``−10`` on contact: :meth:`compute_reward` (module docstring).

    ## Episode End
    Terminated on success (tip within ``success_tolerance`` and no contact) or contact (surface
    clearance below ``margin``); truncated by ``max_episode_steps`` (300 at registration).

    ## Arguments
    - ``tank``: tank name or YAML path; ``n_sections``: default the tank arm's maximum.
    - ``target``: fixed target [cm] for every episode; default drawn per episode with
      ``np_random``, uniformly among points ``target_clearance`` (10 cm) from every surface and
      20 cm from the start, in ``bay`` (1, 2, or None for the whole tank).
    - ``success_tolerance`` (2 cm), ``margin`` (1 cm), ``kappa_step`` (0.1 rad), ``push_step``
      (5 cm), ``start_height`` (10 cm), ``samples_per_section`` (10), ``shaping`` (False).
    - ``guide`` (False): append to ``observation`` what the way to *this* target looks like: the
      free-space distance-to-go (cm/100, at most 10), then, in the frame the steered section
      bends in (:meth:`FTLBatch.steering_frames`), the unit way to the next point of the
      shortest way (:class:`~aftir_rl.envs.ftl_batch.FieldGuide`), ``(target − tip)/100`` and
      the tip's heading. These depend on the goal, so HER's relabelled goals would not match them:
      use it with PPO, not HER.
    - ``render_mode``: ``"rgb_array"``.

    ``reset(options={"target": (x, y, z)})`` sets the target of one episode.

    ## Version History
    - v0: initial version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        tank: str | Path | Tank = "b737_center",
        n_sections: int | None = None,
        target: Sequence[float] | None = None,
        bay: int | None = None,
        target_clearance: float = 10.0,
        success_tolerance: float = 2.0,
        margin: float = 1.0,
        kappa_step: float = 0.1,
        push_step: float = 5.0,
        start_height: float = 10.0,
        samples_per_section: int = 10,
        shaping: bool = False,
        guide: bool = False,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        self.render_mode = render_mode
        self._setup(
            tank,
            n_sections,
            1,
            target,
            bay,
            target_clearance,
            success_tolerance,
            margin,
            kappa_step,
            push_step,
            start_height,
            samples_per_section,
            shaping,
            guide,
        )
        self.arm = self.tank.arm
        # gymnasium types a Dict space's elements as dict[str, Space], not dict[str, element]
        self.action_space, self.observation_space = self._spaces()  # type: ignore[assignment]
        self._tips: list[NDArray[np.float64]] = []

    @property
    def target(self) -> NDArray[np.float64]:
        """The episode's target [cm]."""
        return self.batch.target[0].copy()

    @property
    def tip(self) -> NDArray[np.float64]:
        """The tip's position [cm]."""
        return self.batch.tip[0].copy()

    @property
    def posture(self) -> Posture:
        """The current joint variables ``(dis, θ, φ)``."""
        b = self.batch
        return Posture(b.dis[0], b.theta[0], b.phi[0])

    @property
    def route_kappa(self) -> NDArray[np.float64]:
        """The traced route's ``κ`` ``(k + 1, 2)`` [rad], the steered section last."""
        return self.batch.kappa[0, : self.batch.k[0] + 1].copy()

    @property
    def insertion(self) -> float:
        """The tip's arc length ``s`` along the route, from the floor [cm]."""
        return float(self.batch.s[0])

    def body(self, points_per_section: int = 10) -> NDArray[np.float64]:
        """Backbone points of the current posture [cm]."""
        b = self.batch
        return body_points(b.dis[0], b.theta[0], b.phi[0], b.l, points_per_section)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Straighten the arm just inside the panel and set a target."""
        super().reset(seed=seed)
        options = _check_options(options)
        if options.get("target") is not None:
            target = self._check_target(options["target"])
        elif self.fixed_target is not None:
            target = self.fixed_target
        else:
            target = draw_targets(
                [self.np_random],
                self.batch.grid,
                self.region,
                self.target_clearance,
                self.start_tip,
            )[0]
        self.batch.reset_rows(np.array([0]), target[None])
        self._tips = [self.tip]
        info = {"distance_cm": float(np.linalg.norm(self.tip - target)), "target": target.copy()}
        return {k: v[0] for k, v in self._obs_dict(slice(None)).items()}, info

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[dict[str, NDArray[np.float32]], SupportsFloat, bool, bool, dict[str, Any]]:
        """Steer and push; see the class docstring for rewards and termination."""
        a = self._check_action(action, self.action_space.shape)
        b = self.batch
        prev = self._goal_clip(b.step(a[None]))[0]
        self._tips.append(self.tip)
        obs = {k: v[0] for k, v in self._obs_dict(slice(None)).items()}
        contact = bool(b.contact[0])
        info: dict[str, Any] = {"prev_achieved_goal": prev, "contact": contact}
        reward = self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        distance = _distance(obs["achieved_goal"], obs["desired_goal"])
        success = bool(distance < b.success_tolerance) and not contact
        info.update(
            is_success=success,
            collision=contact,
            distance_cm=float(distance),
            min_clearance_cm=float(b.body_clearance[0]),
        )
        return obs, float(reward), bool(success or contact), False, info

    def render(self) -> NDArray[np.uint8] | None:
        """The tank, the arm, its tip path and the target (``rgb_array``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        if getattr(self, "_renderer", None) is None:
            from aftir_rl.plotting import PathRenderer

            self._renderer = PathRenderer(self.tank, title="AFTIR-ArmFTL")
        return self._renderer.render(np.array(self._tips), self.target, arms=[self.body()])


class ArmFTLVectorEnv(
    _Setup, _GoalReward, VectorEnv[dict[str, NDArray[np.float32]], NDArray[np.float32], Any]
):
    """``num_envs`` :class:`ArmFTLEnv` s stepped together in numpy (autoreset: next step).

    Same arguments as :class:`ArmFTLEnv` plus ``num_envs`` and ``max_episode_steps``
    (truncation). Row ``i`` draws its targets from its own generator, seeded ``seed + i`` by
    ``reset(seed=seed)``, so it reproduces a single env seeded ``seed + i``. As in Gymnasium's
    ``CartPoleVectorEnv``, a row that ended is reset by the next ``step`` (which returns its
    first observation with reward 0 and no termination, ignoring that row's action).
    ``reset(options={"target": ...})`` takes one target for all rows or one per row ``(B, 3)``.
    ``info`` holds per-row arrays ``prev_achieved_goal``, ``contact``, ``is_success``,
    ``distance_cm`` and ``min_clearance_cm``. With ``autoreset_mode="SameStep"`` rows that end are
    reset within the step instead: their last observations are in ``info["final_obs"]`` (the
    batched ``Dict``, valid where ``info["_final_obs"]``) and the step returns their first ones
    (what SB3's ``VecEnv`` adapter :class:`aftir_rl.agents.vec_adapter.SB3VectorEnv` wants).
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int = 300,
        tank: str | Path | Tank = "b737_center",
        n_sections: int | None = None,
        target: Sequence[float] | None = None,
        bay: int | None = None,
        target_clearance: float = 10.0,
        success_tolerance: float = 2.0,
        margin: float = 1.0,
        kappa_step: float = 0.1,
        push_step: float = 5.0,
        start_height: float = 10.0,
        samples_per_section: int = 10,
        shaping: bool = False,
        guide: bool = False,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None:
            raise ConfigError("ArmFTLVectorEnv does not render; use ArmFTLEnv for pictures")
        if num_envs < 1 or max_episode_steps < 1:
            raise ConfigError("num_envs and max_episode_steps must be at least 1")
        self.num_envs = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.render_mode = None
        self._setup(
            tank,
            n_sections,
            self.num_envs,
            target,
            bay,
            target_clearance,
            success_tolerance,
            margin,
            kappa_step,
            push_step,
            start_height,
            samples_per_section,
            shaping,
            guide,
        )
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ConfigError(
                f"autoreset_mode must be 'NextStep' or 'SameStep', got {autoreset_mode!r}"
            ) from None
        if self.autoreset_mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ConfigError("autoreset_mode must be 'NextStep' or 'SameStep'")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.single_action_space, self.single_observation_space = self._spaces()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._rngs = [seeding.np_random()[0] for _ in range(self.num_envs)]
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self.prev_done = np.zeros(self.num_envs, dtype=bool)
        self._targets_option: NDArray[np.float64] | None = None

    def _new_targets(self, rows: NDArray[np.int64]) -> NDArray[np.float64]:
        if self._targets_option is not None:
            return self._targets_option[rows]
        if self.fixed_target is not None:
            return np.repeat(self.fixed_target[None], len(rows), axis=0)
        rngs = [self._rngs[i] for i in rows]
        return draw_targets(
            rngs, self.batch.grid, self.region, self.target_clearance, self.start_tip
        )

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Reset every row; ``seed`` seeds row ``i`` with ``seed + i`` (or a list, one each)."""
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else seed
            if len(seeds) != self.num_envs:
                raise ConfigError(f"reset got {len(seeds)} seeds for {self.num_envs} envs")
            self._rngs = [seeding.np_random(int(s))[0] for s in seeds]
            self._np_random, self._np_random_seed = seeding.np_random(seeds[0])
        options = _check_options(options)
        self._targets_option = None
        if options.get("target") is not None:
            t = np.asarray(options["target"], dtype=np.float64)
            rows = t.reshape(-1, 3) if t.size % 3 == 0 else t
            if rows.ndim != 2 or len(rows) not in (1, self.num_envs):
                raise TargetError(f"target must be (3,) or ({self.num_envs}, 3), got {t.shape}")
            checked = np.array([self._check_target(r) for r in rows])
            self._targets_option = np.broadcast_to(checked, (self.num_envs, 3)).copy()
        every = np.arange(self.num_envs)
        self.batch.reset_rows(every, self._new_targets(every))
        self.steps[:] = 0
        self.prev_done[:] = False
        return self._obs_dict(slice(None)), {"target": self.batch.target.copy()}

    def step(
        self, actions: NDArray[np.float32]
    ) -> tuple[
        dict[str, NDArray[np.float32]],
        NDArray[np.float64],
        NDArray[np.bool_],
        NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step every row; rows that ended on the previous step are reset instead."""
        a = self._check_action(actions, self.action_space.shape)
        b = self.batch
        done_rows = np.flatnonzero(self.prev_done)
        if len(done_rows):
            a[done_rows] = 0.0
            b.reset_rows(done_rows, self._new_targets(done_rows), refresh=False)
        prev_tip = b.step(a)
        prev_tip[done_rows] = b.tip[done_rows]
        obs = self._obs_dict(slice(None))
        prev = self._goal_clip(prev_tip)
        contact = b.contact.copy()
        info: dict[str, Any] = {"prev_achieved_goal": prev, "contact": contact}
        reward = np.asarray(
            self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info), dtype=np.float64
        )
        distance = _distance(obs["achieved_goal"], obs["desired_goal"])
        success = (distance < b.success_tolerance) & ~contact
        terminated = success | contact
        self.steps += 1
        truncated = self.steps >= self.max_episode_steps
        reward[done_rows] = 0.0
        terminated[done_rows] = False
        truncated[done_rows] = False
        self.steps[done_rows] = 0
        info.update(
            is_success=success,
            collision=contact,
            distance_cm=distance,
            min_clearance_cm=b.body_clearance.copy(),
        )
        done = terminated | truncated
        if self.autoreset_mode is AutoresetMode.NEXT_STEP:
            self.prev_done = done
        elif done.any():  # SAME_STEP: the last observations go to info, the rows start again
            rows = np.flatnonzero(done)
            info.update(final_obs={k: v.copy() for k, v in obs.items()}, _final_obs=done)
            b.reset_rows(rows, self._new_targets(rows))
            self.steps[rows] = 0
            obs = self._obs_dict(slice(None))
        return obs, reward, terminated, truncated, info
