"""A tank box split into cubic cells: cell indexing, BFS through free cells, a z-slice text view.

A cell is *obstructed* when a solid overlaps its cube with positive volume (a solid that only
touches a face does not obstruct it); :attr:`Tank.raster <aftir_rl.core.tank.geometry.Tank.raster>`
builds it from the tank's solids.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import TargetError
from aftir_rl.core.tank.solids import Vec3

__all__ = ["Raster", "format_point"]


def format_point(v: ArrayLike) -> str:
    """``(x, y, z)`` with ``%g`` numbers, for messages."""
    return "(" + ", ".join(f"{float(x):g}" for x in np.asarray(v).ravel()) + ")"


@dataclass(frozen=True)
class Raster:
    """The box split into cubic cells; cell ``(a, b, c)`` counts from the box minimum, 0-based.

    Attributes:
        origin: the box minimum [cm].
        cell_size: edge of a cell [cm].
        obstructed: boolean array of shape ``shape``; True where a solid overlaps the cell.

    """

    origin: Vec3
    cell_size: float
    obstructed: NDArray[np.bool_] = field(repr=False)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Number of cells along x, y, z."""
        return tuple(int(n) for n in self.obstructed.shape)  # type: ignore[return-value]

    @property
    def n_cells(self) -> int:
        """Total number of cells."""
        return int(self.obstructed.size)

    def in_bounds(self, cell: Sequence[int]) -> bool:
        """Whether ``cell`` is inside the raster."""
        return all(0 <= int(c) < n for c, n in zip(cell, self.shape))

    def point_to_cell(self, point: ArrayLike) -> tuple[int, int, int]:
        """The cell holding ``point`` [cm]; points on the box's upper faces belong to the last cell.

        Raises:
            TargetError: the point is outside the box.

        """
        p = np.asarray(point, dtype=np.float64)
        rel = (p - np.array(self.origin)) / self.cell_size
        upper = np.array(self.shape)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or np.any(rel < 0) or np.any(rel > upper):
            lo = np.array(self.origin)
            hi = lo + upper * self.cell_size
            box = f"{format_point(lo)}..{format_point(hi)}"
            raise TargetError(
                f"point {format_point(p)} cm is outside the tank box {box} cm; "
                "give a point inside it"
            )
        cell = np.minimum(np.floor(rel).astype(int), upper - 1)
        return (int(cell[0]), int(cell[1]), int(cell[2]))

    def cell_indices(self, points: ArrayLike) -> NDArray[np.int64]:
        """Flat indices (:meth:`index`) of the cells holding points ``(..., 3)`` [cm], vectorised.

        Points outside the box count as in the nearest cell (clipped), unlike
        :meth:`point_to_cell`, which refuses them.
        """
        rel = (np.asarray(points, dtype=np.float64) - np.array(self.origin)) / self.cell_size
        shape = np.array(self.shape)
        c = np.clip(np.floor(rel).astype(np.int64), 0, shape - 1)
        return (c[..., 0] * shape[1] + c[..., 1]) * shape[2] + c[..., 2]

    def cell_center(self, cell: Sequence[int]) -> NDArray[np.float64]:
        """Centre of ``cell`` [cm]."""
        return np.array(self.origin) + (np.asarray(cell, dtype=np.float64) + 0.5) * self.cell_size

    def cell_bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lower and upper corners of every cell, each of shape ``shape + (3,)``."""
        idx = np.stack(np.meshgrid(*[np.arange(n) for n in self.shape], indexing="ij"), axis=-1)
        lo = np.array(self.origin) + idx * self.cell_size
        return lo, lo + self.cell_size

    def index(self, cell: Iterable[int]) -> int:
        """Flat state index ``ravel_multi_index(cell, shape)``."""
        return int(np.ravel_multi_index(tuple(int(c) for c in cell), self.shape))

    def cell(self, index: int) -> tuple[int, int, int]:
        """Cell of a flat state index."""
        a, b, c = np.unravel_index(int(index), self.shape)
        return (int(a), int(b), int(c))

    def bfs_distances(self, start: Sequence[int]) -> NDArray[np.int64]:
        """BFS steps from ``start`` through free cells (6-neighbourhood); -1 where unreachable."""
        dist = np.full(self.shape, -1, dtype=np.int64)
        start = tuple(int(c) for c in start)
        if self.obstructed[start]:
            return dist
        dist[start] = 0
        queue = deque([start])
        while queue:
            cur = queue.popleft()
            for axis in range(3):
                for step in (-1, 1):
                    nxt = list(cur)
                    nxt[axis] += step
                    t = tuple(nxt)
                    if self.in_bounds(t) and not self.obstructed[t] and dist[t] < 0:
                        dist[t] = dist[cur] + 1
                        queue.append(t)
        return dist

    def ascii(self, marks: Mapping[tuple[int, int, int], str] | None = None) -> str:
        """Z-slices of the raster, top slice first, y growing upwards in each slice.

        ``#`` is an obstructed cell, ``.`` a free one; ``marks`` puts a character on given cells.
        """
        marks = dict(marks or {})
        nx, ny, nz = self.shape
        lines = []
        for c in reversed(range(nz)):
            z0 = self.origin[2] + c * self.cell_size
            lines.append(f"z in [{z0:g}, {z0 + self.cell_size:g}) cm  (c = {c})")
            for b in reversed(range(ny)):
                row = "".join(
                    marks.get((a, b, c), "#" if self.obstructed[a, b, c] else ".")
                    for a in range(nx)
                )
                lines.append(f"  b={b:<2d} {row}")
            lines.append("       " + "".join(str(a % 10) for a in range(nx)) + "  (a)")
        return "\n".join(lines)
