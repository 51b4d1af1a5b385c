"""Tapered tanks: wedges against python-fcl and sampling, the taper key, tapered wings."""

from __future__ import annotations

import fcl
import numpy as np
import pytest

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import load_tank
from aftir_rl.core.tank.loading import tank_from_mapping
from aftir_rl.core.tank.wedge import Wedge

BASE = {"box": {"min": [-50, -50, 0], "max": [250, 50, 100]}, "cell_size": 10}


def random_wedge(seed: int) -> Wedge:
    rng = np.random.default_rng(seed)
    tri = rng.uniform(-40, 40, 6)
    return Wedge(int(rng.integers(0, 3)), -10.0, rng.uniform(0, 30), tuple(tri))


def fcl_distance(solid, points):
    obj = solid.fcl_object()
    out = []
    for p in points:
        probe = fcl.CollisionObject(fcl.Sphere(1e-6), fcl.Transform(p))
        res = fcl.DistanceResult()
        out.append(max(fcl.distance(obj, probe, fcl.DistanceRequest(), res), 0.0))
    return np.array(out)


@pytest.mark.parametrize("seed", range(5))
def test_signed_distance_is_exact_outside_and_signs_agree(seed):
    wedge = random_wedge(seed)
    pts = np.random.default_rng(seed + 10).uniform(-60, 60, (800, 3))
    sdf = wedge.signed_distance(pts)
    fcl_d = fcl_distance(wedge, pts)
    outside = sdf > 1e-3
    np.testing.assert_allclose(sdf[outside], fcl_d[outside], atol=1e-4)  # GJK's tolerance
    assert np.all(fcl_d[sdf < -1e-3] == 0)


@pytest.mark.parametrize("seed", range(3))
def test_raster_overlap_agrees_with_sampling(seed):
    wedge = random_wedge(seed)
    rng = np.random.default_rng(seed + 20)
    lo = rng.uniform(-50, 40, (400, 3))
    hi = lo + 10.0
    t = (np.arange(15) + 0.5) / 15
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    for cell_lo, cell_hi, verdict in zip(lo, hi, wedge.overlaps(lo, hi)):
        samples = cell_lo + grid * (cell_hi - cell_lo)
        if wedge.contains(samples).any():
            assert verdict
        elif verdict:
            assert wedge.signed_distance(samples).min() < 0.7


def test_taper_shrinks_the_section_linearly():
    data = {**BASE, "taper": {"along": "x", "end": {"min": [-30, 0], "max": [40, 70]}}}
    tank = tank_from_mapping(data, "t.yaml")
    assert sorted(w.name for w in tank.taper) == ["taper_y_max", "taper_y_min", "taper_z_max"]
    # at x = 100 (half way), the ceiling is at 85 and the sides at -40 and 45
    for point, expect in [((100, 0, 80), 5.0), ((100, 40, 40), 5.0), ((100, -35, 40), 5.0)]:
        assert tank.distance(np.array(point)) == pytest.approx(expect, abs=0.05)


@pytest.mark.parametrize(
    ("taper", "message"),
    [
        ({"along": "z", "end": {"min": [0, 0], "max": [1, 1]}}, "taper.along: expected 'x' or 'y'"),
        ({"along": "x", "end": {"min": [-60, 0], "max": [40, 70]}}, "inside the box"),
        ({"along": "x", "end": {"min": [0, 0], "max": [0, 70]}}, "non-empty"),
        ({"along": "x", "end": {"min": [0, 0]}}, "missing key 'max'"),
    ],
)
def test_bad_tapers_are_one_line_errors(taper, message):
    with pytest.raises(ConfigError, match=message):
        tank_from_mapping({**BASE, "taper": taper}, "t.yaml")


def test_generated_wings_taper():
    tank = load_tank("wing:4:2")
    assert {w.name for w in tank.taper} >= {"taper_z_max"}
    assert tank.distance(np.array(tank.targets)).min() >= 10.0
