"""Compiled kernels of the follow-the-leader planner: sections, tips, closing and clearances.

Each computes in one compiled loop what the planner (:mod:`aftir_rl.planning.ftl`) defines,
tested against numpy in ``tests/planning/test_route_kernels.py``: a new route section from every
beam state (:func:`extend`), route tips (:func:`tip_of`), closing routes on a target by damped
least squares (:func:`close`), the exact smallest clearance of many backbones
(:func:`min_clearance`, :func:`postures_min_clearance`, pruned by the clearance grid as the env's
step is), the deployment's FTL deviation (:func:`traced_deviation`) and its between-stage shape
fit (:func:`fit_shape`).

numba caches a function by its own file only: after editing :mod:`.geometry`, clear the caches
(``make clean``) so these kernels recompile against it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.geometry import fk_row, grid_value, rotate, sdf
from aftir_rl.core.robot import SMALL

__all__ = [
    "clip_bend",
    "clearance_at",
    "min_clearance",
    "postures_min_clearance",
    "extend",
    "chain",
    "tip_of",
    "close",
    "traced_deviation",
    "fit_shape",
]


@njit(cache=True, inline="always")
def clip_bend(kx: float, ky: float, limit: float) -> tuple[float, float, float, float, float]:
    """A bending vector shortened to ``limit`` [rad]: ``(κx, κy, θ, cos φ, sin φ)``."""
    norm = math.hypot(kx, ky)
    if norm > limit:
        scale = limit / max(norm, 1e-12)
        kx, ky = kx * scale, ky * scale
    theta = math.hypot(kx, ky)
    phi = math.atan2(ky, kx) if theta > 1e-12 else 0.0
    return kx, ky, theta, math.cos(phi), math.sin(phi)


@njit(cache=True, inline="always")
def arc_point(theta: float, cp: float, sp: float, arc: float) -> tuple[float, float, float]:
    """The point ``arc`` [cm] along a section bent by ``θ`` over that arc, in its base frame."""
    h = 0.5 * theta
    sinc_h = 1.0 - h * h / 6.0 if abs(h) < 0.5 * SMALL else math.sin(h) / h
    radial = arc * (h * sinc_h * sinc_h)
    return radial * cp, radial * sp, arc * (sinc_h * math.cos(h))


@njit(cache=True, inline="always")
def clearance_at(x: float, y: float, z: float, tank: KernelTank, exact_below: float) -> float:
    """Signed distance [cm]: exact where it may be below ``exact_below``, else the grid's value.

    The grid's value is within ``tank.slack`` of the exact one, so any answer below
    ``exact_below`` is exact and any other is at least ``exact_below``.
    """
    v = grid_value(x, y, z, tank.grid_lo, tank.grid_spacing, tank.grid_shape,
                   tank.grid_offset, tank.grid_values)  # fmt: skip
    if math.isnan(v) or v - tank.slack < exact_below:
        return sdf(x, y, z, tank)
    return v


@njit(cache=True)
def min_clearance(points: NDArray[np.float64], tank: KernelTank) -> float:
    """The exact smallest signed distance [cm] of points ``(P, 3)`` (grid-pruned)."""
    upper = math.inf
    n = points.shape[0]
    bound = np.empty(n)
    for p in range(n):
        v = grid_value(points[p, 0], points[p, 1], points[p, 2], tank.grid_lo,
                       tank.grid_spacing, tank.grid_shape, tank.grid_offset,
                       tank.grid_values)  # fmt: skip
        bound[p] = v
        if not math.isnan(v):
            upper = min(upper, v + tank.slack)
    best = math.inf
    for p in range(n):
        v = bound[p]
        if math.isnan(v) or v - tank.slack <= upper:
            best = min(best, sdf(points[p, 0], points[p, 1], points[p, 2], tank))
    return best


@njit(cache=True)
def postures_min_clearance(
    dis: NDArray[np.float64],
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: int,
    tank: KernelTank,
) -> float:
    """The exact smallest signed distance [cm] of the backbones of postures ``(T,), (T, N)``.

    Each posture sampled ``samples`` times per section (:func:`~.geometry.fk_row`), one at a time.
    """
    points = np.empty((theta.shape[1] * samples + 1, 3))
    rot = np.empty((3, 3))
    best = math.inf
    for t in range(theta.shape[0]):
        fk_row(dis[t], theta[t], phi[t], section_length, samples, rot, points)
        best = min(best, min_clearance(points, tank))
    return best


@njit(cache=True, parallel=True)
def extend(
    rot: NDArray[np.float64],
    pos: NDArray[np.float64],
    last: NDArray[np.float64],
    allowed: NDArray[np.bool_],
    changes: NDArray[np.float64],
    shape: tuple[float, float, int],
    clearance: tuple[float, float, float, float],
    tank: KernelTank,
    out_kappa: NDArray[np.float64],
    out_rot: NDArray[np.float64],
    out_pos: NDArray[np.float64],
    out_cost: NDArray[np.float64],
    out_ok: NDArray[np.bool_],
) -> None:
    """Every move of every beam state: one new section each, its end frame and clearance cost.

    Row ``b·C + c`` bends by ``clip(last[b] + changes[c])`` from the end frame ``rot[b], pos[b]``
    (``shape``: the joint limit [rad], section length [cm] and samples per section). It is ok
    when ``allowed[b]`` and every sample keeps ``need`` from the tank; its cost is
    ``Σ 1 / max(d − radius − margin, 0.25)`` over the samples (``clearance``: ``need``, the
    arm's radius, the margin and the distance below which ``d`` is exact).
    """
    theta_max, l, k = shape
    need, radius, margin, exact_below = clearance
    n_changes = changes.shape[0]
    for b in prange(rot.shape[0]):  # the states' rows are disjoint: one thread each
        r = rot[b]
        for c in range(n_changes):
            i = b * n_changes + c
            kx, ky, th, cp, sp = clip_bend(
                last[b, 0] + changes[c, 0], last[b, 1] + changes[c, 1], theta_max
            )
            out_kappa[i, 0], out_kappa[i, 1] = kx, ky
            ok, cost = allowed[b], 0.0
            px, py, pz = pos[b, 0], pos[b, 1], pos[b, 2]
            # sample j bends by h_j = j·h₁ (half its angle): sin, cos by the addition formulas
            h1 = 0.5 * th / k
            s1, c1 = math.sin(h1), math.cos(h1)
            sj, cj = 0.0, 1.0
            for j in range(1, k + 1):
                if not ok:
                    break
                sj, cj = sj * c1 + cj * s1, cj * c1 - sj * s1
                h = h1 * j
                sinc_h = 1.0 - h * h / 6.0 if abs(h) < 0.5 * SMALL else sj / h
                arc = l * j / k
                radial = arc * (h * sinc_h * sinc_h)
                lx, ly, lz = radial * cp, radial * sp, arc * (sinc_h * cj)
                px = r[0, 0] * lx + r[0, 1] * ly + r[0, 2] * lz + pos[b, 0]
                py = r[1, 0] * lx + r[1, 1] * ly + r[1, 2] * lz + pos[b, 1]
                pz = r[2, 0] * lx + r[2, 1] * ly + r[2, 2] * lz + pos[b, 2]
                d = clearance_at(px, py, pz, tank, exact_below)
                if d < need:
                    ok = False
                cost += 1.0 / max(d - radius - margin, 0.25)
            out_ok[i] = ok
            out_cost[i] = cost
            out_pos[i, 0], out_pos[i, 1], out_pos[i, 2] = px, py, pz
            out_rot[i] = r
            rotate(out_rot[i], th, cp, sp)


@njit(cache=True)
def chain(
    kappa: NDArray[np.float64],
    first: int,
    stop: int,
    l: float,
    r: NDArray[np.float64],
    start: tuple[float, float, float],
) -> tuple[float, float, float]:
    """The end of sections ``first..stop−1`` bent by ``kappa (M, 2)`` from frame ``r, start``.

    ``r (3, 3)`` ends as the last section's end rotation (in place).
    """
    x, y, z = start
    for j in range(first, stop):
        kx, ky = kappa[j, 0], kappa[j, 1]
        th = math.hypot(kx, ky)
        ph = math.atan2(ky, kx) if th > 1e-12 else 0.0
        cp, sp = math.cos(ph), math.sin(ph)
        lx, ly, lz = arc_point(th, cp, sp, l)
        x += r[0, 0] * lx + r[0, 1] * ly + r[0, 2] * lz
        y += r[1, 0] * lx + r[1, 1] * ly + r[1, 2] * lz
        z += r[2, 0] * lx + r[2, 1] * ly + r[2, 2] * lz
        rotate(r, th, cp, sp)
    return x, y, z


@njit(cache=True)
def tip_of(
    lead: float, kappa: NDArray[np.float64], l: float, r: NDArray[np.float64]
) -> tuple[float, float, float]:
    """The tip [cm] of a route: ``lead`` up the axis, then sections bent by ``kappa (M, 2)``.

    ``r (3, 3)`` is scratch space.
    """
    r[:] = 0.0
    r[0, 0], r[1, 1], r[2, 2] = 1.0, 1.0, 1.0
    return chain(kappa, 0, kappa.shape[0], l, r, (0.0, 0.0, lead))


@njit(cache=True)
def _dls_step(
    jac: NDArray[np.float64],
    err: NDArray[np.float64],
    norm: float,
    l: float,
    lead_weight: float,
    dk: NDArray[np.float64],
) -> float:
    """One bounded damped least-squares step: ``Δκ`` into ``dk (nk,)``, ``Δlead`` returned.

    ``jac (3, nk)``; the lead's column is ``(0, 0, l·lead_weight)``. The 3×3 system by Cramer.
    """
    nk = jac.shape[1]
    damping = (1e-6 if norm > 5 else 1e-8) * l * l
    a = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            v = 0.0
            for c in range(nk):
                v += jac[i, c] * jac[j, c]
            a[i, j] = v
    a[2, 2] += (l * lead_weight) ** 2
    a[0, 0] += damping
    a[1, 1] += damping
    a[2, 2] += damping
    det = (
        a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
        - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
        + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0])
    )
    y = np.empty(3)
    for col in range(3):
        m = a.copy()
        m[0, col], m[1, col], m[2, col] = err[0], err[1], err[2]
        y[col] = (
            m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
            - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
            + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])
        ) / det
    size = 0.0
    for c in range(nk):
        dk[c] = jac[0, c] * y[0] + jac[1, c] * y[1] + jac[2, c] * y[2]
        size += dk[c] * dk[c]
    dlead = l * lead_weight * y[2] * l
    scale = min(min(1.0, 0.3 / max(math.sqrt(size), 1e-12)), 10.0 / max(abs(dlead), 1e-12))
    for c in range(nk):
        dk[c] *= scale
    return dlead * scale


@njit(cache=True)
def close(
    lead: NDArray[np.float64],
    kappa: NDArray[np.float64],
    target: NDArray[np.float64],
    l: float,
    theta_max: float,
    free: int,
    iterations: int,
    lead_lo: NDArray[np.float64],
    lead_hi: NDArray[np.float64],
    free_lead: bool,
    ok: NDArray[np.bool_],
) -> None:
    """:func:`~aftir_rl.planning.ftl.closing.close_batch`, in place on ``lead`` and ``kappa``.

    Per route: damped least squares on its lead and last ``free`` bending vectors, the tip's
    Jacobian by forward differences (step 1e-6), until the tip is within 1e-7 cm of ``target``;
    ``ok`` where it ends within 1e-6 cm.
    """
    m = kappa.shape[1]
    j0 = max(0, m - free)
    nk = 2 * (m - j0)
    jac, err, dk = np.empty((3, nk)), np.empty(3), np.empty(nk)
    r, r0 = np.empty((3, 3)), np.empty((3, 3))
    lead_weight = 1.0 if free_lead else 0.0
    for c in range(kappa.shape[0]):
        kap = kappa[c]
        lead[c] = min(max(lead[c], lead_lo[c]), lead_hi[c])
        # the fixed sections' end frame, once: each tip below chains only the free ones
        r0[:] = 0.0
        r0[0, 0], r0[1, 1], r0[2, 2] = 1.0, 1.0, 1.0
        q0 = chain(kap, 0, j0, l, r0, (0.0, 0.0, 0.0))
        for _ in range(iterations):
            r[:] = r0
            tx, ty, tz = chain(kap, j0, m, l, r, (q0[0], q0[1], q0[2] + lead[c]))
            err[0], err[1], err[2] = target[0] - tx, target[1] - ty, target[2] - tz
            norm = math.sqrt(err[0] ** 2 + err[1] ** 2 + err[2] ** 2)
            if norm < 1e-7:
                break
            for v in range(nk):
                row, col = j0 + v // 2, v % 2
                keep = kap[row, col]
                kap[row, col] = keep + 1e-6
                r[:] = r0
                x, y, z = chain(kap, j0, m, l, r, (q0[0], q0[1], q0[2] + lead[c]))
                kap[row, col] = keep
                jac[0, v], jac[1, v], jac[2, v] = (x - tx) / 1e-6, (y - ty) / 1e-6, (z - tz) / 1e-6
            dlead = _dls_step(jac, err, norm, l, lead_weight, dk)
            for j in range(j0, m):
                kx, ky, _, _, _ = clip_bend(
                    kap[j, 0] + dk[2 * (j - j0)], kap[j, 1] + dk[2 * (j - j0) + 1], theta_max
                )
                kap[j, 0], kap[j, 1] = kx, ky
            lead[c] = min(max(lead[c] + dlead, lead_lo[c]), lead_hi[c])
        tx, ty, tz = tip_of(lead[c], kap, l, r)
        ok[c] = (
            math.sqrt((target[0] - tx) ** 2 + (target[1] - ty) ** 2 + (target[2] - tz) ** 2) < 1e-6
        )


@njit(cache=True)
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
    panel's axis below the first tip.
    """
    worst, total = 0.0, 0.0
    for i in range(points.shape[0]):
        t = first + i
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
    return worst, total


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
