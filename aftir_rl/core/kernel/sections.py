"""Compiled kernels of the follow-the-leader planner: sections, tips, closing and clearances.

Each computes in one compiled loop what the planner (:mod:`aftir_rl.planning.ftl`) defines,
tested against numpy in ``tests/planning/test_route_kernels.py``: a new route section from every
beam state (:func:`extend`), route tips (:func:`tip_of`; of a joint vector and its Jacobian,
for the posture chain: :func:`joint_tip_jacobian`), closing routes on a target by damped
least squares (:func:`close`) and the exact smallest clearance of many backbones
(:func:`min_clearance`, :func:`postures_min_clearance`, pruned by the clearance grid as the env's
step is). The deployment's kernels are in :mod:`.deployment`.

numba caches a function by its own file only: after editing :mod:`.geometry`, clear the caches
(``make clean``) so these kernels recompile against it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.geometry import fk_row, grid_value, least_distance, rotate, sdf
from aftir_rl.core.robot import SMALL

__all__ = [
    "clip_bend",
    "clearance_at",
    "min_clearance",
    "postures_min_clearance",
    "posture_verdict",
    "postures_clear",
    "extend",
    "chain",
    "tip_of",
    "joint_tip",
    "joint_tip_jacobian",
    "close",
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
    return least_distance(points, -math.inf, np.empty(points.shape[0]), tank)


@njit(cache=True, parallel=True)
def postures_min_clearance(
    dis: NDArray[np.float64],
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: int,
    tank: KernelTank,
) -> float:
    """The exact smallest signed distance [cm] of the backbones of postures ``(T,), (T, N)``.

    Each posture sampled ``samples`` times per section (:func:`~.geometry.fk_row`); the postures
    are independent: one thread each.
    """
    entries = theta.shape[0]
    best = np.full(entries, math.inf)
    for t in prange(entries):
        points = np.empty((theta.shape[1] * samples + 1, 3))
        rot = np.empty((3, 3))
        fk_row(dis[t], theta[t], phi[t], section_length, samples, rot, points)
        best[t] = min_clearance(points, tank)
    return best.min() if entries else math.inf


@njit(cache=True, parallel=True)
def postures_clear(
    points: NDArray[np.float64], limit: float, tank: KernelTank, out: NDArray[np.bool_]
) -> None:
    """``out[b]``: every point ``points[b] (P, 3)`` is farther than ``limit`` from the tank.

    The grid's bound decides where it can; the exact distance elsewhere, until a point fails.
    """
    for b in prange(points.shape[0]):
        out[b] = True
        for p in range(points.shape[1]):
            if clearance_at(points[b, p, 0], points[b, p, 1], points[b, p, 2], tank,
                            limit + 1e-9) <= limit:  # fmt: skip
                out[b] = False
                break


@njit(cache=True)
def posture_verdict(
    dis: float,
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: tuple[int, int],
    frame: NDArray[np.float64],
    bounds: tuple[float, float],
    tank: KernelTank,
    points: NDArray[np.float64],
) -> int:
    """One posture's backbone into ``points``, and what the samples alone decide about contact.

    ``samples``: samples per section, and the stride of those the panel rule reads.
    ``frame``: the panel's centre and radius, then the box's corners ``x0, y0, x1, y1, z1``.
    ``-1``: a sample below the panel's centre lies outside its radius (the panel rule), or a
    sample inside the box, higher than ``bounds[0]`` above the floor, is nearer the tank than
    ``bounds[0]`` (exact signed distance); ``1``: every sample is farther than ``bounds[1]``;
    ``0``: neither, so the body must be checked.
    """
    rot = np.empty((3, 3))
    fk_row(dis, theta, phi, section_length, samples[0], rot, points)
    touch, clear = bounds
    for p in range(points.shape[0]):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        if z < frame[2]:
            if p % samples[1]:
                continue
            if math.sqrt((x - frame[0]) ** 2 + (y - frame[1]) ** 2) > frame[3] + 1e-9:
                return -1
        elif frame[4] < x < frame[6] and frame[5] < y < frame[7] and z < frame[8]:
            if z > frame[2] + touch and clearance_at(x, y, z, tank, touch) < touch:
                return -1
    return 1 if min_clearance(points, tank) > clear else 0


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
            ok, cost, px, py, pz = allowed[b], 0.0, pos[b, 0], pos[b, 1], pos[b, 2]
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
            out_ok[i], out_cost[i] = ok, cost
            out_pos[i, 0], out_pos[i, 1], out_pos[i, 2] = px, py, pz
            out_rot[i] = r
            rotate(out_rot[i], th, cp, sp)


@njit(cache=True, inline="always")
def _arc_step(
    th: float, cp: float, sp: float, l: float, r: NDArray[np.float64], x: float, y: float, z: float
) -> tuple[float, float, float]:
    """The end of one section bent by ``θ`` in the plane at ``φ`` (given as cos, sin).

    It starts at ``(x, y, z)`` in frame ``r``; ``r`` turns to its end rotation (in place).
    """
    lx, ly, lz = arc_point(th, cp, sp, l)
    x += r[0, 0] * lx + r[0, 1] * ly + r[0, 2] * lz
    y += r[1, 0] * lx + r[1, 1] * ly + r[1, 2] * lz
    z += r[2, 0] * lx + r[2, 1] * ly + r[2, 2] * lz
    rotate(r, th, cp, sp)
    return x, y, z


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
        x, y, z = _arc_step(th, math.cos(ph), math.sin(ph), l, r, x, y, z)
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
def joint_tip(
    x: NDArray[np.float64], l: float, r: NDArray[np.float64]
) -> tuple[float, float, float]:
    """The tip [cm] of the joint vector ``x = (dis, θ_1..θ_N, φ_1..φ_N)``; ``r (3, 3)`` scratch."""
    n = (x.shape[0] - 1) // 2
    r[:] = 0.0
    r[0, 0], r[1, 1], r[2, 2] = 1.0, 1.0, 1.0
    px, py, pz = 0.0, 0.0, x[0]
    for j in range(n):
        ph = x[1 + n + j]
        px, py, pz = _arc_step(x[1 + j], math.cos(ph), math.sin(ph), l, r, px, py, pz)
    return px, py, pz


@njit(cache=True)
def joint_tip_jacobian(
    x: NDArray[np.float64], l: float, h: float, tip: NDArray[np.float64], jac: NDArray[np.float64]
) -> None:
    """The tip into ``tip (3,)`` and its Jacobian by central differences into ``jac (3, P)``.

    What :func:`~aftir_rl.core.robot.tip_jacobian` computes with numpy, in one compiled loop.
    """
    r = np.empty((3, 3))
    y = x.copy()
    tip[0], tip[1], tip[2] = joint_tip(x, l, r)
    for c in range(x.shape[0]):
        y[c] = x[c] + h
        ax, ay, az = joint_tip(y, l, r)
        y[c] = x[c] - h
        bx, by, bz = joint_tip(y, l, r)
        y[c] = x[c]
        jac[0, c] = (ax - bx) / (2 * h)
        jac[1, c] = (ay - by) / (2 * h)
        jac[2, c] = (az - bz) / (2 * h)


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


@njit(cache=True, parallel=True)
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
    ``ok`` where it ends within 1e-6 cm. The routes are independent: one thread each.
    """
    m = kappa.shape[1]
    j0 = max(0, m - free)
    nk = 2 * (m - j0)
    lead_weight = 1.0 if free_lead else 0.0
    for c in prange(kappa.shape[0]):
        jac, err, dk = np.empty((3, nk)), np.empty(3), np.empty(nk)
        r, r0 = np.empty((3, 3)), np.empty((3, 3))
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
