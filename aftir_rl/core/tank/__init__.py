"""Tanks: geometry from YAML, the raster of cubic cells, the signed distance and the scene export.

- :mod:`~aftir_rl.core.tank.solids`: boxes, axis-aligned cylinders and spheres, each with its
  bounds, signed distance, python-fcl object and drawing geometry;
- :mod:`~aftir_rl.core.tank.geometry`: :class:`Tank` (box, access panel, baffle and hatch,
  obstacles, the arm) and its :class:`Enclosure` (the walls, the floor open at the panel);
- :mod:`~aftir_rl.core.tank.raster`: :class:`Raster`, cubes of ``cell_size``, BFS, z-slices;
- :mod:`~aftir_rl.core.tank.distance`: :class:`TankDistance`, the signed distance to every solid
  and wall, compiled once per tank;
- :mod:`~aftir_rl.core.tank.loading`: :func:`load_tank` from ``configs/tanks/NAME.yaml`` or a
  path, validated key by key.

The tank YAML: docs/design.md §3; the raster: §4; the scene export
(``python -m aftir_rl.tank --json``): docs/design.md §5.
"""

from __future__ import annotations

from aftir_rl.core.tank.distance import SolidStack, TankDistance
from aftir_rl.core.tank.geometry import Baffle, Enclosure, Hatch, Panel, Tank
from aftir_rl.core.tank.loading import (
    RUN_TANK_FILE,
    TANK_DIR,
    available_tanks,
    keep_run_tank,
    load_tank,
    resolve_run_tank,
    tank_files,
    tank_from_mapping,
)
from aftir_rl.core.tank.raster import Raster
from aftir_rl.core.tank.solids import Box, Cylinder, Solid, Sphere, Vec3

__all__ = [
    "Box",
    "Cylinder",
    "Sphere",
    "Solid",
    "Vec3",
    "Panel",
    "Baffle",
    "Hatch",
    "Enclosure",
    "Raster",
    "Tank",
    "TankDistance",
    "SolidStack",
    "TANK_DIR",
    "load_tank",
    "resolve_run_tank",
    "keep_run_tank",
    "tank_files",
    "RUN_TANK_FILE",
    "tank_from_mapping",
    "available_tanks",
]
