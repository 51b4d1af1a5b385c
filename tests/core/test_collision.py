from __future__ import annotations

import math

import fcl
import numpy as np
import pytest

from aftir_rl.core.collision import CollisionScene, panel_violation, point_clearance, points_clear
from aftir_rl.core.robot import Posture


@pytest.fixture(scope="module")
def scene(tank):
    return CollisionScene(tank)


def test_straight_arm_through_the_panel_is_free(scene):
    report = scene.check(Posture(-40, (0.0, 0.0), (0.0, 0.0)))
    assert not report.collides and report.panel_ok
    # Nearest surface: the edge of the floor opening, 12 cm from the axis, minus the radius.
    assert report.clearance_cm == pytest.approx(12 - 2.5, abs=1e-6)


@pytest.mark.parametrize("dis, collides", [(-3.0, False), (-2.0, True)])
def test_touching_the_ceiling(scene, dis, collides):
    # Two straight sections: the tip at z = dis + 100, the body 2.5 cm beyond it.
    report = scene.check(Posture(dis, (0.0, 0.0), (0.0, 0.0)))
    assert report.collides is collides
    if not collides:
        assert report.clearance_cm == pytest.approx(0.5, abs=1e-6)
    else:
        assert report.hit == "wall"


def test_into_the_baffle_below_the_hatch(scene):
    # Bend 90 deg towards +y at z = 11.8, then straight on through y = 58..62 below the hatch.
    report = scene.check(Posture(-20, (math.pi / 2, 0.0), (math.pi / 2, math.pi / 2)))
    assert report.collides and report.hit == "baffle_below_hatch"


@pytest.mark.parametrize("aim_x, hit", [(100.0, ""), (40.0, "baffle_left_of_hatch")])
def test_through_the_hatch(scene, aim_x, hit):
    # In the vertical plane through the panel and (aim_x, 60): bend 90 deg to level off at z = 50,
    # then three straight sections across y = 60: through the hatch centre, or into the baffle.
    psi = math.atan2(60.0, aim_x)
    r = 50 / (math.pi / 2)
    posture = Posture(50 - r, (math.pi / 2, 0.0, 0.0, 0.0), (psi,) * 4)
    pts = posture.points(50, 20)
    crossing = pts[(pts[:, 1] > 57) & (pts[:, 1] < 63)]
    np.testing.assert_allclose(crossing[:, 2], 50, atol=1e-9)
    assert np.all(np.abs(crossing[:, 0] - aim_x) < 6)
    report = scene.check(posture)
    assert report.collides is bool(hit) and report.hit == hit
    if not hit:
        # Nearest: the vertical edge of the opening at (80, 58), whose distance to the arm's
        # straight line through the z axis at bearing psi is |80 sin psi - 58 cos psi|.
        edge = abs(80 * math.sin(psi) - 58 * math.cos(psi))
        assert report.clearance_cm == pytest.approx(edge - 2.5, abs=0.01)


def test_inside_a_pipe(scene):
    # One section bent towards +y whose tip lies on the axis of the bay-1 pipe (y = 20, z = 85).
    lo, hi = 0.1, 1.5
    for _ in range(100):  # bisection for (l/θ)(1 − cos θ) = 20
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if 50 / mid * (1 - math.cos(mid)) < 20 else (lo, mid)
    theta = (lo + hi) / 2
    dis = 85 - 50 / theta * math.sin(theta)
    posture = Posture(dis, (theta,), (math.pi / 2,))
    np.testing.assert_allclose(posture.tip(50), [0, 20, 85], atol=1e-9)
    report = scene.check(posture)
    assert report.collides and report.hit == "fuel_pipe_bay1"


def test_bent_section_under_the_floor(scene):
    posture = Posture(-40, (1.2, 0.0), (0.0, 0.0))
    assert posture.points(50, 10)[3, 2] < 0  # still below the floor, already off the axis
    report = scene.check(posture)
    assert report.collides and not report.panel_ok


