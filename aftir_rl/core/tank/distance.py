"""The signed distance [cm] from points to a tank's solids and walls, compiled for many calls.

:class:`SolidStack` stacks the parameters of solids of one kind (and, for cylinders, one axis)
into arrays and evaluates each kind's :meth:`~aftir_rl.core.tank.solids.Box.distance_field` on all
of them at once: one call is a few dozen numpy operations whatever the number of solids.
:class:`TankDistance` adds the walls (:class:`~aftir_rl.core.tank.geometry.Enclosure`: the floor's
round opening continued as the guide tube below it). It is the one signed distance of the
package: :attr:`Tank.distance <aftir_rl.core.tank.geometry.Tank.distance>` and
:func:`aftir_rl.core.collision.point_clearance` are this class, and the compiled kernels (the FTL
env's contact check among them) evaluate its formulas (:func:`aftir_rl.core.kernel.geometry.sdf`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.tank.solids import Solid

__all__ = ["SolidStack", "TankDistance", "DistanceScene"]


class DistanceScene(Protocol):
    """What :class:`TankDistance` reads of a tank (:class:`~aftir_rl.core.tank.geometry.Tank`)."""

    @property
    def solids(self) -> Sequence[Solid]: ...  # noqa: D102

    @property
    def enclosure(self) -> Any: ...  # noqa: D102

    @property
    def walls(self) -> bool: ...  # noqa: D102

    @property
    def box_min(self) -> Any: ...  # noqa: D102

    @property
    def panel(self) -> Any: ...  # noqa: D102


class SolidStack:
    """The nearest of several solids: their signed distance fields evaluated stacked.

    Args:
        solids: any boxes, cylinders and spheres.

    """

    def __init__(self, solids: Sequence[Solid]) -> None:
        groups: dict[tuple[str, int], list[Solid]] = {}
        for solid in solids:
            groups.setdefault((solid.kind, solid.stack_key), []).append(solid)
        #: (the distance field of the group's kind, the group's parameters as arrays (S,))
        self._groups = [
            (group[0].distance_field, np.array([s.distance_params for s in group], float).T)
            for group in groups.values()
        ]

    def signed_distance_xyz(
        self, x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Signed distance [cm] of points ``(x, y, z)``, each ``(P,)``, to the nearest solid.

        ``inf`` without solids.
        """
        best = np.full(len(x), np.inf)
        x, y, z = x[:, None], y[:, None], z[:, None]
        for field, params in self._groups:
            best = np.minimum(best, field(x, y, z, *params).min(-1))
        return best


class TankDistance:
    """Signed distance [cm] of points to the nearest solid or wall of a tank (< 0 inside).

    Every solid (:class:`SolidStack`) and, for a tank with walls, its
    :class:`~aftir_rl.core.tank.geometry.Enclosure`: side walls, ceiling, and the floor with the
    panel's round opening continued below it as the guide tube (python-fcl's floor slab has the
    square around that circle as its opening, so this is stricter).

    Args:
        tank: the tank.
        solids: the solids to measure against (default: the tank's).

    """

    def __init__(self, tank: DistanceScene, solids: Sequence[Solid] | None = None) -> None:
        self.tank = tank
        solids = tank.solids if solids is None else solids
        self._solids = SolidStack(solids)
        self._walls = tank.enclosure if tank.walls else None
        # Points below this height skip the solids: the guide tube (at most the panel's radius
        # away, or negative outside it) is nearer than any solid, which lies at least that far up.
        lowest = min((float(s.aabb()[0][2]) for s in solids), default=np.inf)
        self._skip_below = min(float(tank.box_min[2]), lowest) - tank.panel.radius

    def __call__(self, points: ArrayLike) -> NDArray[np.float64]:
        """Signed distance [cm] of points ``(..., 3)`` to the nearest solid or wall."""
        p = np.asarray(points, dtype=np.float64)
        flat = p.reshape(-1, 3)
        if self._walls is None:
            return self._solids.signed_distance_xyz(flat[:, 0], flat[:, 1], flat[:, 2]).reshape(
                p.shape[:-1]
            )
        near = np.flatnonzero(flat[:, 2] > self._skip_below)
        best: NDArray[np.float64] = np.full(len(flat), np.inf)
        q = flat[near]
        best[near] = self._solids.signed_distance_xyz(q[:, 0], q[:, 1], q[:, 2])
        walls = self._walls.signed_distance_xyz(p[..., 0], p[..., 1], p[..., 2])
        return np.minimum(best.reshape(p.shape[:-1]), walls)
