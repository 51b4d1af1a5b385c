"""Baffles with holes: the signed distance against python-fcl, the raster against sampling."""

from __future__ import annotations

import fcl
import numpy as np
import pytest

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank.generate import wing_tank
from aftir_rl.core.tank.loading import tank_from_mapping
from aftir_rl.core.tank.plate import ROUND_VERTICES, Hole, Plate

#: Largest gap between a round hole and its inscribed polygon, for the radii below [cm].
SAGITTA = 25.0 * (1 - np.cos(np.pi / ROUND_VERTICES))


def random_plate(seed: int) -> Plate:
    """A plate across a random axis with a rect, a circle and an oval hole, apart."""
    rng = np.random.default_rng(seed)
    holes = (
        Hole("rect", (20.0 + rng.uniform(-5, 5), 50.0), rng.uniform(10, 30), rng.uniform(10, 40)),
        Hole("circle", (90.0, 50.0 + rng.uniform(-10, 10)), 2 * rng.uniform(8, 25), 0.0),
        Hole("oval", (160.0, 45.0), rng.uniform(20, 50), rng.uniform(10, 40)),
    )
    holes = (holes[0], Hole("circle", holes[1].center, holes[1].width, holes[1].width), holes[2])
    return Plate(int(rng.integers(0, 3)), rng.uniform(-20, 20), rng.uniform(1, 6), (-10, 0),
                 (200, 100), holes)  # fmt: skip


def fcl_distance(plate: Plate, points: np.ndarray) -> np.ndarray:
    """Distance from each point to the plate's python-fcl pieces (0 where it touches)."""
    manager = fcl.DynamicAABBTreeCollisionManager()
    objects = plate.fcl_objects()
    manager.registerObjects(objects)
    manager.setup()
    out = []
    for p in points:
        probe = fcl.CollisionObject(fcl.Sphere(1e-6), fcl.Transform(p))
        data = fcl.DistanceData()
        manager.distance(probe, data, fcl.defaultDistanceCallback)
        out.append(max(data.result.min_distance, 0.0))
    return np.array(out)


def in_plane_points(plate: Plate, rng: np.random.Generator, n: int) -> np.ndarray:
    """Points over the plate's rectangle, within 15 cm of its mid-plane."""
    a, b = [i for i in range(3) if i != plate.axis]
    pts = np.empty((n, 3))
    pts[:, a] = rng.uniform(plate.lo[0], plate.hi[0], n)
    pts[:, b] = rng.uniform(plate.lo[1], plate.hi[1], n)
    pts[:, plate.axis] = plate.position + rng.uniform(-15, 15, n)
    return pts


@pytest.mark.parametrize("seed", range(4))
def test_signed_distance_is_fcls_distance(seed):
    plate = random_plate(seed)
    rng = np.random.default_rng(100 + seed)
    pts = in_plane_points(plate, rng, 600)
    sdf = plate.signed_distance(pts)
    outside = sdf > 0
    gap = sdf[outside] - fcl_distance(plate, pts[outside])
    # fcl's round edges are inscribed polygons: it sees at least as much material as there is
    assert gap.min() > -1e-4  # python-fcl's GJK tolerance
    assert gap.max() < SAGITTA + 1e-4
    assert np.mean(gap < 1e-4) > 0.6  # exact wherever the nearest edge is straight


@pytest.mark.parametrize("seed", range(4))
def test_inside_agrees_with_fcl_collision(seed):
    plate = random_plate(seed)
    pts = in_plane_points(plate, np.random.default_rng(200 + seed), 1500)
    pts[:, plate.axis] = plate.position + np.random.default_rng(seed).uniform(-3, 3, len(pts))
    sdf = plate.signed_distance(pts)
    touching = fcl_distance(plate, pts) == 0
    assert np.all(touching[sdf < 0])
    assert not np.any(touching[sdf > SAGITTA + 1e-6])
    assert np.array_equal(plate.contains(pts), sdf < 0)


def test_distance_is_exact_inside_the_material_and_holes():
    """Inside the material, the nearest boundary is a face, the rim or a hole's edge."""
    plate = Plate(1, 0.0, 4.0, (0.0, 0.0), (100.0, 60.0), (Hole("circle", (50.0, 30.0), 20, 20),))
    # on the mid-plane, 5 cm from the hole's edge: the faces (2 cm) are nearer
    assert plate.signed_distance([65.0, 0.0, 30.0]) == pytest.approx(-2.0)
    # in the hole's centre: 10 cm to its edge
    assert plate.signed_distance([50.0, 0.0, 30.0]) == pytest.approx(10.0)
    # inside the material, 0.5 cm from the hole's edge, on the mid-plane
    assert plate.signed_distance([60.5, 0.0, 30.0]) == pytest.approx(-0.5)
    # beside a face, over the material: the face
    assert plate.signed_distance([80.0, 7.0, 30.0]) == pytest.approx(5.0)
    # beside a face, in front of the hole's edge: to the rim's circle
    assert plate.signed_distance([57.0, 6.0, 30.0]) == pytest.approx(np.hypot(3.0, 4.0))


