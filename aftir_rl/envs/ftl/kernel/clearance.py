"""The tank's signed distance and clearance grids, compiled: the arms' clearance, usable targets."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aftir_rl.envs.ftl.kernel.kinematics import fk_row

__all__ = ["KernelTank", "sdf", "grid_value", "refresh", "usable_point", "usable"]


class KernelTank(NamedTuple):
    """A tank's signed distance and clearance grids as the arrays the kernels read.

    ``boxes (S, 6)``: centre and half-size; ``cylinders (S, 6)``: the axis's two coordinates
    across, radius, middle and half-length along, and the axis (0, 1, 2); ``spheres (S, 4)``;
    ``walls (11,)``: whether the tank has walls, its box's corners, the panel's centre (x, y)
    and radius, and the height below which solids are skipped (as
    :class:`~aftir_rl.core.tank.distance.TankDistance`). The grids: per grid its corner ``lo (G,
    3)``,
    spacing ``(G,)``, shape ``(G, 3)`` and offset ``(G,)`` into the concatenated values; ``slack``
    bounds a value's distance from the exact one.
    """

    boxes: NDArray[np.float64]
    cylinders: NDArray[np.float64]
    spheres: NDArray[np.float64]
    walls: NDArray[np.float64]
    grid_lo: NDArray[np.float64]
    grid_spacing: NDArray[np.float64]
    grid_shape: NDArray[np.int64]
    grid_offset: NDArray[np.int64]
    grid_values: NDArray[np.float64]
    slack: float


@njit(cache=True)
def sdf(
    x: float,
    y: float,
    z: float,
    boxes: NDArray[np.float64],
    cylinders: NDArray[np.float64],
    spheres: NDArray[np.float64],
    walls: NDArray[np.float64],
) -> float:
    """Signed distance [cm] of one point to the tank (:class:`TankDistance`'s, compiled)."""
    best = math.inf
    if walls[0] == 0.0 or z > walls[10]:
        for i in range(boxes.shape[0]):
            qx = abs(x - boxes[i, 0]) - boxes[i, 3]
            qy = abs(y - boxes[i, 1]) - boxes[i, 4]
            qz = abs(z - boxes[i, 2]) - boxes[i, 5]
            ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
            d = math.sqrt(ox * ox + oy * oy + oz * oz) + min(max(max(qx, qy), qz), 0.0)
            best = min(best, d)
        for i in range(cylinders.shape[0]):
            axis = int(cylinders[i, 5])
            if axis == 0:
                along, c1, c2 = x, y, z
            elif axis == 1:
                along, c1, c2 = y, x, z
            else:
                along, c1, c2 = z, x, y
            radial = math.hypot(c1 - cylinders[i, 0], c2 - cylinders[i, 1]) - cylinders[i, 2]
            axial = abs(along - cylinders[i, 3]) - cylinders[i, 4]
            d = math.hypot(max(radial, 0.0), max(axial, 0.0)) + min(max(radial, axial), 0.0)
            best = min(best, d)
        for i in range(spheres.shape[0]):
            dx, dy, dz = x - spheres[i, 0], y - spheres[i, 1], z - spheres[i, 2]
            best = min(best, math.sqrt(dx * dx + dy * dy + dz * dz) - spheres[i, 3])
    if walls[0] != 0.0:
        side = min(min(x - walls[1], walls[4] - x), min(y - walls[2], walls[5] - y))
        radial = math.hypot(x - walls[7], y - walls[8])
        height = z - walls[3]
        if radial > walls[9]:
            floor = height
        elif height >= 0:
            floor = math.hypot(walls[9] - radial, height)
        else:
            floor = walls[9] - radial
        best = min(best, min(min(side, walls[6] - z), floor))
    return best


@njit(cache=True)
def grid_value(
    x: float,
    y: float,
    z: float,
    lo: NDArray[np.float64],
    spacing: NDArray[np.float64],
    shape: NDArray[np.int64],
    offset: NDArray[np.int64],
    values: NDArray[np.float64],
) -> float:
    """The nearest node's value of the first grid holding the point; NaN outside every grid."""
    for gi in range(lo.shape[0]):
        g = spacing[gi]
        ix = int(np.rint((x - lo[gi, 0]) / g))
        iy = int(np.rint((y - lo[gi, 1]) / g))
        iz = int(np.rint((z - lo[gi, 2]) / g))
        if 0 <= ix < shape[gi, 0] and 0 <= iy < shape[gi, 1] and 0 <= iz < shape[gi, 2]:
            return values[offset[gi] + (ix * shape[gi, 1] + iy) * shape[gi, 2] + iz]
    return math.nan


@njit(cache=True)
def refresh(
    rows: NDArray[np.int64],
    kappa: NDArray[np.float64],
    k: NDArray[np.int64],
    s: NDArray[np.float64],
    section_length: float,
    samples: int,
    radius: float,
    deep: float,
    ray_axes: NDArray[np.float64],
    ray_distances: NDArray[np.float64],
    tank: KernelTank,
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    points: NDArray[np.float64],
    heading: NDArray[np.float64],
    body_clearance: NDArray[np.float64],
    ray_clearance: NDArray[np.float64],
) -> None:
    """Postures, backbone samples, headings and clearances of the arms ``rows``, in place.

    Per row ``b``: ``θ, φ (N,)`` of the FTL posture of route ``kappa[b, :k[b] + 1]`` with the
    tip at arc length ``s[b]``; ``points (N·K + 1, 3)`` from the base at ``(0, 0, s − N·l)``;
    the unit heading of the last sample step; the surface clearance ``min(distance) − radius``
    over the samples above ``deep`` (and the base), exact (grid-pruned); the clearances at
    ``ray_distances`` along the heading and ``ray_axes`` (grid values, exact outside).
    """
    n = kappa.shape[1]
    boxes, cylinders, spheres, walls = tank.boxes, tank.cylinders, tank.spheres, tank.walls
    lo, spacing, shape = tank.grid_lo, tank.grid_spacing, tank.grid_shape
    offset, values, slack = tank.grid_offset, tank.grid_values, tank.slack
    l = section_length
    n_points = n * samples + 1
    bound = np.empty(n_points)
    rot = np.empty((3, 3))
    for b in rows:
        # shift-and-copy: the route's κ interpolated at the sections' arc lengths
        m = k[b] + 1
        u = min(max(s[b] / l, 0.0), float(m))
        kk = min(int(math.floor(u)), m)
        f = u - kk
        for j in range(n):
            q0, q1 = 0.0, 0.0  # (1 − f)·κ(j) + f·κ(j + 1), straight before the route
            for side in range(2):
                idx = kk + j - n + side
                if idx >= 0:
                    src = min(max(min(idx, m - 1), 0), n - 1)
                    w = f if side else 1.0 - f
                    q0 += w * kappa[b, src, 0]
                    q1 += w * kappa[b, src, 1]
            th = math.hypot(q0, q1)
            theta[b, j] = th
            phi[b, j] = math.atan2(q1, q0) if th > 1e-12 else 0.0
        # forward kinematics of every sample
        fk_row(s[b] - n * l, theta[b], phi[b], l, samples, rot, points[b])
        last, before = n_points - 1, n_points - 2
        tx, ty, tz = points[b, last, 0], points[b, last, 1], points[b, last, 2]
        hx, hy, hz = tx - points[b, before, 0], ty - points[b, before, 1], tz - points[b, before, 2]
        norm = max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-12)
        heading[b, 0], heading[b, 1], heading[b, 2] = hx / norm, hy / norm, hz / norm
        # the exact minimum over the used samples: only those whose bound can hold it
        upper = math.inf
        for p in range(n_points):
            if p > 0 and points[b, p, 2] <= deep:
                bound[p] = math.inf
                continue
            v = grid_value(points[b, p, 0], points[b, p, 1], points[b, p, 2], lo, spacing,
                            shape, offset, values)  # fmt: skip
            bound[p] = v
            if not math.isnan(v):
                upper = min(upper, v + slack)
        best = math.inf
        for p in range(n_points):
            v = bound[p]
            if v == math.inf:
                continue
            if math.isnan(v) or v - slack <= upper:
                d = sdf(points[b, p, 0], points[b, p, 1], points[b, p, 2], boxes, cylinders,
                        spheres, walls)  # fmt: skip
                best = min(best, d)
        body_clearance[b] = best - radius
        # the rays: the heading, then the fixed axes
        n_d = ray_distances.shape[0]
        for a in range(ray_axes.shape[0] + 1):
            if a == 0:
                ax, ay, az = heading[b, 0], heading[b, 1], heading[b, 2]
            else:
                ax, ay, az = ray_axes[a - 1, 0], ray_axes[a - 1, 1], ray_axes[a - 1, 2]
            for di in range(n_d):
                dd = ray_distances[di]
                px, py, pz = tx + ax * dd, ty + ay * dd, tz + az * dd
                v = grid_value(px, py, pz, lo, spacing, shape, offset, values)
                if math.isnan(v):
                    v = sdf(px, py, pz, boxes, cylinders, spheres, walls)
                ray_clearance[b, a * n_d + di] = v


