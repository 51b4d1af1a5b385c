"""The guide field's queries, compiled: the way to a target, its lookahead, its columns."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "cell_of",
    "descend_field",
    "guide_query",
    "lookahead",
    "relax_field",
    "field_query",
]


#: A guide grid as the kernels read it: its corner ``origin (3,)`` [cm], cell ``size`` [cm] and
#: ``shape (3,)``.
Grid = tuple[NDArray[np.float64], float, NDArray[np.int64]]


@njit(cache=True)
def cell_of(px: float, py: float, pz: float, grid: Grid) -> tuple[int, int, int]:
    """The cell of ``grid`` that holds point ``(px, py, pz)`` [cm], clamped to the grid."""
    origin, size, shape = grid
    c0 = min(max(int(math.floor((px - origin[0]) / size)), 0), shape[0] - 1)
    c1 = min(max(int(math.floor((py - origin[1]) / size)), 0), shape[1] - 1)
    c2 = min(max(int(math.floor((pz - origin[2]) / size)), 0), shape[2] - 1)
    return c0, c1, c2


@njit(cache=True)
def guide_query(
    p: NDArray[np.float64],
    g: NDArray[np.float64],
    ids: NDArray[np.int64],
    table: NDArray[np.float32],
    edges: NDArray[np.bool_],
    neighbours: NDArray[np.int64],
    grid: Grid,
    to_go: NDArray[np.float64],
    way: NDArray[np.float64],
) -> None:
    """:meth:`FieldGuide.__call__ <aftir_rl.envs.ftl.fields.FieldGuide.__call__>`, in place."""
    origin, size, shape = grid
    s1, s2 = shape[1], shape[2]
    for b in range(p.shape[0]):
        px, py, pz = p[b, 0], p[b, 1], p[b, 2]
        c0, c1, c2 = cell_of(px, py, pz, grid)
        flat = (c0 * s1 + c1) * s2 + c2
        row = ids[b]
        dx = px - (origin[0] + (c0 + 0.5) * size)
        dy = py - (origin[1] + (c1 + 0.5) * size)
        dz = pz - (origin[2] + (c2 + 0.5) * size)
        value = float(table[row, flat]) + math.sqrt(dx * dx + dy * dy + dz * dz)
        best, wx, wy, wz = math.inf, 0.0, 0.0, 0.0
        first = True
        for e in range(neighbours.shape[0]):
            n0, n1, n2 = c0 + neighbours[e, 0], c1 + neighbours[e, 1], c2 + neighbours[e, 2]
            ok = 0 <= n0 < shape[0] and 0 <= n1 < shape[1] and 0 <= n2 < s2
            if not ok:
                n0, n1, n2 = 0, 0, 0
            ok = ok and edges[e, flat]
            sx = origin[0] + (n0 + 0.5) * size - px
            sy = origin[1] + (n1 + 0.5) * size - py
            sz = origin[2] + (n2 + 0.5) * size - pz
            v = math.inf
            if ok:
                v = float(table[row, (n0 * s1 + n1) * s2 + n2]) + math.sqrt(
                    sx * sx + sy * sy + sz * sz
                )
            if first or v < best:  # argmin: the first of equals
                best, wx, wy, wz = v, sx, sy, sz
                first = False
        value = min(value, best)
        g0, g1, g2 = cell_of(g[b, 0], g[b, 1], g[b, 2], grid)
        if (c0 == g0 and c1 == g1 and c2 == g2) or not math.isfinite(best):
            wx, wy, wz = g[b, 0] - px, g[b, 1] - py, g[b, 2] - pz
            value = math.sqrt(wx * wx + wy * wy + wz * wz)
        to_go[b] = value
        norm = math.sqrt(wx * wx + wy * wy + wz * wz)
        if norm > 1e-9:
            way[b, 0], way[b, 1], way[b, 2] = wx / norm, wy / norm, wz / norm
        else:
            way[b, 0], way[b, 1], way[b, 2] = 0.0, 0.0, 0.0


@njit(cache=True)
def lookahead(
    p: NDArray[np.float64],
    g: NDArray[np.float64],
    ids: NDArray[np.int64],
    nxt: NDArray[np.int32],
    hops: NDArray[np.int64],
    grid: Grid,
    out: NDArray[np.float64],
) -> None:
    """:meth:`FieldGuide.lookahead <aftir_rl.envs.ftl.fields.FieldGuide.lookahead>`, in place."""
    origin, size, shape = grid
    s1, s2 = shape[1], shape[2]
    for b in range(p.shape[0]):
        c0, c1, c2 = cell_of(p[b, 0], p[b, 1], p[b, 2], grid)
        cell = (c0 * s1 + c1) * s2 + c2
        g0, g1, g2 = cell_of(g[b, 0], g[b, 1], g[b, 2], grid)
        home = (g0 * s1 + g1) * s2 + g2
        done = 0
        for j in range(hops.shape[0]):
            for _ in range(hops[j] - done):
                cell = int(nxt[ids[b], cell])
            done = hops[j]
            if cell == home:
                out[b, j, 0], out[b, j, 1], out[b, j, 2] = g[b, 0], g[b, 1], g[b, 2]
            else:
                a0, rem = cell // (s1 * s2), cell % (s1 * s2)
                out[b, j, 0] = origin[0] + (a0 + 0.5) * size
                out[b, j, 1] = origin[1] + (rem // s2 + 0.5) * size
                out[b, j, 2] = origin[2] + (rem % s2 + 0.5) * size


@njit(cache=True)
def relax_field(
    dist: NDArray[np.float64],
    free: NDArray[np.bool_],
    edges: NDArray[np.bool_],
    weights: NDArray[np.float64],
    neighbours: NDArray[np.int64],
    shape: NDArray[np.int64],
) -> None:
    """Shortest distances to the seeds (finite ``dist``) over a grid's edges, in place (Dijkstra).

    Flat grid points; ``edges[e, x]``: the edge from ``x`` to ``x + neighbours[e]`` exists,
    ``weights[e, x]`` its length. ``dist`` ends as the fixed point of ``dist[x] = min_e
    dist[x + d_e] + w_e(x)`` over free points (:class:`~aftir_rl.planning.ftl.guide.GuideField`).
    The queue is a binary heap of ``(distance, point)`` holding each point once (a lowered
    distance moves it up), so points settle in the order of ``heapq`` on those pairs.
    """
    s1, s2 = shape[1], shape[2]
    # flat offsets: an edge from x is there only where x + neighbours[e] is inside the grid, so
    # a flat x = y - offset[e] in range with edges[e, x] is the grid point y - neighbours[e]
    offset = (neighbours[:, 0] * s1 + neighbours[:, 1]) * s2 + neighbours[:, 2]
    n = dist.shape[0]
    keys, points = np.empty(n), np.empty(n, dtype=np.int64)
    slot = np.full(n, -1, dtype=np.int64)  # a point's place in the heap; -1: not in it
    size = 0
    for x in range(n):
        if math.isfinite(dist[x]):
            _sift_up(keys, points, slot, size, dist[x], x)
            size += 1
    while size > 0:
        dy, y = keys[0], points[0]
        slot[y] = -1
        size -= 1
        if size > 0:
            _sift_down(keys, points, slot, size, keys[size], points[size])
        for e in range(offset.shape[0]):
            x = y - offset[e]
            if not (0 <= x < n and edges[e, x] and free[x]):
                continue
            v = dy + weights[e, x]
            if v < dist[x]:
                dist[x] = v
                if slot[x] < 0:
                    _sift_up(keys, points, slot, size, v, x)
                    size += 1
                else:
                    _sift_up(keys, points, slot, slot[x], v, x)


@njit(cache=True, inline="always")
def _before(k1: float, p1: int, k2: float, p2: int) -> bool:
    """Whether ``(k1, p1)`` comes before ``(k2, p2)`` (as tuples compare)."""
    return k1 < k2 or (k1 == k2 and p1 < p2)


@njit(cache=True)
def _sift_up(
    keys: NDArray[np.float64],
    points: NDArray[np.int64],
    slot: NDArray[np.int64],
    i: int,
    key: float,
    point: int,
) -> None:
    """Put ``(key, point)`` at heap place ``i`` (free, or its own) and move it up to its place."""
    while i > 0:
        parent = (i - 1) >> 1
        if not _before(key, point, keys[parent], points[parent]):
            break
        keys[i], points[i] = keys[parent], points[parent]
        slot[points[i]] = i
        i = parent
    keys[i], points[i], slot[point] = key, point, i


@njit(cache=True)
def _sift_down(
    keys: NDArray[np.float64],
    points: NDArray[np.int64],
    slot: NDArray[np.int64],
    size: int,
    key: float,
    point: int,
) -> None:
    """Put ``(key, point)`` at the root of a heap of ``size`` and move it down to its place."""
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _before(keys[right], points[right], keys[child], points[child]):
            child = right
        if not _before(keys[child], points[child], key, point):
            break
        keys[i], points[i] = keys[child], points[child]
        slot[points[i]] = i
        i = child
    keys[i], points[i], slot[point] = key, point, i


@njit(cache=True)
def descend_field(
    dist: NDArray[np.float64],
    edges: NDArray[np.bool_],
    weights: NDArray[np.float64],
    neighbours: NDArray[np.int64],
    shape: NDArray[np.int64],
    out: NDArray[np.int32],
) -> None:
    """Per grid point (flat), the neighbour its shortest way goes to next, into ``out``.

    The first neighbour (in ``neighbours`` order) of least ``dist[x + d_e] + w_e(x)`` over the
    edges of ``x``; a point whose own distance is below that by more than 1e-9 (a seed, an
    unreachable point) points to itself. One pass per direction, over the points it joins.
    """
    s0, s1, s2 = shape[0], shape[1], shape[2]
    n = dist.shape[0]
    best = np.full(n, np.inf)
    for x in range(n):
        out[x] = x
    for e in range(neighbours.shape[0]):
        d0, d1, d2 = neighbours[e, 0], neighbours[e, 1], neighbours[e, 2]
        step = (d0 * s1 + d1) * s2 + d2
        for x0 in range(max(0, -d0), min(s0, s0 - d0)):
            for x1 in range(max(0, -d1), min(s1, s1 - d1)):
                row = (x0 * s1 + x1) * s2
                for x in range(row + max(0, -d2), row + min(s2, s2 - d2)):
                    if edges[e, x]:
                        via = dist[x + step] + weights[e, x]
                        if via < best[x]:  # strict: the first direction of equals
                            best[x], out[x] = via, x + step
    for x in range(n):
        if dist[x] < best[x] - 1e-9:
            out[x] = x


@njit(cache=True)
def field_query(
    p: NDArray[np.float64],
    dist: NDArray[np.float64],
    edges: NDArray[np.bool_],
    neighbours: NDArray[np.int64],
    grid: Grid,
    target: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """:meth:`GuideField.__call__ <aftir_rl.planning.ftl.guide.GuideField.__call__>`, in place.

    Points ``p (B, 3)``; ``dist`` and ``edges`` flat over the grid.
    """
    origin, size, shape = grid
    s1, s2 = shape[1], shape[2]
    for b in range(p.shape[0]):
        px, py, pz = p[b, 0], p[b, 1], p[b, 2]
        c0, c1, c2 = cell_of(px, py, pz, grid)
        flat = (c0 * s1 + c1) * s2 + c2
        dx = px - (origin[0] + (c0 + 0.5) * size)
        dy = py - (origin[1] + (c1 + 0.5) * size)
        dz = pz - (origin[2] + (c2 + 0.5) * size)
        best = dist[flat] + math.sqrt(dx * dx + dy * dy + dz * dz)
        for e in range(neighbours.shape[0]):
            n0, n1, n2 = c0 + neighbours[e, 0], c1 + neighbours[e, 1], c2 + neighbours[e, 2]
            if not (0 <= n0 < shape[0] and 0 <= n1 < s1 and 0 <= n2 < s2) or not edges[e, flat]:
                continue
            sx = origin[0] + (n0 + 0.5) * size - px
            sy = origin[1] + (n1 + 0.5) * size - py
            sz = origin[2] + (n2 + 0.5) * size - pz
            best = min(
                best, dist[(n0 * s1 + n1) * s2 + n2] + math.sqrt(sx * sx + sy * sy + sz * sz)
            )
        tx, ty, tz = px - target[0], py - target[1], pz - target[2]
        near = math.sqrt(tx * tx + ty * ty + tz * tz)
        out[b] = min(best, near) if near < size else best
