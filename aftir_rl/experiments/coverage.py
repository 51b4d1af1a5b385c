"""How much of a surface a motion's tip camera sees, measured by ray casting on the tank's mesh.

The check apart from the planner: it reads only the motion's postures, places the camera at the
tip of each (forward kinematics), draws its own surface samples, and casts a ray from the
camera to every sample within the camera's cone, range and incidence limits against the
triangles of :func:`~aftir_rl.core.tank.surface.scene_mesh` (trimesh, not the planner's
signed distance). The arm's own body is not an occluder (the camera looks ahead of the tip).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.camera import Camera
from aftir_rl.core.robot import forward_kinematics
from aftir_rl.core.tank import Tank
from aftir_rl.core.tank.surface import SurfaceSamples, scene_mesh, surface_samples

__all__ = ["CoverageMeasure", "camera_poses", "measure_coverage", "seen_from_poses"]

#: A ray that hits a triangle this much [cm] before the sample it aims at is blocked.
RAY_TOLERANCE = 0.5
#: Poses whose rays are cast together.
POSE_CHUNK = 16


@dataclass(frozen=True)
class CoverageMeasure:
    """The share of the surface samples seen, with how it was measured."""

    fraction: float
    samples: int
    area_cm2: float
    poses: int
    rays: int
    seconds: float

    def to_json(self) -> dict[str, Any]:
        """The measure as a plain mapping."""
        return {
            "fraction": self.fraction,
            "samples": self.samples,
            "surface_area_cm2": self.area_cm2,
            "seen_area_cm2": self.fraction * self.area_cm2,
            "camera_poses": self.poses,
            "rays": self.rays,
            "seconds": self.seconds,
        }


def camera_poses(
    dis: ArrayLike, theta: ArrayLike, phi: ArrayLike, section_length: float, step: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tip positions and unit tip tangents of the postures.

    One posture where the tip moved ``step`` cm or turned 2° since the last one kept.
    """
    frames = forward_kinematics(dis, theta, phi, section_length)[..., -1, :3, :]
    tips, looks = frames[:, :, 3], frames[:, :, 2]
    keep, last = [0], 0
    for i in range(1, len(tips)):
        moved = np.linalg.norm(tips[i] - tips[last])
        if moved >= step or looks[i] @ looks[last] < np.cos(np.radians(2.0)):
            keep.append(i)
            last = i
    return tips[keep], looks[keep]


def _candidates(
    c: NDArray[np.float64], w: NDArray[np.float64], points: NDArray[np.float64],
    normals: NDArray[np.float64], camera: Camera,
) -> NDArray[np.bool_]:  # fmt: skip
    """Samples within the camera's cone, range and incidence limits (before occlusion)."""
    cos_fov, reach, cos_max, cos_min = camera.cosines()
    v = points - c
    d = np.linalg.norm(v, axis=1)
    u = v / np.maximum(d, 1e-12)[:, None]
    facing = -np.einsum("ij,ij->i", u, normals)
    return (
        (d <= reach)
        & (d > 1e-9)
        & (u @ w >= cos_fov)
        & (facing >= cos_max)
        & (facing <= cos_min + 1e-12)
    )


def seen_from_poses(
    mesh: Any,
    tips: NDArray[np.float64],
    looks: NDArray[np.float64],
    surface: SurfaceSamples,
    camera: Camera,
) -> tuple[NDArray[np.bool_], int]:
    """Which samples a camera at some tip ``(P, 3)`` looking along ``looks`` sees; rays cast.

    A ray from the camera to a sample within the cone, range and incidence limits is cast
    against ``mesh`` (a ``trimesh.Trimesh``); the sample is seen where the first triangle hit
    is not :data:`RAY_TOLERANCE` before it.
    """
    seen = np.zeros(len(surface.points), dtype=np.bool_)
    rays = 0
    for at in range(0, len(tips), POSE_CHUNK):
        origins, targets = [], []
        for c, w in zip(tips[at : at + POSE_CHUNK], looks[at : at + POSE_CHUNK]):
            todo = np.flatnonzero(~seen)
            hit = todo[_candidates(c, w, surface.points[todo], surface.normals[todo], camera)]
            origins.append(np.broadcast_to(c, (len(hit), 3)))
            targets.append(hit)
        index = np.concatenate(targets)
        if len(index) == 0:
            continue
        o = np.vstack(origins)
        v = surface.points[index] - o
        d = np.linalg.norm(v, axis=1)
        where, ray, _ = mesh.ray.intersects_location(o, v / d[:, None], multiple_hits=False)
        first = np.full(len(index), np.inf)
        first[ray] = np.linalg.norm(where - o[ray], axis=1)
        seen[index[first >= d - RAY_TOLERANCE]] = True
        rays += len(index)
    return seen, rays


def measure_coverage(
    tank: Tank,
    motion: tuple[ArrayLike, ArrayLike, ArrayLike],
    box: tuple[ArrayLike, ArrayLike],
    camera: Camera | None = None,
    samples: int = 4000,
    seed: int = 1_000_003,
) -> CoverageMeasure:
    """The share of the surface in ``box`` the tip camera sees along ``motion`` (dis, θ, φ)."""
    start, camera = time.perf_counter(), camera or tank.arm.camera
    surface = surface_samples(tank, box, samples, seed)
    mesh = scene_mesh(tank)
    dis, theta, phi = (np.asarray(a, dtype=np.float64) for a in motion)
    tips, looks = camera_poses(dis, theta, phi, tank.arm.section_length)
    inside = tips[:, 2] > tank.box_min[2]  # the guide below the floor sees nothing
    tips, looks = tips[inside], looks[inside]
    seen, rays = seen_from_poses(mesh, tips, looks, surface, camera)
    return CoverageMeasure(float(seen.mean()), len(seen), surface.area_cm2, len(tips), rays,
                           time.perf_counter() - start)  # fmt: skip