@njit(cache=True)
def usable_point(
    x: float,
    y: float,
    z: float,
    clearance: float,
    start: NDArray[np.float64],
    far: float,
    tank: KernelTank,
) -> bool:
    """Whether a point is at least ``clearance`` from the surfaces and ``√far`` from ``start``.

    The exact verdict: the grid's value settles a point when it is more than ``slack`` from
    ``clearance``, the exact signed distance the others.
    """
    dx, dy, dz = x - start[0], y - start[1], z - start[2]
    if dx * dx + dy * dy + dz * dz < far:
        return False
    v = grid_value(x, y, z, tank.grid_lo, tank.grid_spacing, tank.grid_shape,
                    tank.grid_offset, tank.grid_values)  # fmt: skip
    if math.isnan(v) or abs(v - clearance) <= tank.slack:
        v = sdf(x, y, z, tank.boxes, tank.cylinders, tank.spheres, tank.walls)
    return v >= clearance


@njit(cache=True)
def usable(
    points: NDArray[np.float64],
    clearance: float,
    start: NDArray[np.float64],
    min_distance: float,
    tank: KernelTank,
    first_only: bool = False,
) -> NDArray[np.bool_]:
    """Whether each candidate ``(R, C, 3)`` is usable as a target (exact verdicts).

    At least ``clearance`` [cm] from the tank's surfaces and ``min_distance`` [cm] from
    ``start`` (:func:`usable_point`). With ``first_only`` each row stops at its first usable
    candidate (the rest of the row reads False), so a row whose first candidate is usable
    costs one check.
    """
    out = np.zeros(points.shape[:2], dtype=np.bool_)
    far = min_distance * min_distance
    for r in range(points.shape[0]):
        for c in range(points.shape[1]):
            p = points[r, c]
            out[r, c] = usable_point(p[0], p[1], p[2], clearance, start, far, tank)
            if first_only and out[r, c]:
                break
    return out
