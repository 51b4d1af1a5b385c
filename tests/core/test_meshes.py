"""Tanks from triangle meshes: a tank exported and read back, hostile mesh files."""

from __future__ import annotations

import dataclasses
import os
import struct
from pathlib import Path

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.robot import Posture
from aftir_rl.core.tank import load_tank, tank_from_mapping
from aftir_rl.core.tank.meshes import export_tank_mesh, read_mesh

trimesh = pytest.importorskip("trimesh")


@pytest.fixture(scope="module")
def round_trip(tmp_path_factory):
    """The reference tank and the same tank read back from its exported mesh."""
    folder = tmp_path_factory.mktemp("mesh")
    tank = load_tank("b737_center")
    export_tank_mesh(tank, folder / "b737.stl", folder / "b737_mesh.yaml")
    return tank, load_tank(folder / "b737_mesh.yaml")


def test_exported_tank_reads_back_with_the_same_raster(round_trip):
    tank, meshed = round_trip
    assert meshed.obstacles[0].kind == "mesh"
    assert np.array_equal(tank.raster.obstructed, meshed.raster.obstructed)
    assert np.array_equal(tank.reachable, meshed.reachable)


def test_exported_tank_has_the_same_signed_distance(round_trip):
    tank, meshed = round_trip
    rng = np.random.default_rng(0)
    pts = rng.uniform(tank.box_min, tank.box_max, (100_000, 3))
    exact, read = tank.distance(pts), meshed.distance(pts)
    near = np.abs(exact) < 4.0  # where contact and the 1 cm margin are decided
    # the pipes are 24-gons in the mesh (0.04 cm inside the circle), the grid is 1 cm
    assert np.abs(read - exact)[near].max() < 0.35
    assert np.abs(read - exact).max() < 0.5
    flipped = (read < 0) != (exact < 0)
    assert np.abs(exact[flipped]).max(initial=0.0) < 0.3  # inside and outside agree off the surface


def test_inside_a_hollow_mesh_is_a_collision(tmp_path):
    """python-fcl's BVH models are hollow; the scene adds the grid's inside test."""
    write_stl(tmp_path / "block.stl", box_triangles((-20, -20, 0), (20, 20, 700)))
    data = {
        "box": {"min": [-100, -100, 0], "max": [100, 100, 800]},
        "walls": False,
        "obstacles": [{"type": "mesh", "file": "block.stl"}],
    }
    tank = tank_from_mapping(data, str(tmp_path / "t.yaml"))
    scene = CollisionScene(tank)
    inside = Posture(5.0, np.zeros(12), np.zeros(12))  # 2.5 cm or more from every face
    outside = Posture(5.0, np.full(12, 0.3), np.zeros(12))  # bends out through a face
    assert scene.collides(inside) and scene.check(inside).collides
    assert scene.check(inside).clearance_cm <= 0
    assert scene.collides(outside)
    free = dataclasses.replace(tank, obstacles=())
    assert not CollisionScene(free).collides(inside)


def write_stl(path: Path, tri: np.ndarray) -> None:
    """A binary STL of triangles ``(F, 3, 3)``."""
    with open(path, "wb") as fh:
        fh.write(b"\0" * 80 + struct.pack("<I", len(tri)))
        for t in tri:
            fh.write(struct.pack("<12fH", 0, 0, 0, *t.ravel(), 0))


def box_triangles(lo=(0, 0, 0), hi=(10, 10, 10)) -> np.ndarray:
    from aftir_rl.core.tank.solids import Box

    v, f = Box(tuple(map(float, lo)), tuple(map(float, hi))).mesh()
    return v[f]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda t: t[:-1], "not watertight"),
        (lambda t: t[:, ::-1], "normals point inward"),
        (lambda t: np.where(np.arange(t.size).reshape(t.shape) == 4, np.nan, t), "not a finite"),
        (lambda t: t * 1e6, "beyond"),
        (lambda t: np.concatenate([t, [[[0, 0, 0], [1, 1, 1], [2, 2, 2]]]]), "degenerate"),
    ],
)
def test_hostile_meshes_are_one_line_errors(tmp_path, make, message):
    path = tmp_path / "bad.stl"
    write_stl(path, make(box_triangles()))
    with pytest.raises(ConfigError, match=message):
        read_mesh(path, "obstacles[0]: file")


def test_mesh_files_that_are_not_meshes(tmp_path):
    text = tmp_path / "walls.stl"
    text.write_bytes(b"\x00\x01garbage" * 100)
    with pytest.raises(ConfigError, match="not a valid binary STL: its header says"):
        read_mesh(text, "w")
    text.write_bytes(b"solid x\nfacet normal garbage\n" * 10)
    with pytest.raises(ConfigError, match="not a readable mesh|holds no triangles"):
        read_mesh(text, "w")
    with pytest.raises(ConfigError, match="expected a .stl, .obj, .ply file"):
        read_mesh(tmp_path / "walls.txt", "w")
    fifo = tmp_path / "fifo.stl"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        read_mesh(fifo, "w")


