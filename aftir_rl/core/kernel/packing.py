"""A tank's solids and clearance grids packed into the arrays the compiled kernels read."""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.tank import Tank

__all__ = ["kernel_tank"]


def _solid_rows(tank: Tank) -> tuple[dict[str, list[tuple[float, ...]]], NDArray[np.float32]]:
    """Each kind's rows of parameters (plates' holes as rows of their own), and mesh grids."""
    rows: dict[str, list[tuple[float, ...]]] = {
        k: [] for k in ("box", "cylinder", "sphere", "plate", "hole", "wedge", "mesh")
    }
    mesh_values: list[NDArray[np.float32]] = []
    for solid in tank.solids:
        if solid.kind == "mesh":
            lo, g, values = cast(Any, solid).grid
            start = sum(len(v) for v in mesh_values)
            rows["mesh"].append((*lo, g, *values.shape, start, *np.concatenate(solid.aabb())))
            mesh_values.append(values.ravel())
            continue
        params = tuple(float(v) for v in solid.distance_params)
        if solid.kind == "plate":
            holes = rows["hole"]
            n_holes = (len(params) - 7) // 5
            rows["plate"].append((*params[:7], len(holes), len(holes) + n_holes))
            holes.extend(params[i : i + 5] for i in range(7, len(params), 5))
            continue
        if solid.kind == "cylinder":
            params += (float(solid.stack_key),)
        rows[solid.kind].append(params)
    values = np.concatenate(mesh_values) if mesh_values else np.zeros(0, np.float32)
    return rows, values


def kernel_tank(tank: Tank, grid: Any = None) -> KernelTank:
    """The :class:`KernelTank` of a tank and its clearance grid.

    ``grid`` is the tank's :class:`~aftir_rl.core.kernel.clearance.ClearanceGrid`, or None for
    none (every distance then exact: what the grid itself is filled with).
    """
    rows, mesh_values = _solid_rows(tank)

    def stack(rows: list[tuple[float, ...]], width: int) -> NDArray[np.float64]:
        return np.array(rows, dtype=np.float64).reshape(-1, width)

    lowest = min((float(s.aabb()[0][2]) for s in tank.solids), default=math.inf)
    c, r = tank.panel.center, float(tank.panel.radius)
    walls = np.array(
        [float(tank.walls), *tank.box_min, *tank.box_max, c[0], c[1], r,
         min(float(tank.box_min[2]), lowest) - r],
        dtype=np.float64,
    )  # fmt: skip
    grids = [] if grid is None else grid.grids
    offsets, total = [], 0
    for _, _, _, values in grids:
        offsets.append(total)
        total += len(values)
    return KernelTank(
        stack(rows["box"], 6),
        stack(rows["cylinder"], 6),
        stack(rows["sphere"], 4),
        stack(rows["plate"], 9),
        stack(rows["hole"], 5),
        stack(rows["wedge"], 9),
        stack(rows["mesh"], 14),
        mesh_values,
        walls,
        np.array([lo for lo, _, _, _ in grids], dtype=np.float64).reshape(-1, 3),
        np.array([g for _, g, _, _ in grids], dtype=np.float64),
        np.array([shape for _, _, shape, _ in grids], dtype=np.int64).reshape(-1, 3),
        np.array(offsets, dtype=np.int64),
        np.concatenate([np.zeros(0), *(values for _, _, _, values in grids)]).astype(np.float64),
        0.0 if grid is None else float(grid.slack),
    )
