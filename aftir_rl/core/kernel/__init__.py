"""Compiled kernels (numba) of the arm's geometry, shared by the planners and the FTL env.

One loop per arm or point, no temporaries. By concern: :mod:`.geometry` (forward kinematics,
shift-and-copy, the tank's signed distance and the arms' clearance, usable targets), :mod:`.guide`
(the guide field: Dijkstra and queries), :mod:`.surface` (the clearance of the whole backbone,
between its samples too), :mod:`.sections` and :mod:`.deployment` (the route search and the
deployment), :mod:`.planar` (the posture search in the bending plane), :mod:`.visibility` (the
tip camera's lines of sight), :mod:`.arrays` (the arrays they read), :mod:`.packing` and
:mod:`.clearance` (a tank packed into those arrays, with its clearance grid). Compiled on first
use and cached beside the files (``cache=True``); each is tested equal to its numpy definition.
"""

from aftir_rl.core.kernel.arrays import KernelArms, KernelTank
from aftir_rl.core.kernel.geometry import (
    fk_points,
    refresh,
    sdf,
    steering_frames,
    usable,
)
from aftir_rl.core.kernel.guide import Grid, descend_field, guide_query, lookahead
from aftir_rl.core.kernel.surface import surface_clearance

__all__ = [
    "Grid",
    "KernelArms",
    "KernelTank",
    "descend_field",
    "fk_points",
    "guide_query",
    "lookahead",
    "refresh",
    "sdf",
    "steering_frames",
    "surface_clearance",
    "usable",
]
