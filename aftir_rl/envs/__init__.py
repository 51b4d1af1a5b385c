"""Gymnasium environments of aftir_rl: the grid worlds, the arm envs and the FTL family.

The env classes load on first use (``from aftir_rl.envs import ArmFTLEnv`` or ``gym.make``), so
``import aftir_rl`` registers the ids without importing numba or python-fcl.
"""

from __future__ import annotations

import importlib
from typing import Any

from aftir_rl.envs.registration import ENV_IDS, register_envs

__all__ = [
    "Action",
    "TankGridEnv",
    "TankGoalEnv",
    "ArmEnv",
    "ArmFTLEnv",
    "ArmFTLVectorEnv",
    "ENV_IDS",
    "register_envs",
]

_LAZY = {
    "Action": "aftir_rl.envs.tank_grid",
    "TankGridEnv": "aftir_rl.envs.tank_grid",
    "TankGoalEnv": "aftir_rl.envs.tank_goal",
    "ArmEnv": "aftir_rl.envs.arm",
    "ArmFTLEnv": "aftir_rl.envs.ftl.env",
    "ArmFTLVectorEnv": "aftir_rl.envs.ftl.env",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
