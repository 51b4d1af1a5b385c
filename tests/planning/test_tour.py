"""Inspection tours: the order against brute force, the tour against its own contract."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from aftir_rl.cli import check as check_cli
from aftir_rl.cli import tour as tour_cli
from aftir_rl.core.robot import forward_kinematics
from aftir_rl.planning.ftl import tour as tour_module
from aftir_rl.planning.ftl.model import Route
from aftir_rl.planning.ftl.tree import shared, union_length

pytest.importorskip("ortools")
pytest.importorskip("toppra")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_order_is_the_cheapest_cycle(seed):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 100, (7, 2))
    costs = np.linalg.norm(points[:, None] - points[None], axis=2) + rng.uniform(0, 5, (7, 7))
    order = tour_module._order(costs, 1.0)

    def length(cycle):
        stops = [0, *cycle, 0]
        return sum(costs[a, b] for a, b in zip(stops[:-1], stops[1:]))

    best = min(itertools.permutations(range(1, 7)), key=length)
    assert sorted(order) == list(range(1, 7))
    assert length(order) == pytest.approx(length(best), abs=1e-2)


def test_nearest_first_visits_every_node_once():
    costs = np.array([[0, 5, 1, 9], [5, 0, 2, 1], [1, 2, 0, 7], [9, 1, 7, 0]], dtype=float)
    assert tour_module._nearest_first(costs) == [2, 1, 3]


def test_shared_prefixes():
    kappa = np.array([[0.1, 0.0], [0.2, 0.1], [0.0, 0.3]])
    a = Route(15.0, kappa, 50.0)
    assert shared(a, Route(15.0, kappa[:2], 50.0)) == (115.0, 2)
    other = kappa.copy()
    other[1, 0] += 1e-9
    assert shared(a, Route(15.0, other, 50.0)) == (65.0, 1)
    assert shared(a, Route(30.0, kappa, 50.0)) == (15.0, 0)  # the straight lead
    assert shared(Route(-10.0, kappa, 50.0), a) == (-10.0, 0)  # in the guide


def test_the_union_of_routes_counts_shared_prefixes_once():
    kappa = np.array([[0.1, 0.0], [0.2, 0.1], [0.0, 0.3]])
    a, b = Route(15.0, kappa, 50.0), Route(15.0, kappa[:2], 50.0)
    other = kappa.copy()
    other[2] += 0.1
    c = Route(15.0, other, 50.0)
    assert union_length([]) == 0.0
    assert union_length([a]) == a.length == 165.0
    assert union_length([a, b]) == 165.0  # b is a prefix of a
    assert union_length([a, c]) == 15.0 + 4 * 50.0  # they part after two sections
    assert union_length([a, Route(30.0, kappa, 50.0)]) == 30.0 + 6 * 50.0  # other leads


@pytest.mark.slow
def test_a_tour_visits_every_target_and_passes_the_check(tmp_path, capsys):
    out = tmp_path / "tour"
    argv = ["--random", "4", "--bay", "2", "--seed", "3", "-o", str(out), "--quiet"]
    argv += ["--solver-seconds", "0.2"]  # OR-Tools settles the order of 5 nodes at once
    assert tour_cli.main(argv) == 0
    assert "% of" in capsys.readouterr().out
    report = json.loads((out / "tour.json").read_text())
    trajectory = json.loads((out / "trajectory.json").read_text())
    assert not report["failures"] and sorted(report["order"]) == [0, 1, 2, 3]
    assert report["duration_s"] < report["separate_deployments_s"]
    # every target is reached by the entry the tour names, by forward kinematics
    motion, targets = trajectory["motion"], np.array(report["targets"])
    for j, entry in zip(report["order"], trajectory["waypoint_index"]):
        posture = motion[entry]
        tip = forward_kinematics(posture["dis"], posture["theta"], posture["phi"], 50.0)[-1, :3, 3]
        assert np.linalg.norm(tip - targets[j]) < 1e-3
    # time always moves on (a JointTrajectory's points strictly increase in time)
    assert all(b > a for a, b in zip(trajectory["timing"]["t"], trajectory["timing"]["t"][1:]))
    # starts and ends straight in the guide (the panel), at rest
    assert motion[0] == {**motion[-1], "t": 0.0} and not any(motion[0]["theta"])
    assert not any(trajectory["timing"]["velocities"][-1])
    assert check_cli.main([str(out)]) == 0
