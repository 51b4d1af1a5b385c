"""Tanks whose walls are a triangle mesh (``mesh: walls.stl``): read back, checked, refused."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.robot import Posture
from aftir_rl.core.tank import load_tank, tank_from_mapping
from aftir_rl.core.tank.generate import wing_tank
from aftir_rl.core.tank.meshes import box_inside_mesh, export_tank_mesh, inside_mesh, is_walls

trimesh = pytest.importorskip("trimesh")


@pytest.fixture(scope="module")
def walled(tmp_path_factory):
    """The reference tank, and the same tank read back from its walls and solids meshes."""
    folder = tmp_path_factory.mktemp("walls")
    tank = load_tank("b737_center")
    export_tank_mesh(tank, folder / "solids.stl", folder / "t.yaml", folder / "walls.stl")
    return tank, load_tank(folder / "t.yaml")


def _write(path, verts, faces):
    path.write_bytes(trimesh.Trimesh(verts, faces, process=False).export(file_type="stl"))


def test_the_reference_tank_from_its_walls_mesh_is_the_same_tank(walled):
    tank, meshed = walled
    assert "box" not in yaml.safe_load(open(meshed.source))
    assert (meshed.box_min, meshed.box_max) == (tank.box_min, tank.box_max)
    assert is_walls(meshed.obstacles[0]) and not is_walls(meshed.obstacles[1])
    assert np.array_equal(tank.raster.obstructed, meshed.raster.obstructed)
    assert np.array_equal(tank.reachable, meshed.reachable)
    rng = np.random.default_rng(1)
    pts = rng.uniform(tank.box_min, tank.box_max, (100_000, 3))
    exact, read = tank.distance(pts), meshed.distance(pts)
    free = exact > 0
    assert np.abs(read - exact)[free].max() < 0.5
    assert np.abs(read - exact)[free & (exact < 4.0)].max() < 0.35
    # the panel's opening and the guide below it, where the arm enters
    r, z = rng.uniform(0, 8, 2000), rng.uniform(-12, 3, 2000)
    a = rng.uniform(0, 2 * np.pi, 2000)
    guide = np.c_[r * np.cos(a), r * np.sin(a), z] + tank.panel.center
    np.testing.assert_allclose(meshed.distance(guide), tank.distance(guide), atol=0.35)


def test_python_fcl_sees_the_same_walls(walled):
    """Random postures collide in the meshed tank exactly where they do in the primitive one,
    but for those within half a centimetre of touching."""
    tank, meshed = walled
    rng = np.random.default_rng(2)
    scenes = CollisionScene(tank), CollisionScene(meshed)
    agree = 0
    for _ in range(150):
        posture = Posture(rng.uniform(-200, 0), rng.uniform(0, 0.4, 12), rng.uniform(-3, 3, 12))
        exact = scenes[0].check(posture)
        if abs(exact.clearance_cm) < 0.5:
            continue
        assert scenes[1].collides(posture) == exact.collides
        agree += 1
    assert agree > 100


def test_a_tapered_wing_from_its_walls_mesh_is_the_same_tank(tmp_path):
    """The walls mesh of a tapered box (the far end's section smaller) against the YAML taper."""
    data = wing_tank(3, 5)
    lo, hi = np.array(data["box"]["min"], float), np.array(data["box"]["max"], float)
    end = data["taper"]["end"]
    assert data["taper"]["along"] == "x"
    verts, faces = box_inside_mesh(lo, hi)
    far = verts[:, 0] == hi[0]
    verts[far, 1] = np.where(verts[far, 1] == lo[1], end["min"][0], end["max"][0])
    verts[far, 2] = np.where(verts[far, 2] == lo[2], end["min"][1], end["max"][1])
    _write(tmp_path / "walls.stl", verts, faces)
    walled = {k: v for k, v in data.items() if k not in ("box", "taper")}
    meshed = tank_from_mapping({**walled, "mesh": "walls.stl"}, str(tmp_path / "w.yaml"))
    tank = tank_from_mapping(data, str(tmp_path / "t.yaml"))
    assert (meshed.box_min, meshed.box_max) == (tank.box_min, tank.box_max)
    assert np.array_equal(tank.raster.obstructed, meshed.raster.obstructed)
    pts = np.random.default_rng(3).uniform(lo, hi, (50_000, 3))
    exact, read = tank.distance(pts), meshed.distance(pts)
    free = exact > 0
    assert np.abs(read - exact)[free].max() < 0.5
    assert ((read > 0) == free)[np.abs(exact) > 0.5].all()
    # export --walls writes that hexahedron, and leaves the taper's wedges out of the solids
    np.testing.assert_allclose(inside_mesh(tank)[0], verts)
    export_tank_mesh(tank, tmp_path / "s.stl", tmp_path / "e.yaml", tmp_path / "e.stl")
    exported = load_tank(tmp_path / "e.yaml")
    assert np.array_equal(tank.raster.obstructed, exported.raster.obstructed)
    assert len(exported.obstacles[1].faces) < export_tank_mesh(tank, tmp_path / "all.stl")


def test_a_walls_mesh_grows_its_box_to_whole_cells(tmp_path):
    _write(tmp_path / "walls.stl", *box_inside_mesh((-30, -30, 0), (95, 33, 61)))
    data = {"mesh": "walls.stl", "cell_size": 10}
    tank = tank_from_mapping(data, str(tmp_path / "t.yaml"))
    assert (tank.box_min, tank.box_max) == ((-30, -30, 0), (100, 40, 70))
    assert tank.raster.shape == (13, 7, 7)
    assert tank.raster.obstructed.reshape(tank.raster.shape)[-1].all()  # beyond the walls


@pytest.mark.parametrize(
    ("change", "says"),
    [
        ({"panel": {"center": [0, 0, 0], "radius": 12}}, "do not hold the panel"),
        ({"box": {"min": [-10, -50, 0], "max": [100, 50, 100]}}, "give mesh or box"),
        ({"taper": {"along": "x", "end": {"min": [-40, 0], "max": [40, 90]}}}, "mesh or taper"),
        ({"walls": False}, "has walls"),
        ({"mesh": "../walls.stl"}, "leads out of the tank file's folder"),
        ({"mesh": "open.stl"}, "mesh: file: open.stl is not watertight|not watertight"),
    ],
)
def test_bad_walls_meshes_are_one_line_errors(tmp_path, change, says):
    _write(tmp_path / "walls.stl", *box_inside_mesh((-10, -50, 0), (100, 50, 100)))
    verts, faces = box_inside_mesh((-10, -50, 0), (100, 50, 100))
    _write(tmp_path / "open.stl", verts, faces[:-1])
    data = {"mesh": "walls.stl", "panel": {"center": [0, 0, 0], "radius": 5}, **change}
    with pytest.raises(ConfigError, match=says) as info:
        tank_from_mapping(data, str(tmp_path / "t.yaml"))
    assert "\n" not in str(info.value)


@pytest.mark.slow
def test_a_run_keeps_its_walls_mesh(tmp_path):
    from aftir_rl.core.tank.loading import keep_run_tank, resolve_run_tank

    source, run = tmp_path / "src", tmp_path / "run"
    source.mkdir()
    run.mkdir()
    export_tank_mesh(load_tank("wing:2:2"), source / "s.stl", source / "w.yaml", source / "w.stl")
    assert keep_run_tank(source / "w.yaml", run) == "tank.yaml"
    for name in ("s.stl", "w.stl"):
        (source / name).unlink()
    kept = load_tank(resolve_run_tank("tank.yaml", run))
    assert is_walls(kept.obstacles[0]) and len(list(run.glob("tank_mesh_*.stl"))) == 2
    with pytest.raises(ConfigError, match="walls are a mesh already"):
        export_tank_mesh(kept, tmp_path / "again.stl", walls_out=tmp_path / "again_walls.stl")