def test_a_mesh_reads_no_other_file(tmp_path):
    """An OBJ's mtllib is never opened: a FIFO there would block, a huge file would be read."""
    tri = box_triangles()
    verts = tri.reshape(-1, 3)
    lines = ["mtllib fifo.mtl", "usemtl a"] + [f"v {x} {y} {z}" for x, y, z in verts]
    lines += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(len(tri))]
    (tmp_path / "box.obj").write_text("\n".join(lines) + "\n")
    os.mkfifo(tmp_path / "fifo.mtl")
    v, f = read_mesh(tmp_path / "box.obj", "w")
    assert len(f) == len(tri) and len(v) == 8


def test_counts_are_checked_before_parsing(tmp_path):
    """A header or line count above the cap is refused without parsing the file."""
    from aftir_rl.core.tank.meshes import MAX_TRIANGLES

    n = MAX_TRIANGLES + 1
    stl = tmp_path / "big.stl"
    with stl.open("wb") as fh:  # a sparse binary STL whose header and size agree
        fh.write(b"\0" * 80 + np.uint32(n).tobytes())
        fh.truncate(84 + 50 * n)
    with pytest.raises(ConfigError, match="1,000,001 triangles, more than"):
        read_mesh(stl, "w")
    ply = tmp_path / "big.ply"
    ply.write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        b"property float y\nproperty float z\nelement face 999999999\n"
        b"property list uchar int vertex_indices\nend_header\n"
    )
    with pytest.raises(ConfigError, match="999,999,999 triangles, more than"):
        read_mesh(ply, "w")


def test_a_mesh_too_large_is_refused_unread(tmp_path, monkeypatch):
    from aftir_rl.core.tank import meshes

    path = tmp_path / "big.stl"
    write_stl(path, box_triangles())
    monkeypatch.setattr(meshes, "MAX_MESH_BYTES", 100)
    with pytest.raises(ConfigError, match="larger than 100 bytes"):
        read_mesh(path, "w")


def test_overlapping_bodies_read_as_their_union(tmp_path):
    """Two closed boxes that overlap: inside either is inside (winding, not parity)."""
    path = tmp_path / "two.stl"
    write_stl(path, np.concatenate([box_triangles((0, 0, 0), (10, 10, 10)),
                                    box_triangles((5, 5, 5), (15, 15, 15))]))  # fmt: skip
    from aftir_rl.core.tank.meshes import MeshSolid

    solid = MeshSolid(*read_mesh(path, "w"))
    pts = np.array([[7.0, 7.0, 7.0], [2.0, 2.0, 2.0], [12.0, 12.0, 12.0], [12.0, 2.0, 2.0]])
    assert solid.contains(pts).tolist() == [True, True, True, False]
    assert solid.signed_distance(pts[3]) == pytest.approx(2.0, abs=1e-6)


def test_a_run_keeps_its_mesh_tank_and_refuses_paths_out(tmp_path):
    from aftir_rl.core.tank.loading import keep_run_tank, resolve_run_tank

    source, run = tmp_path / "src", tmp_path / "run"
    source.mkdir()
    run.mkdir()
    export_tank_mesh(load_tank("wing:2:2"), source / "w.stl", source / "w.yaml")
    assert keep_run_tank(source / "w.yaml", run) == "tank.yaml"
    (source / "w.stl").unlink()  # the run does not need the original any more
    kept = load_tank(resolve_run_tank("tank.yaml", run))
    assert kept.obstacles[0].kind == "mesh" and (run / "tank_mesh_0.stl").is_file()
    text = (run / "tank.yaml").read_text()
    for escape in ("../src/w.stl", str(tmp_path / "src" / "w.stl")):
        (run / "tank.yaml").write_text(text.replace("tank_mesh_0.stl", escape))
        with pytest.raises(ConfigError, match="leads out of the tank file's folder"):
            load_tank(resolve_run_tank("tank.yaml", run))


@pytest.mark.slow
def test_a_huge_mesh_grows_its_grid_within_the_node_bound(tmp_path):
    from aftir_rl.core.tank import meshes

    write_stl(tmp_path / "slab.stl", box_triangles((-9000, -9000, 10), (9000, 9000, 60)))
    data = {
        "box": {"min": [-9500, -9500, 0], "max": [9500, 9500, 100]},
        "walls": False,
        "obstacles": [{"type": "mesh", "file": "slab.stl"}],
    }
    tank = tank_from_mapping(data, str(tmp_path / "t.yaml"))
    lo, g, values = tank.obstacles[0].grid
    assert values.size <= meshes.MAX_GRID_NODES and g > meshes.GRID_SPACING
    probe = np.array([[0.0, 0.0, 80.0], [0.0, 0.0, 35.0], [9200.0, 0.0, 35.0]])
    np.testing.assert_allclose(tank.distance(probe), [20.0, -25.0, 200.0], atol=g)
