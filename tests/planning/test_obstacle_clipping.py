from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import PlanningError
from aftir_rl.core.papers import ICRA2014_OBSTACLES, ICRA2014_TANKS, ICRA2014_TARGET
from aftir_rl.core.robot import body_points, tip_position
from aftir_rl.core.tank import Sphere, load_tank
from aftir_rl.planning.posture import Planner
from aftir_rl.planning.posture.obstacle_clipping import obstacle_clipping

TARGET = np.array(ICRA2014_TARGET)
OBSTACLES = list(ICRA2014_OBSTACLES)  # icra2014 §IV
ROWS = list(ICRA2014_TANKS)


def zone_distance(posture, obstacles):
    """Independent: horizontal distance of the backbone above the floor to each obstacle."""
    pts = body_points(posture.dis, posture.theta, posture.phi, 25.0, 40)
    pts = pts[pts[:, 2] >= 0]
    return min(
        (float(np.min(np.hypot(pts[:, 0] - o[0], pts[:, 1] - o[1]))) for o in obstacles),
        default=math.inf,
    )


@pytest.mark.parametrize("row", range(4))
def test_icra2014_table2_rows(row):
    planner = Planner(ROWS[row])
    assert [s.center for s in planner.tank.obstacles] == OBSTACLES[:row]
    result = planner.plan(TARGET, method="obstacle_clipping")
    p = result.posture
    assert result.method == "obstacle_clipping" and p.n_sections == 3  # as in the paper
    tip = tip_position(p.dis, p.theta, p.phi, 25.0)
    assert np.linalg.norm(tip - TARGET) < 0.01
    assert max(abs(t) for t in p.theta) <= math.pi / 2 + 1e-9
    # Obstacle space zones: r_oba = r0 + r_b = 2 + 2 cm (sampled 4x denser than the planner).
    assert zone_distance(p, OBSTACLES[:row]) > 4.0
    assert not CollisionScene(planner.tank).check(p).collides


@pytest.mark.slow
def test_paper_mode_stops_in_the_target_plane_zone():
    planner = Planner(ROWS[1])
    result = obstacle_clipping(planner, TARGET, r_target=1.0, refine=False)
    tip = result.tip
    assert math.hypot(tip[0] - TARGET[0], tip[1] - TARGET[1]) <= 1.0 + 1e-6
    assert tip[2] == pytest.approx(TARGET[2], abs=1e-9)  # the rising distance sets the height
    assert result.details["loops"] >= 3


def test_obstacle_under_the_target_makes_it_unreachable():
    tank = dataclasses.replace(load_tank("open_space"), obstacles=(Sphere((30, 17, 20), 2.0),))
    with pytest.raises(PlanningError, match="Cannot reach the target: it lies in the obstacle"):
        Planner(tank).plan(TARGET, method="obstacle_clipping")


def test_plan_cli_obstacle_clipping_json():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "aftir_rl.plan",
            "--tank",
            ROWS[3],
            "--target",
            "30",
            "18",
            "51",
            "--method",
            "obstacle_clipping",
            "--json",
            "--margin",
            "0",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    data = json.loads(out.stdout)
    assert data["method"] == "obstacle_clipping" and data["error_cm"] < 0.01
    assert len(data["theta"]) == len(data["phi"]) == 3
