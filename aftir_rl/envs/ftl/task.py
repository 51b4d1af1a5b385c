"""The parts of an ``AFTIR-ArmFTL-v0`` env and what its two shells share.

:func:`build_parts` composes an env from its spec: the arm's state
(:class:`~aftir_rl.envs.ftl.state.FTLBatch`), the reward
(:class:`~aftir_rl.envs.ftl.reward.FTLReward`) and the target sampler
(:class:`~aftir_rl.envs.ftl.targets.TargetSampler`), each built from its own spec. The single
and the vector env (:mod:`aftir_rl.envs.ftl.env`) hold the three and step them; the spaces, the
observation dicts and the checks of actions and reset options they share are here too.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError, InvalidActionError
from aftir_rl.envs.ftl.reward import FTLReward
from aftir_rl.envs.ftl.spec import FTLSpec
from aftir_rl.envs.ftl.state import FTLBatch
from aftir_rl.envs.ftl.targets import TargetSampler

__all__ = [
    "build_parts",
    "check_action",
    "check_options",
    "goal_clip",
    "observations",
    "spaces_of",
]

#: What an env's observation dict holds, per key, as arrays of every row (or of some rows).
Observations = dict[str, NDArray[np.float32]]


def build_parts(
    spec: FTLSpec,
    rows: int,
    goal_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> tuple[FTLBatch, FTLReward, TargetSampler]:
    """The state, the reward and the target sampler of ``rows`` arms, each from its spec.

    ``goal_bounds``: the goal space's corners (see :class:`FTLBatch`).
    """
    batch = FTLBatch(spec.task, rows, spec.training.slack, goal_bounds)
    return batch, FTLReward(spec.reward, batch), TargetSampler(batch, spec.task, spec.training)


def spaces_of(batch: FTLBatch) -> tuple[spaces.Box, spaces.Dict]:
    """The action space and the observation space of one row of ``batch``."""
    lo, hi = batch.goal_bounds
    goal = spaces.Box(lo.astype(np.float32), hi.astype(np.float32), (3,), np.float32)
    action = spaces.Box(-1.0, 1.0, (3,), np.float32)
    obs = spaces.Dict(
        {
            "observation": spaces.Box(-10.0, 10.0, (batch.obs_size,), np.float32),
            "achieved_goal": goal,
            "desired_goal": goal,
        }
    )
    return action, obs


def observations(batch: FTLBatch, rows: NDArray[np.int64] | None = None) -> Observations:
    """The observations of every row (or of ``rows``) as the observation space holds them."""
    tip, target = (
        (batch.tip, batch.target) if rows is None else (batch.tip[rows], batch.target[rows])
    )
    return {
        "observation": batch.observation(rows),
        "achieved_goal": goal_clip(batch, tip),
        "desired_goal": target.astype(np.float32),
    }


def goal_clip(batch: FTLBatch, points: NDArray[np.float64]) -> NDArray[np.float32]:
    """Points as the goal space holds them: clipped to its bounds, float32."""
    lo, hi = batch.goal_bounds
    return np.minimum(np.maximum(points, lo), hi).astype(np.float32)


def check_options(
    options: Mapping[str, Any] | None, allowed: tuple[str, ...] = ("target",)
) -> dict[str, Any]:
    """``reset``'s options as a dict; any key not ``allowed`` is a :class:`ConfigError`."""
    options = dict(options or {})
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise ConfigError(f"unknown reset option {unknown[0]!r}; use {' or '.join(allowed)}")
    return options


def check_action(action: object, shape: tuple[int, ...] | None) -> NDArray[np.float64]:
    """``action`` as float64 of ``shape``, clipped to ``[-1, 1]``.

    Raises:
        InvalidActionError: another shape, or a value that is not a finite number.

    """
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != shape or not np.isfinite(a).all():
        raise InvalidActionError(
            f"invalid action of shape {a.shape}: expected {shape} finite values in [-1, 1]"
        )
    return np.minimum(np.maximum(a, -1.0), 1.0)
