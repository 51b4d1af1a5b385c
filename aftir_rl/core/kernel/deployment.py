"""Compiled kernels of a follow-the-leader deployment: its FTL deviation and shape fit.

What :func:`~aftir_rl.planning.ftl.model.ftl_deviation` and the between-stage fit of
:func:`~aftir_rl.planning.ftl.model.ftl_motion` define, in one compiled loop each (tested against
numpy in ``tests/planning/test_route_kernels.py``). numba caches a function by its own file
only: after editing :mod:`.geometry`, clear the caches (``make clean``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from aftir_rl.core.kernel.geometry import fk_row

__all__ = ["traced_deviation", "fit_shape"]


@njit(cache=True, parallel=True)
def traced_deviation(
    points: NDArray[np.float64],
    tips: NDArray[np.float64],
    s: NDArray[np.float64],
    back: NDArray[np.float64],
    half_window: int,
    first: int,
) -> tuple[float, float]:
    """:func:`~aftir_rl.planning.ftl.model.ftl_deviation`'s largest and summed distance [cm].

    ``points (T', P, 3)`` of the entries from ``first`` on, of a motion whose tips ``(T, 3)`` are
    at arc lengths ``s (T,)``; sample ``p`` lies ``back[p]`` behind the tip. Each is compared
    with the tip's traced polyline near the entry whose tip passed its arc length, or with the
    panel's axis below the first tip. The entries are independent: one thread each.
    """
    entries = points.shape[0]
    worst_of, total_of = np.zeros(entries), np.zeros(entries)
    for i in prange(entries):
        t, worst, total = first + i, 0.0, 0.0
        for p in range(points.shape[1]):
            px, py, pz = points[i, p, 0], points[i, p, 1], points[i, p, 2]
            u = s[t] - back[p]
            if u <= s[0]:
                d = math.hypot(px, py)
            else:
                centre = np.searchsorted(s, u)
                d = math.inf
                for w in range(-half_window, half_window + 1):
                    a = min(max(centre + w, 0), max(t - 1, 0))
                    b = min(a + 1, t)
                    ax, ay, az = tips[a, 0], tips[a, 1], tips[a, 2]
                    ex, ey, ez = tips[b, 0] - ax, tips[b, 1] - ay, tips[b, 2] - az
                    dot = (px - ax) * ex + (py - ay) * ey + (pz - az) * ez
                    f = min(max(dot / max(ex * ex + ey * ey + ez * ez, 1e-12), 0.0), 1.0)
                    qx, qy, qz = ax + f * ex - px, ay + f * ey - py, az + f * ez - pz
                    d = min(d, math.sqrt(qx * qx + qy * qy + qz * qz))
            worst = max(worst, d)
            total += d
        worst_of[i], total_of[i] = worst, total
    return (worst_of.max() if entries else 0.0), total_of.sum()


@njit(cache=True)
def fit_shape(
    dis: float,
    kappa: NDArray[np.float64],
    first_free: int,
    goal: NDArray[np.float64],
    weight: NDArray[np.float64],
    l: float,
    per: int,
    iterations: int,
) -> None:
    """:func:`~aftir_rl.planning.ftl.model.fit_shape`'s Gauss-Newton, in place on ``kappa``.

    Moves the bending vectors ``kappa[first_free:]`` so that the body's samples (``per`` a
    section, from the base at height ``dis``) approach ``goal (N·per + 1, 3)``, sample ``p``
    weighted by ``weight[p]``; forward differences of step 1e-6, damping 1e-6.
    """
    n = kappa.shape[0]
    n_points = n * per + 1
    nv = 2 * (n - first_free)
    theta, phi = np.empty(n), np.empty(n)
    base, trial, rot = np.empty((n_points, 3)), np.empty((n_points, 3)), np.empty((3, 3))
    jac, err = np.empty((3 * n_points, nv)), np.empty(3 * n_points)
    for _ in range(iterations):
        _angles(kappa, theta, phi)
        fk_row(dis, theta, phi, l, per, rot, base)
        for p in range(n_points):
            for a in range(3):
                err[3 * p + a] = (goal[p, a] - base[p, a]) * weight[p]
        for v in range(nv):
            row, col = first_free + v // 2, v % 2
            keep = kappa[row, col]
            kappa[row, col] = keep + 1e-6
            _angles(kappa, theta, phi)
            fk_row(dis, theta, phi, l, per, rot, trial)
            kappa[row, col] = keep
            for p in range(n_points):
                for a in range(3):
                    jac[3 * p + a, v] = (trial[p, a] - base[p, a]) * weight[p] / 1e-6
        step = _normal_solve(jac, err, 1e-6)
        for v in range(nv):
            kappa[first_free + v // 2, v % 2] += step[v]
        if np.abs(step).max() < 1e-7:
            break


@njit(cache=True)
def _normal_solve(
    jac: NDArray[np.float64], err: NDArray[np.float64], damping: float
) -> NDArray[np.float64]:
    """``(JᵀJ + damping·I)⁻¹ Jᵀ err`` by Gaussian elimination with partial pivoting (no BLAS)."""
    nv = jac.shape[1]
    a = np.empty((nv, nv + 1))
    for i in range(nv):
        for j in range(i, nv):
            v = 0.0
            for p in range(jac.shape[0]):
                v += jac[p, i] * jac[p, j]
            a[i, j], a[j, i] = v, v
        a[i, i] += damping
        v = 0.0
        for p in range(jac.shape[0]):
            v += jac[p, i] * err[p]
        a[i, nv] = v
    for col in range(nv):
        pivot = col
        for row in range(col + 1, nv):
            if abs(a[row, col]) > abs(a[pivot, col]):
                pivot = row
        if pivot != col:
            for j in range(nv + 1):
                a[col, j], a[pivot, j] = a[pivot, j], a[col, j]
        for row in range(col + 1, nv):
            f = a[row, col] / a[col, col]
            for j in range(col, nv + 1):
                a[row, j] -= f * a[col, j]
    x = np.empty(nv)
    for row in range(nv - 1, -1, -1):
        v = a[row, nv]
        for j in range(row + 1, nv):
            v -= a[row, j] * x[j]
        x[row] = v / a[row, row]
    return x


@njit(cache=True)
def _angles(
    kappa: NDArray[np.float64], theta: NDArray[np.float64], phi: NDArray[np.float64]
) -> None:
    """``θ, φ`` of bending vectors ``(N, 2)``, in place (``φ = 0`` where straight)."""
    for j in range(kappa.shape[0]):
        theta[j] = math.hypot(kappa[j, 0], kappa[j, 1])
        phi[j] = math.atan2(kappa[j, 1], kappa[j, 0]) if theta[j] > 1e-12 else 0.0
