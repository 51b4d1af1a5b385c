"""The guide of the route search: a distance-to-go field over the free space of a tank.

:class:`GuideField` runs Dijkstra over a grid of half the raster's cells
(26-neighbourhood, Euclidean steps, an edge only where its midpoint is free, so a thin wall cuts
it), optionally restricted to a corridor around a learned cell path (:func:`corridor`). Used by
:func:`aftir_rl.planning.ftl.route.plan_route` and by the batched kernels of the FTL env
(:mod:`aftir_rl.envs.ftl.fields`).
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from collections.abc import Sequence
from itertools import product

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.kernel.clearance import compiled_distance
from aftir_rl.core.kernel.guide import field_query, relax_field
from aftir_rl.core.tank import Tank

__all__ = ["GuideField", "corridor", "guide_field"]

NEIGHBOURS = np.array([d for d in product((-1, 0, 1), repeat=3) if any(d)], dtype=np.int64)
"""The 26 neighbour directions of a grid point."""


class GuideField:
    """Distance-to-go [cm] to a target through the free space of a tank, on a fine grid.

    The grid has cells of half the raster's size (10 cm in the reference tank). A grid point is
    free when it keeps the arm's radius from every solid and wall; two neighbouring points
    (26-neighbourhood) are joined when the midpoint between them is free too, so a thin wall
    such as the 4 cm baffle cuts every edge across it except through the hatch. Distances are
    Euclidean along the edges, shortest by Dijkstra (compiled,
    :func:`~aftir_rl.core.kernel.guide.relax_field`). ``allowed`` (on the raster) restricts the
    field to a corridor.

    ``clearance_cost`` ``α`` (0: plain lengths) makes an edge near a surface dearer, so the
    shortest way keeps away from surfaces where it can (clearance as a cost, after Kuntz et al.):
    each end of an edge whose surface clearance ``c`` (centre clearance minus the arm's radius)
    is below :data:`CLEARANCE_RANGE` adds ``α·(1 − c/CLEARANCE_RANGE)/2`` times the edge's
    length.
    """

    def __init__(
        self,
        tank: Tank,
        target: ArrayLike,
        allowed: NDArray[np.bool_] | None = None,
        clearance_cost: float = 0.0,
    ) -> None:
        raster = tank.raster
        self.size = float(raster.cell_size) / 2
        self.origin = np.array(raster.origin, dtype=np.float64)
        self.shape = np.array(raster.shape) * 2
        free, edges, clear = _grid_edges(tank, self.size)
        if allowed is not None:
            free = free & np.repeat(np.repeat(np.repeat(allowed, 2, 0), 2, 1), 2, 2)
        self.free, self.edges = free, edges
        target = np.asarray(target, dtype=np.float64)
        centres, weights, table = _grid_weights(tank, self.size, float(clearance_cost))
        dist = np.full(tuple(self.shape), np.inf)
        near = np.linalg.norm(centres - target, axis=-1)
        seed = free & (near <= 1.75 * self.size)
        if not seed.any():
            seed = free & (near <= near[free].min() + 1e-9) if free.any() else seed
        dist[seed] = near[seed]
        #: Each neighbour direction's edge lengths [cm] (a number, or one per grid point).
        self.weights = weights
        #: The same, ``(26, n)`` over the flat grid (shared by the fields of a tank: read only).
        self.weight_table = table
        self._flat_edges = edges.reshape(len(NEIGHBOURS), -1)
        flat = dist.reshape(-1)  # a view: relaxed in place
        relax_field(flat, free.reshape(-1), self._flat_edges, table, NEIGHBOURS, self.shape)
        self.dist = dist
        self.target = target

    def __call__(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance-to-go of points ``(..., 3)``; ``inf`` where no reachable grid point is near.

        A point uses its own grid cell and the neighbours joined to it by an edge (so nothing
        leaks through a thin wall), each at its distance plus the straight line to it.
        """
        p = np.asarray(points, dtype=np.float64)
        flat = np.ascontiguousarray(p.reshape(-1, 3))
        out = np.empty(len(flat))
        grid = (self.origin, self.size, self.shape)
        field_query(
            flat, self.dist.reshape(-1), self._flat_edges, NEIGHBOURS, grid, self.target, out
        )
        return out.reshape(p.shape[:-1])


def shifted(a: NDArray[np.float64], d: NDArray[np.int64]) -> NDArray[np.float64]:
    """``out[x] = a[x - d]`` with ``inf`` where ``x - d`` is outside."""
    out = np.full_like(a, np.inf)
    src = tuple(slice(max(0, -k), a.shape[i] - max(0, k)) for i, k in enumerate(d))
    dst = tuple(slice(max(0, k), a.shape[i] - max(0, -k)) for i, k in enumerate(d))
    out[dst] = a[src]
    return out


#: Per tank (by value, held weakly) and grid size: free grid points, edges, clearances.
_EDGE_CACHE: weakref.WeakKeyDictionary[
    Tank, dict[float, tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.float64]]]
] = weakref.WeakKeyDictionary()

#: Surface clearance [cm] below which ``clearance_cost`` makes an edge dearer.
CLEARANCE_RANGE = 15.0


#: Per tank (held weakly), grid size and clearance cost: grid centres and edge lengths.
_WEIGHT_CACHE: weakref.WeakKeyDictionary[
    Tank,
    dict[
        tuple[float, float],
        tuple[NDArray[np.float64], list[NDArray[np.float64] | float], NDArray[np.float64]],
    ],
] = weakref.WeakKeyDictionary()


