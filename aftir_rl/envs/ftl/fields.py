"""Grids of ``AFTIR-ArmFTL-v0``: the guide's fields and the raster's distance table.

The exact clearances come from :mod:`aftir_rl.core.kernel.clearance` (shared with the planner).

- :class:`FieldGuide`: the free-space distance-to-go fields of the targets seen so far (the
  motion planner's guide field), read for every tip at once.
- :func:`raster_distance_table`: all-pairs 6-connected distances through the raster, and
  :func:`raster_detour_table`, their detours beyond Manhattan, for the reward's shaping term and
  the sampler's ``detour_bias``.

How the bounds work: docs/envs/armftl.md.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core import kernel
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import Tank
from aftir_rl.envs.ftl.kernel.raster import all_pairs_bfs

__all__ = [
    "FieldGuide",
    "field_guide",
    "raster_detour_table",
    "raster_distance_table",
]

#: Largest number of distance-to-go values the :class:`FieldGuide` s of a process keep together
#: (8 bytes each, with the next-step table): a pool of tanks shares one budget.
MAX_GUIDE_VALUES = 50_000_000
#: ``clearance_cost`` of :class:`FieldGuide`'s fields: ways keep off surfaces where they can.
GUIDE_CLEARANCE_COST = 2.0
#: Grid steps ahead of the tip of :meth:`FieldGuide.lookahead`'s points.
LOOKAHEAD_HOPS = (3, 6)


def raster_distance_table(tank: Tank) -> NDArray[np.int32]:
    """Shortest 6-connected raster distances ``D[c, g]`` [cells] between every pair of cells.

    One breadth-first search through free cells from every cell (compiled:
    :func:`~aftir_rl.envs.ftl.kernel.raster.all_pairs_bfs`, what
    :meth:`~aftir_rl.core.tank.Raster.bfs_distances` gives from one cell); an obstructed end cell
    (a free point can lie in a cell a solid only partly fills) counts as one step from its nearest
    free neighbour, and an obstructed source from either end. Unreachable pairs get the largest
    finite distance plus one. Shape ``(cells, cells)``, flat cell indices. Cached per tank.
    """
    cached = _TABLES.get(tank)
    if cached is not None:
        return cached
    raster = tank.raster
    free = np.ascontiguousarray(~raster.obstructed).reshape(-1)
    flat = all_pairs_bfs(free, *(int(n) for n in raster.shape))
    unreached = flat < 0
    flat[unreached] = np.iinfo(np.int32).max
    flat = np.minimum(flat, flat.T)  # obstructed sources: from either end
    unreached = flat == np.iinfo(np.int32).max
    if unreached.any():
        flat[unreached] = flat[~unreached].max() + 1 if (~unreached).any() else 0
    flat.setflags(write=False)
    _TABLES[tank] = flat
    return flat


_TABLES: weakref.WeakKeyDictionary[Tank, NDArray[np.int32]] = weakref.WeakKeyDictionary()


def raster_detour_table(tank: Tank) -> NDArray[np.int32]:
    """Detour ``e[c, g]`` [cells] of the shortest 6-connected raster path beyond Manhattan.

    ``e = D − |c − g|₁ ≥ 0`` with ``D`` the all-pairs BFS distances of
    :func:`raster_distance_table` (unreachable pairs: the largest
    distance plus one). Shape ``(cells, cells)``, flat cell indices; cached with the table.
    """
    cached = _DETOUR_CACHE.get(tank)
    if cached is not None:
        return cached
    detour = raster_distance_table(tank).copy()
    for axis in np.indices(tank.raster.shape).reshape(3, -1).astype(np.int32):
        detour -= np.abs(axis[:, None] - axis[None, :])  # minus the Manhattan distance
    np.clip(detour, 0, None, out=detour)
    detour.setflags(write=False)
    _DETOUR_CACHE[tank] = detour
    return detour


_DETOUR_CACHE: weakref.WeakKeyDictionary[Tank, NDArray[np.int32]] = weakref.WeakKeyDictionary()


class FieldGuide:
    """Distance-to-go through free space and the way to go, for many targets at once.

    The field of a target is :class:`aftir_rl.planning.ftl.route.GuideField` (the fine grid of half
    the raster's cell, points that keep the arm's radius from every surface, 26-neighbour edges
    whose midpoints are free too, so a thin wall is crossed only through its hatch), built for
    the centre of the target's grid cell the first time a target falls in that cell and kept
    (at most :data:`MAX_GUIDE_VALUES` values in all, :attr:`capacity` fields; the cache starts
    again when full, and :attr:`generation` tells holders of ids to ask again).
    :meth:`__call__` returns, for each tip, the distance-to-go ``P`` [cm] (its cell's or a
    joined neighbour's distance plus the straight line to that grid point, as ``GuideField``
    does) and the unit vector towards the joined neighbour that minimises it: the next waypoint.
    In the target's own cell both are the straight line to the target.

    The fields are built with ``clearance_cost`` (:data:`GUIDE_CLEARANCE_COST`; see
    ``GuideField``): edges near a surface cost more, so the way passes through the middle of the
    hatch rather than along its edge, where an arm that cannot bend sharper than ``θ_max`` per
    section would cut the corner. With each field the next grid point of its shortest way is kept
    for every grid point, so :meth:`lookahead` follows the way several steps ahead in a few
    gathers.
    """

    def __init__(self, tank: Tank, clearance_cost: float = GUIDE_CLEARANCE_COST) -> None:
        from aftir_rl.planning.ftl.route import NEIGHBOURS, GuideField

        lo, hi = np.asarray(tank.box_min, float), np.asarray(tank.box_max, float)
        probe = GuideField(tank, (lo + hi) / 2)
        self.size, self.origin = probe.size, probe.origin
        self.shape = np.asarray(probe.shape, dtype=np.int64)
        self.edges, self.neighbours = probe.edges, np.asarray(NEIGHBOURS, dtype=np.int64)
        self._edges_flat = np.ascontiguousarray(self.edges.reshape(len(self.neighbours), -1))
        self._origin = np.asarray(self.origin, dtype=np.float64)
        self._last_cell = self.shape - 1
        self.clearance_cost = float(clearance_cost)
        self._tank = tank
        self._field_cls = GuideField
        n = self.n_points = int(np.prod(self.shape))
        self.capacity = max(1, MAX_GUIDE_VALUES // n)
        #: Incremented whenever the cache starts again: ids from an older generation are void.
        self.generation = 0
        #: The table row of each target cell's field (flat cell index; -1: not built).
        self._row_of = np.full(n, -1, dtype=np.int64)
        self._count = 0
        self._start_again()
        self.generation = 0

    def __len__(self) -> int:
        """The number of fields kept."""
        return self._count

    def _start_again(self) -> None:
        """Drop every field (ids given out before are void: see ``generation``), free the tables."""
        self._row_of[:] = -1
        self._count = 0
        self.generation += 1
        rows = min(64, self.capacity)
        self._table = np.empty((rows, self.n_points), dtype=np.float32)
        self._next = np.empty((rows, self.n_points), dtype=np.int32)

    def _over_budget(self, new: int) -> bool:
        """Whether ``new`` more fields would take the process's guides over the budget."""
        kept = sum(g._count * g.n_points for g in list(_GUIDES))
        return kept + new * self.n_points > MAX_GUIDE_VALUES

    def _flat(self, cell: NDArray[np.int64]) -> NDArray[np.int64]:
        return (cell[..., 0] * self.shape[1] + cell[..., 1]) * self.shape[2] + cell[..., 2]

    def _cell(self, p: NDArray[np.float64]) -> NDArray[np.int64]:
        c = np.floor((p - self._origin) / self.size).astype(np.int64)
        return np.minimum(np.maximum(c, 0), self._last_cell)

    def field_ids(self, targets: NDArray[np.float64]) -> NDArray[np.int64]:
        """Rows of the field table for targets ``(B, 3)``, building the missing fields."""
        keys = self._flat(self._cell(np.asarray(targets, dtype=np.float64)))
        out = self._row_of[keys]
        if (out >= 0).all():  # every field built already: one gather
            return out
        if self._count and self._over_budget(len(np.unique(keys[out < 0]))):
            self._start_again()  # before any id is given out: this call's ids stay valid
            out = self._row_of[keys]
        for i, key in enumerate(keys.tolist()):
            row = int(self._row_of[key])
            if row < 0:
                if self._count >= self.capacity:
                    self._start_again()
                row = self._count
                if row >= len(self._table):
                    size = min(2 * len(self._table), self.capacity)
                    grown = np.empty((size,) + self._table.shape[1:], np.float32)
                    grown[: len(self._table)] = self._table
                    self._table = grown
                    nxt = np.empty((size,) + self._next.shape[1:], np.int32)
                    nxt[: len(self._next)] = self._next
                    self._next = nxt
                cell = np.array(
                    [
                        key // (self.shape[1] * self.shape[2]),
                        key // self.shape[2] % self.shape[1],
                        key % self.shape[2],
                    ]
                )
                centre = self.origin + (cell + 0.5) * self.size
                field = self._field_cls(self._tank, centre, None, self.clearance_cost)
                self._table[row] = field.dist.reshape(-1)
                kernel.descend_field(
                    field.dist.reshape(-1),
                    self._edges_flat,
                    field.weight_table,
                    self.neighbours,
                    self.shape,
                    self._next[row],
                )
                self._row_of[key] = row
                self._count += 1
            out[i] = row
        return out

    def lookahead(
        self,
        p: NDArray[np.float64],
        g: NDArray[np.float64],
        ids: NDArray[np.int64],
        hops: Sequence[int] = LOOKAHEAD_HOPS,
    ) -> NDArray[np.float64]:
        """Points ``(B, len(hops), 3)`` [cm] of the shortest ways from the tips ``p`` ahead.

        Each is where the way reaches after that many ``hops`` (increasing; grid steps of 10-17
        cm from the tip's grid point). A way that reaches the target's grid point ends at the
        target ``g`` itself.
        """
        out = np.empty((len(p), len(hops), 3))
        kernel.lookahead(
            np.ascontiguousarray(p, dtype=np.float64),
            np.ascontiguousarray(g, dtype=np.float64),
            np.asarray(ids, dtype=np.int64),
            self._next,
            np.asarray(hops, dtype=np.int64),
            self._kernel_grid(),
            out,
        )
        return out

    def _kernel_grid(self) -> kernel.Grid:
        """The grid as the compiled queries read it."""
        return self._origin, float(self.size), self.shape

    def __call__(
        self, p: NDArray[np.float64], g: NDArray[np.float64], ids: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Distance-to-go and way to go of tips ``p`` to targets ``g`` (fields: rows ``ids``).

        Returns ``P`` ``(B,)`` [cm] and the unit way ``(B, 3)``.
        """
        to_go, way = np.empty(len(p)), np.empty((len(p), 3))
        kernel.guide_query(
            np.ascontiguousarray(p, dtype=np.float64),
            np.ascontiguousarray(g, dtype=np.float64),
            np.asarray(ids, dtype=np.int64),
            self._table,
            self._edges_flat,
            self.neighbours,
            self._kernel_grid(),
            to_go,
            way,
        )
        return to_go, way


#: The guides :func:`field_guide` handed out that are alive (their tanks are): one budget.
_GUIDES: weakref.WeakSet[FieldGuide] = weakref.WeakSet()


def field_guide(tank: Tank, rows: int = 0) -> FieldGuide:
    """The :class:`FieldGuide` of a tank, shared by every env of it (its fields are kept).

    Raises:
        ConfigError: the guide keeps too few target fields for ``rows`` envs (two each).

    """
    guide = tank.memo("field_guide", lambda: FieldGuide(tank))
    _GUIDES.add(guide)
    if guide.capacity < 2 * rows:
        raise ConfigError(
            f"the guide keeps {guide.capacity} target fields of this tank's grid, too "
            f"few for {rows} envs; use fewer envs or guide=False"
        )
    return guide
