"""What the single and the vector ``AFTIR-ArmFTL-v0`` share: the spec applied, targets, spaces.

:class:`FTLTask` is the base class of both envs (:mod:`aftir_rl.envs.ftl.env`): it checks the
options against the tank, builds the batched state (:class:`~aftir_rl.envs.ftl.state.FTLBatch`),
draws and checks targets, and assembles the observation dict and the spaces.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import ConfigError, InvalidActionError, TargetError
from aftir_rl.core.tank import load_tank
from aftir_rl.envs.ftl.reward import GoalReward
from aftir_rl.envs.ftl.spec import FTLSpec
from aftir_rl.envs.ftl.state import FTLBatch, raster_detour_table
from aftir_rl.envs.ftl.targets import FailureRates, bay_region, draw_targets

__all__ = ["FTLTask", "check_options"]


def check_options(
    options: Mapping[str, Any] | None, allowed: tuple[str, ...] = ("target",)
) -> dict[str, Any]:
    """``reset``'s options as a dict; any key not ``allowed`` is a :class:`ConfigError`."""
    options = dict(options or {})
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise ConfigError(f"unknown reset option {unknown[0]!r}; use {' or '.join(allowed)}")
    return options


class FTLTask(GoalReward):
    """The base of :class:`~aftir_rl.envs.ftl.env.ArmFTLEnv` and its vector env.

    :meth:`_configure` applies an :class:`~aftir_rl.envs.ftl.spec.FTLSpec` to ``rows`` arms;
    the attributes it sets (``tank``, ``batch``, ``region``, ``start_tip``,
    ``fixed_target``, ``failures`` and the training options) are the envs' public state.
    """

    def _configure(self, spec: FTLSpec, rows: int) -> None:
        task, reward, training = spec.task, spec.reward, spec.training
        self.tank = load_tank(task.tank)
        arm = self.tank.arm
        n = arm.max_sections if task.n_sections is None else int(task.n_sections)
        if not 1 <= n <= arm.max_sections:
            raise ConfigError(f"n_sections must be in 1..{arm.max_sections}, got {task.n_sections}")
        if task.push_step > arm.section_length:
            raise ConfigError(f"push_step must be at most the section length, got {task.push_step}")
        if not 0 <= task.start_height < arm.section_length:
            raise ConfigError(f"start_height must be in [0, {arm.section_length:g}) cm")
        shaping = reward.shaping_kind
        raster = self.tank.cell_size is not None
        if (training.detour_bias > 0 or shaping) and not raster:
            raise ConfigError("detour_bias and shaping need a tank with a raster (cell_size)")
        if training.failure_bias > 0 and not raster:
            raise ConfigError("failure_bias needs a tank with a raster (cell_size)")
        self.slack, self.step_cost = float(training.slack), float(reward.step_cost)
        self.detour_bias = float(training.detour_bias)
        self.corner_bias = float(training.corner_bias)
        self.failure_bias = float(training.failure_bias)
        #: The failure rates ``failure_bias`` draws by (None without it).
        self.failures = (
            FailureRates(self.tank.raster.n_cells) if training.failure_bias > 0 else None
        )
        self.region = bay_region(self.tank, task.bay)
        self.bay = task.bay
        self.target_clearance = float(training.target_clearance)
        self.batch = FTLBatch(
            self.tank,
            n,
            rows,
            task.samples_per_section,
            task.kappa_step,
            task.push_step,
            task.start_height,
            task.margin + self.slack,
            task.success_tolerance - self.slack,
            shaping,
            task.guide,
            task.steer,
            task.near_goal,
        )
        self.start_tip = np.array([0.0, 0.0, float(task.start_height)])
        self.fixed_target = None if task.target is None else self._check_target(task.target)

    def _draw_targets(self, rngs: Sequence[np.random.Generator]) -> NDArray[np.float64]:
        """One target per generator (:func:`~aftir_rl.envs.ftl.targets.draw_targets`)."""
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

    def _spaces(self) -> tuple[spaces.Box, spaces.Dict]:
        action = spaces.Box(-1.0, 1.0, (3,), np.float32)
        goal = self._goal_space()
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
            "achieved_goal": self._goal_clip(tip),
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
