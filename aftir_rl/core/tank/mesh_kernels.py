"""Compiled loops over a triangle mesh: distances near it, inside by winding, cells it cuts.

:func:`band_distances` computes the exact distance from grid nodes within a band of every
triangle (Ericson's closest point on a triangle); :func:`column_winding` counts, per node, the
oriented crossings of the mesh below it along +z (inside where the count is positive, so closed
bodies that overlap read as their union); :func:`cells_cut` tells which raster cells a triangle
passes through the inside of (the separating-axis test of Akenine-Möller, strict, so a face
lying on a cell's face does not cut it). Used by :mod:`aftir_rl.core.tank.meshes`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "band_distances",
    "column_winding",
    "cells_cut",
    "closest_on_triangle",
    "sweep_nearest",
]


@njit(cache=True)
def closest_on_triangle(
    p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64]
) -> tuple[float, float, float]:
    """The point of the triangle ``abc`` nearest ``p`` (Ericson, Real-Time Collision Detection)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1, d2 = abx * apx + aby * apy + abz * apz, acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2]
    bpx, bpy, bpz = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3, d4 = abx * bpx + aby * bpy + abz * bpz, acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2]
    cpx, cpy, cpz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5, d6 = abx * cpx + aby * cpy + abz * cpz, acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2]
    vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        return a[0] + t * abx, a[1] + t * aby, a[2] + t * abz
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        return a[0] + t * acx, a[1] + t * acy, a[2] + t * acz
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + t * (c[0] - b[0]), b[1] + t * (c[1] - b[1]), b[2] + t * (c[2] - b[2])
    denom = 1.0 / max(va + vb + vc, 1e-300)
    v, w = vb * denom, vc * denom
    return a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w


