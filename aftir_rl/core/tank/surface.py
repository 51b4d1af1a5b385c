"""The tank's surface as a mesh, and points sampled on it by area: what an inspection must see.

:func:`scene_mesh` is every solid and (where the tank has them) the walls as one outward
triangle mesh; :func:`surface_samples` draws points uniformly by area on the part of it inside
a box (e.g. a bay), keeping those that face the free space, each with its normal. Needs trimesh
(``aftir_rl[mesh]``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.extras import require
from aftir_rl.core.tank.geometry import Tank
from aftir_rl.core.tank.meshes import is_walls, tank_bodies

__all__ = ["SurfaceSamples", "scene_mesh", "surface_samples", "MAX_SURFACE_SAMPLES"]

#: The most surface points one call draws.
MAX_SURFACE_SAMPLES = 200_000
#: How far [cm] off the surface a sample's free side is tested, and the clearance it needs there.
FREE_SIDE = 1.0


@dataclass(frozen=True)
class SurfaceSamples:
    """Points on the surface ``(S, 3)`` [cm], their unit normals into the free space, the area.

    Every point stands for ``area_cm2 / S`` of the surface.
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    area_cm2: float


def scene_mesh(tank: Tank) -> Any:
    """The tank's solids and walls as one ``trimesh.Trimesh`` (outward faces; not merged)."""
    trimesh = require("trimesh", "mesh")
    parts = [tank_bodies(tank)] if any(not is_walls(s) for s in tank.solids) else []
    parts += [s.mesh() for s in tank.solids if is_walls(s)]  # facing the inside
    if tank.walls:
        parts += [slab.mesh() for slab in tank.enclosure.slabs()]
    if not parts:
        raise ConfigError(f"{tank.name} has no surface: no walls and no solids")
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    return trimesh.Trimesh(
        np.vstack([v for v, _ in parts]),
        np.vstack([np.asarray(f) + o for (_, f), o in zip(parts, offsets)]),
        process=False,
    )


def _facing_free_space(
    tank: Tank, points: NDArray[np.float64], normals: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Whether free space lies along each normal, just off the face and :data:`FREE_SIDE` out.

    (A face under a thin sliver of another solid, e.g. a wall under a taper, is not surface.)
    """
    out = tank.distance(points + FREE_SIDE * normals) > FREE_SIDE / 2
    return out & (tank.distance(points + 0.2 * normals) > 0.1)


def surface_samples(tank: Tank, box: tuple[ArrayLike, ArrayLike], count: int, seed: int = 0
                    ) -> SurfaceSamples:  # fmt: skip
    """About ``count`` points drawn by area on the surface inside ``box`` that face free space.

    A point is kept where the tank is at least half of :data:`FREE_SIDE` away from it at
    :data:`FREE_SIDE` along its normal, and 0.1 cm away at 0.2 cm along it (faces buried in
    another solid or in a wall are not surface).
    """
    trimesh = require("trimesh", "mesh")
    if not 1 <= count <= MAX_SURFACE_SAMPLES:
        raise ConfigError(f"surface samples: expected 1 to {MAX_SURFACE_SAMPLES:,}, got {count}")
    lo, hi = (np.asarray(b, dtype=np.float64) - 0.5 for b in box)
    hi = hi + 1.0  # the box, 0.5 cm beyond each side
    mesh = scene_mesh(tank)
    tri = mesh.triangles
    near = np.all(tri.min(axis=1) <= hi, axis=1) & np.all(tri.max(axis=1) >= lo, axis=1)
    if not near.any():
        raise ConfigError(f"no surface of {tank.name} inside {lo.tolist()}..{hi.tolist()}")
    part = trimesh.Trimesh(mesh.vertices, mesh.faces[near], process=False)
    rng = np.random.default_rng(seed)
    points: list[NDArray[np.float64]] = []
    normals: list[NDArray[np.float64]] = []
    kept, drawn = 0, 0
    while kept < count and drawn < 64 * count:
        xyz, faces = trimesh.sample.sample_surface(part, 4 * count, seed=rng)
        n = part.face_normals[faces]
        inside = np.all((xyz >= lo) & (xyz <= hi), axis=1)
        inside[inside] = _facing_free_space(tank, xyz[inside], n[inside])
        points.append(xyz[inside])
        normals.append(n[inside])
        kept, drawn = kept + int(inside.sum()), drawn + len(xyz)
    if kept == 0:
        raise ConfigError(f"no surface of {tank.name} inside the box faces its free space")
    area = float(part.area) * kept / drawn
    keep = slice(0, count)
    return SurfaceSamples(np.vstack(points)[keep], np.vstack(normals)[keep], area)
