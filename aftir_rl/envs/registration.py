"""The ids of this package's environments, their registration, and checking an id read from a file.

Registration uses string entry points, so registering imports nothing but Gymnasium: an env's
module (numba, python-fcl) loads at its first ``gym.make``. An id read from a file must be one
of :data:`ENV_IDS` (bare or prefixed ``aftir_rl:``); Gymnasium would import the module before
the colon of any other, so nothing else is accepted (:func:`registered_env_id`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import gymnasium as gym

from aftir_rl.core.config import shorten
from aftir_rl.core.errors import ConfigError

__all__ = [
    "ARM_FTL",
    "ENV_IDS",
    "PREFIX",
    "REACH_REGION",
    "REGISTRATIONS",
    "ROUTE",
    "ROUTE_IDS",
    "bare_env_id",
    "register_envs",
    "registered_env_id",
]

#: The follow-the-leader arm env (:mod:`aftir_rl.envs.ftl`): the one that takes a tank or pool.
ARM_FTL = "AFTIR-ArmFTL-v0"
#: The route env (:mod:`aftir_rl.envs.ftl.route_env`), its latest version.
ROUTE = "AFTIR-ArmRoute-v1"
#: Every version of the route env, latest first.
ROUTE_IDS = (ROUTE, "AFTIR-ArmRoute-v0")
#: The prefix of an env id that ``gym.make`` imports this package by (``aftir_rl:ID``).
PREFIX = "aftir_rl:"

#: Bay-1 reach task: targets in front of the panel that 2 sections reach, drawn per episode.
REACH_REGION = ((-40.0, -40.0, 20.0), (60.0, 40.0, 90.0))

_ARM = "aftir_rl.envs.arm:ArmEnv"
_FTL = "aftir_rl.envs.ftl.env"
#: id -> :func:`gymnasium.register`'s arguments (string entry points: nothing imported here).
REGISTRATIONS: dict[str, dict[str, Any]] = {
    "AFTIR-Tank-v0": {
        "entry_point": "aftir_rl.envs.tank_grid:TankGridEnv",
        "max_episode_steps": 500,
    },
    "AFTIR-TankGoal-v0": {
        "entry_point": "aftir_rl.envs.tank_goal:TankGoalEnv",
        "max_episode_steps": 100,
    },
    "AFTIR-Arm-v0": {"entry_point": _ARM, "max_episode_steps": 300, "kwargs": {"n_sections": 4}},
    "AFTIR-ArmReach-v0": {
        "entry_point": _ARM,
        "max_episode_steps": 100,
        "kwargs": {"n_sections": 2, "target_region": REACH_REGION},
    },
    "AFTIR-ArmFull-v0": {
        "entry_point": _ARM,
        "max_episode_steps": 300,
        "kwargs": {"n_sections": 12, "free_targets": True},
    },
    ARM_FTL: {
        "entry_point": f"{_FTL}:ArmFTLEnv",
        "vector_entry_point": "aftir_rl.envs.ftl.pool_vector:make_vector_env",
        "max_episode_steps": 300,
    },
    ROUTE: {
        "entry_point": "aftir_rl.envs.ftl.route_env:ArmRouteEnv",
        "max_episode_steps": 30,
    },
    # v0's leads and moves (before the deeper leads and sharper turns of v1)
    "AFTIR-ArmRoute-v0": {
        "entry_point": "aftir_rl.envs.ftl.route_env:ArmRouteEnv",
        "max_episode_steps": 30,
        "kwargs": {"leads": (-20.0, -10.0, 0.0, 15.0, 30.0), "max_change": 0.75},
    },
}

#: Every environment id registered by :func:`register_envs`.
ENV_IDS: tuple[str, ...] = tuple(REGISTRATIONS)


def register_envs() -> None:
    """Register the aftir_rl environments with Gymnasium (idempotent).

    Runs at ``import aftir_rl``; Gymnasium 1.x no longer reads pyproject entry points, and
    ``gym.make("aftir_rl:AFTIR-Tank-v0")`` imports ``aftir_rl`` first, which is what subprocess
    vector envs rely on.
    """
    for env_id, arguments in REGISTRATIONS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, **arguments)


def registered_env_id(value: Any, where: str, allowed: Iterable[str] | None = None) -> str:
    """The bare id of one of this package's environments, from ``value`` read from a file.

    Accepts ``ID`` or ``aftir_rl:ID`` where ``ID`` is in ``allowed`` (default: every id
    :data:`aftir_rl.envs.ENV_IDS` registers). Anything else, a ``module:ID`` that Gymnasium would
    import above all, is a :class:`ConfigError`; nothing is imported.
    """
    ids = tuple(allowed) if allowed is not None else tuple(ENV_IDS)
    if not isinstance(value, str) or len(value) > 200:
        raise ConfigError(f"{where}: env_id must be one of {', '.join(ids)}")
    bare = bare_env_id(value)
    if bare not in ids:
        raise ConfigError(
            f"{where}: env_id {shorten(repr(value), 80)} is not one of {', '.join(ids)} "
            f"(optionally prefixed {PREFIX!r}); no other module is imported"
        )
    return bare


def bare_env_id(env_id: str) -> str:
    """``env_id`` without the :data:`PREFIX` that ``gym.make`` imports this package by."""
    return env_id.removeprefix(PREFIX)
