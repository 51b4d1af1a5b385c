from __future__ import annotations

import math

import numpy as np
import pytest

from aftir_rl.core.papers import ICRA2014_TABLE2, JACE_TABLE2
from aftir_rl.core.robot import (
    ArmSpec,
    Posture,
    body_points,
    forward_kinematics,
    tip_jacobian,
    tip_position,
)

# icra2014 Table II: theta, phi, dis, printed tip (l = 25 cm).
ICRA2014 = [(r.theta, r.phi, r.dis, r.tip) for r in ICRA2014_TABLE2]
# jace Table II, both searches: target, theta, d (planar arm in the target's plane, l = 25 cm).
JACE = [(r.target, s.theta, s.dis) for r in JACE_TABLE2 for s in (r.blind, r.clipping)]


def test_straight_arm_points_up():
    pts = body_points(7.0, [0.0, 0.0, 0.0], [0.3, -1.0, 2.0], 50.0, points_per_section=5)
    expected = np.stack([np.zeros(16), np.zeros(16), 7.0 + np.linspace(0, 150, 16)], axis=1)
    np.testing.assert_allclose(pts, expected, atol=1e-12)


def test_single_section_closed_form():
    # A quarter circle of length l bends to (l/θ)(1 − cos θ) sideways and (l/θ) sin θ up.
    length, th, ph = 50.0, math.pi / 2, 0.7
    r = length / th
    tip = tip_position(0.0, [th], [ph], length)
    np.testing.assert_allclose(tip, [r * math.cos(ph), r * math.sin(ph), r], atol=1e-12)


@pytest.mark.parametrize("theta, phi, dis, printed", ICRA2014)
def test_icra2014_table2_tips(theta, phi, dis, printed):
    tip = tip_position(dis, theta, phi, 25.0)
    assert np.linalg.norm(tip - printed) < 0.5


@pytest.mark.parametrize("target, theta, dis", JACE)
def test_jace_table2_tips(target, theta, dis):
    phi = [math.atan2(target[1], target[0])] * len(theta)
    tip = tip_position(dis, theta, phi, 25.0)
    assert np.linalg.norm(tip - target) < 0.7


def test_theta_to_zero_is_smooth_and_finite():
    thetas = np.array([-1e-3, -1e-4, -9.999e-5, -1e-8, 0.0, 1e-8, 9.999e-5, 1e-4, 1e-3])
    tips = tip_position(0.0, thetas[:, None], np.full((len(thetas), 1), 0.4), 50.0)
    assert np.all(np.isfinite(tips))
    # Lateral offset is l·θ/2 to first order, through the series/closed-form switch at 1e-4.
    lateral = np.hypot(tips[:, 0], tips[:, 1]) * np.sign(thetas)
    np.testing.assert_allclose(lateral, 50.0 * thetas / 2, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(tips[:, 2], 50.0 * np.sinc(thetas / np.pi), rtol=1e-14)
    # Both sides of the switch agree to float precision.
    a = tip_position(0.0, [1e-4 * (1 - 1e-12)], [0.4], 50.0)
    b = tip_position(0.0, [1e-4 * (1 + 1e-12)], [0.4], 50.0)
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-15)


def test_derivative_through_zero_matches_finite_difference():
    # d tip / d θ at θ = 0 for a single section: (l/2)·(cos φ, sin φ, 0).
    h = 1e-6
    plus = tip_position(0.0, [h], [0.9], 50.0)
    minus = tip_position(0.0, [-h], [0.9], 50.0)
    np.testing.assert_allclose(
        (plus - minus) / (2 * h), [25 * math.cos(0.9), 25 * math.sin(0.9), 0], atol=1e-6
    )


