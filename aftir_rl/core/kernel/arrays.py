"""The arrays the compiled kernels read: a batch of arms and a tank (no compiled code here)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["KernelArms", "KernelTank"]


class KernelArms(NamedTuple):
    """A batch of arms as the kernels read them: the state, then what :func:`refresh` derives.

    The route ``kappa (B, N, 2)``, the steered section ``k (B,)`` and the tip's arc length ``s
    (B,)``; the posture ``theta``, ``phi (B, N)``, the backbone ``points (B, N·K + 1, 3)``, the
    tip's ``heading (B, 3)``, the ``body_clearance (B,)`` and the ``ray_clearance (B, R)``.
    """

    kappa: NDArray[np.float64]
    k: NDArray[np.int64]
    s: NDArray[np.float64]
    theta: NDArray[np.float64]
    phi: NDArray[np.float64]
    points: NDArray[np.float64]
    heading: NDArray[np.float64]
    body_clearance: NDArray[np.float64]
    ray_clearance: NDArray[np.float64]


class KernelTank(NamedTuple):
    """A tank's signed distance and clearance grids as the arrays the kernels read.

    ``boxes (S, 6)``: centre and half-size; ``cylinders (S, 6)``: the axis's two coordinates
    across, radius, middle and half-length along, and the axis (0, 1, 2); ``spheres (S, 4)``;
    ``plates (P, 9)``: axis, position, half thickness, the rectangle's corners in the plane and
    the range of the plate's rows of ``holes (H, 5)`` (shape code, centre, half-sizes);
    ``wedges (W, 9)``: axis, middle, half length and the triangle's corners;
    ``meshes (M, 14)``: a mesh solid's grid corner, spacing, shape, offset into ``mesh_values``
    and its box's corners;
    ``walls (11,)``: whether the tank has walls, its box's corners, the panel's centre (x, y)
    and radius, and the height below which solids are skipped (as
    :class:`~aftir_rl.core.tank.distance.TankDistance`). The grids: per grid its corner ``lo
    (G, 3)``, spacing ``(G,)``, shape ``(G, 3)`` and offset ``(G,)`` into the concatenated
    values; ``slack`` bounds a value's distance from the exact one.
    """

    boxes: NDArray[np.float64]
    cylinders: NDArray[np.float64]
    spheres: NDArray[np.float64]
    plates: NDArray[np.float64]
    holes: NDArray[np.float64]
    wedges: NDArray[np.float64]
    meshes: NDArray[np.float64]
    mesh_values: NDArray[np.float32]
    walls: NDArray[np.float64]
    grid_lo: NDArray[np.float64]
    grid_spacing: NDArray[np.float64]
    grid_shape: NDArray[np.int64]
    grid_offset: NDArray[np.int64]
    grid_values: NDArray[np.float64]
    slack: float
