"""The arms' geometry, compiled: forward kinematics, shift-and-copy, the tank's clearance.

Forward kinematics of every backbone sample, the steering frames and one step of shift-and-copy;
the tank's signed distance and clearance grids (:class:`KernelTank`), the arms' clearance and
rays (:func:`refresh`) and usable targets. One file: numba's cache checks only the file of a
cached function, so kernels that call each other live together.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelArms, KernelTank
from aftir_rl.core.robot import SMALL

__all__ = [
    "rotate",
    "fk_row",
    "fk_points",
    "steering_frames",
    "KernelTank",
    "hole_2d",
    "plate_sdf",
    "wedge_sdf",
    "mesh_sdf",
    "sdf",
    "sdf_points",
    "grid_value",
    "least_distance",
    "refresh",
    "usable_point",
    "usable",
]


@njit(cache=True)
def rotate(r: NDArray[np.float64], theta: float, cp: float, sp: float) -> None:
    """``r ← r @ E``, ``E`` the rotation of an arc bent by ``θ`` in the plane at ``φ``."""
    ct, st = math.cos(theta), math.sin(theta)
    off = cp * sp * (ct - 1.0)
    e00, e01, e02 = cp * cp * ct + sp * sp, off, cp * st
    e10, e11, e12 = off, sp * sp * ct + cp * cp, sp * st
    e20, e21, e22 = -cp * st, -sp * st, ct
    for i in range(3):
        a, b, c = r[i, 0], r[i, 1], r[i, 2]
        r[i, 0] = a * e00 + b * e10 + c * e20
        r[i, 1] = a * e01 + b * e11 + c * e21
        r[i, 2] = a * e02 + b * e12 + c * e22


@njit(cache=True)
def fk_row(
    dis: float,
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: int,
    rot: NDArray[np.float64],
    points: NDArray[np.float64],
) -> None:
    """:func:`~aftir_rl.core.robot.body_points` of one posture into ``points (N·K + 1, 3)``.

    ``rot (3, 3)`` is scratch space.
    """
    l = section_length
    points[0, 0], points[0, 1], points[0, 2] = 0.0, 0.0, dis
    ox, oy, oz = 0.0, 0.0, dis
    rot[:] = 0.0
    rot[0, 0], rot[1, 1], rot[2, 2] = 1.0, 1.0, 1.0
    for i in range(theta.shape[0]):
        th, cp, sp = theta[i], math.cos(phi[i]), math.sin(phi[i])
        # sample j bends by h_j = j·h₁ (half its angle): sin, cos by the addition formulas
        h1 = 0.5 * th / samples
        s1, c1 = math.sin(h1), math.cos(h1)
        sj, cj = 0.0, 1.0
        for j in range(1, samples + 1):
            sj, cj = sj * c1 + cj * s1, cj * c1 - sj * s1
            h = h1 * j
            sinc_h = 1.0 - h * h / 6.0 if abs(h) < 0.5 * SMALL else sj / h
            arc = l * (j / samples)
            radial = arc * (h * sinc_h * sinc_h)
            lx, ly, lz = radial * cp, radial * sp, arc * (sinc_h * cj)
            row = 1 + i * samples + j - 1
            points[row, 0] = rot[0, 0] * lx + rot[0, 1] * ly + rot[0, 2] * lz + ox
            points[row, 1] = rot[1, 0] * lx + rot[1, 1] * ly + rot[1, 2] * lz + oy
            points[row, 2] = rot[2, 0] * lx + rot[2, 1] * ly + rot[2, 2] * lz + oz
        end = i * samples + samples
        ox, oy, oz = points[end, 0], points[end, 1], points[end, 2]
        rotate(rot, th, cp, sp)


@njit(cache=True)
def fk_points(
    dis: NDArray[np.float64],
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: int,
    points: NDArray[np.float64],
) -> None:
    """:func:`~aftir_rl.core.robot.body_points` of many postures, into ``points (B, N·K + 1, 3)``.

    ``dis (B,)``, ``theta`` and ``phi`` ``(B, N)``.
    """
    rot = np.empty((3, 3))
    for b in range(theta.shape[0]):
        fk_row(dis[b], theta[b], phi[b], section_length, samples, rot, points[b])


@njit(cache=True)
def steering_frames(
    kappa: NDArray[np.float64], k: NDArray[np.int64], out: NDArray[np.float64]
) -> None:
    """Rotations ``(B, 3, 3)`` of the frames the steered sections bend in, in place.

    The product of the end rotations of the route's frozen sections ``0..k−1`` (arc length
    irrelevant: a rotation depends on ``θ, φ`` only).
    """
    for b in range(kappa.shape[0]):
        r = out[b]
        r[:] = 0.0
        r[0, 0], r[1, 1], r[2, 2] = 1.0, 1.0, 1.0
        for j in range(k[b]):
            th = math.hypot(kappa[b, j, 0], kappa[b, j, 1])
            ph = math.atan2(kappa[b, j, 1], kappa[b, j, 0]) if th > 1e-12 else 0.0
            rotate(r, th, math.cos(ph), math.sin(ph))


@njit(cache=True, inline="always")
def _norm2(a: float, b: float) -> float:
    """``√(a² + b²)`` (faster than ``math.hypot``; no overflow at tank coordinates)."""
    return math.sqrt(a * a + b * b)


@njit(cache=True)
def hole_2d(shape: float, da: float, db: float, ha: float, hb: float) -> float:
    """2D signed distance to a rect (0), circle (1) or oval (2) hole, compiled."""
    if shape == 0.0:
        qa, qb = abs(da) - ha, abs(db) - hb
        return _norm2(max(qa, 0.0), max(qb, 0.0)) + min(max(qa, qb), 0.0)
    if shape == 1.0:
        return _norm2(da, db) - ha
    r = min(ha, hb)
    if ha >= hb:
        return _norm2(max(abs(da) - (ha - r), 0.0), db) - r
    return _norm2(da, max(abs(db) - (hb - r), 0.0)) - r


@njit(cache=True)
def plate_sdf(
    x: float, y: float, z: float, plate: NDArray[np.float64], holes: NDArray[np.float64]
) -> float:
    """Signed distance to one plate ``(9,)`` with its rows of ``holes`` (:class:`Plate`'s)."""
    k = int(plate[0])
    n = x if k == 0 else (y if k == 1 else z)
    a = y if k == 0 else x
    b = y if k == 2 else z
    ha, hb = (plate[5] - plate[3]) / 2, (plate[6] - plate[4]) / 2
    flat = hole_2d(0.0, a - plate[3] - ha, b - plate[4] - hb, ha, hb)
    for h in range(int(plate[7]), int(plate[8])):
        hole = holes[h]
        flat = max(flat, -hole_2d(hole[0], a - hole[1], b - hole[2], hole[3], hole[4]))
    w = abs(n - plate[1]) - plate[2]
    return _norm2(max(flat, 0.0), max(w, 0.0)) + min(max(flat, w), 0.0)


@njit(cache=True)
def wedge_sdf(x: float, y: float, z: float, w: NDArray[np.float64]) -> float:
    """Signed distance to one wedge ``(9,)`` (:class:`~aftir_rl.core.tank.wedge.Wedge`'s)."""
    k = int(w[0])
    n = x if k == 0 else (y if k == 1 else z)
    a = y if k == 0 else x
    b = y if k == 2 else z
    orient = (w[5] - w[3]) * (w[8] - w[4]) - (w[7] - w[3]) * (w[6] - w[4])
    best, inside = math.inf, True
    for i in range(3):
        j = (i + 1) % 3
        pa, pb, ea, eb = (
            w[3 + 2 * i],
            w[4 + 2 * i],
            w[3 + 2 * j] - w[3 + 2 * i],
            w[4 + 2 * j] - w[4 + 2 * i],
        )
        wa, wb = a - pa, b - pb
        t = min(max((wa * ea + wb * eb) / max(ea * ea + eb * eb, 1e-300), 0.0), 1.0)
        best = min(best, _norm2(wa - t * ea, wb - t * eb))
        inside = inside and (ea * wb - eb * wa) * orient >= 0
    flat = -best if inside else best
    h = abs(n - w[1]) - w[2]
    return _norm2(max(flat, 0.0), max(h, 0.0)) + min(max(flat, h), 0.0)


@njit(cache=True)
def mesh_sdf(
    x: float, y: float, z: float, m: NDArray[np.float64], values: NDArray[np.float32]
) -> float:
    """A mesh solid's grid ``m (14,)`` read trilinearly; outside, the distance to its box."""
    p = (x, y, z)
    base, frac, inside = np.empty(3, np.int64), np.empty(3), True
    for d in range(3):
        r = (p[d] - m[d]) / m[3]
        n = int(m[4 + d])
        inside = inside and 0.0 <= r <= n - 1
        base[d] = min(max(int(math.floor(r)), 0), n - 2)
        frac[d] = min(max(r - base[d], 0.0), 1.0)
    if not inside:
        ox = max(m[8] - x, x - m[11], 0.0)
        oy = max(m[9] - y, y - m[12], 0.0)
        oz = max(m[10] - z, z - m[13], 0.0)
        return math.sqrt(ox * ox + oy * oy + oz * oz)
    ny, nz, out = int(m[5]), int(m[6]), 0.0
    for dx in range(2):
        for dy in range(2):
            for dz in range(2):
                w = (frac[0] if dx else 1.0 - frac[0]) * (frac[1] if dy else 1.0 - frac[1])
                w *= frac[2] if dz else 1.0 - frac[2]
                flat = ((base[0] + dx) * ny + base[1] + dy) * nz + base[2] + dz
                out += w * values[int(m[7]) + flat]
    return out


@njit(cache=True, inline="always")
def sdf(x: float, y: float, z: float, tank: KernelTank) -> float:
    """Signed distance [cm] of one point to the tank (:class:`TankDistance`'s, compiled)."""
    boxes, cylinders, spheres, walls = tank.boxes, tank.cylinders, tank.spheres, tank.walls
    best = math.inf
    # the walls first: a near wall lets the plates and wedges farther than it be skipped
    if walls[0] != 0.0:
        side = min(min(x - walls[1], walls[4] - x), min(y - walls[2], walls[5] - y))
        radial = _norm2(x - walls[7], y - walls[8])
        height = z - walls[3]
        if radial > walls[9]:
            floor = height
        elif height >= 0:
            floor = _norm2(walls[9] - radial, height)
        else:
            floor = walls[9] - radial
        best = min(best, min(min(side, walls[6] - z), floor))
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
            radial = _norm2(c1 - cylinders[i, 0], c2 - cylinders[i, 1]) - cylinders[i, 2]
            axial = abs(along - cylinders[i, 3]) - cylinders[i, 4]
            d = _norm2(max(radial, 0.0), max(axial, 0.0)) + min(max(radial, axial), 0.0)
            best = min(best, d)
        for i in range(spheres.shape[0]):
            dx, dy, dz = x - spheres[i, 0], y - spheres[i, 1], z - spheres[i, 2]
            best = min(best, math.sqrt(dx * dx + dy * dy + dz * dz) - spheres[i, 3])
        plates, wedges = tank.plates, tank.wedges
        for i in range(plates.shape[0]):  # no nearer than its faces' planes: skipped if as far
            k = int(plates[i, 0])
            if abs((x if k == 0 else (y if k == 1 else z)) - plates[i, 1]) - plates[i, 2] < best:
                best = min(best, plate_sdf(x, y, z, plates[i], tank.holes))
        for i in range(wedges.shape[0]):
            k = int(wedges[i, 0])
            if abs((x if k == 0 else (y if k == 1 else z)) - wedges[i, 1]) - wedges[i, 2] < best:
                best = min(best, wedge_sdf(x, y, z, wedges[i]))
        for i in range(tank.meshes.shape[0]):
            best = min(best, mesh_sdf(x, y, z, tank.meshes[i], tank.mesh_values))
    return best


@njit(cache=True)
def sdf_points(points: NDArray[np.float64], tank: KernelTank, out: NDArray[np.float64]) -> None:
    """:func:`sdf` of every point ``(P, 3)`` into ``out (P,)``: how grids of it are filled."""
    for p in range(points.shape[0]):
        out[p] = sdf(points[p, 0], points[p, 1], points[p, 2], tank)


@njit(cache=True, inline="always")
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


@njit(cache=True, inline="always")
def _route_posture(
    kappa: NDArray[np.float64],
    m: int,
    u: float,
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
) -> None:
    """``θ, φ (N,)`` with the tip ``u`` sections along route ``kappa[:m]`` (shift-and-copy)."""
    n = kappa.shape[0]
    kk = min(int(math.floor(u)), m)
    f = u - kk
    for j in range(n):
        q0, q1 = 0.0, 0.0  # (1 − f)·κ(j) + f·κ(j + 1), straight before the route
        for side in range(2):
            idx = kk + j - n + side
            if idx >= 0:
                src = min(max(min(idx, m - 1), 0), n - 1)
                w = f if side else 1.0 - f
                q0 += w * kappa[src, 0]
                q1 += w * kappa[src, 1]
        th = math.hypot(q0, q1)
        theta[j] = th
        phi[j] = math.atan2(q1, q0) if th > 1e-12 else 0.0


@njit(cache=True, inline="always")
def least_distance(
    points: NDArray[np.float64], deep: float, bound: NDArray[np.float64], tank: KernelTank
) -> float:
    """The exact least signed distance [cm] of ``points (P, 3)`` above ``deep`` (and the first).

    Exact only where the grid value (± its slack) can hold the minimum; ``bound (P,)``: scratch.
    """
    lo, spacing, shape = tank.grid_lo, tank.grid_spacing, tank.grid_shape
    offset, values, slack = tank.grid_offset, tank.grid_values, tank.slack
    upper = math.inf
    for p in range(points.shape[0]):
        if p > 0 and points[p, 2] <= deep:
            bound[p] = math.inf
            continue
        v = grid_value(points[p, 0], points[p, 1], points[p, 2], lo, spacing, shape, offset,
                       values)  # fmt: skip
        bound[p] = v
        if not math.isnan(v):
            upper = min(upper, v + slack)
    best = math.inf
    for p in range(points.shape[0]):
        v = bound[p]
        if v == math.inf:
            continue
        if math.isnan(v) or v - slack <= upper:
            best = min(best, sdf(points[p, 0], points[p, 1], points[p, 2], tank))
    return best


@njit(cache=True)
def refresh(
    rows: NDArray[np.int64],
    arms: KernelArms,
    section_length: float,
    samples: int,
    radius: float,
    deep: float,
    rays: tuple[NDArray[np.float64], NDArray[np.float64]],
    tank: KernelTank,
) -> None:
    """Postures, backbone samples, headings and clearances of the arms ``rows``, in place.

    Per row ``b`` (of :class:`KernelArms`): ``θ, φ (N,)`` of the FTL posture of route
    ``kappa[b, :k[b] + 1]`` with the tip at arc length ``s[b]``; ``points (N·K + 1, 3)`` from
    the base at ``(0, 0, s − N·l)``; the unit heading of the last sample step; the surface
    clearance ``min(distance) − radius`` over the samples above ``deep`` (and the base), exact
    (grid-pruned); the clearances at the ray distances along the heading and the ray axes
    (``rays``: axes ``(A, 3)`` and distances; grid values, exact outside).
    """
    kappa, k, s, theta, phi = arms.kappa, arms.k, arms.s, arms.theta, arms.phi
    points, heading = arms.points, arms.heading
    ray_axes, ray_distances = rays
    n, n_d = kappa.shape[1], ray_distances.shape[0]
    l, n_points = section_length, n * samples + 1
    bound = np.empty(n_points)
    rot = np.empty((3, 3))
    for b in rows:
        m = k[b] + 1
        _route_posture(kappa[b], m, min(max(s[b] / l, 0.0), float(m)), theta[b], phi[b])
        fk_row(s[b] - n * l, theta[b], phi[b], l, samples, rot, points[b])
        tip, before = points[b, n_points - 1], points[b, n_points - 2]
        hx, hy, hz = tip[0] - before[0], tip[1] - before[1], tip[2] - before[2]
        norm = max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-12)
        heading[b, 0], heading[b, 1], heading[b, 2] = hx / norm, hy / norm, hz / norm
        arms.body_clearance[b] = least_distance(points[b], deep, bound, tank) - radius
        # the rays: the heading, then the fixed axes
        for a in range(ray_axes.shape[0] + 1):
            axis = heading[b] if a == 0 else ray_axes[a - 1]
            for di in range(n_d):
                dd = ray_distances[di]
                px, py, pz = tip[0] + axis[0] * dd, tip[1] + axis[1] * dd, tip[2] + axis[2] * dd
                v = grid_value(px, py, pz, tank.grid_lo, tank.grid_spacing, tank.grid_shape,
                               tank.grid_offset, tank.grid_values)  # fmt: skip
                if math.isnan(v):
                    v = sdf(px, py, pz, tank)
                arms.ray_clearance[b, a * n_d + di] = v


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
        v = sdf(x, y, z, tank)
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
