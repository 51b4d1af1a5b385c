"""The arm's clearance along its whole backbone, not only at its samples: a contact rule to trust.

The signed distance is 1-Lipschitz and the backbone between two samples is an arc of length
``h``, so every point of it lies at least ``min(a, b, (a + b − h) / 2)`` from the tank, where
``a`` and ``b`` are the samples' distances. Where that bound does not clear the threshold, the
arc is halved (the distance at its middle, exact), down to arcs of :data:`FINEST` [cm]: a dip
below the threshold is missed by less than half of that, and an arc still undecided there counts
as one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelArms, KernelTank
from aftir_rl.core.kernel.geometry import grid_value, rotate, sdf
from aftir_rl.core.kernel.sections import arc_point

__all__ = ["FINEST", "surface_clearance"]

#: The shortest arc [cm] the halving goes down to.
FINEST = 0.01


@njit(cache=True)
def _backbone_point(
    base: tuple[float, float],
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    arc: float,
    rot: NDArray[np.float64],
) -> tuple[float, float, float]:
    """The backbone's point ``arc`` [cm] from the base ``(0, 0, base[0])``; sections ``base[1]``."""
    l = base[1]
    rot[:] = 0.0
    rot[0, 0], rot[1, 1], rot[2, 2] = 1.0, 1.0, 1.0
    ox, oy, oz = 0.0, 0.0, base[0]
    for i in range(theta.shape[0]):
        t = min(arc, l)
        cp, sp = math.cos(phi[i]), math.sin(phi[i])
        lx, ly, lz = arc_point(theta[i] * t / l, cp, sp, t)
        ox += rot[0, 0] * lx + rot[0, 1] * ly + rot[0, 2] * lz
        oy += rot[1, 0] * lx + rot[1, 1] * ly + rot[1, 2] * lz
        oz += rot[2, 0] * lx + rot[2, 1] * ly + rot[2, 2] * lz
        arc -= l
        if arc <= 0.0:
            break
        rotate(rot, theta[i], cp, sp)
    return ox, oy, oz


@njit(cache=True)
def _arc_bound(
    ends: tuple[float, float, float, float],
    threshold: float,
    base: tuple[float, float],
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    deep: tuple[float, float],
    tank: KernelTank,
    rot: NDArray[np.float64],
) -> float:
    """The backbone's distance from the tank between arc lengths ``t0, t1``, distances ``a, b``.

    ``ends = (t0, t1, a, b)``. Returns ``inf`` when every point clears ``threshold``, an exact
    distance below it when a point is nearer, or the bound of an undecided arc of
    :data:`FINEST`. ``deep``: the height at or below which a point counts as the base, and the
    base's distance.
    """
    stack = np.empty((64, 4))
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = ends
    top, undecided = 1, math.inf
    while top > 0:
        top -= 1
        t0, t1, a, b = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        bound = min(min(a, b), 0.5 * (a + b - (t1 - t0)))
        if bound >= threshold:
            continue
        if t1 - t0 <= FINEST or top + 2 > stack.shape[0]:
            undecided = min(undecided, bound)
            continue
        tm = 0.5 * (t0 + t1)
        x, y, z = _backbone_point(base, theta, phi, tm, rot)
        dm = deep[1] if z <= deep[0] else sdf(x, y, z, tank)
        if dm < threshold:
            return dm
        stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = t0, tm, a, dm
        stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2], stack[top + 1, 3] = tm, t1, dm, b
        top += 2
    return undecided


@njit(cache=True)
def surface_clearance(
    rows: NDArray[np.int64],
    arms: KernelArms,
    section_length: float,
    samples: int,
    margins: tuple[float, float, float],
    tank: KernelTank,
    out: NDArray[np.float64],
) -> None:
    """``out[b]``: the arms' surface clearance [cm] as the contact rule reads it, in place.

    After :func:`~.geometry.refresh` (its samples and ``body_clearance``). ``margins``: the
    arm's radius, the margin and the height at or below which a sample counts as the base (as
    ``refresh``'s ``deep``). ``out[b]`` is ``body_clearance[b]`` where that is below the margin
    or every point of the backbone keeps it, else the surface clearance at a point between
    samples that does not (or of an undecided arc): so ``out < margin`` exactly when the
    backbone comes nearer than the margin (up to ``FINEST / 2``).
    """
    radius, margin, deep = margins
    threshold = radius + margin
    h = section_length / samples
    rot = np.empty((3, 3))
    lo, spacing, shape = tank.grid_lo, tank.grid_spacing, tank.grid_shape
    for b in rows:
        out[b] = arms.body_clearance[b]
        if out[b] < margin or out[b] - 0.5 * h >= margin:
            continue  # contact at a sample, or every point within h/2 of one clears the margin
        points, n_points = arms.points[b], arms.points.shape[1]
        base = (points[0, 2], section_length)
        base_distance = sdf(points[0, 0], points[0, 1], points[0, 2], tank)
        lower = np.empty(n_points)
        for p in range(n_points):
            x, y, z = points[p, 0], points[p, 1], points[p, 2]
            if p == 0 or z <= deep:
                lower[p] = base_distance
                continue
            v = grid_value(x, y, z, lo, spacing, shape, tank.grid_offset, tank.grid_values)
            lower[p] = sdf(x, y, z, tank) if math.isnan(v) else v - tank.slack
        for p in range(n_points - 1):
            a, c = lower[p], lower[p + 1]
            if min(min(a, c), 0.5 * (a + c - h)) >= threshold:
                continue
            for q in (p, p + 1):  # the exact distances of this arc's ends
                if q > 0 and points[q, 2] > deep:
                    lower[q] = sdf(points[q, 0], points[q, 1], points[q, 2], tank)
            ends = (p * h, (p + 1) * h, lower[p], lower[p + 1])
            d = _arc_bound(ends, threshold, base, arms.theta[b], arms.phi[b], (deep, base_distance),
                           tank, rot)  # fmt: skip
            out[b] = min(out[b], d - radius)