def test_arc_length_is_preserved():
    rng = np.random.default_rng(0)
    theta = rng.uniform(-1.5, 1.5, size=(5, 4))
    phi = rng.uniform(-np.pi, np.pi, size=(5, 4))
    pts = body_points(rng.uniform(-20, 20, 5), theta, phi, 30.0, points_per_section=400)
    length = np.linalg.norm(np.diff(pts, axis=1), axis=-1).sum(axis=1)
    np.testing.assert_allclose(length, 4 * 30.0, rtol=1e-4)


def test_batched_equals_one_by_one():
    rng = np.random.default_rng(1)
    theta = rng.uniform(-1.5, 1.5, size=(2, 3, 5))
    phi = rng.uniform(-np.pi, np.pi, size=(2, 3, 5))
    dis = rng.uniform(-10, 10, size=(2, 3))
    batch = body_points(dis, theta, phi, 25.0, points_per_section=4)
    frames = forward_kinematics(dis, theta, phi, 25.0)
    assert batch.shape == (2, 3, 21, 3) and frames.shape == (2, 3, 6, 4, 4)
    for i in range(2):
        for j in range(3):
            one = Posture(dis[i, j], theta[i, j], phi[i, j]).points(25.0, points_per_section=4)
            np.testing.assert_allclose(batch[i, j], one, atol=1e-12)
            np.testing.assert_allclose(frames[i, j, -1, :3, 3], one[-1], atol=1e-12)


def test_rotation_part_stays_orthonormal():
    rng = np.random.default_rng(2)
    frames = forward_kinematics(
        0.0, rng.uniform(-1.5, 1.5, (50, 6)), rng.uniform(-3, 3, (50, 6)), 50
    )
    rot = frames[..., :3, :3]
    np.testing.assert_allclose(
        rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="same shape"):
        tip_position(0.0, [0.1, 0.2], [0.1], 50.0)
    with pytest.raises(ValueError, match="section_length"):
        ArmSpec(section_length=-1)
    with pytest.raises(ValueError, match="one value per section"):
        Posture(0.0, (0.1, 0.2), (0.0,))


def test_posture_vector_and_dict_round_trip():
    p = Posture(-12.5, (0.1, -0.2, 0.3), (1.0, 2.0, -3.0))
    x = p.to_vector()
    np.testing.assert_array_equal(x, [-12.5, 0.1, -0.2, 0.3, 1.0, 2.0, -3.0])
    assert Posture.from_vector(x) == p
    assert Posture(**p.to_dict()) == p
    with pytest.raises(ValueError, match="1 \\+ 2N values"):
        Posture.from_vector([0.0, 1.0])


def test_tip_jacobian_matches_forward_kinematics():
    rng = np.random.default_rng(3)
    x = np.concatenate([[-20.0], rng.uniform(-1.2, 1.2, 4), rng.uniform(-3, 3, 4)])
    tip, jac = tip_jacobian(x, 25.0)
    assert jac.shape == (3, 9)
    np.testing.assert_array_equal(tip, tip_position(x[0], x[1:5], x[5:], 25.0))
    np.testing.assert_allclose(jac[:, 0], [0.0, 0.0, 1.0], atol=1e-8)  # dis moves the tip up
    for i in range(1, 9):
        step = np.zeros(9)
        step[i] = 1e-4
        plus, minus = x + step, x - step
        slope = tip_position(plus[0], plus[1:5], plus[5:], 25.0)
        slope = (slope - tip_position(minus[0], minus[1:5], minus[5:], 25.0)) / 2e-4
        np.testing.assert_allclose(jac[:, i], slope, atol=1e-5)
    # Batched, forward differences, other parameters: the same columns.
    batch, fwd = tip_jacobian(np.stack([x, x]), 25.0, central=False)
    assert fwd.shape == (2, 3, 9) and np.array_equal(batch[1], tip)
    np.testing.assert_allclose(fwd[0], jac, atol=1e-4)
    _, theta_only = tip_jacobian(
        x[1:5], 25.0, joints=lambda p: (x[0], p, np.broadcast_to(x[5:], p.shape))
    )
    np.testing.assert_array_equal(theta_only, jac[:, 1:5])