def test_agrees_with_point_sampling(tank, scene):
    """fcl capsules against an independent dense check on backbone points."""
    rng = np.random.default_rng(0)
    agree, both = 0, {True: 0, False: 0}
    for _ in range(300):
        n = int(rng.integers(1, 4))
        posture = Posture(
            rng.uniform(5, 40), rng.uniform(-1.5, 1.5, n), rng.uniform(-math.pi, math.pi, n)
        )
        clearance = point_clearance(tank, posture.points(50, 200)).min() - tank.arm.radius
        if abs(clearance) < 0.15:  # within the chord sagitta of the capsule chain: undecided
            continue
        fcl_says = scene.collides(posture)
        assert fcl_says == (clearance < 0), (posture, clearance)
        both[fcl_says] += 1
        agree += 1
    assert agree > 250 and both[True] > 30 and both[False] > 30


def test_clearance_matches_sampling_when_free(tank, scene):
    rng = np.random.default_rng(1)
    checked = 0
    while checked < 20:
        posture = Posture(rng.uniform(5, 30), rng.uniform(-1, 1, 2), rng.uniform(-3, 3, 2))
        sampled = point_clearance(tank, posture.points(50, 200)).min() - tank.arm.radius
        if sampled < 0.5:
            continue
        assert scene.clearance(posture) == pytest.approx(sampled, abs=0.15)
        checked += 1


def test_batch_and_vectorised_helpers(tank, scene):
    dis = np.array([-40.0, -2.0, -40.0])
    theta = np.array([[0.0, 0.0], [0.0, 0.0], [1.2, 0.0]])
    phi = np.zeros((3, 2))
    np.testing.assert_array_equal(scene.collides_batch(dis, theta, phi), [False, True, True])
    rng = np.random.default_rng(2)
    pts = rng.uniform([-70, -60, -20], [250, 160, 110], (500, 6, 3))
    for limit in (0.0, 2.5):
        np.testing.assert_array_equal(
            points_clear(tank, pts, limit), np.all(point_clearance(tank, pts) > limit, axis=1)
        )
    below = np.array([[[0, 0, -5.0], [5, 0, -1.0]], [[0, 0, -5.0], [13, 0, -1.0]]])
    np.testing.assert_array_equal(panel_violation(tank, below), [False, True])


def test_point_clearance_is_the_fcl_distance_to_the_scene(tank, scene):
    # Away from the floor's opening (round here, square in fcl), the signed distance to every
    # solid and wall is python-fcl's distance from a tiny ball to the scene.
    rng = np.random.default_rng(5)
    pts = rng.uniform(tank.box_min, tank.box_max, (300, 3))
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) > 40]
    d = point_clearance(tank, pts)
    eps, checked = 1e-3, 0
    for p, expected in zip(pts, d):
        if expected < 0.01:
            continue
        ball = fcl.CollisionObject(fcl.Sphere(eps), fcl.Transform(p))
        data = fcl.DistanceData()
        scene._scene.distance(ball, data, fcl.defaultDistanceCallback)
        assert data.result.min_distance + eps == pytest.approx(expected, abs=1e-4), p
        checked += 1
    assert checked > 150
    # with solids given, only those and the walls count
    pipe = [s for s in tank.solids if s.name == "fuel_pipe_bay1"]
    np.testing.assert_array_equal(
        point_clearance(tank, pts, pipe),
        np.minimum(pipe[0].signed_distance(pts), tank.enclosure.signed_distance_xyz(*pts.T)),
    )