def _grid_weights(
    tank: Tank, size: float, clearance_cost: float
) -> tuple[NDArray[np.float64], list[NDArray[np.float64] | float], NDArray[np.float64]]:
    """The grid points' centres [cm], and the edge lengths as a list and a ``(26, n)`` table.

    They do not depend on the target: built once per tank, grid and cost (read only).
    """
    cache = _WEIGHT_CACHE.setdefault(tank, {})
    key = (size, clearance_cost)
    if key not in cache:
        shape = tuple(int(n) * 2 for n in tank.raster.shape)
        origin = np.array(tank.raster.origin, dtype=np.float64)
        centres = origin + (np.indices(shape).transpose(1, 2, 3, 0) + 0.5) * size
        _, _, clear = _grid_edges(tank, size)
        lengths = np.linalg.norm(NEIGHBOURS, axis=1) * size
        weights: list[NDArray[np.float64] | float] = list(lengths)
        if clearance_cost > 0:
            cost = clearance_cost * np.clip(1.0 - (clear - tank.arm.radius) / CLEARANCE_RANGE, 0, 1)
            weights = [
                w * (1.0 + (cost + shifted(cost, -d)) / 2) for d, w in zip(NEIGHBOURS, lengths)
            ]
        table = np.empty((len(NEIGHBOURS), int(np.prod(shape))))
        for e, w in enumerate(weights):
            table[e] = np.broadcast_to(w, shape).reshape(-1)
        for item in (centres, table, *weights):
            if isinstance(item, np.ndarray):
                item.flags.writeable = False
        cache[key] = (centres, weights, table)
    return cache[key]


def _grid_edges(
    tank: Tank, size: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.float64]]:
    """Free grid points, edges and the grid points' centre clearances [cm].

    An edge (per neighbour direction) is there where both ends and its midpoint are free.
    """
    cache = _EDGE_CACHE.setdefault(tank, {})
    if size not in cache:
        shape = tuple(int(n) * 2 for n in tank.raster.shape)
        origin = np.array(tank.raster.origin, dtype=np.float64)
        distance, r = compiled_distance(tank), tank.arm.radius
        # every grid point and every edge's midpoint is a node of the grid of half the spacing:
        # grid point i is node 2i + 1 along each axis, the midpoint towards d node 2i + 1 + d
        across = np.meshgrid(
            *(origin[k] + 0.5 * size * np.arange(2 * shape[k] + 1) for k in (1, 2)), indexing="ij"
        )

        def plane(m: int) -> NDArray[np.float64]:
            x = np.full(across[0].shape, origin[0] + 0.5 * size * m)
            return distance(np.stack([x, *across], -1))

        clear = np.empty(shape)
        mid_free = np.zeros((len(NEIGHBOURS),) + shape, dtype=bool)
        below = plane(0)
        for i in range(shape[0]):  # a plane of grid points at a time: memory of three planes
            planes = (below, plane(2 * i + 1), plane(2 * i + 2))
            clear[i] = planes[1][1::2, 1::2]
            for e, (dx, dy, dz) in enumerate(NEIGHBOURS):
                rows = slice(1 + dy, 1 + dy + 2 * shape[1], 2)
                cols = slice(1 + dz, 1 + dz + 2 * shape[2], 2)
                mid_free[e, i] = planes[dx + 1][rows, cols] >= r
            below = planes[2]
        free = clear >= r
        edges = np.zeros((len(NEIGHBOURS),) + shape, dtype=bool)
        for e, d in enumerate(NEIGHBOURS):
            target_free = shifted(free.astype(np.float64), -d) == 1.0
            edges[e] = free & target_free & mid_free[e]
        cache[size] = (free, edges, clear)
    return cache[size]


def corridor(tank: Tank, cells: Sequence[Sequence[int]], grow: int) -> NDArray[np.bool_]:
    """The raster cells within ``grow`` cells of ``cells`` (a box around each)."""
    mask = np.zeros(tank.raster.shape, dtype=bool)
    shape = np.array(tank.raster.shape)
    for c in cells:
        lo = np.clip(np.asarray(c) - grow, 0, shape)
        hi = np.clip(np.asarray(c) + grow + 1, 0, shape)
        mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = True
    return mask


#: Guide fields kept per tank by :func:`guide_field` (about 0.4 MB each in the reference tank).
GUIDE_CACHE_SIZE = 16

_FIELDS: weakref.WeakKeyDictionary[Tank, OrderedDict[bytes, GuideField]] = (
    weakref.WeakKeyDictionary()
)


def guide_field(
    tank: Tank, target: ArrayLike, allowed: NDArray[np.bool_] | None = None
) -> GuideField:
    """:class:`GuideField` ``(tank, target, allowed)``, built once and kept (least recently used).

    The route search asks for the same field once per search setting of a target; the last
    :data:`GUIDE_CACHE_SIZE` fields of each tank are kept.
    """
    point = np.asarray(target, dtype=np.float64)
    key = point.tobytes() + (b"" if allowed is None else np.packbits(allowed).tobytes())
    fields = _FIELDS.setdefault(tank, OrderedDict())
    field = fields.get(key)
    if field is None:
        field = fields[key] = GuideField(tank, point, allowed)
        while len(fields) > GUIDE_CACHE_SIZE:
            fields.popitem(last=False)
    fields.move_to_end(key)
    return field
