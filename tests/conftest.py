from __future__ import annotations

from collections import deque

import numpy as np
import pytest

import aftir_rl  # noqa: F401  (registers the envs)
from aftir_rl.core.tank import load_tank


@pytest.fixture(scope="session")
def tank():
    return load_tank("b737_center")


def bfs_steps(obstructed: np.ndarray, start: tuple[int, int, int]) -> dict:
    """Independent BFS over a boolean obstruction grid (6-neighbourhood)."""
    dist = {start: 0}
    queue = deque([start])
    while queue:
        a, b, c = queue.popleft()
        for da, db, dc in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
            n = (a + da, b + db, c + dc)
            if all(0 <= n[i] < obstructed.shape[i] for i in range(3)) and not obstructed[n]:
                if n not in dist:
                    dist[n] = dist[(a, b, c)] + 1
                    queue.append(n)
    return dist


@pytest.fixture(scope="session")
def scene_grid(tank):
    """The obstruction grid rebuilt from the JSON scene export, and the BFS from the start."""
    scene = tank.scene_dict()
    grid = np.zeros(scene["raster"]["shape"], dtype=bool)
    for cell in scene["raster"]["obstructed"]:
        grid[tuple(cell)] = True
    return grid, bfs_steps(grid, (3, 2, 0))
