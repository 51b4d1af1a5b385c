"""The scene suite: fixed, clear, reachable targets; results as JSON, CSV and OMPL's database."""

from __future__ import annotations

import json
import sqlite3

import numpy as np
import pytest

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.suite import CLEARANCE, SCENES, run_suite, suite_targets


@pytest.mark.parametrize("name", ["b737_center", "wing:4:3"])
def test_targets_are_fixed_clear_and_reachable(name):
    tank = load_tank(name)
    targets = suite_targets(tank, 40, seed=3)
    assert np.array_equal(targets, suite_targets(tank, 40, seed=3))
    assert len(targets) == 40
    assert tank.distance(targets).min() >= CLEARANCE - 0.01  # rounded to 0.01 cm
    assert all(tank.reachable[tank.raster.point_to_cell(t)] > 0 for t in targets)


def test_the_suite_has_eight_scenes():
    assert len(SCENES) == 8


@pytest.mark.slow
def test_suite_writes_json_csv_and_an_ompl_database(tmp_path):
    pytest.importorskip("trimesh")
    rows = run_suite(tmp_path, 1, scenes=["wing_round_holes", "b737_center_mesh"])
    assert [r.scene for r in rows] == ["wing_round_holes", "b737_center_mesh"]
    assert all(r.complete and r.min_clearance_cm >= 1.0 - 1e-6 for r in rows)
    data = json.loads((tmp_path / "suite.json").read_text())
    assert len(data["rows"]) == 2 and "machine" in data
    assert (tmp_path / "suite.csv").read_text().startswith("scene,index,target")
    with sqlite3.connect(tmp_path / "suite.db") as con:
        got = con.execute(
            "SELECT e.name, COUNT(*), SUM(r.solved) FROM runs r JOIN experiments e "
            "ON e.id = r.experimentid GROUP BY e.name ORDER BY e.id"
        ).fetchall()
        assert got == [("wing_round_holes", 1, 1), ("b737_center_mesh", 1, 1)]
        assert con.execute("SELECT name FROM plannerConfigs").fetchall() == [("geometric_FTL",)]


def test_targets_in_a_bay_and_too_small_regions():
    tank = load_tank("wing:3:1")
    lo, hi = tank.bay(3)
    targets = suite_targets(tank, 5, seed=0, region=(lo, hi))
    assert np.all((targets >= lo) & (targets <= hi))
    with pytest.raises(ConfigError, match="too small"):
        suite_targets(tank, 1, 0, region=(lo, lo + 15.0))


def test_posture_target_draws_need_a_hatch():
    """They draw on both sides of a hatch; a tank without one is refused, not looped on."""
    from aftir_rl.planning.posture.context import random_free_targets
    from aftir_rl.planning.posture.planner import Planner

    with pytest.raises(ConfigError, match="has none"):
        random_free_targets(Planner(load_tank("wing:2:1")), 2, 0)
