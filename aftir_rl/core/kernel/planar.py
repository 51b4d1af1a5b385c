"""Compiled kernels of the posture search in the bending plane: tips, MDS and clearance.

What :mod:`aftir_rl.planning.posture.planar` defines in numpy (the arm with every ``φ_i`` equal,
a point ``(ρ, z)`` in its plane), one loop per candidate posture: the tips (:func:`planar_tips`),
the distance summation to the reference segment (:func:`planar_mds`) and the search's
feasibility check in a frame of the tank (:func:`planar_clear`, the panel rule and the exact
clearance, pruned by the clearance grid). Tested equal to numpy in
``tests/planning/test_posture_kernels.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.sections import clearance_at

__all__ = ["planar_tips", "planar_tips_serial", "planar_mds", "planar_clear"]


@njit(cache=True, inline="always")
def _half_sinc(b: float) -> float:
    """``sin(b/2) / (b/2)``, its series below ``|b| = 1e-4``."""
    if abs(b) < 1e-4:
        return 1.0 - b * b / 24.0
    return math.sin(0.5 * b) / (0.5 * b)


@njit(cache=True, inline="always")
def _tip(theta: NDArray[np.float64], b: int, l: float) -> tuple[float, float]:
    """Tip ``(ρ, z)`` of the planar arm ``theta[b]`` based at the origin."""
    heading, r, h = 0.0, 0.0, 0.0
    for i in range(theta.shape[1]):
        th = theta[b, i]
        step = l * _half_sinc(th)
        mid = heading + 0.5 * th
        r += step * math.sin(mid)
        h += step * math.cos(mid)
        heading += th
    return r, h


@njit(cache=True, parallel=True)
def planar_tips(
    theta: NDArray[np.float64], l: float, rho: NDArray[np.float64], z: NDArray[np.float64]
) -> None:
    """Tips ``(ρ, z)`` of planar arms ``theta (B, N)`` based at the origin, into ``rho, z (B,)``.

    The arms spread over the cores; :func:`planar_tips_serial` for a few (a refinement's).
    """
    for b in prange(theta.shape[0]):
        rho[b], z[b] = _tip(theta, b, l)


@njit(cache=True)
def planar_tips_serial(
    theta: NDArray[np.float64], l: float, rho: NDArray[np.float64], z: NDArray[np.float64]
) -> None:
    """:func:`planar_tips` in one thread (starting threads costs more for a few arms)."""
    for b in range(theta.shape[0]):
        rho[b], z[b] = _tip(theta, b, l)


@njit(cache=True, parallel=True)
def planar_mds(
    theta: NDArray[np.float64],
    dis: NDArray[np.float64],
    l: float,
    k: int,
    end: tuple[float, float],
    out: NDArray[np.float64],
) -> None:
    """Distance summation of planar arms' ``k`` points a section (and base) to ``0 → end``.

    Arm ``b`` is based at ``(0, dis[b])``; ``out (B,)``.
    """
    ex, ez = end
    length2 = ex * ex + ez * ez
    for b in prange(theta.shape[0]):
        total = _segment_distance(0.0, dis[b], ex, ez, length2)
        heading, r0, z0 = 0.0, 0.0, dis[b]
        for i in range(theta.shape[1]):
            th = theta[b, i]
            for j in range(1, k + 1):
                bend = th * (j / k)
                step = l * (j / k) * _half_sinc(bend)
                mid = heading + 0.5 * bend
                total += _segment_distance(
                    r0 + step * math.sin(mid), z0 + step * math.cos(mid), ex, ez, length2
                )
            step = l * _half_sinc(th)
            r0 += step * math.sin(heading + 0.5 * th)
            z0 += step * math.cos(heading + 0.5 * th)
            heading += th
        out[b] = total


@njit(cache=True, inline="always")
def _segment_distance(px: float, pz: float, ex: float, ez: float, length2: float) -> float:
    """Distance of ``(px, pz)`` to the segment from the origin to ``(ex, ez)``."""
    if length2 == 0.0:
        return math.hypot(px, pz)
    t = min(max((px * ex + pz * ez) / length2, 0.0), 1.0)
    return math.hypot(px - t * ex, pz - t * ez)


@njit(cache=True, parallel=True)
def planar_clear(
    theta: NDArray[np.float64],
    dis: NDArray[np.float64],
    l: float,
    k: int,
    frame: tuple[float, NDArray[np.float64], NDArray[np.float64]],
    panel: tuple[float, float, float, float],
    tank: KernelTank,
    limit: float,
    out: NDArray[np.bool_],
) -> None:
    """Whether each planar arm, put in 3D, keeps every point farther than ``limit`` [cm].

    Arm ``b`` (``theta[b]``, based at ``(0, dis[b])`` in its plane, ``k`` points a section and
    the base) lies in the plane of bearing ``ψ``; ``frame`` is ``(ψ, R, o)``: a point is
    ``R (ρ cos ψ, ρ sin ψ, z) + o``. ``panel`` is the panel's centre and radius (a negative
    radius: no panel rule): no point below the panel outside that radius.
    """
    psi, rot, origin = frame
    cx, cy, cz, radius = panel
    cp, sp = math.cos(psi), math.sin(psi)
    exact_below = limit + 1e-6  # the grid's value is returned only where it is above this
    for b in prange(theta.shape[0]):
        heading, r0, z0 = 0.0, 0.0, dis[b]
        ok = _point_clear(0.0, z0, (cp, sp), rot, origin, panel, tank, limit, exact_below)
        for i in range(theta.shape[1]):
            if not ok:
                break
            th = theta[b, i]
            for j in range(1, k + 1):
                bend = th * (j / k)
                step = l * (j / k) * _half_sinc(bend)
                mid = heading + 0.5 * bend
                r, h = r0 + step * math.sin(mid), z0 + step * math.cos(mid)
                if not _point_clear(r, h, (cp, sp), rot, origin, panel, tank, limit, exact_below):
                    ok = False
                    break
            step = l * _half_sinc(th)
            r0 += step * math.sin(heading + 0.5 * th)
            z0 += step * math.cos(heading + 0.5 * th)
            heading += th
        out[b] = ok


@njit(cache=True, inline="always")
def _point_clear(
    r: float,
    h: float,
    bearing: tuple[float, float],
    rot: NDArray[np.float64],
    origin: NDArray[np.float64],
    panel: tuple[float, float, float, float],
    tank: KernelTank,
    limit: float,
    exact_below: float,
) -> bool:
    """:func:`planar_clear` of one plane point ``(ρ, z)``: the panel rule, then the clearance."""
    lx, ly = r * bearing[0], r * bearing[1]
    x = rot[0, 0] * lx + rot[0, 1] * ly + rot[0, 2] * h + origin[0]
    y = rot[1, 0] * lx + rot[1, 1] * ly + rot[1, 2] * h + origin[1]
    z = rot[2, 0] * lx + rot[2, 1] * ly + rot[2, 2] * h + origin[2]
    cx, cy, cz, radius = panel
    if radius >= 0.0 and z < cz and math.hypot(x - cx, y - cy) > radius + 1e-9:
        return False
    return clearance_at(x, y, z, tank, exact_below) > limit
