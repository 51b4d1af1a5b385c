from __future__ import annotations

import json
import subprocess
import sys

import fcl
import numpy as np
import pytest

from aftir_rl.cli import tank as tank_module
from aftir_rl.core.errors import ConfigError, TargetError
from aftir_rl.core.tank import (
    RUN_TANK_FILE,
    TANK_DIR,
    Box,
    Cylinder,
    SolidStack,
    Sphere,
    keep_run_tank,
    load_tank,
    resolve_run_tank,
)

REF_YAML = TANK_DIR / "b737_center.yaml"


def test_reference_tank_matches_design(tank):
    assert tank.box_min == (-60, -50, 0) and tank.box_max == (240, 150, 100)
    assert tank.raster.shape == (15, 10, 5)
    assert tank.start_cell == (3, 2, 0)
    assert tank.panel.radius == 12
    assert len(tank.targets) == 4


def test_baffle_row_blocked_except_hatch(tank):
    row = tank.raster.obstructed[:, 5, :]
    free = {(int(a), int(c)) for a, c in np.argwhere(~row)}
    assert free == {(7, 2), (8, 2)}


def test_start_targets_and_hatch_are_free_and_everything_reachable(tank, scene_grid):
    grid, dist = scene_grid
    for cell in [(3, 2, 0), (7, 5, 2), (8, 5, 2)] + [
        tank.raster.point_to_cell(t) for t in tank.targets
    ]:
        assert not grid[cell]
    free = {tuple(map(int, c)) for c in np.argwhere(~grid)}
    assert set(dist) == free, "every free cell is reachable from the start cell"


def test_obstruction_agrees_with_point_sampling(tank):
    # Independent check: a cell is obstructed iff some sample point strictly inside it lies inside
    # a solid. Samples every 1 cm resolve the 3 cm stringers and 5 cm pipes.
    raster = tank.raster
    offs = np.arange(0.5, raster.cell_size, 1.0)
    grid = np.stack(np.meshgrid(offs, offs, offs, indexing="ij"), -1).reshape(-1, 3)
    for cell in np.ndindex(raster.shape):
        pts = np.array(raster.origin) + np.array(cell) * raster.cell_size + grid
        inside = any(bool(np.any(s.contains(pts))) for s in tank.solids)
        assert inside == bool(raster.obstructed[cell]), cell


def test_point_cell_round_trip(tank):
    r = tank.raster
    for cell in [(0, 0, 0), (14, 9, 4), (7, 5, 2)]:
        assert r.point_to_cell(r.cell_center(cell)) == cell
        assert r.cell(r.index(cell)) == cell
    assert r.point_to_cell((240, 150, 100)) == (14, 9, 4)
    with pytest.raises(TargetError, match="outside the tank box"):
        r.point_to_cell((300, 0, 10))


def test_cell_indices_are_point_to_cell_vectorised(tank):
    r = tank.raster
    rng = np.random.default_rng(4)
    pts = rng.uniform(tank.box_min, tank.box_max, (500, 3))
    want = [r.index(r.point_to_cell(p)) for p in pts]
    np.testing.assert_array_equal(r.cell_indices(pts), want)
    np.testing.assert_array_equal(r.cell_indices(pts.reshape(25, 20, 3)).reshape(-1), want)
    # outside the box: the nearest cell
    assert r.cell_indices((300.0, 0.0, 10.0)) == r.index(r.point_to_cell((240.0, 0.0, 10.0)))


def test_target_errors(tank):
    with pytest.raises(TargetError, match="outside"):
        tank.target_cell((0, 0, -5))
    with pytest.raises(TargetError, match="obstructed cell.*baffle"):
        tank.target_cell((0, 60, 50))


