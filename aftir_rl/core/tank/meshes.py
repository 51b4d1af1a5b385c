"""Tanks from triangle meshes: read, check and measure a mesh solid; write a tank as a mesh.

:func:`read_mesh` reads STL, OBJ or PLY with trimesh (``aftir_rl[mesh]``) within bounds (file
size, triangles, coordinates) and refuses, in one line, a mesh with NaN or huge vertices,
degenerate triangles, holes (an edge not matched by one in the opposite direction), or inverted
normals. :class:`MeshSolid` is a tank solid made of it: its signed distance is tabulated on a
grid (exact at the nodes within :data:`BAND` of a triangle; beyond, the distance to the nearest of
the mesh points its neighbours found, an upper bound, near-exact; inside where
the oriented crossings below a node are positive, so overlapping closed bodies are their union)
and read trilinearly; the raster marks cells a triangle cuts or whose centre is inside;
python-fcl gets a BVH model, hollow, so the collision check adds the inside test of the grid.
:func:`export_tank_mesh` writes any tank's solids as one mesh. More: docs/tanks.md.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, cast

import fcl
import numpy as np
import yaml
from numpy.typing import NDArray

from aftir_rl.core.config import read_limited
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.extras import require
from aftir_rl.core.files import atomic_open
from aftir_rl.core.tank import mesh_kernels
from aftir_rl.core.tank.solids import Box, Mesh, Shape
from aftir_rl.core.tank.wedge import Wedge, taper_side

if TYPE_CHECKING:
    from aftir_rl.core.tank.geometry import Tank
    from aftir_rl.core.tank.plate import Plate

__all__ = [
    "MeshSolid",
    "read_mesh",
    "export_tank_mesh",
    "is_walls",
    "MAX_MESH_BYTES",
    "MAX_TRIANGLES",
]

_Array = NDArray[np.float64]
#: Largest mesh file read [bytes], and most triangles in it.
MAX_MESH_BYTES = 128 * 2**20
MAX_TRIANGLES = 1_000_000
#: Largest magnitude of a vertex coordinate [cm], as for every tank coordinate.
MAX_MESH_COORD = 1e4
#: Spacing of the signed-distance grid [cm] (grown until it has at most MAX_GRID_NODES nodes),
#: and the band around the surface where its values are exact [cm].
GRID_SPACING = 1.0
MAX_GRID_NODES = 16_000_000
BAND = 2.0
#: How far [cm] the grid reaches beyond the mesh and the tank's box.
GRID_PAD = 6.0
MESH_SUFFIXES = (".stl", ".obj", ".ply")
#: Vertices this near [cm] the walls' lowest plane are in their floor.
FLOOR_EPS = 1e-6
#: How far below a tank's floor [cm] the grid of its meshes reaches: the panel's opening
#: continues down as the linear module's guide, where the arm's body is checked too.
GUIDE_DEPTH = 20.0


def _trimesh() -> Any:
    return require("trimesh", "mesh")


def _counted(data: bytes, suffix: str, where: str) -> int:
    """The triangles (or faces) a mesh file's bytes declare, before any parsing.

    A binary STL's header count must match its size; a PLY's header names its elements; an
    ASCII STL and an OBJ are counted by their facet and face lines (an OBJ polygon of ``k``
    corners is ``k − 2`` triangles: its corners are counted too). Vertices are bounded as well.

    Raises:
        ConfigError: a count above :data:`MAX_TRIANGLES`, or a binary STL whose header and size
            disagree.

    """
    faces, vertices = 0, 0
    declared = int(np.frombuffer(data[80:84], dtype="<u4")[0]) if len(data) >= 84 else -1
    binary = len(data) == 84 + 50 * declared  # an ASCII STL starts "solid"; a binary may too
    if suffix == ".stl" and not (data[:5].lower() == b"solid" and not binary):
        if len(data) < 84:
            raise ConfigError(f"{where}: not a binary STL (shorter than its 84-byte header)")
        faces = declared
        if not binary:
            raise ConfigError(
                f"{where}: not a valid binary STL: its header says {faces:,} triangles "
                f"({84 + 50 * faces:,} bytes), the file holds {len(data):,} bytes"
            )
    elif suffix == ".stl":
        faces = data.count(b"endfacet")
    elif suffix == ".ply":
        header = data[: data.find(b"end_header")] if b"end_header" in data else b""
        for line in header.decode("latin-1").splitlines():
            words = line.split()
            if len(words) == 3 and words[0] == "element" and words[2].isdigit():
                count = int(words[2][:12])
                faces += count if words[1] == "face" else 0
                vertices += count if words[1] == "vertex" else 0
    else:  # .obj: each face line's corners beyond two are triangles
        lines = data.replace(b"\r", b"\n").split(b"\n")
        corners = [len(line.split()) - 1 for line in lines if line.startswith(b"f ")]
        faces = sum(max(k - 2, 1) for k in corners)
        vertices = sum(1 for line in lines if line.startswith(b"v "))
    if faces > MAX_TRIANGLES or vertices > 3 * MAX_TRIANGLES:
        what = f"{faces:,} triangles" if faces > MAX_TRIANGLES else f"{vertices:,} vertices"
        raise ConfigError(f"{where}: {what}, more than {MAX_TRIANGLES:,} triangles allow")
    return faces


def read_mesh(path: str | Path, where: str) -> tuple[_Array, NDArray[np.int64]]:
    """Vertices ``(V, 3)`` [cm] and faces ``(F, 3)`` of a closed, outward mesh file.

    Only this one file is read, at most :data:`MAX_MESH_BYTES`, its counts checked from its
    bytes (:func:`_counted`) before it is parsed: no material, texture or other file it names
    is ever opened (an OBJ's ``mtllib`` is ignored).

    Raises:
        ConfigError: naming ``where`` and what is wrong (never the file's content).

    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ConfigError(f"{where}: expected a {', '.join(MESH_SUFFIXES)} file, got {path.name!r}")
    data = read_limited(path, MAX_MESH_BYTES, ConfigError, "mesh file", "mesh")
    _counted(data, suffix, f"{where}: {path.name}")
    trimesh = _trimesh()
    options = {"skip_materials": True} if suffix == ".obj" else {}
    try:
        mesh = trimesh.load_mesh(
            io.BytesIO(data), file_type=suffix[1:], process=False, resolver=None, **options
        )
    except Exception as exc:  # noqa: BLE001 - any parser failure is one line
        raise ConfigError(
            f"{where}: {path.name} is not a readable mesh ({type(exc).__name__})"
        ) from None
    if not hasattr(mesh, "faces") or len(mesh.faces) == 0:
        raise ConfigError(f"{where}: {path.name} holds no triangles")
    return check_mesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), where)


