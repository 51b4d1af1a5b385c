"""The raster's all-pairs 6-connected distances: one breadth-first search per cell."""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["all_pairs_bfs"]


@njit(cache=True)
def all_pairs_bfs(free: NDArray[np.bool_], nx: int, ny: int, nz: int) -> NDArray[np.int32]:
    """``D[s, c]``: 6-connected steps from cell ``s`` to cell ``c`` through free cells, −1 if none.

    ``free`` is the raster's free mask, flat in C order (cell ``(a, b, c)`` is
    ``(a·ny + b)·nz + c``). Every cell is a source, free or not; a path's other cells before its
    end are free; an obstructed end cell is one step from its nearest free neighbour the search
    reached (or from the source itself). ``O(cells²)`` time, no other memory than the table.
    """
    n = nx * ny * nz
    out = np.full((n, n), -1, dtype=np.int32)
    queue = np.empty(n, dtype=np.int64)
    strides = (ny * nz, nz, 1)
    sizes = (nx, ny, nz)
    for s in range(n):
        row = out[s]
        row[s] = 0
        queue[0] = s
        head, tail = 0, 1
        while head < tail:
            u = queue[head]
            head += 1
            coords = (u // strides[0], (u // strides[1]) % ny, u % nz)
            for axis in range(3):
                for step in (-1, 1):
                    x = coords[axis] + step
                    if x < 0 or x >= sizes[axis]:
                        continue
                    v = u + step * strides[axis]
                    if free[v] and row[v] < 0:
                        row[v] = row[u] + 1
                        queue[tail] = v
                        tail += 1
        for c in range(n):  # obstructed ends: one step from a reached free neighbour or the source
            if free[c] or c == s:
                continue
            coords = (c // strides[0], (c // strides[1]) % ny, c % nz)
            best = -1
            for axis in range(3):
                for step in (-1, 1):
                    x = coords[axis] + step
                    if x < 0 or x >= sizes[axis]:
                        continue
                    w = c + step * strides[axis]
                    if (free[w] or w == s) and row[w] >= 0 and (best < 0 or row[w] + 1 < best):
                        best = row[w] + 1
            row[c] = best
    return out