def test_scene_export_schema(tank, capsys):
    assert tank_module.main(["--json"]) == 0
    scene = json.loads(capsys.readouterr().out)
    assert set(scene) == {"units", "box", "panel", "solids", "raster", "arm"}
    assert scene["units"] == "cm"
    assert scene["box"] == {"min": [-60, -50, 0], "max": [240, 150, 100]}
    assert scene["panel"] == {"center": [0, 0, 0], "radius": 12}
    assert set(scene["raster"]) == {"shape", "cell_size", "origin", "obstructed"}
    assert scene["raster"]["shape"] == [15, 10, 5] and scene["raster"]["cell_size"] == 20
    assert set(scene["arm"]) == {"section_length", "max_sections", "radius", "theta_max"}
    kinds = {
        "box": {"type", "min", "max"},
        "cylinder": {"type", "p0", "p1", "radius"},
        "sphere": {"type", "center", "radius"},
    }
    for solid in scene["solids"]:
        assert set(solid) == kinds[solid["type"]]
    assert sum(s["type"] == "cylinder" for s in scene["solids"]) == 2


def test_ascii_view(capsys):
    assert tank_module.main([]) == 0
    out = capsys.readouterr().out
    assert "15 x 10 x 5" in out and "S" in out and "HH" in out


def _write(tmp_path, text):
    path = tmp_path / "tank.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("cell_size: 20", "cell_size: 20\ncolour: red", r"unknown key 'colour'"),
        ("cell_size: 20", "cell_size: -20", r"cell_size: must be positive"),
        ("radius: 5}", "radius: 5, length: 3}", r"obstacles\[0\]: unknown key 'length'"),
        ("center: [100, 60, 50], width: 40", "center: [100, 60, 50], width: 400", r"hatch"),
        (
            "center: [100, 60, 50]",
            "center: [100, 70, 50]",
            r"hatch.center: the hatch is not in its baffle",
        ),
        ("p1: [240, 20, 85]", "p1: [300, 20, 85]", r"obstacles\[0\].*reaches outside the box"),
        ("box: {min:", "box: {mn:", r"box: unknown key 'mn'"),
        ("radius: 2.5", "radius: lots", r"arm.radius: expected a number"),
        ("start_point: [0, 0, 10]", "start_point: [0, 60, 10]", r"start_point.*obstructed cell"),
    ],
)
def test_malformed_yaml_names_file_and_key(tmp_path, old, new, message):
    text = REF_YAML.read_text()
    assert old in text
    path = _write(tmp_path, text.replace(old, new, 1))
    with pytest.raises(ConfigError, match=message) as info:
        load_tank(path)
    assert str(path) in str(info.value)


def test_yaml_numbers_written_as_strings_are_parsed(tmp_path):
    # PyYAML reads 2e1 as a string; the loader converts it deliberately.
    path = _write(tmp_path, REF_YAML.read_text().replace("cell_size: 20", "cell_size: 2e1"))
    assert load_tank(path).raster.shape == (15, 10, 5)