def check_mesh(
    verts: _Array, faces: NDArray[np.int64], where: str
) -> tuple[_Array, NDArray[np.int64]]:
    """The mesh with equal vertices merged, checked: finite, bounded, closed, outward."""
    if len(faces) > MAX_TRIANGLES:
        raise ConfigError(f"{where}: {len(faces):,} triangles, more than {MAX_TRIANGLES:,}")
    if not np.all(np.isfinite(verts)):
        raise ConfigError(f"{where}: a vertex is not a finite number (NaN or inf)")
    if np.abs(verts).max(initial=0.0) > MAX_MESH_COORD:
        raise ConfigError(f"{where}: a vertex lies beyond {MAX_MESH_COORD:g} cm of the origin")
    if faces.min(initial=0) < 0 or faces.max(initial=0) >= len(verts):
        raise ConfigError(f"{where}: a face names a vertex that does not exist")
    # merge equal vertices (an STL repeats them per triangle)
    unique, inverse = np.unique(np.round(verts, 6), axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    tri = unique[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if np.any(area2 <= 1e-12):
        bad = int(np.flatnonzero(area2 <= 1e-12)[0])
        raise ConfigError(f"{where}: triangle {bad} is degenerate (zero area)")
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    forward = np.unique(edges, axis=0, return_counts=True)
    backward = np.unique(edges[:, ::-1], axis=0, return_counts=True)
    if len(forward[0]) != len(backward[0]) or not (
        np.array_equal(forward[0], backward[0]) and np.array_equal(forward[1], backward[1])
    ):
        raise ConfigError(
            f"{where}: the mesh is not watertight (an edge has no matching edge in the opposite "
            "direction: a hole, or faces turned inconsistently)"
        )
    volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6)
    if volume <= 0:
        raise ConfigError(f"{where}: the mesh's normals point inward (its volume is {volume:.4g})")
    return unique, faces.astype(np.int64)


@dataclass(frozen=True, eq=False)
class MeshSolid(Shape):
    """A solid bounded by a closed triangle mesh (one or more bodies) [cm]."""

    vertices: _Array = field(repr=False)
    faces: NDArray[np.int64] = field(repr=False)
    name: str = ""
    source: str = ""
    #: Corners [cm] of a region the distance grid must cover too (the tank's box), or None.
    extent: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    #: The tank's walls: the mesh bounds the tank's inside, and the solid is what lies outside
    #: it above its floor (its lowest plane, the box's floor, whose triangles are left to the
    #: box's floor with its panel opening).
    walls: bool = False
    kind: ClassVar[str] = "mesh"

    @cached_property
    def surface(self) -> NDArray[np.int64]:
        """The faces distances, the raster and python-fcl see (the walls' floor left out)."""
        if not self.walls:
            return self.faces
        z = self.vertices[self.faces][..., 2]
        return self.faces[~np.all(np.abs(z - self.vertices[:, 2].min()) < FLOOR_EPS, axis=1)]

    @property
    def stack_key(self) -> int:
        """Every mesh is its own group: its grid is not a parameter."""
        return id(self)

    def aabb(self) -> tuple[_Array, _Array]:
        """Axis-aligned bounds ``(lo, hi)``."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    @cached_property
    def grid(self) -> tuple[_Array, float, NDArray[np.float32]]:
        """The signed-distance grid: corner [cm], spacing [cm] and values ``(nx, ny, nz)``."""
        lo, hi = self.aabb()
        pad = GRID_PAD
        lo, hi = lo - pad, hi + pad
        if self.extent is not None:  # the tank's box, and the panel's guide below its floor
            lo = np.minimum(lo, np.array(self.extent[0]) - [pad, pad, GUIDE_DEPTH])
            hi = np.maximum(hi, np.array(self.extent[1]) + pad)
        g = GRID_SPACING
        while math.prod(int(math.ceil((hi - lo)[d] / g)) + 1 for d in range(3)) > MAX_GRID_NODES:
            g *= 1.25
        floor = float(self.vertices[:, 2].min())
        if self.walls:  # a plane of nodes in the floor: no read above it reaches below
            lo[2] = floor - math.ceil((floor - lo[2]) / g) * g
        shape = np.array([int(math.ceil((hi - lo)[d] / g)) + 1 for d in range(3)], np.int64)
        band = max(BAND, 1.5 * g)  # every triangle has nodes within its band
        near, nearest = mesh_kernels.band_distances(self.vertices, self.surface, lo, g, shape, band)
        winding = mesh_kernels.column_winding(self.vertices, self.faces, lo, g, shape)
        if self.walls:
            above = lo[2] + g * np.arange(shape[2]) > floor + FLOOR_EPS  # the floor: the box's
            inside = (winding <= 0) & above[None, None, :]
        else:
            inside = winding > 0
        ndimage = require("scipy.ndimage", "mesh")
        # beyond the band: the nearest node within it hands over its mesh point, then two
        # sweeps hand each node the nearest of its neighbours' points
        far = ~np.isfinite(near)
        if far.any() and not far.all():
            i, j, k = ndimage.distance_transform_edt(
                far, return_distances=False, return_indices=True
            )
            nearest = np.ascontiguousarray(nearest[i, j, k])
            del i, j, k, far
            mesh_kernels.sweep_nearest(near, nearest, lo, g)
        values = np.where(inside, -near, near).astype(np.float32)
        values.setflags(write=False)
        return lo, g, values

    @property
    def distance_params(self) -> tuple[float, ...]:
        """None: the grid is the solid's own (:attr:`grid`)."""
        return ()

    def distance_field(self, x: _Array, y: _Array, z: _Array, *params: Any) -> _Array:
        """Signed distance [cm]: the grid read trilinearly; beyond it, the distance to the box."""
        lo, g, values = self.grid
        pts = np.stack(np.broadcast_arrays(x, y, z), axis=-1).astype(np.float64)
        return trilinear(pts, lo, g, values, self.aabb())

    def overlaps(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        """Positive-volume overlap with cells ``[lo, hi]`` (a triangle cuts it, or it is inside)."""
        inside = self.signed_distance((np.asarray(lo) + np.asarray(hi)) / 2) < 0
        return inside | self._cut(lo, hi)

    def _cut(self, lo: _Array, hi: _Array) -> NDArray[np.bool_]:
        flat_lo = np.asarray(lo, float).reshape(-1, 3)
        size = (
            float((np.asarray(hi) - np.asarray(lo)).reshape(-1, 3)[0, 0]) if flat_lo.size else 1.0
        )
        origin = flat_lo.min(axis=0) if flat_lo.size else np.zeros(3)
        shape = np.round((flat_lo.max(axis=0) - origin) / size).astype(np.int64) + 1
        cut = mesh_kernels.cells_cut(self.vertices, self.surface, origin, size, shape)
        index = np.round((flat_lo - origin) / size).astype(np.int64)
        return cut[index[:, 0], index[:, 1], index[:, 2]].reshape(np.shape(lo)[:-1])

    def contains(self, points: _Array) -> NDArray[np.bool_]:
        """Whether points ``(..., 3)`` lie inside (the grid's sign)."""
        return self.signed_distance(points) < 0

    def to_json(self) -> dict[str, Any]:
        """Scene-export form (the file it was read from, and its size)."""
        out = {"type": "mesh", "file": self.source, "triangles": len(self.faces)}
        return {**out, "walls": True} if self.walls else out

    def fcl_objects(self) -> list[Any]:
        """A python-fcl BVH model of the triangles (hollow: see :meth:`contains`)."""
        model = fcl.BVHModel()
        model.beginModel(len(self.vertices), len(self.surface))
        model.addSubModel(self.vertices, self.surface)
        model.endModel()
        return [fcl.CollisionObject(model, fcl.Transform())]

    def mesh(self) -> Mesh:
        """The mesh, outward from the solid (the walls': turned inward, without the floor)."""
        return (self.vertices, self.surface[:, ::-1]) if self.walls else (self.vertices, self.faces)

    def wireframe(self) -> list[_Array]:
        """Its bounding box's edges (a picture of a large mesh draws the mesh, not lines)."""
        lo, hi = self.aabb()
        return Box(tuple(lo), tuple(hi)).wireframe()


def trilinear(points: _Array, lo: _Array, g: float, values: NDArray[np.float32],
              box: tuple[_Array, _Array]) -> _Array:  # fmt: skip
    """Grid values at points ``(..., 3)`` read trilinearly; outside, the distance to ``box``.

    The distance to ``box`` is a lower bound of the distance to anything in it.
    """
    shape = np.array(values.shape)
    rel = (points - lo) / g
    inside = np.all((rel >= 0) & (rel <= shape - 1), axis=-1)
    base = np.clip(np.floor(rel).astype(np.int64), 0, shape - 2)
    f = np.clip(rel - base, 0.0, 1.0)
    out = np.zeros(points.shape[:-1])
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = (f[..., 0] if dx else 1 - f[..., 0]) * (f[..., 1] if dy else 1 - f[..., 1])
                w = w * (f[..., 2] if dz else 1 - f[..., 2])
                out += w * values[base[..., 0] + dx, base[..., 1] + dy, base[..., 2] + dz]
    outside = np.linalg.norm(np.maximum(np.maximum(box[0] - points, points - box[1]), 0), axis=-1)
    return np.where(inside, out, outside)


def is_walls(solid: Any) -> bool:
    """Whether a tank solid is the tank's walls given as a mesh (:attr:`MeshSolid.walls`)."""
    return solid.kind == "mesh" and bool(solid.walls)


def tank_bodies(tank: Tank, taper: bool = True) -> tuple[_Array, NDArray[np.int64]]:
    """Every solid of a tank as closed outward bodies in one mesh ``(V, F)``, but its walls.

    With ``taper=False`` its taper's wedges are left out too (:func:`inside_mesh` has them).
    """
    verts, faces, offset = [], [], 0
    for solid in tank.solids:
        if is_walls(solid) or (not taper and any(solid is w for w in tank.taper)):
            continue
        bodies = cast("Plate", solid).bodies() if solid.kind == "plate" else [solid.mesh()]
        for bv, bf in bodies:
            tri = bv[bf]
            volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
            verts.append(bv)
            faces.append((bf if volume > 0 else bf[:, ::-1]) + offset)
            offset += len(bv)
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.vstack(verts), np.vstack(faces).astype(np.int64)


def box_inside_mesh(lo: Any, hi: Any) -> tuple[_Array, NDArray[np.int64]]:
    """The box ``lo..hi`` as a closed outward mesh (12 triangles): walls around its inside."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts = np.array([[(lo, hi)[(i >> d) & 1][d] for d in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int64)
    return verts, faces


def inside_mesh(tank: Tank) -> tuple[_Array, NDArray[np.int64]]:
    """The tank's inside as a closed outward mesh: its box, its far end narrowed by its taper."""
    lo, hi = np.array(tank.box_min, float), np.array(tank.box_max, float)
    verts, faces = box_inside_mesh(lo, hi)
    for wedge in tank.taper:
        along, c, side, end = taper_side(cast("Wedge", wedge))  # a taper holds wedges
        far = (verts[:, along] == hi[along]) & (verts[:, c] == (lo if side == "min" else hi)[c])
        verts[far, c] = end
    return verts, faces


def export_tank_mesh(
    tank: Tank,
    output: str | Path,
    yaml_out: str | Path | None = None,
    walls_out: str | Path | None = None,
) -> int:
    """Write a tank's solids as one mesh file; their triangles.

    ``yaml_out``: also a tank file that reads it back; ``walls_out``: also the tank's inside
    (:func:`inside_mesh`) as a walls mesh (:attr:`MeshSolid.walls`), which that tank file then
    names instead of a box and taper (whose wedges then stay out of the solids).
    """
    trimesh = _trimesh()
    outputs = [Path(output)] + ([Path(walls_out)] if walls_out is not None else [])
    for path, flag in zip(outputs, ("-o", "--walls")):
        if path.suffix.lower() not in MESH_SUFFIXES:
            raise ConfigError(
                f"{flag}: expected a {', '.join(MESH_SUFFIXES)} file, got {path.name!r}"
            )
    if walls_out is not None and not tank.walls:
        raise ConfigError(f"--walls: {tank.name} has no walls (walls: false)")
    if any(is_walls(s) for s in tank.solids) and (walls_out or yaml_out) is not None:
        raise ConfigError(f"{tank.name}'s walls are a mesh already: its own file reads them")
    meshes = [tank_bodies(tank, taper=walls_out is None)]
    if walls_out is not None:
        meshes.append(inside_mesh(tank))
    for path, (verts, faces) in zip(outputs, meshes):
        if not len(faces):
            raise ConfigError(f"{tank.name} has no solids to write")
        mesh = trimesh.Trimesh(verts, faces, process=False)
        data = mesh.export(file_type=path.suffix[1:].lower())
        with atomic_open(path, "wb" if isinstance(data, bytes) else "w") as fh:
            fh.write(data)
    if yaml_out is not None:
        _write_mesh_yaml(tank, outputs, Path(yaml_out))
    return len(meshes[0][1])


def _write_mesh_yaml(tank: Tank, mesh_files: list[Path], yaml_out: Path) -> None:
    """A tank file with ``tank``'s box (or walls mesh), panel, arm and targets, and its solids."""
    rel = []
    for mesh_file in mesh_files:
        rel.append(os.path.relpath(mesh_file.resolve(), yaml_out.resolve().parent))
        if rel[-1].startswith(".."):
            raise ConfigError(f"--yaml {yaml_out}: write it in the mesh files' folder or above it")
    shape = (
        {"mesh": rel[1]}
        if len(rel) > 1
        else {"box": {"min": list(tank.box_min), "max": list(tank.box_max)}}
    )
    data = {
        "name": f"{tank.name}_mesh",
        "description": f"{tank.name} with its solids read from {mesh_files[0].name}",
        **shape,
        "cell_size": tank.cell_size,
        "panel": {"center": list(tank.panel.center), "radius": tank.panel.radius},
        "start_point": list(tank.start_point),
        "walls": tank.walls,
        "obstacles": [{"type": "mesh", "name": "solids", "file": rel[0]}],
        "arm": {
            "section_length": tank.arm.section_length,
            "max_sections": tank.arm.max_sections,
            "radius": tank.arm.radius,
            "theta_max": tank.arm.theta_max,
        },  # fmt: skip
        "targets": [list(t) for t in tank.targets],
    }
    with atomic_open(yaml_out, "w") as fh:
        yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None, width=100)
