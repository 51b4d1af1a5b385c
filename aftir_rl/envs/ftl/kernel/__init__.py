"""Compiled kernels (numba) of ``AFTIR-ArmFTL-v0``'s step: one loop per arm, no temporaries.

They compute what :class:`~aftir_rl.envs.ftl.state.FTLBatch` defines with numpy, per arm in
one compiled loop, and are tested equal to those definitions (``tests/envs/test_ftl_kernel.py``).
By concern: :mod:`.geometry` (forward kinematics, shift-and-copy, the tank's signed distance
and the arms' clearance, usable targets), :mod:`.guide` (the guide field's queries) and
:mod:`.observation` (the observation vector, the guide's columns, the reward).
Compiled on first use and cached beside the files (``cache=True``). See docs/envs/armftl.md.
"""

from aftir_rl.envs.ftl.kernel.arrays import KernelArms, KernelTank
from aftir_rl.envs.ftl.kernel.geometry import (
    fk_points,
    refresh,
    sdf,
    steering_frames,
    usable,
)
from aftir_rl.envs.ftl.kernel.guide import Grid, guide_query, lookahead
from aftir_rl.envs.ftl.kernel.observation import (
    CONTACT_PENALTY,
    OBS_LIMIT,
    PROGRESS_PER_CM,
    SUCCESS_REWARD,
    goal_reward,
    guide_columns,
    observation,
)
from aftir_rl.envs.ftl.kernel.step import advance

__all__ = [
    "CONTACT_PENALTY",
    "OBS_LIMIT",
    "PROGRESS_PER_CM",
    "SUCCESS_REWARD",
    "Grid",
    "KernelArms",
    "KernelTank",
    "refresh",
    "sdf",
    "usable",
    "guide_columns",
    "guide_query",
    "lookahead",
    "advance",
    "fk_points",
    "steering_frames",
    "goal_reward",
    "observation",
]
