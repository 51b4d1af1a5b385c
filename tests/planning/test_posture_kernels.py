"""The posture search's compiled kernels equal their numpy definitions (random postures, seeds)."""

from __future__ import annotations

import numpy as np
import pytest

from aftir_rl.core.collision import panel_violation, points_clear
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.planar import planar_clear, planar_grid, planar_mds, planar_refine
from aftir_rl.core.robot import forward_kinematics
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.posture.clipping import gauss_newton
from aftir_rl.planning.posture.planar import distance_sum, planar_points, planar_tip, to_frame


@pytest.fixture(scope="module")
def tank():
    return load_tank("b737_center")


def test_planar_tips_equal_forward_kinematics():
    rng = np.random.default_rng(3)
    theta = rng.uniform(-1.5, 1.5, (500, 5))
    theta[:50] *= 1e-6  # the series near straight
    rho, z = planar_tip(theta, 50.0)
    tip = forward_kinematics(np.zeros(500), np.abs(theta), np.where(theta < 0, np.pi, 0.0), 50.0)
    np.testing.assert_allclose(rho, tip[:, -1, 0, 3], atol=1e-9)
    np.testing.assert_allclose(z, tip[:, -1, 2, 3], atol=1e-9)
    np.testing.assert_allclose(
        np.stack([rho, z]), np.stack(planar_points(theta, 50.0, 3))[:, :, -1]
    )


@pytest.mark.parametrize("end", [(60.0, 120.0), (0.0, 0.0), (-30.0, 10.0)])
def test_planar_mds_equals_the_distance_sum(end):
    rng = np.random.default_rng(4)
    theta = rng.uniform(-1.5, 1.5, (300, 4))
    dis = rng.uniform(-60.0, 0.0, 300)
    got = np.empty(300)
    planar_mds(theta, dis, 50.0, 8, end, got)
    rho, z = planar_points(theta, 50.0, 8)
    np.testing.assert_allclose(got, distance_sum((rho, z + dis[:, None]), end), rtol=1e-12)


@pytest.mark.parametrize("framed", [False, True])
def test_planar_clear_equals_the_panel_rule_and_points_clear(tank, framed):
    """In S (with the panel rule) and in a hatch frame: the same verdict on every posture."""
    rng = np.random.default_rng(5 + framed)
    # two sections; in S from up to 60 cm down the guide (a third break the panel rule), in the
    # hatch frame from up to 20 cm before the hatch
    theta = rng.uniform(-1.5, 1.5, (4000, 2))
    dis = rng.uniform(-20.0 if framed else -60.0, 0.0, 4000)
    if framed:  # the hatch frame of a target beyond the baffle (as TSM's P3)
        rotation = np.column_stack([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        origin, psi = np.array([100.0, 60.0, 50.0]), 0.7
        radius = -1.0
    else:
        rotation, origin, psi = np.eye(3), np.zeros(3), 0.9
        radius = float(tank.panel.radius)
    for points, limit in ((4, 2.5), (10, 3.5)):
        got = np.empty(4000, dtype=bool)
        centre = tank.panel.center
        panel = (float(centre[0]), float(centre[1]), float(centre[2]), radius)
        grid = kernel_grid(tank)
        planar_clear(theta, dis, (50.0, points), (psi, rotation, origin), panel, grid, limit, got)
        rho, z = planar_points(theta, 50.0, points)
        pts = to_frame(rho, z + dis[:, None], psi, rotation, origin)
        want = points_clear(tank, pts, limit)
        if not framed:
            want &= ~panel_violation(tank, pts)
        assert 40 < want.sum() < len(want) - 40  # both verdicts are tried
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("heading", [None, 0.8])
def test_planar_refine_takes_the_numpy_gauss_newton_steps(heading):
    """The same refined angles as the numpy Gauss–Newton on the planar tip, or the same refusal."""
    rng = np.random.default_rng(6)
    tmax, l, agree = 1.2, 50.0, 0
    for _ in range(200):
        m = int(rng.integers(1, 5))
        x0 = rng.uniform(-tmax, tmax, m)
        goal_rho = float(rng.uniform(-40.0, 120.0))

        def rho(probe, m=m):
            full = probe if heading is None else np.column_stack([probe, heading - probe.sum(1)])
            return planar_tip(full, l)[0][:, None]

        limits = (np.full(m, -tmax), np.full(m, tmax))
        want = gauss_newton(rho, (goal_rho,), x0.copy(), limits, 1e-9, 60)
        got = x0.copy()
        ok = planar_refine(got, (goal_rho, np.nan if heading is None else heading), l, tmax,
                           1e-9, 60, 1e-7)  # fmt: skip
        assert ok == (want is not None)
        if ok:
            np.testing.assert_allclose(got, want, atol=1e-9)
            agree += abs(rho(got[None])[0, 0] - goal_rho) < 1e-9
    assert agree > 50  # many of the draws converge


@pytest.mark.parametrize("heading", [None, 0.6])
def test_planar_grid_keeps_the_grid_postures_numpy_keeps(heading):
    """Each grid combination's tip, ``dis`` and last angle as numpy computes them, in order."""
    rng = np.random.default_rng(7)
    for m in (1, 2, 3, 4):
        values = [np.sort(rng.uniform(-1.2, 1.2, 7)) for _ in range(m)]
        free = np.stack(np.meshgrid(*values, indexing="ij"), axis=-1).reshape(-1, m)
        full = free if heading is None else np.column_stack([free, heading - free.sum(axis=1)])
        rho, z = planar_tip(full, 50.0)
        n = full.shape[1]
        target, radius, dis_range = (20.0 * n, 40.0 * n), 10.0 * n, (-20.0, 10.0)
        dis = target[1] - z
        keep = (np.abs(rho - target[0]) <= radius) & (dis >= dis_range[0]) & (dis <= dis_range[1])
        if heading is not None:
            keep &= np.abs(full[:, -1]) <= 1.2 + 1e-12
        goal = (*target, np.nan if heading is None else heading, 1.2)
        theta, got_dis, gap = planar_grid(np.array(values), goal, 50.0, dis_range, radius)
        assert 0 < keep.sum() < len(keep)
        np.testing.assert_allclose(theta, full[keep], atol=1e-12)
        np.testing.assert_allclose(got_dis, dis[keep], atol=1e-9)
        np.testing.assert_allclose(gap, np.abs(rho - target[0])[keep], atol=1e-9)
