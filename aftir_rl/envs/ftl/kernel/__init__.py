"""Compiled kernels (numba) of ``AFTIR-ArmFTL-v0``'s step: one loop per arm, no temporaries.

They compute what :class:`~aftir_rl.envs.ftl.state.FTLBatch` defines with numpy, per arm in
one compiled loop, and are tested equal to those definitions (``tests/envs/test_ftl_kernel.py``).
By concern: :mod:`.kinematics` (forward kinematics, steering frames, shift-and-copy),
:mod:`.clearance` (the tank's signed distance and clearance grids, usable targets),
:mod:`.guide` (the guide field's queries) and :mod:`.observation` (observation and reward).
Compiled on first use and cached beside the files (``cache=True``). See docs/envs/armftl.md.
"""

from aftir_rl.envs.ftl.kernel.clearance import KernelTank, refresh, sdf, usable
from aftir_rl.envs.ftl.kernel.guide import guide_columns, guide_query, lookahead
from aftir_rl.envs.ftl.kernel.kinematics import advance, fk_points, steering_frames
from aftir_rl.envs.ftl.kernel.observation import (
    CONTACT_PENALTY,
    OBS_LIMIT,
    PROGRESS_PER_CM,
    SUCCESS_REWARD,
    goal_reward,
    observation,
)

__all__ = [
    "CONTACT_PENALTY",
    "OBS_LIMIT",
    "PROGRESS_PER_CM",
    "SUCCESS_REWARD",
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
