"""Side trips: the posture reaches the other target by forward kinematics, the move keeps the
margin by python-fcl, only the last sections bend; the choice never strands a trip's host."""

from __future__ import annotations

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.robot import Posture, angles_to_kappa, body_points, forward_kinematics
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.model import kappa_to_angles
from aftir_rl.planning.ftl.plan import plan_motion
from aftir_rl.planning.ftl.side_trip import (
    FREE_SECTIONS,
    STEP_CM,
    SideTrip,
    choose_side_trips,
    host_postures,
    side_trips,
    straight_move,
)
from aftir_rl.planning.posture.planner import Planner, random_free_targets

pytest.importorskip("toppra")


@pytest.fixture(scope="module")
def tank():
    return load_tank("b737_center")


def _joints(dis, theta, phi):
    return np.concatenate([[dis], angles_to_kappa(theta, phi).ravel()])


def _host(tank, target):
    plan = plan_motion(tank, target)
    assert plan.complete, plan.reason
    m = plan.motion
    return host_postures({0: (m.dis, m.theta, m.phi)})[0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_trip_reaches_the_other_target_and_keeps_the_margin(tank, seed):
    rng = np.random.default_rng(seed)
    a = np.array(random_free_targets(Planner(tank), 1, 100 + seed, clearance=10.0)["bay2"][0])
    qa = _host(tank, a)
    n, l = (len(qa) - 1) // 2, tank.arm.section_length
    # a reachable second target: the last two sections bent a little more
    kappa = qa[1:].reshape(n, 2).copy()
    kappa[-2:] += rng.uniform(-0.25, 0.25, (2, 2))
    theta, phi = kappa_to_angles(kappa[None])
    b = forward_kinematics(qa[0], theta[0], phi[0], l)[-1, :3, 3]
    trips = side_trips(tank, {0: qa, 1: qa}, np.array([a, b]), margin=1.0)
    trip = trips[0, 1]  # these draws' bends keep the margin
    dis, theta, phi = trip.path
    # starts at the host's posture and ends on the target (forward kinematics)
    assert np.allclose(_joints(dis[0], theta[0], phi[0]), qa)
    tip = forward_kinematics(dis[-1], theta[-1], phi[-1], l)[-1, :3, 3]
    assert np.linalg.norm(tip - b) < 1e-5
    # only the last sections bend; the module stays
    kappas = angles_to_kappa(theta, phi)
    assert np.all(dis == dis[0])
    fixed = n - max(FREE_SECTIONS)
    assert np.abs(kappas[:, :fixed] - kappas[0, :fixed]).max() < 1e-12
    # dense, and clear of the tank by python-fcl at every entry
    points = body_points(dis, theta, phi, l, 10)
    assert np.linalg.norm(np.diff(points, axis=0), axis=2).max() <= STEP_CM + 1e-9
    scene = CollisionScene(tank, links_per_section=20)
    worst = min(
        scene.check(Posture(d, tuple(t), tuple(p))).clearance_cm
        for d, t, p in zip(dis[::4], theta[::4], phi[::4])
    )
    assert worst >= 1.0 - 0.05 and trip.clearance_cm >= 1.0
    assert trip.duration > 0 and trip.timed.t[-1] == pytest.approx(trip.duration)


def test_straight_moves_are_dense(tank):
    rng = np.random.default_rng(5)
    for _ in range(5):
        a, b = (np.concatenate([[rng.uniform(0, 50)], rng.uniform(-0.3, 0.3, 16)]) for _ in "ab")
        dis, theta, phi = straight_move(a, b, tank.arm)
        points = body_points(dis, theta, phi, tank.arm.section_length, 10)
        assert np.linalg.norm(np.diff(points, axis=0), axis=2).max() <= STEP_CM + 1e-9
        assert np.allclose(_joints(dis[-1], theta[-1], phi[-1]), b)


class _Timed:
    def __init__(self, duration):
        self.duration = duration


@pytest.mark.parametrize("seed", range(6))
def test_the_choice_keeps_hosts_and_only_saves_time(seed):
    rng = np.random.default_rng(seed)
    nodes = list(range(8))
    points = rng.uniform(0, 100, (9, 2))
    costs = np.linalg.norm(points[:, None] - points[None], axis=2) + 40.0
    np.fill_diagonal(costs, 0.0)
    trips = {
        (h, j): SideTrip(h, j, (), _Timed(float(rng.uniform(1, 40))), 2.0)  # type: ignore[arg-type]
        for h in nodes
        for j in nodes
        if h != j and rng.random() < 0.3
    }
    order = list(rng.permutation(nodes))

    def cycle(o):
        stops = [0, *(j + 1 for j in o), 0]
        return sum(costs[a, b] for a, b in zip(stops[:-1], stops[1:]))

    kept, chosen = choose_side_trips(costs, nodes, order, trips)
    assert sorted(kept + list(chosen)) == nodes
    assert kept == [j for j in order if j in kept]  # the order of the rest is kept
    for j, trip in chosen.items():
        assert trip.target == j and trip.host in kept and (trip.host, j) in trips
    assert cycle(kept) + 2 * sum(t.duration for t in chosen.values()) <= cycle(order) + 1e-9


def test_a_trip_past_a_cables_travel_is_left_out(tank, monkeypatch):
    from aftir_rl.core.errors import PlanningError
    from aftir_rl.planning.ftl import side_trip

    a = np.array(random_free_targets(Planner(tank), 1, 100, clearance=10.0)["bay2"][0])
    qa = _host(tank, a)
    n, l = (len(qa) - 1) // 2, tank.arm.section_length
    kappa = qa[1:].reshape(n, 2).copy()
    kappa[-2:] += 0.1
    theta, phi = kappa_to_angles(kappa[None])
    b = forward_kinematics(qa[0], theta[0], phi[0], l)[-1, :3, 3]
    assert (0, 1) in side_trips(tank, {0: qa, 1: qa}, np.array([a, b]), margin=1.0)

    def refuse(*args, **kwargs):
        raise PlanningError("a cable leaves its travel")

    monkeypatch.setattr(side_trip, "time_motion", refuse)
    assert side_trips(tank, {0: qa, 1: qa}, np.array([a, b]), margin=1.0) == {}
