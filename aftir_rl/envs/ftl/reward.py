"""The reward of ``AFTIR-ArmFTL-v0``: progress, shaping, success, contact, a cost per step.

:class:`RewardSpec` holds the reward's options and :class:`FTLReward`, built from it and the
env's state, is the one formula (:meth:`FTLReward.compute_reward`, compiled in
:func:`~aftir_rl.envs.ftl.kernel.goal_reward`) that serves the envs' steps and HER's
relabelling. A new term is a field here, its use in :meth:`FTLReward.step` (and the kernel).
The terms and the two shaping potentials are described in docs/envs/armftl.md.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import AftirError, ConfigError
from aftir_rl.envs.ftl import kernel
from aftir_rl.envs.ftl.fields import field_guide, raster_detour_table
from aftir_rl.envs.ftl.kernel import PROGRESS_PER_CM
from aftir_rl.envs.ftl.state import FTLBatch

__all__ = ["MAX_STEP_COST", "SHAPING_KINDS", "FTLReward", "RewardSpec"]

#: The largest ``step_cost``: 300 steps of it stay below the contact penalty, so ending an
#: episode on contact never pays better than waiting.
MAX_STEP_COST = 0.03
#: The ``shaping`` values and the potential each one adds.
SHAPING_KINDS = {False: "", True: "raster", "raster": "raster", "field": "field"}


@dataclasses.dataclass(frozen=True)
class RewardSpec:
    """The reward's options: the potential term (``shaping``) and a cost per step."""

    shaping: bool | str = False
    step_cost: float = 0.0

    @property
    def shaping_kind(self) -> str:
        """``""``, ``"raster"`` or ``"field"`` (``True`` is the raster)."""
        return SHAPING_KINDS[self.shaping]

    def __post_init__(self) -> None:
        if not (isinstance(self.shaping, bool | str) and self.shaping in SHAPING_KINDS):
            raise ConfigError(
                f"shaping must be false, true, 'raster' or 'field', got {self.shaping!r}"
            )
        step_cost = self.step_cost
        if not (
            isinstance(step_cost, int | float)
            and not isinstance(step_cost, bool)
            and 0 <= step_cost <= MAX_STEP_COST
        ):
            raise ConfigError(f"step_cost must be in [0, {MAX_STEP_COST:g}], got {step_cost!r}")


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


class FTLReward:
    """The goal-conditioned reward and terminations of an FTL env's ``batch``.

    :meth:`compute_reward` is vectorised and is the step reward itself, so HER relabels with the
    same function (the envs expose it as Gymnasium-Robotics' ``GoalEnv`` does). Success is the
    tip within ``success_tolerance`` of the target (the batch's, which training's ``slack``
    tightens) without contact.

    Raises:
        ConfigError: a shaping that needs the tank's raster in a tank without one, or a
            ``"field"`` shaping for more envs than the guide keeps fields for.

    """

    def __init__(self, spec: RewardSpec, batch: FTLBatch) -> None:
        self.spec, self.batch, self.tank = spec, batch, batch.tank
        #: ``""``, ``"raster"`` or ``"field"``: the potential term.
        self.shaping = spec.shaping_kind
        if self.shaping and self.tank.cell_size is None:
            raise ConfigError("shaping needs a tank with a raster (cell_size)")
        self._detour = raster_detour_table(self.tank) if self.shaping == "raster" else None
        self._fields = field_guide(self.tank, batch.b) if self.shaping == "field" else None

    def compute_reward(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> NDArray[np.float64] | float:
        """The step reward for tips ``achieved_goal`` and targets ``desired_goal`` [cm].

        Vectorised over leading axes. ``info`` is the step's info dict (``prev_achieved_goal``,
        ``contact``), or a sequence / object array of them, one per row (HER's relabelling).
        """
        shape, a2, g2 = _goal_rows(achieved_goal, desired_goal)
        prev, contact = _info_arrays(info, len(a2))
        out = self.step(a2, g2, prev, contact)[0].reshape(shape)
        return float(out) if out.ndim == 0 else out

    def step(
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
            float(self.spec.step_cost),
            reward,
            d,
        )
        if not self.shaping:
            return reward, d, None
        if prev_potential is None:
            stale = np.arange(len(a2))
            before = np.empty(len(a2))
        else:
            stale = np.flatnonzero(np.isnan(prev_potential))
            before = np.array(prev_potential, dtype=np.float64)
        # an env's observations have asked the guide both already: the new tips just now, the
        # stale rows' starts when they restarted (_field_detour reuses those answers)
        potential = self.potential(a2, g2)
        if len(stale):
            before[stale] = self.potential(prev[stale], g2[stale])
        reward += PROGRESS_PER_CM * (before - potential)
        return reward, d, potential

    def potential(self, p: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """The shaping's potential [cm] of tips ``p`` for targets ``g`` (both ``(R, 3)``).

        The raster detour (``"raster"``) or the guide field's detour (``"field"``); the reward
        adds ``PROGRESS_PER_CM`` times its decrease.
        """
        if self.shaping == "raster":
            return self._cells(p, g)
        return self._field_detour(p, g)

    def _cells(self, p: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """``cell · e(p, g)`` [cm]: the raster detour from ``p``'s cell to ``g``'s."""
        assert self._detour is not None
        raster = self.tank.raster
        cells = self._detour[raster.cell_indices(p), raster.cell_indices(g)]
        return raster.cell_size * cells.astype(np.float64)

    def _field_detour(self, p: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """``P(p, g) − |p − g|`` [cm]: the guide field's cost-to-go beyond the straight line."""
        fields = self._fields
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
