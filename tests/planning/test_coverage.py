"""Seeing the surface: the camera model, the compiled line of sight and the ray-cast measure
against the geometry worked by hand, and coverage tours measured apart from their planner."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aftir_rl.cli import tour as tour_cli
from aftir_rl.core.camera import Camera
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.visibility import seen_by_groups
from aftir_rl.core.tank import load_tank, tank_from_mapping
from aftir_rl.core.tank.surface import SurfaceSamples, scene_mesh, surface_samples
from aftir_rl.experiments.coverage import measure_coverage, seen_from_poses
from aftir_rl.planning.ftl.coverage import plan_coverage, viewpoint_lattice

pytest.importorskip("trimesh")
pytest.importorskip("rtree")


def _room(obstacles=(), camera=None):
    """A walled 200 x 200 x 100 cm room with the panel at the floor's centre."""
    arm = {"section_length": 50, "max_sections": 6}
    if camera is not None:
        arm["camera"] = camera
    return tank_from_mapping(
        {
            "name": "room",
            "box": {"min": [-100, -100, 0], "max": [100, 100, 100]},
            "cell_size": 20,
            "panel": {"center": [0, 0, 0], "radius": 12},
            "start_point": [0, 0, 10],
            "obstacles": list(obstacles),
            "arm": arm,
        },
        "room",
    )


def _both(tank, tips, looks, surface):
    """What the compiled kernel and the ray-cast measure say a camera at each tip sees."""
    kernel = np.zeros((1, len(surface.points)), dtype=np.bool_)
    seen_by_groups(tips, looks, np.array([0, len(tips)]), surface.points, surface.normals,
                   tank.arm.camera.cosines(), kernel_grid(tank), kernel)  # fmt: skip
    rays, _ = seen_from_poses(scene_mesh(tank), tips, looks, surface, tank.arm.camera)
    return kernel[0], rays


def test_the_camera_reads_its_yaml_and_refuses_bad_values():
    tank = _room(camera={"fov_deg": 60, "range_cm": "80"})
    assert tank.arm.camera == Camera(60.0, 80.0)
    for bad in ({"fov_deg": 180}, {"range_cm": -1}, {"zoom": 2}, {"max_incidence_deg": "x"},
                {"min_incidence_deg": 80, "max_incidence_deg": 70}, [1]):  # fmt: skip
        with pytest.raises(ConfigError, match="arm.camera"):
            _room(camera=bad)


def test_the_surface_area_of_an_empty_room():
    tank = _room()
    surface = surface_samples(tank, (tank.box_min, tank.box_max), 4000, seed=3)
    # floor, ceiling and four walls, less the panel's 24 x 24 cm square opening
    area = 2 * 200 * 200 + 4 * 200 * 100 - 24 * 24
    assert surface.area_cm2 == pytest.approx(area, rel=0.03)
    floor = surface.points[:, 2] < 0.5
    assert np.allclose(surface.normals[floor], [0, 0, 1])
    assert floor.mean() == pytest.approx((200 * 200 - 24 * 24) / area, abs=0.03)


def test_a_camera_looking_down_sees_the_floor_disc_its_cone_cuts():
    tank = _room()
    surface = surface_samples(tank, (tank.box_min, tank.box_max), 6000, seed=4)
    tips, looks = np.array([[30.0, -20.0, 50.0]]), np.array([[0.0, 0.0, -1.0]])
    radius = np.hypot(surface.points[:, 0] - 30.0, surface.points[:, 1] + 20.0)
    truth = (surface.points[:, 2] < 0.5) & (radius <= 50.0)  # tan 45° x 50 cm
    sure = np.abs(radius - 50.0) > 0.5
    kernel, rays = _both(tank, tips, looks, surface)
    assert truth.sum() > 200  # about 6000 x 7854 / 160000 points
    assert np.array_equal(kernel[sure], truth[sure])
    assert np.array_equal(rays[sure], truth[sure])


def test_a_box_in_the_way_shades_the_floor_below_it():
    tank = _room(obstacles=[{"name": "shade", "type": "box", "min": [-10, -10, 20],
                             "max": [10, 10, 30]}])  # fmt: skip
    surface = surface_samples(tank, (tank.box_min, tank.box_max), 6000, seed=5)
    tips, looks = np.array([[0.0, 0.0, 50.0]]), np.array([[0.0, 0.0, -1.0]])
    p = surface.points
    floor = p[:, 2] < 0.5
    # a ray to (x, y, 0) crosses the box's top (z = 30) at 0.4 (x, y): shaded within 25 cm
    square = np.maximum(np.abs(p[:, 0]), np.abs(p[:, 1]))
    truth = floor & (np.hypot(p[:, 0], p[:, 1]) <= 50.0) & (square > 25.0)
    sure = (np.abs(square - 25.0) > 1.5) & (np.abs(np.hypot(p[:, 0], p[:, 1]) - 50.0) > 0.5)
    kernel, rays = _both(tank, tips, looks, surface)
    assert (floor & (square < 24.0)).sum() > 50
    assert np.array_equal(kernel[sure & floor], truth[sure & floor])
    assert np.array_equal(rays[sure & floor], truth[sure & floor])