def test_not_yaml_and_unknown_name(tmp_path, capsys):
    path = _write(tmp_path, "box: {min: [0, 0\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_tank(path)
    with pytest.raises(ConfigError, match="unknown tank 'nope'.*b737_center"):
        load_tank("nope")
    assert tank_module.main(["--tank", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and "Traceback" not in err


# ------------------------------------------------------------------------------ solids
SOLIDS = [
    Box((-3.0, 1.0, 2.0), (5.0, 4.0, 9.0)),
    Cylinder((1.0, 2.0, -4.0), (1.0, 2.0, 6.0), 3.0),
    Cylinder((9.0, 2.0, 3.0), (-1.0, 2.0, 3.0), 2.0),
    Cylinder((0.0, -5.0, 1.0), (0.0, 7.0, 1.0), 2.5),
    Sphere((1.0, 2.0, 3.0), 4.0),
]


@pytest.mark.parametrize("solid", SOLIDS, ids=lambda s: f"{s.kind}")
def test_signed_distance_matches_fcl(solid):
    # Outside: the distance python-fcl finds to a tiny ball at the point. Inside: negative
    # exactly where python-fcl and contains() find the point inside.
    rng = np.random.default_rng(3)
    lo, hi = solid.aabb()
    pts = rng.uniform(lo - 2, hi + 2, (400, 3))
    d = solid.signed_distance(pts)
    np.testing.assert_array_equal(d, solid.signed_distance_xyz(*pts.T))
    obj, eps = solid.fcl_object(), 1e-3
    outside = inside = 0
    for p, expected in zip(pts, d):
        ball = fcl.CollisionObject(fcl.Sphere(eps), fcl.Transform(p))
        if expected > 0.01:
            found = fcl.distance(obj, ball, fcl.DistanceRequest(), fcl.DistanceResult())
            assert found + eps == pytest.approx(expected, abs=1e-4), p
            outside += 1
        elif expected < -0.01:
            result = fcl.CollisionResult()
            assert fcl.collide(obj, ball, fcl.CollisionRequest(), result) and solid.contains(p)
            inside += 1
    assert outside > 50 and inside > 20
    # The depth inside: the point is within |d| of the surface, and no nearer to it.
    deep = pts[d < -0.01]
    depth = -solid.signed_distance(deep)
    directions = rng.normal(size=(64, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for p, r in zip(deep, depth):
        assert np.all(solid.contains(p + 0.999 * r * directions))
    assert np.all(solid.signed_distance(deep + depth[:, None] * 1e-9) <= 0)


def test_solid_stack_is_the_nearest_solid(tank):
    solids = list(tank.solids) + SOLIDS
    rng = np.random.default_rng(4)
    pts = rng.uniform([-70, -60, -10], [250, 160, 110], (2000, 3))
    nearest = np.min([s.signed_distance(pts) for s in solids], axis=0)
    np.testing.assert_array_equal(SolidStack(solids).signed_distance_xyz(*pts.T), nearest)
    assert np.all(SolidStack([]).signed_distance_xyz(*pts.T) == np.inf)


@pytest.mark.parametrize("solid", SOLIDS, ids=lambda s: f"{s.kind}")
def test_drawings_lie_on_the_surface(solid):
    vertices, faces = solid.mesh()
    assert faces.min() == 0 and faces.max() == len(vertices) - 1
    np.testing.assert_allclose(solid.signed_distance(vertices), 0, atol=1e-9)
    for line in solid.wireframe():
        np.testing.assert_allclose(solid.signed_distance(line), 0, atol=1e-9)


def test_enclosure_distance(tank):
    # the panel's axis 30 cm up (the floor's rim), in the guide, under the floor beside the panel,
    # above the floor, beside the wall at x = 240
    pts = np.array([[0, 0, 30.0], [0, 0, -30.0], [20, 0, -1.0], [100, 100, 3.0], [239, 0, 50.0]])
    expected = [np.hypot(12, 30), 12, -1, 3, 1]
    np.testing.assert_allclose(tank.enclosure.signed_distance_xyz(*pts.T), expected)
    np.testing.assert_allclose(tank.enclosure.floor_distance_xyz(*pts.T)[:4], expected[:4])


def test_python_m_tank_runs_the_cli():
    proc = subprocess.run(
        [sys.executable, "-m", "aftir_rl.tank", "--tank", "single_cabin", "--json"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0 and proc.stderr == ""
    assert json.loads(proc.stdout)["units"] == "cm"


@pytest.mark.parametrize(
    "name",
    ["/etc/passwd", "../b737_center.yaml", "../../etc/passwd", "out.yaml", "", "a\x00b", 3, None],
)
def test_a_run_names_only_shipped_tanks_or_its_own_files(tmp_path, name):
    run = tmp_path / "run"
    run.mkdir()
    (run / "out.yaml").symlink_to(TANK_DIR / "b737_center.yaml")  # leads out of the run
    with pytest.raises(ConfigError, match="neither a shipped tank") as err:
        resolve_run_tank(name, run)
    assert "root:" not in str(err.value) and "\n" not in str(err.value)


def test_a_run_keeps_a_tank_given_by_path(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    assert keep_run_tank("b737_center", run) == "b737_center"
    assert not (run / RUN_TANK_FILE).exists()
    own = tmp_path / "mine.yaml"
    own.write_text((TANK_DIR / "single_cabin.yaml").read_text())
    assert keep_run_tank(own, run) == RUN_TANK_FILE
    own.unlink()  # the run no longer needs the original
    path = resolve_run_tank(RUN_TANK_FILE, run)
    assert load_tank(path).fingerprint == load_tank("single_cabin").fingerprint
    assert resolve_run_tank("b737_center", run) == "b737_center"