@njit(cache=True)
def band_distances(
    verts: NDArray[np.float64],
    faces: NDArray[np.int64],
    lo: NDArray[np.float64],
    g: float,
    shape: NDArray[np.int64],
    band: float,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Exact distances to the mesh of nodes ``lo + g·(i, j, k)`` within ``band`` of a triangle.

    Returns the distances (inf beyond the band) and each node's nearest mesh point ``(..., 3)``.
    """
    out = np.full((shape[0], shape[1], shape[2]), np.inf, dtype=np.float32)
    nearest = np.zeros((shape[0], shape[1], shape[2], 3), dtype=np.float32)
    p = np.empty(3)
    i0 = np.empty(3, np.int64)
    i1 = np.empty(3, np.int64)
    for f in range(faces.shape[0]):
        a, b, c = verts[faces[f, 0]], verts[faces[f, 1]], verts[faces[f, 2]]
        n = np.cross(b - a, c - a)
        n /= max(math.sqrt(n @ n), 1e-300)
        offset = n @ a
        for d in range(3):
            t_lo = min(a[d], b[d], c[d]) - band
            t_hi = max(a[d], b[d], c[d]) + band
            i0[d] = max(int(math.ceil((t_lo - lo[d]) / g)), 0)
            i1[d] = min(int(math.floor((t_hi - lo[d]) / g)), shape[d] - 1)
        for i in range(i0[0], i1[0] + 1):
            p[0] = lo[0] + g * i
            for j in range(i0[1], i1[1] + 1):
                p[1] = lo[1] + g * j
                for k in range(i0[2], i1[2] + 1):
                    p[2] = lo[2] + g * k
                    plane = abs(n[0] * p[0] + n[1] * p[1] + n[2] * p[2] - offset)
                    if plane > band or plane >= out[i, j, k]:
                        continue
                    qx, qy, qz = closest_on_triangle(p, a, b, c)
                    dist = math.sqrt((p[0] - qx) ** 2 + (p[1] - qy) ** 2 + (p[2] - qz) ** 2)
                    if dist < out[i, j, k]:
                        out[i, j, k] = dist
                        nearest[i, j, k, 0], nearest[i, j, k, 1], nearest[i, j, k, 2] = qx, qy, qz
    return out, nearest


@njit(cache=True)
def column_winding(
    verts: NDArray[np.float64],
    faces: NDArray[np.int64],
    lo: NDArray[np.float64],
    g: float,
    shape: NDArray[np.int64],
) -> NDArray[np.int32]:
    """Per node, the oriented crossings of the mesh below it along +z (entering +1, leaving −1).

    Columns run through ``(x, y)`` nudged by 1e-7·g so that no column meets an edge or a
    vertex exactly.
    """
    delta = np.zeros((shape[0], shape[1], shape[2] + 1), dtype=np.int32)
    nudge_x, nudge_y = 1.0000001e-7 * g, 0.7000003e-7 * g
    for f in range(faces.shape[0]):
        a, b, c = verts[faces[f, 0]], verts[faces[f, 1]], verts[faces[f, 2]]
        area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if area == 0.0:
            continue  # vertical in z: no column crosses it
        sign = -1 if area > 0 else 1  # facing up (counter-clockwise from above): leaving
        i0 = max(int(math.ceil((min(a[0], b[0], c[0]) - nudge_x - lo[0]) / g)), 0)
        i1 = min(int(math.floor((max(a[0], b[0], c[0]) - nudge_x - lo[0]) / g)), shape[0] - 1)
        j0 = max(int(math.ceil((min(a[1], b[1], c[1]) - nudge_y - lo[1]) / g)), 0)
        j1 = min(int(math.floor((max(a[1], b[1], c[1]) - nudge_y - lo[1]) / g)), shape[1] - 1)
        for i in range(i0, i1 + 1):
            x = lo[0] + g * i + nudge_x
            for j in range(j0, j1 + 1):
                y = lo[1] + g * j + nudge_y
                w0 = (b[0] - x) * (c[1] - y) - (c[0] - x) * (b[1] - y)
                w1 = (c[0] - x) * (a[1] - y) - (a[0] - x) * (c[1] - y)
                w2 = (a[0] - x) * (b[1] - y) - (b[0] - x) * (a[1] - y)
                if not ((w0 > 0 and w1 > 0 and w2 > 0) or (w0 < 0 and w1 < 0 and w2 < 0)):
                    continue
                z = (w0 * a[2] + w1 * b[2] + w2 * c[2]) / (w0 + w1 + w2)
                k = min(max(int(math.floor((z - lo[2]) / g)) + 1, 0), shape[2])
                delta[i, j, k] += sign
    out = np.empty((shape[0], shape[1], shape[2]), dtype=np.int32)
    for i in range(shape[0]):
        for j in range(shape[1]):
            total = 0
            for k in range(shape[2]):
                total += delta[i, j, k]
                out[i, j, k] = total
    return out


@njit(cache=True)
def _separated(
    v: NDArray[np.float64], axis: NDArray[np.float64], half: NDArray[np.float64]
) -> bool:
    """Whether the triangle ``v (3, 3)`` (box-centred) and the box lie apart along ``axis``."""
    p0, p1, p2 = v[0] @ axis, v[1] @ axis, v[2] @ axis
    r = half[0] * abs(axis[0]) + half[1] * abs(axis[1]) + half[2] * abs(axis[2])
    return min(p0, p1, p2) >= r or max(p0, p1, p2) <= -r


@njit(cache=True)
def cells_cut(
    verts: NDArray[np.float64],
    faces: NDArray[np.int64],
    lo: NDArray[np.float64],
    size: float,
    shape: NDArray[np.int64],
) -> NDArray[np.bool_]:
    """Which cells ``lo + size·(i, j, k)`` a triangle passes through the open inside of."""
    out = np.zeros((shape[0], shape[1], shape[2]), dtype=np.bool_)
    half = np.full(3, size / 2)
    v = np.empty((3, 3))
    eye = np.eye(3)
    for f in range(faces.shape[0]):
        tri = np.empty((3, 3))
        for m in range(3):
            tri[m] = verts[faces[f, m]]
        i0 = np.empty(3, np.int64)
        i1 = np.empty(3, np.int64)
        for d in range(3):
            i0[d] = max(int(math.floor((tri[:, d].min() - lo[d]) / size)), 0)
            i1[d] = min(int(math.floor((tri[:, d].max() - lo[d]) / size)), shape[d] - 1)
        edges = np.empty((3, 3))
        edges[0], edges[1], edges[2] = tri[1] - tri[0], tri[2] - tri[1], tri[0] - tri[2]
        normal = np.cross(edges[0], edges[1])
        for i in range(i0[0], i1[0] + 1):
            for j in range(i0[1], i1[1] + 1):
                for k in range(i0[2], i1[2] + 1):
                    centre = lo + size * np.array([i + 0.5, j + 0.5, k + 0.5])
                    for m in range(3):
                        v[m] = tri[m] - centre
                    cut = not _separated(v, normal, half)
                    for d in range(3):
                        cut = cut and not _separated(v, eye[d], half)
                    for e in range(3):
                        for d in range(3):
                            axis = np.cross(edges[e], eye[d])
                            if cut and axis @ axis > 1e-24:
                                cut = not _separated(v, axis, half)
                    out[i, j, k] = out[i, j, k] or cut
    return out


@njit(cache=True)
def sweep_nearest(
    dist: NDArray[np.float32], nearest: NDArray[np.float32], lo: NDArray[np.float64], g: float
) -> None:
    """Improve each node's nearest mesh point from its neighbours', in place (two sweeps).

    ``nearest`` holds a mesh point per node (exact near the mesh, a neighbour's guess beyond);
    a forward and a backward sweep over the grid hand each node the nearest of its 26
    neighbours' points when it is nearer, and ``dist`` becomes the distance to it.
    """
    nx, ny, nz = dist.shape
    for sweep in range(2):
        step = 1 if sweep == 0 else -1
        for ii in range(nx):
            i = ii if step == 1 else nx - 1 - ii
            x = lo[0] + g * i
            for jj in range(ny):
                j = jj if step == 1 else ny - 1 - jj
                y = lo[1] + g * j
                for kk in range(nz):
                    k = kk if step == 1 else nz - 1 - kk
                    z = lo[2] + g * k
                    best = dist[i, j, k]
                    for di in range(-1, 2):
                        for dj in range(-1, 2):
                            for dk in range(-1, 2):
                                a, b, c = i + di, j + dj, k + dk
                                if a < 0 or b < 0 or c < 0 or a >= nx or b >= ny or c >= nz:
                                    continue
                                qx, qy, qz = (
                                    nearest[a, b, c, 0],
                                    nearest[a, b, c, 1],
                                    nearest[a, b, c, 2],
                                )
                                d = math.sqrt((x - qx) ** 2 + (y - qy) ** 2 + (z - qz) ** 2)
                                if d < best:
                                    best = d
                                    nearest[i, j, k, 0], nearest[i, j, k, 1] = qx, qy
                                    nearest[i, j, k, 2] = qz
                    dist[i, j, k] = best
