from __future__ import annotations

import math

import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.robot import Posture, tip_position
from aftir_rl.planning.jointspace import (
    align,
    bending_plane,
    bridge,
    densify,
    first_collision,
    in_plane,
    joint_distance,
    rrt_connect,
    tip_path_length,
)
from aftir_rl.planning.posture import Planner
from aftir_rl.planning.posture.trajectory import (
    pad_sections,
    plan_trajectory,
    repair_posture,
    slide,
)


@pytest.fixture(scope="module")
def planner(tank):
    return Planner(tank)


def random_postures(rng, count, n):
    theta = rng.uniform(-math.pi / 2, math.pi / 2, (count, n)) * rng.uniform(0, 1, (count, 1))
    phi = rng.uniform(-math.pi, math.pi, (count, n))
    dis = rng.uniform(-n * 50, 0, count)
    return [Posture(d, t, p) for d, t, p in zip(dis, theta, phi)]


def test_align_keeps_the_arm_and_takes_the_nearest_joint_values():
    rng = np.random.default_rng(3)
    for a, b in zip(random_postures(rng, 50, 4), random_postures(rng, 50, 4)):
        c = align(b, a)
        np.testing.assert_allclose(c.points(50, 6), b.points(50, 6), atol=1e-9)
        assert np.all(np.abs(np.subtract(c.phi, a.phi)) <= math.pi / 2 + 1e-9)
    # A section bent the other way round is the same section: no 180 deg swing.
    a = Posture(-10, (0.5,), (0.0,))
    b = Posture(-10, (-0.5,), (math.pi,))
    assert joint_distance(a, align(b, a), 50) == pytest.approx(0.0, abs=1e-12)
    assert joint_distance(a, b, 50) == pytest.approx(math.hypot(1.0, math.pi))


def test_densify_bounds_every_joint_step():
    a = Posture(-100, (0.0, 1.0), (0.0, 0.5))
    b = Posture(-60, (0.7, -1.0), (0.3, 0.5))
    dense = densify([a, b], max_angle=math.radians(1), max_dis=1.0)
    assert dense[0] == a and dense[-1] == b
    x = np.array([[p.dis, *p.theta, *p.phi] for p in dense])
    steps = np.abs(np.diff(x, axis=0))
    assert steps[:, 0].max() <= 1.0 + 1e-9
    assert steps[:, 1:].max() <= math.radians(1) + 1e-9
    assert len(dense) == math.ceil(2.0 / math.radians(1)) + 1


def test_tip_path_length_of_a_straight_push():
    postures = densify([Posture(-100, (0.0,), (0.0,)), Posture(-40, (0.0,), (0.0,))])
    assert tip_path_length(postures, 50) == pytest.approx(60.0)


def test_fast_check_agrees_with_fcl(tank):
    # The numpy pre-check may only skip python-fcl where it would find no collision.
    scene = CollisionScene(tank)
    rng = np.random.default_rng(11)
    postures = random_postures(rng, 300, 3) + random_postures(rng, 100, 6)
    verdicts = [(scene.collides_fast(p), scene.collides(p)) for p in postures]
    assert all(fast == full for fast, full in verdicts)
    assert 0 < sum(full for _, full in verdicts) < len(verdicts)  # both kinds were tested


def test_first_collision_finds_the_first_bad_posture(planner):
    free = Posture(-40, (0.0, 0.0), (0.0, 0.0))
    ceiling = Posture(0.0, (0.0, 0.0), (0.0, 0.0))  # the tip pokes 2.5 cm into the ceiling
    dense = densify([free, ceiling], max_dis=1.0)
    hit = first_collision(planner.scene, dense)
    # The body touches the ceiling (z = 100) when dis + 100 + 2.5 > 100, i.e. dis > -2.5.
    assert dense[hit].dis > -2.5 and dense[hit - 1].dis <= -2.5


def test_repair_keeps_the_tip_and_clears_the_tank(planner):
    # Three sections whose lowest bend scrapes the floor's opening; the tip is free.
    bad = Posture(-93.71, (-0.2307, 1.0118, -1.1278), (-1.1021, -0.5643, -0.7728))
    assert planner.scene.check(bad).hit == "wall"
    target = bad.tip(50)
    fixed = repair_posture(planner, bad, target)
    assert fixed is not None
    assert np.linalg.norm(fixed.tip(50) - target) < 0.01
    assert not CollisionScene(planner.tank).check(fixed).collides


def test_rrt_connect_from_the_start_posture_in_bay_1(planner):
    goal = planner.plan((20, 10, 60))
    n = goal.posture.n_sections
    start = Posture(10 - n * 50, (0.0,) * n, (0.0,) * n)
    plan = rrt_connect(planner.scene, start, goal.posture, time_limit=20, seed=1)
    assert plan.solved, plan.reason
    assert plan.postures[0] == start
    np.testing.assert_allclose(
        plan.postures[-1].points(50, 4), goal.posture.points(50, 4), atol=1e-9
    )
    # Independent check of the whole path: dense interpolation, fcl on every posture.
    scene = CollisionScene(planner.tank)
    dense = densify(plan.postures)
    assert not any(scene.collides(p) for p in dense)
    assert plan.joint_length(50) > 0 and plan.checks > 0


def test_rrt_connect_reports_a_colliding_goal(planner):
    start = Posture(-90, (0.0, 0.0), (0.0, 0.0))
    goal = Posture(0.0, (0.0, 0.0), (0.0, 0.0))
    plan = rrt_connect(planner.scene, start, goal, time_limit=1)
    assert not plan.solved and plan.reason == "the goal posture collides"


