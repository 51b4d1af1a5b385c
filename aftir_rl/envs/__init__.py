"""Gymnasium environments of aftir_rl and their registration."""

from __future__ import annotations

import gymnasium as gym

from aftir_rl.envs.arm_ftl import ArmFTLEnv, ArmFTLVectorEnv
from aftir_rl.envs.tank_goal import TankGoalEnv
from aftir_rl.envs.tank_grid import Action, TankGridEnv

__all__ = [
    "Action",
    "TankGridEnv",
    "TankGoalEnv",
    "ArmFTLEnv",
    "ArmFTLVectorEnv",
    "ENV_IDS",
    "register_envs",
]

#: Every environment id registered by :func:`register_envs`.
ENV_IDS: tuple[str, ...] = (
    "AFTIR-Tank-v0",
    "AFTIR-TankGoal-v0",
    "AFTIR-Arm-v0",
    "AFTIR-ArmReach-v0",
    "AFTIR-ArmFull-v0",
    "AFTIR-ArmFTL-v0",
)

#: Bay-1 reach task: targets in front of the panel that 2 sections reach, drawn per episode.
REACH_REGION = ((-40.0, -40.0, 20.0), (60.0, 40.0, 90.0))


def register_envs() -> None:
    """Register the aftir_rl environments with Gymnasium (idempotent).

    Runs at ``import aftir_rl``; Gymnasium 1.x no longer reads pyproject entry points, and
    ``gym.make("aftir_rl:AFTIR-Tank-v0")`` imports ``aftir_rl`` first, which is what subprocess
    vector envs rely on.
    """
    if "AFTIR-Tank-v0" not in gym.registry:
        gym.register(
            id="AFTIR-Tank-v0",
            entry_point="aftir_rl.envs.tank_grid:TankGridEnv",
            max_episode_steps=500,
        )
    if "AFTIR-TankGoal-v0" not in gym.registry:
        gym.register(
            id="AFTIR-TankGoal-v0",
            entry_point="aftir_rl.envs.tank_goal:TankGoalEnv",
            max_episode_steps=100,
        )
    if "AFTIR-Arm-v0" not in gym.registry:
        gym.register(
            id="AFTIR-Arm-v0",
            entry_point="aftir_rl.envs.arm:ArmEnv",
            max_episode_steps=300,
            kwargs={"n_sections": 4},
        )
    if "AFTIR-ArmReach-v0" not in gym.registry:
        gym.register(
            id="AFTIR-ArmReach-v0",
            entry_point="aftir_rl.envs.arm:ArmEnv",
            max_episode_steps=100,
            kwargs={"n_sections": 2, "target_region": REACH_REGION},
        )
    if "AFTIR-ArmFull-v0" not in gym.registry:
        gym.register(
            id="AFTIR-ArmFull-v0",
            entry_point="aftir_rl.envs.arm:ArmEnv",
            max_episode_steps=300,
            kwargs={"n_sections": 12, "free_targets": True},
        )
    if "AFTIR-ArmFTL-v0" not in gym.registry:
        gym.register(
            id="AFTIR-ArmFTL-v0",
            entry_point="aftir_rl.envs.arm_ftl:ArmFTLEnv",
            vector_entry_point="aftir_rl.envs.arm_ftl:ArmFTLVectorEnv",
            max_episode_steps=300,
        )
