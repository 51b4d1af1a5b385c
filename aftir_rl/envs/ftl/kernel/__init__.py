"""Compiled kernels (numba) of ``AFTIR-ArmFTL-v0``'s step that only the env needs.

The observation vector, the guide's columns and the reward (:mod:`.observation`), the step's
shift-and-copy advance (:mod:`.step`) and the raster's all-pairs distances for the shaping
(:mod:`.raster`, tested against one BFS per cell); the geometry they share with the planner is
in :mod:`aftir_rl.core.kernel`. The step's kernels are tested equal to the numpy definition of
:class:`~aftir_rl.envs.ftl.state.FTLBatch` (``tests/envs/test_ftl_kernel.py``). See
docs/envs/armftl.md.
"""

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
    "advance",
    "goal_reward",
    "guide_columns",
    "observation",
]
