"""Compiled kernels of the posture search in the bending plane: tips, MDS and clearance.

What :mod:`aftir_rl.planning.posture.planar` defines in numpy (the arm with every ``φ_i`` equal, a
point ``(ρ, z)`` in its plane), one loop per candidate posture: the tips (:func:`planar_tips`; over
a search grid, :func:`planar_grid`), the distance summation to the reference segment
(:func:`planar_mds`), the search's feasibility check in a frame of the tank (:func:`planar_clear`,
the panel rule and the exact clearance, pruned by the clearance grid) and the Gauss–Newton
refinement of a tip's ``ρ`` (:func:`planar_refine`). Tested equal to numpy in
``tests/planning/test_posture_kernels.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.sections import clearance_at

__all__ = [
    "planar_tips",
    "planar_tips_serial",
    "planar_grid",
    "planar_mds",
    "planar_clear",
    "planar_refine",
]


@njit(cache=True, inline="always")
def _half_sinc(b: float) -> float:
    """``sin(b/2) / (b/2)``, its series below ``|b| = 1e-4``."""
    if abs(b) < 1e-4:
        return 1.0 - b * b / 24.0
    return math.sin(0.5 * b) / (0.5 * b)


@njit(cache=True, inline="always")
def _advance(th: float, l: float, start: tuple[float, float, float]) -> tuple[float, float, float]:
    """The next section's base ``(heading, ρ, z)`` after one bending by ``th`` from ``start``."""
    heading, r0, z0 = start
    step = l * _half_sinc(th)
    mid = heading + 0.5 * th
    return heading + th, r0 + step * math.sin(mid), z0 + step * math.cos(mid)


@njit(cache=True, inline="always")
def _chords(
    th: float, k: int, l: float, heading: float
) -> tuple[float, float, float, float, float]:
    """A section bending by ``th`` from ``heading`` as ``k`` equal chords.

    Returns the chord's length, the ``(cos, sin)`` of the turn between chords and the
    ``(sin, cos)`` of the first chord's direction. The points follow each other by
    ``ρ += length · sin``, ``z += length · cos`` and a turn of the direction (:func:`_turn`):
    one sine and cosine a section, not one a point.
    """
    turn = th / k
    mid = heading + 0.5 * turn
    return l / k * _half_sinc(turn), math.cos(turn), math.sin(turn), math.sin(mid), math.cos(mid)


@njit(cache=True, inline="always")
def _turn(s: float, c: float, c_turn: float, s_turn: float) -> tuple[float, float]:
    """``(sin, cos)`` of a direction turned by the angle of ``(c_turn, s_turn)``."""
    return s * c_turn + c * s_turn, c * c_turn - s * s_turn


