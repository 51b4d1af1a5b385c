"""The tank's signed distance on grids: exact clearances of many points, pruned by bounds.

:class:`ClearanceGrid` tabulates the signed distance where it is 1-Lipschitz, so per row of
points only the samples that can hold the minimum go to the exact function (the result equals
the exact minimum); :func:`kernel_grid` packs it with the tank's solids for the compiled
kernels. Shared by the follow-the-leader planner and the FTL env. The bounds: docs/envs/armftl.md.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.kernel.arrays import KernelTank
from aftir_rl.core.kernel.geometry import sdf_points
from aftir_rl.core.kernel.packing import kernel_tank
from aftir_rl.core.tank import Tank

__all__ = [
    "ClearanceGrid",
    "clearance_grid",
    "compiled_distance",
    "kernel_grid",
    "GRID_SPACING",
    "MAX_GRID_NODES",
]

#: Grid spacing [cm] of :class:`ClearanceGrid`.
GRID_SPACING = 2.0
#: Largest number of grid nodes a tank may ask for (about 8 bytes each).
MAX_GRID_NODES = 8_000_000


class ClearanceGrid:
    """Exact per-row minimum signed distance of many points, pruned by tabulated bounds.

    Args:
        distance: the exact signed distance [cm] of points ``(..., 3)`` (e.g.
            :class:`aftir_rl.core.tank.TankDistance`).
        boxes: ``(lo, hi)`` corners [cm] of the boxes the grids cover (e.g. the tank and the
            guide tube below its floor); points outside every box are always computed exactly.
            Within each box ``distance`` must be 1-Lipschitz (a true signed distance, with no
            jump), or the bounds are wrong.
        spacing: grid spacing ``g`` [cm] (grown for a box until its grid has at most
            :data:`MAX_GRID_NODES` nodes).
        lipschitz: a bound on how fast ``distance`` changes (1 for a true signed distance; √3
            for a grid read trilinearly, as a mesh solid's is).
        fill: the function the nodes are filled with (default ``distance``): the same distance
            computed faster (:func:`compiled_distance`).

    """

    def __init__(
        self,
        distance: Callable[[NDArray[np.float64]], NDArray[np.float64]],
        boxes: Sequence[tuple[ArrayLike, ArrayLike]],
        spacing: float = GRID_SPACING,
        lipschitz: float = 1.0,
        fill: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    ) -> None:
        self.distance = distance
        fill = fill or distance
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
            values = np.concatenate([fill(c) for c in chunks]).astype(np.float64)
            self.grids.append((lo, g, shape, values))
            self.slack = max(self.slack, lipschitz * g * math.sqrt(3.0) / 2.0)

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


def clearance_grid(tank: Tank) -> ClearanceGrid:
    """The :class:`ClearanceGrid` of a tank, built once per tank.

    The grids cover only where the signed distance is 1-Lipschitz, as their bound needs: the
    tank's box grown by 10 cm sideways and above (not below the floor, where the distance jumps
    at the guide's wall), and a column around the guide's axis below the floor, narrow enough
    that no node or point of it reaches the wall, down to the deepest base of the longest arm.
    Everything else is computed exactly.
    """

    def build() -> ClearanceGrid:
        lo, hi = np.asarray(tank.box_min, float) - 10.0, np.asarray(tank.box_max, float) + 10.0
        lo[2] = tank.box_min[2]
        c, r = np.asarray(tank.panel.center, float), float(tank.panel.radius)
        half = max((r - 2.0 * GRID_SPACING) / math.sqrt(2.0), 0.0)
        depth = tank.arm.max_sections * tank.arm.section_length + 10.0
        column = (c - [half, half, depth], c + [half, half, 0.0])
        steep = any(s.kind == "mesh" for s in tank.solids)
        return ClearanceGrid(
            tank.distance,
            [(lo, hi), column],
            lipschitz=math.sqrt(3.0) if steep else 1.0,
            fill=compiled_distance(tank),
        )

    return tank.memo("clearance_grid", build)


def compiled_distance(tank: Tank) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """The tank's signed distance [cm] of points ``(..., 3)``, compiled: the fast way to fill grids.

    :func:`~aftir_rl.core.kernel.geometry.sdf`, the formulas of :attr:`Tank.distance
    <aftir_rl.core.tank.geometry.Tank.distance>` compiled (equal to within 1e-12 cm), with no
    grid to prune by: about 5 times as fast on a grid's hundred thousands of nodes.
    """
    packed = tank.memo("exact_kernel", lambda: kernel_tank(tank))

    def distance(points: NDArray[np.float64]) -> NDArray[np.float64]:
        p = np.ascontiguousarray(points, dtype=np.float64)
        flat = p.reshape(-1, 3)
        out = np.empty(len(flat), dtype=np.float64)
        sdf_points(flat, packed, out)
        return out.reshape(p.shape[:-1])

    return distance


_KERNEL_TANKS: weakref.WeakKeyDictionary[Tank, KernelTank] = weakref.WeakKeyDictionary()


def kernel_grid(tank: Tank) -> KernelTank:
    """The tank's signed distance and :func:`clearance_grid` as the compiled kernels read them.

    Built once per tank (:func:`~aftir_rl.core.kernel.packing.kernel_tank`).
    """
    packed = _KERNEL_TANKS.get(tank)
    if packed is None:
        packed = _KERNEL_TANKS[tank] = kernel_tank(tank, clearance_grid(tank))
    return packed
