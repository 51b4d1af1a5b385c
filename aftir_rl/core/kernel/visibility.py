"""What a tip camera sees, compiled: lines of sight marched through the tank's signed distance.

:func:`seen_by_groups` tells, for groups of camera poses (e.g. the poses along one route),
which surface points any pose of the group sees (:class:`~aftir_rl.core.camera.Camera`'s
cone, range and incidence, then a sphere-traced line of sight). The planner's estimate; the
coverage a motion achieves is measured apart by ray casting on the tank's mesh.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.geometry import sdf

__all__ = ["line_of_sight", "seen_by_groups", "SIGHT_HIT", "SIGHT_STOP"]

#: A line of sight that comes this close to a surface [cm] is blocked.
SIGHT_HIT = 0.25
#: It ends this far before the point it looks at [cm] (the point lies on a surface).
SIGHT_STOP = 2.0
#: The most steps of one line of sight (a grazing march ends blocked).
SIGHT_STEPS = 256


@njit(cache=True)
def line_of_sight(
    c: NDArray[np.float64], u: NDArray[np.float64], length: float, tank: KernelTank
) -> bool:
    """Whether the segment from ``c`` along the unit ``u`` clears the tank up to ``length``.

    Sphere tracing: each step advances by the signed distance, which no surface is nearer than.
    """
    t = 0.0
    for _ in range(SIGHT_STEPS):
        if t >= length - SIGHT_STOP:
            return True
        d = sdf(c[0] + t * u[0], c[1] + t * u[1], c[2] + t * u[2], tank)
        if d < SIGHT_HIT:
            return False
        t += d
    return False


@njit(cache=True)
def _sees(
    c: NDArray[np.float64],
    w: NDArray[np.float64],
    s: NDArray[np.float64],
    n: NDArray[np.float64],
    camera: NDArray[np.float64],
    tank: KernelTank,
    u: NDArray[np.float64],
) -> bool:
    """Whether the camera at ``c`` looking along ``w`` sees point ``s`` of normal ``n``."""
    for i in range(3):
        u[i] = s[i] - c[i]
    d = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    if d > camera[1] or d < 1e-9:
        return False
    for i in range(3):
        u[i] /= d
    if u[0] * w[0] + u[1] * w[1] + u[2] * w[2] < camera[0]:
        return False
    facing = -(u[0] * n[0] + u[1] * n[1] + u[2] * n[2])  # cos of the incidence angle
    if facing < camera[2] or facing > camera[3] + 1e-12:
        return False
    return line_of_sight(c, u, d, tank)


@njit(cache=True, parallel=True)
def seen_by_groups(
    poses: NDArray[np.float64],
    looks: NDArray[np.float64],
    starts: NDArray[np.int64],
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    camera: NDArray[np.float64],
    tank: KernelTank,
    out: NDArray[np.bool_],
) -> None:
    """``out[g, j]``: a pose ``starts[g] <= p < starts[g + 1]`` sees point ``j``, in place.

    Poses ``(P, 3)`` looking along the unit ``looks (P, 3)``; points and their unit normals
    (towards the free space) ``(S, 3)``; ``camera`` from :meth:`Camera.cosines`.
    """
    for g in prange(len(starts) - 1):
        u = np.empty(3)
        for j in range(points.shape[0]):
            for p in range(starts[g], starts[g + 1]):
                if _sees(poses[p], looks[p], points[j], normals[j], camera, tank, u):
                    out[g, j] = True
                    break