@njit(cache=True, inline="always")
def _tip(theta: NDArray[np.float64], b: int, l: float) -> tuple[float, float]:
    """Tip ``(ρ, z)`` of the planar arm ``theta[b]`` based at the origin."""
    base = (0.0, 0.0, 0.0)
    for i in range(theta.shape[1]):
        base = _advance(theta[b, i], l, base)
    return base[1], base[2]


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
def planar_grid(
    values: NDArray[np.float64],
    goal: tuple[float, float, float, float],
    l: float,
    dis_range: tuple[float, float],
    radius: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The postures of a search grid whose tip lies within ``radius`` of the target's ``ρ``.

    The grid is every combination of ``values (m, V)`` (angle ``i`` takes ``values[i]``), in
    the order of ``numpy.meshgrid(..., indexing="ij")`` flattened; ``goal`` is ``(ρ, z)`` of the
    target, the end heading (NaN: none) and ``θ_max``. With an end heading the last angle is
    ``heading − Σ`` and must lie within ``±θ_max``. A posture's base rises by ``dis = z − z_tip``,
    which must lie in ``dis_range``. The grid shares its prefixes: a section's end is computed
    once for all the combinations that share the angles before it. The first angle's values
    spread over the cores.

    Returns:
        The kept postures' angles ``(K, N)``, ``dis (K,)`` and ``|ρ_tip − ρ| (K,)``, in grid
        order (``m ≥ 1``).

    """
    m, v = values.shape
    n = m if math.isnan(goal[2]) else m + 1
    block = v ** (m - 1)
    theta = np.empty((v * block, n))
    dis, gap = np.empty(v * block), np.empty(v * block)
    counts = np.zeros(v, dtype=np.int64)
    for first in prange(v):
        out = (theta, dis, gap)
        counts[first] = _grid_block(values, first, goal, l, (dis_range, radius), out)
    count = 0
    for first in range(v):  # close the blocks' gaps, in order
        for r in range(first * block, first * block + counts[first]):
            theta[count], dis[count], gap[count] = theta[r], dis[r], gap[r]
            count += 1
    return theta[:count], dis[:count], gap[:count]


@njit(cache=True)
def _grid_block(
    values: NDArray[np.float64],
    first: int,
    goal: tuple[float, float, float, float],
    l: float,
    bounds: tuple[tuple[float, float], float],
    out: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
) -> int:
    """:func:`planar_grid` of the combinations whose first angle is ``values[0, first]``.

    They are written from row ``first · V^(m−1)`` of ``out``; returns how many are kept.
    """
    rho_t, z_t, heading, tmax = goal
    (dis_lo, dis_hi), radius = bounds
    theta, dis, gap = out
    m, v = values.shape
    has = not math.isnan(heading)
    block = v ** (m - 1)
    count = first * block
    states = np.zeros((m + 1, 3))  # the base (heading, ρ, z) of each section
    digits = np.zeros(m, dtype=np.int64)
    digits[0] = first
    changed = 0
    for _ in range(block):
        for d in range(changed, m):
            start = (states[d, 0], states[d, 1], states[d, 2])
            states[d + 1, 0], states[d + 1, 1], states[d + 1, 2] = _advance(
                values[d, digits[d]], l, start
            )
        end = (states[m, 0], states[m, 1], states[m, 2])
        last = 0.0
        if has:
            last = heading - end[0]
            end = _advance(last, l, end)
        rise = z_t - end[2]
        off = abs(end[1] - rho_t)
        keep = dis_lo <= rise <= dis_hi and off <= radius
        if keep and (not has or abs(last) <= tmax + 1e-12):
            for d in range(m):
                theta[count, d] = values[d, digits[d]]
            if has:
                theta[count, m] = last
            dis[count], gap[count] = rise, off
            count += 1
        changed = m - 1
        while changed > 0 and digits[changed] == v - 1:
            digits[changed] = 0
            changed -= 1
        if changed > 0:
            digits[changed] += 1
    return count - first * block


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

    Arm ``b`` is based at ``(0, dis[b])``; ``out (B,)``; the points by :func:`_chords`.
    """
    ex, ez = end
    length2 = ex * ex + ez * ez
    for b in prange(theta.shape[0]):
        total = _segment_distance(0.0, dis[b], ex, ez, length2)
        base = (0.0, 0.0, dis[b])
        for i in range(theta.shape[1]):
            chord, c_turn, s_turn, s_mid, c_mid = _chords(theta[b, i], k, l, base[0])
            r, h = base[1], base[2]
            for _ in range(k):
                r += chord * s_mid
                h += chord * c_mid
                total += _segment_distance(r, h, ex, ez, length2)
                s_mid, c_mid = _turn(s_mid, c_mid, c_turn, s_turn)
            base = _advance(theta[b, i], l, base)
        out[b] = total


@njit(cache=True, inline="always")
def _segment_distance(px: float, pz: float, ex: float, ez: float, length2: float) -> float:
    """Distance of ``(px, pz)`` to the segment from the origin to ``(ex, ez)``."""
    if length2 == 0.0:
        return math.sqrt(px * px + pz * pz)
    t = min(max((px * ex + pz * ez) / length2, 0.0), 1.0)
    dx, dz = px - t * ex, pz - t * ez
    return math.sqrt(dx * dx + dz * dz)  # not hypot: twice as fast, the same to 1 ulp here


@njit(cache=True, parallel=True)
def planar_clear(
    theta: NDArray[np.float64],
    dis: NDArray[np.float64],
    shape: tuple[float, int],
    frame: tuple[float, NDArray[np.float64], NDArray[np.float64]],
    panel: tuple[float, float, float, float],
    tank: KernelTank,
    limit: float,
    out: NDArray[np.bool_],
) -> None:
    """Whether each planar arm, put in 3D, keeps every point farther than ``limit`` [cm].

    Arm ``b`` (``theta[b]``, based at ``(0, dis[b])`` in its plane; ``shape``: the section
    length ``l`` and ``k`` points a section, and the base) lies in the plane of bearing ``ψ``;
    ``frame`` is ``(ψ, R, o)``: a point is ``R (ρ cos ψ, ρ sin ψ, z) + o``. ``panel`` is the
    panel's centre and radius (a negative radius: no panel rule): no point below the panel
    outside that radius. The points by :func:`_chords`.
    """
    l, k = shape
    psi, rot, origin = frame
    cp, sp = math.cos(psi), math.sin(psi)
    exact_below = limit + 1e-6  # the grid's value is returned only where it is above this
    for b in prange(theta.shape[0]):
        base = (0.0, 0.0, dis[b])
        ok = _point_clear(0.0, dis[b], (cp, sp), rot, origin, panel, tank, limit, exact_below)
        for i in range(theta.shape[1]):
            chord, c_turn, s_turn, s_mid, c_mid = _chords(theta[b, i], k, l, base[0])
            r, h = base[1], base[2]
            for _ in range(k):
                r += chord * s_mid
                h += chord * c_mid
                ok = _point_clear(r, h, (cp, sp), rot, origin, panel, tank, limit, exact_below)
                if not ok:
                    break
                s_mid, c_mid = _turn(s_mid, c_mid, c_turn, s_turn)
            if not ok:
                break
            base = _advance(theta[b, i], l, base)
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


@njit(cache=True)
def _free_rho(x: NDArray[np.float64], heading: float, l: float) -> float:
    """Tip ``ρ`` of the planar arm of angles ``x`` and, unless NaN, a last ``heading − Σx``."""
    base = (0.0, 0.0, 0.0)
    for i in range(x.shape[0]):
        base = _advance(x[i], l, base)
    if not math.isnan(heading):
        base = _advance(heading - base[0], l, base)
    return base[1]


@njit(cache=True)
def planar_refine(
    x: NDArray[np.float64],
    goal: tuple[float, float],
    l: float,
    tmax: float,
    tol: float,
    iterations: int,
    h: float,
) -> bool:
    """:func:`aftir_rl.planning.posture.clipping.gauss_newton` on the tip's ``ρ``, in place.

    ``x``: the searched angles, clipped to ``±tmax`` after each step; ``goal``: ``(ρ wanted,
    end heading or NaN)``; ``h`` the central-difference step. The same steps and stops
    as the numpy version (minimum-norm step, three steps that do not cut the gap by a tenth);
    False where the gradient vanishes.
    """
    rho_goal, heading = goal[0], goal[1]
    m = x.shape[0]
    grad, probe = np.empty(m), x.copy()
    gaps = np.empty(iterations)
    for it in range(iterations):
        error = _free_rho(x, heading, l) - rho_goal
        for j in range(m):
            probe[j] = x[j] + h
            up = _free_rho(probe, heading, l)
            probe[j] = x[j] - h
            grad[j] = (up - _free_rho(probe, heading, l)) / (2 * h)
            probe[j] = x[j]
        gap = abs(error)
        if gap < tol or it >= 3 and gap > 0.9 * gaps[: it - 2].min():
            break
        gaps[it] = gap
        norm2 = 0.0
        for j in range(m):
            norm2 += grad[j] * grad[j]
        if norm2 < 1e-12:
            return False
        for j in range(m):
            x[j] = min(max(x[j] - error * grad[j] / norm2, -tmax), tmax)
            probe[j] = x[j]
    return True
