"""Batched kernels of ``AFTIR-ArmFTL-v0``: exact clearances through a distance grid, raster guides.

Two things make the batched follow-the-leader env fast and goal-aware without approximations:

- :class:`ClearanceGrid` answers "the smallest signed distance of each arm's backbone samples"
  exactly, but computes the exact distance only where it can matter. The tank's signed distance
  is tabulated once on grids of spacing ``g`` laid where the distance is 1-Lipschitz, so a
  point's value lies within ``δ = g·√3/2`` of its nearest node's. Per arm, the smallest upper
  bound ``v + δ`` over its samples bounds the minimum; only samples whose lower bound ``v − δ``
  is below it can hold the minimum, and only those (typically a handful of 121) go to the exact
  function. The result equals the exact minimum (the tests compare them). The sensing rays of
  the observation read the nearest node's value (:meth:`ClearanceGrid.approx`, within ``δ`` = 1.7 cm).
- :class:`RasterGuide` turns the all-pairs shortest 6-connected distances through the tank's
  raster (the BFS the grid world is checked against) into a smooth distance-to-go ``P(p, g)``
  [cm] by trilinear interpolation between cell centres, and its gradient: the way through the
  hatch as two numbers a policy can read, looked up in a table, for any target, at no per-episode
  cost.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.errors import TargetError
from aftir_rl.tank import Tank

__all__ = ["ClearanceGrid", "RasterGuide", "draw_targets", "raster_distance_table"]

#: Grid spacing [cm] of :class:`ClearanceGrid`.
GRID_SPACING = 2.0
#: Largest number of grid nodes a tank may ask for (about 8 bytes each).
MAX_GRID_NODES = 8_000_000


class ClearanceGrid:
    """Exact per-row minimum signed distance of many points, pruned by tabulated bounds.

    Args:
        distance: the exact signed distance [cm] of points ``(..., 3)`` (e.g.
            :class:`aftir_rl.envs.arm_ftl.TankDistance`).
        boxes: ``(lo, hi)`` corners [cm] of the boxes the grids cover (e.g. the tank and the
            guide tube below its floor); points outside every box are always computed exactly.
            Within each box ``distance`` must be 1-Lipschitz (a true signed distance, with no
            jump), or the bounds are wrong.
        spacing: grid spacing ``g`` [cm] (grown for a box until its grid has at most
            :data:`MAX_GRID_NODES` nodes).

    """

    def __init__(
        self,
        distance: Callable[[NDArray[np.float64]], NDArray[np.float64]],
        boxes: Sequence[tuple[ArrayLike, ArrayLike]],
        spacing: float = GRID_SPACING,
    ) -> None:
        self.distance = distance
        self.grids: list[tuple[NDArray[np.float64], float, NDArray[np.int64], NDArray[np.float64]]]
        self.grids = []
        self.slack = 0.0
        for box_lo, box_hi in boxes:
            lo, hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
            g = float(spacing)
            while np.prod(np.ceil((hi - lo) / g) + 1) > MAX_GRID_NODES:
                g *= 1.25
            shape = np.ceil((hi - lo) / g).astype(np.int64) + 1
            axes = [lo[i] + g * np.arange(shape[i]) for i in range(3)]
            nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
            chunks = np.array_split(nodes, 1 + len(nodes) // 65536)
            values = np.concatenate([distance(c) for c in chunks]).astype(np.float64)
            self.grids.append((lo, g, shape, values))
            self.slack = max(self.slack, g * math.sqrt(3.0) / 2.0)

    def bound(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Nearest-node values of points ``(..., 3)``; NaN outside every grid.

        The first grid that holds a point answers; the exact distance is within :attr:`slack`.
        """
        out = np.full(points.shape[:-1], np.nan)
        for lo, g, shape, values in self.grids:
            idx = np.rint((points - lo) / g).astype(np.int64)
            inside = ((idx >= 0) & (idx < shape)).all(-1) & np.isnan(out)
            idx = np.clip(idx, 0, shape - 1)
            flat = (idx[..., 0] * shape[1] + idx[..., 1]) * shape[2] + idx[..., 2]
            out = np.where(inside, values[flat], out)
        return out

    def row_min(
        self, points: NDArray[np.float64], use: NDArray[np.bool_] | None = None
    ) -> NDArray[np.float64]:
        """Exact ``distance(points).min(-1)`` of points ``(B, P, 3)``, shape ``(B,)``.

        ``use`` ``(B, P)``: only these points count (``inf`` for a row without any).
        """
        if use is None:
            use = np.ones(points.shape[:2], dtype=bool)
        rows, cols = np.nonzero(use)
        pts = points[rows, cols]
        v = self.bound(pts)
        upper = np.full(len(points), np.inf)
        np.minimum.at(upper, rows, np.where(np.isnan(v), np.inf, v + self.slack))
        need = np.isnan(v) | (v - self.slack <= upper[rows])
        exact = self.distance(pts[need])
        out = np.full(len(points), np.inf)
        np.minimum.at(out, rows[need], exact)
        return out

    def approx(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Signed distance of points ``(..., 3)`` within :attr:`slack` [cm].

        The nearest node's value; exact outside the grids.
        """
        v = self.bound(points)
        far = np.isnan(v)
        if far.any():
            v[far] = self.distance(points[far])
        return v


def draw_targets(
    rngs: Sequence[np.random.Generator],
    grid: ClearanceGrid,
    region: tuple[NDArray[np.float64], NDArray[np.float64]],
    clearance: float,
    start: NDArray[np.float64],
) -> NDArray[np.float64]:
    """One target per generator: uniform in ``region``, ``clearance`` [cm] from every surface.

    Each generator draws batches of 64 uniform candidates until one is at least ``clearance``
    from every surface and 20 cm from ``start``; its first such candidate is its target (the
    grid's bounds settle most candidates, the rest are computed exactly, so the verdicts are the
    exact ones). Shape ``(len(rngs), 3)``.
    """
    lo, hi = region
    out = np.empty((len(rngs), 3))
    todo = np.arange(len(rngs))
    for _ in range(200):
        if not len(todo):
            return out
        cand = np.stack([rngs[int(i)].uniform(lo, hi, (64, 3)) for i in todo])
        v = grid.bound(cand)
        ok = v - grid.slack >= clearance
        unsure = np.isnan(v) | (~ok & (v + grid.slack >= clearance))
        if unsure.any():
            ok[unsure] = grid.distance(cand[unsure]) >= clearance
        ok &= np.linalg.norm(cand - start, axis=-1) >= 20.0
        found = ok.any(1)
        rows = np.flatnonzero(found)
        out[todo[rows]] = cand[rows, ok[rows].argmax(1)]
        todo = todo[~found]
    if len(todo):
        raise TargetError(f"no free point {clearance:g} cm from every surface in the target region")
    return out


def raster_distance_table(tank: Tank) -> NDArray[np.int32]:
    """Shortest 6-connected raster distances ``D[c, g]`` [cells] between every pair of cells.

    The BFS through free cells (:meth:`~aftir_rl.tank.Raster.bfs_distances` from every cell at
    once, by numpy relaxation); an obstructed end cell (a free point can lie in a cell a solid
    only partly fills) counts as one step from its nearest free neighbour. Unreachable pairs get
    the largest finite distance plus one. Shape ``(cells, cells)``, flat cell indices. Cached per
    tank.
    """
    cached = _TABLES.get(tank)
    if cached is not None:
        return cached
    raster = tank.raster
    shape = raster.shape
    free = ~raster.obstructed
    n = raster.n_cells
    big = np.int32(10 * n)
    dist = np.full((n,) + shape, big, dtype=np.int32)
    dist.reshape(n, n)[np.arange(n), np.arange(n)] = 0
    moves = [(axis, step) for axis in range(3) for step in (-1, 1)]

    def neighbour_min(d: NDArray[np.int32]) -> NDArray[np.int32]:
        best = np.full_like(d, big)
        for axis, step in moves:
            src = [slice(None)] * 4
            dst = [slice(None)] * 4
            src[axis + 1] = slice(max(0, -step), shape[axis] - max(0, step))
            dst[axis + 1] = slice(max(0, step), shape[axis] - max(0, -step))
            best[tuple(dst)] = np.minimum(best[tuple(dst)], d[tuple(src)])
        return best

    for _ in range(4 * sum(shape)):
        new = np.where(free[None], np.minimum(dist, neighbour_min(dist) + 1), dist)
        if np.array_equal(new, dist):
            break
        dist = new
    dist = np.where(free[None], dist, np.minimum(dist, neighbour_min(dist) + 1))
    flat = dist.reshape(n, n)
    flat = np.minimum(flat, flat.T)  # obstructed sources: from either end
    finite = flat[flat < big]
    flat = np.where(flat < big, flat, (finite.max() + 1) if finite.size else 0).astype(np.int32)
    flat.setflags(write=False)
    _TABLES[tank] = flat
    return flat


_TABLES: weakref.WeakKeyDictionary[Tank, NDArray[np.int32]] = weakref.WeakKeyDictionary()


class RasterGuide:
    """Distance-to-go through the tank's raster, interpolated, and its direction.

    ``P(p, g) = cell · Σ_corners w_c · D[c, cell(g)]`` over the 8 cell centres around ``p``
    (trilinear weights ``w_c``; outside the centres' hull the nearest is repeated), with ``D``
    from :func:`raster_distance_table`. :meth:`__call__` returns ``P`` [cm] and ``−∇P/|∇P|``,
    the unit direction in which the distance-to-go falls fastest (zero where it is flat).
    """

    def __init__(self, tank: Tank) -> None:
        raster = tank.raster
        self.table = raster_distance_table(tank)
        self.shape = np.asarray(raster.shape)
        self.origin = np.asarray(raster.origin, dtype=np.float64)
        self.cell = float(raster.cell_size)

    def cell_index(self, p: NDArray[np.float64]) -> NDArray[np.int64]:
        """Flat raster cell index of points ``(B, 3)``, clipped to the raster."""
        c = np.clip(np.floor((p - self.origin) / self.cell).astype(np.int64), 0, self.shape - 1)
        return (c[:, 0] * self.shape[1] + c[:, 1]) * self.shape[2] + c[:, 2]

    def __call__(
        self, p: NDArray[np.float64], g: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``P`` ``(B,)`` [cm] and the descent direction ``(B, 3)`` for tips ``p``, goals ``g``."""
        u = (p - self.origin) / self.cell - 0.5  # coordinates in cell-centre units
        top = (self.shape - 1).astype(np.float64)
        u = np.clip(u, 0.0, top)
        i0 = np.minimum(np.floor(u).astype(np.int64), np.maximum(self.shape - 2, 0))
        f = u - i0
        goal = self.cell_index(g)
        value = np.zeros(len(p))
        grad = np.zeros((len(p), 3))
        for corner in range(8):
            bits = np.array([(corner >> 2) & 1, (corner >> 1) & 1, corner & 1])
            c = np.minimum(i0 + bits, self.shape - 1)
            d = self.table[(c[:, 0] * self.shape[1] + c[:, 1]) * self.shape[2] + c[:, 2], goal]
            d = d.astype(np.float64) * self.cell
            w = np.where(bits, f, 1.0 - f)  # per-axis weights (B, 3)
            value += w.prod(-1) * d
            for axis in range(3):
                others = np.delete(w, axis, axis=1).prod(-1)
                grad[:, axis] += (1.0 if bits[axis] else -1.0) * others * d
        norm = np.linalg.norm(grad, axis=-1, keepdims=True)
        direction = np.where(norm > 1e-9, -grad / np.maximum(norm, 1e-12), 0.0)
        return value, direction
