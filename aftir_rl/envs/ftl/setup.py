"""What ``AFTIR-ArmFTL-v0``'s single and vector env share: rewards, goals, arguments, spaces."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import AftirError, ConfigError, InvalidActionError, TargetError
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.envs.ftl import kernel
from aftir_rl.envs.ftl.fields import bay_region, draw_targets
from aftir_rl.envs.ftl.kernel import PROGRESS_PER_CM
from aftir_rl.envs.ftl.state import FTLBatch, raster_detour_table


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


class _GoalReward:
    """The reward, terminations and goal spaces shared by the single and the vector env."""

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
        """The goal space's corners [cm]: the tank's box grown by 1 m."""
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


#: The largest ``step_cost``: 300 steps of it stay below the contact penalty, so ending an
#: episode on contact never pays better than waiting.
MAX_STEP_COST = 0.03
#: ``slack`` stays below this [cm] (and below ``success_tolerance``).
MAX_SLACK = 5.0

#: What the two steering actions may command: a change of the steered ``κ``, or ``κ`` itself.
STEER_MODES = ("increment", "target")

#: The ``shaping`` values and the potential each one adds.
SHAPING_KINDS = {False: "", True: "raster", "raster": "raster", "field": "field"}


def _shaping_kind(shaping: Any) -> str:
    """``""``, ``"raster"`` or ``"field"`` for a ``shaping`` argument (``True`` is the raster)."""
    if isinstance(shaping, bool | str) and shaping in SHAPING_KINDS:
        return SHAPING_KINDS[shaping]
    raise ConfigError(f"shaping must be false, true, 'raster' or 'field', got {shaping!r}")


def _check_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    options = dict(options or {})
    unknown = sorted(set(options) - {"target"})
    if unknown:
        raise ConfigError(f"unknown reset option {unknown[0]!r}; use 'target'")
    return options


class FailureRates:
    """Per raster cell of a tank, a running failure rate of the episodes aimed at it.

    Each ended episode moves its target cell's rate by ``rate`` towards 1 (not a success) or 0
    (a success). :meth:`weight` turns the rates into the acceptance probabilities with which
    ``failure_bias`` draws targets: cells never aimed at count as hard (weight 1), the others
    in proportion to their rate against the hardest seen (at least ``floor`` of it), so targets
    come up more often where the policy fails more, wherever that is.
    """

    def __init__(self, n_cells: int, rate: float = 0.02, floor: float = 0.05) -> None:
        self.rate, self.floor = float(rate), float(floor)
        self.fail = np.ones(n_cells)
        self.seen = np.zeros(n_cells, dtype=bool)
        #: Episodes recorded.
        self.count = 0

    def record(self, cells: ArrayLike, success: ArrayLike) -> None:
        """Record ended episodes: their target cells and whether each was a success."""
        for c, ok in zip(np.asarray(cells).tolist(), np.asarray(success).tolist()):
            self.fail[c] += self.rate * (float(not ok) - self.fail[c])
            self.seen[c] = True
            self.count += 1

    def weight(self, cells: ArrayLike) -> NDArray[np.float64]:
        """Acceptance probabilities in ``[floor, 1]`` of targets in ``cells``."""
        c = np.asarray(cells)
        hardest = max(float(self.fail[self.seen].max()) if self.seen.any() else 1.0, 1e-9)
        w = np.maximum(self.fail[c] / hardest, self.floor)
        return np.where(self.seen[c], np.minimum(w, 1.0), 1.0)


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
        shaping: bool | str,
        guide: bool = False,
        detour_bias: float = 0.0,
        steer: str = "increment",
        step_cost: float = 0.0,
        corner_bias: float = 0.0,
        slack: float = 0.0,
        failure_bias: float = 0.0,
        near_goal: bool = False,
    ) -> None:
        self.tank = load_tank(tank)
        if not isinstance(near_goal, bool | np.bool_):
            raise ConfigError(f"near_goal must be true or false, got {near_goal!r}")
        if steer not in STEER_MODES:
            raise ConfigError(f"steer must be 'increment' or 'target', got {steer!r}")
        shaping = _shaping_kind(shaping)
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
        if not (
            isinstance(slack, int | float)
            and not isinstance(slack, bool)
            and 0 <= slack < min(success_tolerance, MAX_SLACK)
        ):
            raise ConfigError(
                f"slack must be in [0, {MAX_SLACK:g}) cm and below success_tolerance, got {slack!r}"
            )
        self.slack = float(slack)
        if not 0 <= margin < 20 or not 0 <= target_clearance < 100:
            raise ConfigError("margin must be in [0, 20) cm and target_clearance in [0, 100) cm")
        if samples_per_section < 2:
            raise ConfigError(f"samples_per_section must be at least 2, got {samples_per_section}")
        if not 0 <= detour_bias <= 1:
            raise ConfigError(f"detour_bias must be in [0, 1], got {detour_bias}")
        if (detour_bias > 0 or shaping) and self.tank.cell_size is None:
            raise ConfigError("detour_bias and shaping need a tank with a raster (cell_size)")
        self.detour_bias = float(detour_bias)
        for name, value in (("corner_bias", corner_bias), ("failure_bias", failure_bias)):
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not (number and 0 <= value <= 1):
                raise ConfigError(f"{name} must be in [0, 1], got {value!r}")
            if value > 0 and detour_bias > 0:
                raise ConfigError(f"give detour_bias or {name}, not both")
        self.corner_bias = float(corner_bias)
        if failure_bias > 0 and self.tank.cell_size is None:
            raise ConfigError("failure_bias needs a tank with a raster (cell_size)")
        self.failure_bias = float(failure_bias)
        #: The failure rates ``failure_bias`` draws by (None without it).
        self.failures = FailureRates(self.tank.raster.n_cells) if failure_bias > 0 else None
        if not (
            isinstance(step_cost, int | float)
            and not isinstance(step_cost, bool)
            and 0 <= step_cost <= MAX_STEP_COST
        ):
            raise ConfigError(f"step_cost must be in [0, {MAX_STEP_COST:g}], got {step_cost!r}")
        self.step_cost = float(step_cost)
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
            margin + self.slack,
            success_tolerance - self.slack,
            shaping,
            guide,
            steer,
            near_goal,
        )
        self.start_tip = np.array([0.0, 0.0, float(start_height)])
        self.fixed_target = None if target is None else self._check_target(target)

    def _draw_targets(self, rngs: Sequence[np.random.Generator]) -> NDArray[np.float64]:
        """One target per generator (:func:`~aftir_rl.envs.ftl.fields.draw_targets`)."""
        if self.failures is not None:
            biased, weight = self.failure_bias, self._failure_weight
        elif self.detour_bias > 0:
            biased, weight = self.detour_bias, self._detour_weight
        else:
            biased, weight = 0.0, None
        return draw_targets(
            rngs,
            self.tank,
            self.region,
            self.target_clearance,
            self.start_tip,
            biased,
            weight,
            self.corner_bias,
        )

    def _failure_weight(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`FailureRates.weight` of the points' raster cells."""
        assert self.failures is not None
        return self.failures.weight(self.tank.raster.cell_indices(points))

    def _record_outcomes(self, targets: NDArray[np.float64], success: ArrayLike) -> None:
        """Give ended episodes (their targets and successes) to :attr:`failures`, if kept."""
        if self.failures is not None and len(targets):
            self.failures.record(self.tank.raster.cell_indices(targets), success)

    def _detour_weight(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(1 + e) / (1 + e_max)``: ``e`` the raster detour [cells] from the start's cell."""
        raster = self.tank.raster
        row = raster_detour_table(self.tank)[raster.cell_indices(self.start_tip)]
        return (1.0 + row[raster.cell_indices(points)]) / (1.0 + row.max())

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

    def _obs_dict(self, rows: NDArray[np.int64] | None = None) -> dict[str, NDArray[np.float32]]:
        """The observations of every env (or of ``rows``) as the observation space holds them."""
        b = self.batch
        tip, target = (b.tip, b.target) if rows is None else (b.tip[rows], b.target[rows])
        return {
            "observation": b.observation(rows),
            "achieved_goal": self._goal_clip(tip),  # type: ignore[attr-defined]
            "desired_goal": target.astype(np.float32),
        }

    def _check_action(self, action: Any, shape: tuple[int, ...] | None) -> NDArray[np.float64]:
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != shape or not np.isfinite(a).all():
            raise InvalidActionError(
                f"invalid action of shape {a.shape}: expected {shape} finite values in [-1, 1]"
            )
        return np.minimum(np.maximum(a, -1.0), 1.0)