@pytest.mark.parametrize("seed", range(3))
def test_raster_overlap_agrees_with_sampling(seed):
    plate = random_plate(seed)
    rng = np.random.default_rng(300 + seed)
    lo = rng.uniform(-20, 200, (300, 3))
    lo[:, plate.axis] = plate.position + rng.uniform(-12, 4, 300)
    a, b = [i for i in range(3) if i != plate.axis]
    lo[:, a] = rng.uniform(plate.lo[0], plate.hi[0] - 10, 300)
    lo[:, b] = rng.uniform(plate.lo[1], plate.hi[1] - 10, 300)
    hi = lo + 10.0
    t = (np.arange(21) + 0.5) / 21
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    overlaps = plate.overlaps(lo, hi)
    for cell_lo, cell_hi, verdict in zip(lo, hi, overlaps):
        inside = plate.contains(cell_lo + grid * (cell_hi - cell_lo)).any()
        if inside:
            assert verdict
        if verdict and not inside:  # only a sliver the samples missed
            assert plate.signed_distance(cell_lo + grid * (cell_hi - cell_lo)).min() < 0.5


def polygon_area(poly: np.ndarray) -> float:
    """The shoelace formula."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))


def test_pieces_cover_exactly_the_material():
    """The convex pieces' areas add up to the rectangle less the holes' polygons."""
    plate = random_plate(7)
    area = sum(polygon_area(p) for p in plate.pieces)
    holes = 0.0
    for h in plate.holes:
        poly = h.polygon()
        holes += 0.5 * abs(
            np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
        )
    rect = (plate.hi[0] - plate.lo[0]) * (plate.hi[1] - plate.lo[1])
    assert area == pytest.approx(rect - holes, rel=1e-9)


BASE = {
    "box": {"min": [-50, -50, 0], "max": [250, 50, 100]},
    "cell_size": 10,
    "panel": {"center": [0, 0, 0], "radius": 12},
}


def with_baffles(*baffles):
    return {**BASE, "baffles": list(baffles)}


@pytest.mark.parametrize(
    ("baffle", "message"),
    [
        ({"axis": "w", "position": 100, "thickness": 2}, "axis: expected 'x', 'y' or 'z'"),
        ({"axis": "x", "position": 260, "thickness": 2}, "must lie inside the box"),
        ({"axis": "x", "position": 100, "thickness": 2, "holes": [{"shape": "star"}]},
         "shape: expected one of rect, circle, oval"),
        ({"axis": "x", "position": 100, "thickness": 2,
          "holes": [{"shape": "circle", "center": [100, 0, 50], "diameter": 200}]},
         "reaches outside its baffle"),
        ({"axis": "x", "position": 100, "thickness": 2,
          "holes": [{"shape": "circle", "center": [90, 0, 50], "diameter": 20}]},
         "is not in its baffle"),
        ({"axis": "x", "position": 100, "thickness": 2,
          "holes": [{"shape": "rect", "center": [100, 0, 50], "width": 20, "height": 20},
                    {"shape": "circle", "center": [100, 10, 50], "diameter": 20}]},
         "holes[1] overlaps holes[0]"),
        ({"axis": "x", "position": 100, "thickness": 2,
          "holes": [{"shape": "oval", "center": [100, 0, 50], "width": 20}]},
         "missing key 'height'"),
        ({"axis": "x", "position": 100, "thickness": -1}, "thickness: must be positive"),
    ],
)  # fmt: skip
def test_bad_baffles_are_one_line_errors(baffle, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
        tank_from_mapping(with_baffles(baffle), "t.yaml")


def test_too_many_baffles_or_holes():
    many = [{"axis": "x", "position": 100, "thickness": 1}] * 33
    with pytest.raises(ConfigError, match="at most 32"):
        tank_from_mapping({**BASE, "baffles": many}, "t.yaml")
    hole = {"shape": "circle", "center": [100, 0, 50], "diameter": 1}
    with pytest.raises(ConfigError, match="at most 32"):
        tank_from_mapping(with_baffles({"axis": "x", "position": 100, "thickness": 1,
                                        "holes": [hole] * 33}), "t.yaml")  # fmt: skip


def test_bays_lie_between_baffles():
    tank = tank_from_mapping(
        with_baffles({"axis": "x", "position": 150, "thickness": 4},
                     {"axis": "x", "position": 50, "thickness": 2}), "t.yaml")  # fmt: skip
    assert [tuple(tank.bay(i)[0][:1]) + tuple(tank.bay(i)[1][:1]) for i in (1, 2, 3)] == [
        (-50, 49), (51, 148), (152, 250)]  # fmt: skip
    with pytest.raises(ConfigError, match="3 bays"):
        tank.bay(4)


@pytest.mark.parametrize(("bays", "seed"), [(2, 0), (3, 1), (5, 2), (4, 9), (3, 10059), (2, 10287)])
def test_generated_wings_are_reproducible_and_reachable(bays, seed):
    """Seeds 10059 and 10287 drew the pipe from an empty range (a stream died on them)."""
    data = wing_tank(bays, seed)
    assert data == wing_tank(bays, seed)
    assert data != wing_tank(bays, seed + 1)
    tank = tank_from_mapping(data, "wing.yaml")
    assert len(tank.baffles) == bays - 1
    for i in range(1, bays + 1):  # a free cell of every bay is reachable on the raster
        lo, hi = tank.bay(i)
        cells = [tank.raster.point_to_cell(t) for t in tank.targets if np.all((t > lo) & (t < hi))]
        assert cells and all(tank.reachable[c] > 0 for c in cells)
        assert tank.distance(np.array(tank.targets)).min() >= 10.0


def test_every_seed_of_a_stretch_generates():
    for bays in (1, 2, 3, 5):
        for seed in range(10_000, 10_400):
            wing_tank(bays, seed)  # no exception
