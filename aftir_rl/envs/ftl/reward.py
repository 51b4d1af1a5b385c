"""The reward of ``AFTIR-ArmFTL-v0``: progress, shaping, success, contact, a cost per step.

One formula (:meth:`GoalReward.compute_reward`, compiled in
:func:`~aftir_rl.envs.ftl.kernel.goal_reward`) serves the envs' steps and HER's relabelling.
The terms and the two shaping potentials are described in docs/envs/armftl.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import AftirError
from aftir_rl.core.tank import Tank
from aftir_rl.envs.ftl import kernel
from aftir_rl.envs.ftl.kernel import PROGRESS_PER_CM
from aftir_rl.envs.ftl.state import FTLBatch

__all__ = ["GoalReward"]


def _distance(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Euclidean distance over the last axis, in float64 (goals are stored as float32)."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.sqrt(np.einsum("...i,...i->...", diff, diff))


def _goal_rows(
    achieved_goal: ArrayLike, desired_goal: ArrayLike
) -> tuple[tuple[int, ...], NDArray[np.float64], NDArray[np.float64]]:
    """The goals' common leading shape and both as ``(rows, 3)`` float64 arrays."""
    a = np.asarray(achieved_goal, dtype=np.float64)
    g = np.asarray(desired_goal, dtype=np.float64)
    if a.shape == g.shape:
        return a.shape[:-1], a.reshape(-1, 3), g.reshape(-1, 3)
    shape = np.broadcast_shapes(a.shape, g.shape)[:-1]
    return (
        shape,
        np.broadcast_to(a, shape + (3,)).reshape(-1, 3),
        np.broadcast_to(g, shape + (3,)).reshape(-1, 3),
    )


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
    prev = np.broadcast_to(prev, (size, 3)) if len(prev) == 1 < size else prev
    contact = np.broadcast_to(contact, (size,)) if len(contact) == 1 < size else contact
    return prev, contact


class GoalReward:
    """The goal-conditioned reward, terminations and goal space both FTL envs share.

    A base class (as Gymnasium-Robotics' ``GoalEnv``): :meth:`compute_reward` is vectorised and
    is the step reward itself, so HER relabels with the same function.
    """

    batch: FTLBatch
    tank: Tank
    step_cost: float

    def compute_reward(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.float64] | float:
        """The step reward for tips ``achieved_goal`` and targets ``desired_goal`` [cm].

        Vectorised over leading axes. ``info`` is the step's info dict (``prev_achieved_goal``,
        ``contact``), or a sequence / object array of them, one per row (HER's relabelling).
        """
        shape, a2, g2 = _goal_rows(achieved_goal, desired_goal)
        prev, contact = _info_arrays(info, len(a2))
        out = self._step_reward(a2, g2, prev, contact)[0].reshape(shape)
        return float(out) if out.ndim == 0 else out

    def _step_reward(
        self,
        a: ArrayLike,
        g: ArrayLike,
        prev: ArrayLike,
        contact: ArrayLike,
        prev_potential: NDArray[np.float64] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
        """Rewards and tip-to-target distances [cm] of rows of tips, targets, previous tips.

        Each ``(R, 3)`` (any float dtype, taken as float64) with contact flags ``(R,)``: the one
        reward formula, which :meth:`compute_reward` and the envs' steps both call. Also returns
        the shaping's potential at ``a`` (``None`` without shaping). An env passes the potentials
        its previous step returned as ``prev_potential`` (NaN for rows whose tip or target has
        changed since), so each step asks the guide about the new tips only: the value at the
        same point and target is the same, so the reward is too.
        """
        a2 = np.asarray(a, dtype=np.float64)
        g2 = np.asarray(g, dtype=np.float64)
        prev = np.asarray(prev, dtype=np.float64)
        reward, d = np.empty(len(a2)), np.empty(len(a2))
        kernel.goal_reward(
            a2,
            g2,
            prev,
            np.asarray(contact, dtype=np.bool_),
            self.batch.success_tolerance,
            self.step_cost,
            reward,
            d,
        )
        if not self.batch.shaping:
            return reward, d, None
        detour = self._cells if self.batch.shaping == "raster" else self._field_detour
        if prev_potential is None:
            stale = np.arange(len(a2))
            before = np.empty(len(a2))
        else:
            stale = np.flatnonzero(np.isnan(prev_potential))
            before = np.array(prev_potential, dtype=np.float64)
        # an env's observations have asked the guide both already: the new tips just now, the
        # stale rows' starts when they restarted (_field_detour reuses those answers)
        potential = detour(a2, g2)
        if len(stale):
            before[stale] = detour(prev[stale], g2[stale])
        reward += PROGRESS_PER_CM * (before - potential)
        return reward, d, potential

    def _cells(self, p: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """``cell · e(p, g)`` [cm]: the raster detour from ``p``'s cell to ``g``'s."""
        assert self.batch.detour is not None
        raster = self.tank.raster
        cells = self.batch.detour[raster.cell_indices(p), raster.cell_indices(g)]
        return self.tank.raster.cell_size * cells.astype(np.float64)

    def _field_detour(self, p: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """``P(p, g) − |p − g|`` [cm]: the guide field's cost-to-go beyond the straight line."""
        fields = self.batch.fields
        assert fields is not None
        for tips, targets, to_go in reversed(self.batch.guide_queries):
            if tips.shape == p.shape and np.array_equal(tips, p) and np.array_equal(targets, g):
                # the same points and targets as an observation's query: the same answer
                return np.minimum(to_go, 1000.0) - _distance(p, g)
        generation = fields.generation
        ids = fields.field_ids(g)
        if fields.generation != generation:  # the cache started again during the call
            ids = fields.field_ids(g)
        to_go, _ = fields(p, g, ids)
        return np.minimum(to_go, 1000.0) - _distance(p, g)

    def compute_terminated(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.bool_] | bool:
        """Success (tip within tolerance, no contact) or contact, vectorised like the reward."""
        shape, a2, g2 = _goal_rows(achieved_goal, desired_goal)
        d = _distance(a2, g2)
        _, contact = _info_arrays(info, len(d))
        out = ((d < self.batch.success_tolerance) | contact).reshape(shape)
        return bool(out) if out.ndim == 0 else out

    def _goal_bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The goal space's corners [cm]: ``goal_bounds`` if set, else the tank's box + 1 m."""
        shared = self.__dict__.get("goal_bounds")
        if shared is not None:
            return shared
        return np.array(self.tank.box_min) - 100.0, np.array(self.tank.box_max) + 100.0

    def _goal_space(self) -> spaces.Box:
        lo, hi = self._goal_bounds()
        return spaces.Box(lo.astype(np.float32), hi.astype(np.float32), (3,), np.float32)

    def _goal_clip(self, points: NDArray[np.float64]) -> NDArray[np.float32]:
        """Points as the goal space holds them: clipped to its bounds, float32."""
        bounds = self.__dict__.get("_bounds")
        if bounds is None:
            bounds = self.__dict__["_bounds"] = self._goal_bounds()
        return np.minimum(np.maximum(points, bounds[0]), bounds[1]).astype(np.float32)