@pytest.mark.parametrize(("name", "bay", "seed"), [("b737_center", 2, 0), ("b737_center", 2, 1),
                                                   ("wing:5:2", 3, 2)])  # fmt: skip
def test_kernel_and_rays_agree_on_random_poses(name, bay, seed):
    """In the 737 and in a wing whose walls lie under the thin wedges of its taper."""
    tank = load_tank(name)
    rng = np.random.default_rng(seed)
    surface = surface_samples(tank, tank.bay(bay), 1500, seed=seed)
    lattice = viewpoint_lattice(tank, tank.bay(bay), 25.0, seed)
    tips = lattice[rng.permutation(len(lattice))[:6]]
    looks = rng.normal(size=(len(tips), 3))
    looks /= np.linalg.norm(looks, axis=1, keepdims=True)
    seen = 0
    for c, w in zip(tips, looks):
        kernel, rays = _both(tank, c[None], w[None], surface)
        # they may differ only at edges: the kernel's line of sight stops 2 cm short
        assert (kernel != rays).mean() <= 0.01
        seen += int(rays.sum())
    assert seen >= 100  # the poses see something, so agreeing is not agreeing on nothing


def test_bad_coverage_options_get_one_line(tmp_path, capsys):
    for argv in (["--coverage", "1.5"], ["--coverage", "nan"], ["--coverage", "0.5", "--random",
                 "3"], ["--coverage", "0.5", "--spacing", "0"]):  # fmt: skip
        assert tour_cli.main([*argv, "-o", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_a_lattice_too_coarse_for_the_goal_is_made_finer_and_the_tour_sees_it():
    pytest.importorskip("ortools")
    pytest.importorskip("toppra")
    tank = _room()
    box = (tank.box_min, tank.box_max)
    plan = plan_coverage(tank, box, goal=0.5, spacing=120.0, samples=400, seed=1)
    assert plan.spacing < 120.0  # the one viewpoint of the first lattice sees a fifth
    assert plan.estimate >= 0.5 and len(plan.tour.order) > 1
    measured = measure_coverage(tank, plan.tour.motion, box, samples=1500, seed=8)
    assert measured.fraction >= 0.5 - 0.04  # a fresh sample of 1,500 points: ±1.3% (1 sd)
    assert plan.tour.min_clearance_cm >= 1.0


@pytest.mark.slow
def test_bay_2_coverage_tour_sees_90_percent_and_passes_the_check(tmp_path, capsys):
    pytest.importorskip("ortools")
    pytest.importorskip("toppra")
    from aftir_rl.cli import check as check_cli

    out = tmp_path / "cov"
    assert tour_cli.main(["--coverage", "0.9", "--bay", "2", "--seed", "11", "-o", str(out),
                          "--quiet"]) == 0  # fmt: skip
    report = json.loads((out / "coverage.json").read_text())
    assert report["measured"]["fraction"] >= 0.9
    assert report["estimate"] >= 0.9
    assert check_cli.main([str(out)]) == 0
    assert "measured by ray casting" in capsys.readouterr().out


def test_the_pick_takes_the_largest_gain_first_and_stops_without_one():
    from aftir_rl.planning.ftl import coverage

    seen = np.array([[1, 1, 0, 0, 0], [1, 1, 1, 0, 0], [0, 0, 0, 1, 0]], dtype=np.bool_)
    assert coverage._greedy(seen, 0.8) == ([1, 2], 0.8)
    assert coverage._greedy(seen, 1.0) == ([1, 2], 0.8)  # nothing sees the last column
    assert coverage._greedy(np.zeros((0, 5), dtype=np.bool_), 0.9) == ([], 0.0)


def test_surface_samples_refuse_bad_counts():
    tank = _room()
    with pytest.raises(ConfigError):
        surface_samples(tank, (tank.box_min, tank.box_max), 0)
    assert isinstance(surface_samples(tank, (tank.box_min, tank.box_max), 10), SurfaceSamples)