def test_pad_then_align_is_the_same_arm(planner):
    p = planner.plan((20, 10, 60)).posture
    padded = pad_sections(p, p.n_sections + 3, 50)
    reference = Posture(-200.0, (0.0,) * padded.n_sections, (1.0,) * padded.n_sections)
    aligned = align(padded, reference)
    # The arm above the padding is the same: the last sections' backbone, point for point.
    k = 5
    tail = slice(-(p.n_sections * k + 1), None)
    np.testing.assert_allclose(aligned.points(50, k)[tail], p.points(50, k), atol=1e-9)
    np.testing.assert_allclose(padded.points(50, k)[tail], p.points(50, k), atol=1e-9)
    assert aligned.phi[0] == 1.0  # a straight section takes the reference's phi


@pytest.mark.slow
def test_trajectory_moves_are_what_it_reports(planner):
    # A bay-1 cell path: (10, 0, 10) .. (30, 20, 50) then the exact target.
    points = [(10, 0, 10), (30, 0, 10), (30, 0, 30), (30, 0, 50), (30, 20, 50)]
    target = (22.0, 12.0, 55.0)
    trajectory = plan_trajectory(planner, points, target)
    scene = CollisionScene(planner.tank)
    assert not trajectory.failures
    for posture, waypoint in zip(trajectory.postures, trajectory.waypoints):
        p = posture.posture
        assert np.linalg.norm(tip_position(p.dis, p.theta, p.phi, 50) - waypoint) < 0.01
        assert not scene.collides(p)
    blocked = {i for i, _ in trajectory.blocked_moves}
    assert [i for i, _ in trajectory.moves] == list(range(len(points)))
    for i, via in trajectory.moves:
        a, b = trajectory.postures[i].posture, trajectory.postures[i + 1].posture
        hit = first_collision(scene, densify([a, *via, b]))
        assert (hit is not None) == (i in blocked), i  # checked independently here
    assert trajectory.complete == (not blocked)
    data = trajectory.to_json()
    assert len(data["moves"]) == len(points) and data["complete"] == trajectory.complete


def test_in_plane_is_the_same_arm():
    # Sections bent in phi = 0.4 and in 0.4 + pi (the other way round), and a straight one.
    p = Posture(-80.0, (0.3, 0.0, 0.7, 1.2), (0.4, 2.0, 0.4 + math.pi, 0.4 - math.pi))
    assert bending_plane(p) == pytest.approx(0.4)
    q = in_plane(p, bending_plane(p))
    np.testing.assert_allclose(q.points(50, 6), p.points(50, 6), atol=1e-9)
    assert np.allclose(q.phi, 0.4) and q.theta[:3] == pytest.approx((0.3, 0.0, -0.7))
    skew = Posture(-80.0, (0.3, 0.5), (0.4, 1.4))
    assert bending_plane(skew) is None
    with pytest.raises(ValueError, match="bend out of the plane"):
        in_plane(skew, 0.4)


def test_bridge_the_first_move_along_the_floor(planner):
    # From the start cell's centre to the next cell along the floor: continuation fails there and
    # the straight joint interpolation to TGA's hooked posture collides at once. Both postures
    # bend in the plane phi = 0 with at most 4 sections out, so the bridge searches 5 joints.
    n, l = 8, 50
    start = pad_sections(planner.plan((10, 0, 10)).posture, n, l)
    goal = align(pad_sections(planner.plan((30, 0, 10)).posture, n, l), start)
    scene = CollisionScene(planner.tank)
    assert first_collision(scene, densify([start, goal])) is not None
    assert bending_plane(start, goal) is not None
    plan = bridge(planner.scene, start, goal, time_limit=30)
    assert plan.solved, plan.reason
    assert plan.postures[0] == start and plan.postures[-1] == goal
    assert all(p.n_sections == n for p in plan.postures)
    # In the plane: every bent section of every posture between bends in phi = 0 (or pi).
    assert all(
        abs(math.sin(phi)) < 1e-9
        for p in plan.postures[1:-1]
        for t, phi in zip(p.theta, p.phi)
        if abs(t) > 1e-9
    )
    # Independent check: every densified posture with fcl itself, not the fast pre-check.
    dense = densify(plan.postures)
    assert not any(scene.collides(p) for p in dense)
    assert max(abs(t) for p in dense for t in p.theta) <= planner.arm.theta_max + 1e-9


def test_slide_by_a_whole_section_keeps_the_body_and_lengthens_it():
    rng = np.random.default_rng(5)
    l, k = 50, 6
    for p in random_postures(rng, 20, 5):
        p = pad_sections(p, 6, l)  # the first section straight, as in the guide
        pushed = slide(p, l, l)
        assert pushed.dis == pytest.approx(p.dis + l)
        # Exact at one section: the old body from its second section on, point for point ...
        np.testing.assert_allclose(pushed.points(l, k)[: 5 * k + 1], p.points(l, k)[k:], atol=1e-9)
        # ... then one more section bent like the last.
        np.testing.assert_allclose(pushed.theta[-1], p.theta[-1])
        np.testing.assert_allclose(slide(p, 0.0, l).points(l, k), p.points(l, k), atol=1e-9)
    with pytest.raises(ValueError, match="can slide by 0 to 50"):
        slide(p, 80.0, l)