@pytest.mark.parametrize("name", ["b737_center", "open_space_obstacles1"])
def test_far_from_everything_is_its_conservative_rule(name):
    """The compiled pre-check against its rule in numpy: solids' bounds grown, walls, floor."""
    from aftir_rl.core.tank import load_tank

    tank = load_tank(name)
    scene = CollisionScene(tank)
    rng = np.random.default_rng(4)
    lo, hi = np.array(tank.box_min, float), np.array(tank.box_max, float)
    seen = set()
    for _ in range(3000):
        centre = rng.uniform(lo - 20, hi + 20)
        pts = centre + rng.normal(0, rng.uniform(1, 40), (rng.integers(1, 40), 3))
        clear = float(rng.uniform(0, 8))
        near = (pts[:, None] > scene._solid_lo - clear) & (pts[:, None] < scene._solid_hi + clear)
        expected = not near.all(-1).any()
        if expected and scene.walls:
            expected = not (pts[:, :2] <= lo[:2] + clear).any() and not (pts >= hi - clear).any()
        if expected and scene.walls:
            floor = tank.enclosure.floor_distance_xyz(pts[:, 0], pts[:, 1], pts[:, 2])
            expected = bool(np.all(floor > clear))
        got = scene.far_from_everything(pts, clear)
        assert got == expected
        seen.add(got)
        # far means far: every point is farther than clear from every surface
        if got:
            assert (point_clearance(tank, pts) > clear - 1e-9).all()
    assert seen == {True, False}


def _contact_boundary(scene, rng, count):
    """Postures just either side of where python-fcl's verdict changes as the arm is pushed."""
    arm, out = scene.arm, []
    while len(out) < 6 * count:
        n = int(rng.integers(2, min(8, arm.max_sections) + 1))
        theta = rng.uniform(-1, 1, n) * arm.theta_max * rng.uniform(0.2, 1)
        phi = rng.uniform(-math.pi, math.pi, n)
        dis = np.arange(-n * arm.section_length, 0, 4.0)
        verdicts = [scene.collides(Posture(d, theta, phi)) for d in dis]
        change = [i for i in range(len(dis) - 1) if verdicts[i] != verdicts[i + 1]]
        if not change:
            continue
        i = change[0]
        a, b = dis[i], dis[i + 1]
        for _ in range(18):  # bisection to 4 cm / 2^18
            m = (a + b) / 2
            a, b = (m, b) if scene.collides(Posture(m, theta, phi)) == verdicts[i] else (a, m)
        out += [Posture((a + b) / 2 + e, theta, phi) for e in (-0.05, -1e-3, 0, 1e-3, 0.05, 1.0)]
    return out


@pytest.mark.parametrize(
    "name", ["b737_center", "wing:3:5", "single_cabin", "open_space_obstacles3"]
)
def test_compiled_pre_check_gives_python_fcls_verdict(name):
    """collides_fast decides by the exact signed distance where it can: never otherwise than fcl.

    At the contact boundary (bisected along the push, within 1e-4 cm) and on random postures;
    a generated wing has plates with round holes, which python-fcl holds as polygons.
    """
    from aftir_rl.core.tank import load_tank

    scene = CollisionScene(load_tank(name))
    rng = np.random.default_rng(17)
    near = _contact_boundary(scene, rng, 8)
    theta = rng.uniform(-1, 1, (300, 4)) * scene.arm.theta_max
    anywhere = [
        Posture(d, t, p)
        for d, t, p in zip(rng.uniform(-200, 0, 300), theta, rng.uniform(-4, 4, (300, 4)))
    ]
    verdicts = [(scene.collides_fast(p), scene.collides(p)) for p in near + anywhere]
    assert all(fast == full for fast, full in verdicts)
    assert 0 < sum(full for _, full in verdicts) < len(verdicts)


def test_pre_check_of_a_scene_without_walls_gives_its_verdict():
    """A scene built without the tank's walls is not pre-checked with the walls' distance."""
    from aftir_rl.core.tank import load_tank

    scene = CollisionScene(load_tank("b737_center"), walls=False)
    rng = np.random.default_rng(5)
    postures = [Posture(10.0, (0.0, 0.0), (0.0, 0.0))]  # pokes through the ceiling: no wall
    theta = rng.uniform(-1, 1, (200, 3)) * scene.arm.theta_max
    postures += [
        Posture(d, t, p)
        for d, t, p in zip(rng.uniform(-150, 0, 200), theta, rng.uniform(-4, 4, (200, 3)))
    ]
    assert all(scene.collides_fast(p) == scene.collides(p) for p in postures)
    assert not scene.collides_fast(postures[0])
