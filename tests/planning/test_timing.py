"""Time parametrisation: limits kept, geometry unchanged, and near the time-optimal schedule.

The reference optimum is computed here by the classic numerical integration (the maximum
velocity curve, a backward pass at the largest deceleration and a forward pass at the largest
acceleration; Bobrow, Dubowsky & Gibson 1985) on a grid four times finer than the motion's
entries, over the same path: a method independent of TOPP-RA's reachability sets.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.cables import cable_lengths
from aftir_rl.core.errors import PlanningError
from aftir_rl.planning.ftl.plan import plan_motion
from aftir_rl.planning.timing import joint_positions, time_motion

pytest.importorskip("toppra")


@pytest.fixture(scope="module")
def corner_plan(tank):
    """The follow-the-leader motion to a bay-2 reference corner, timed with the default limits."""
    plan = plan_motion(tank, tank.targets[0])
    assert plan.complete and plan.timing is not None, plan.timing_note
    return plan


def _bounds(limits: ActuatorLimits, n: int, speed: bool) -> np.ndarray:
    if speed:
        values = (limits.module_speed, limits.bend_rate, limits.cable_speed)
    else:
        values = (limits.module_accel, limits.bend_accel, limits.cable_accel)
    return np.concatenate([[values[0]], np.full(2 * n, values[1]), np.full(3 * n, values[2])])


def optimal_duration(dis, theta, phi, limits: ActuatorLimits, section_length=50.0, refine=4):
    """Duration of the time-optimal schedule by numerical integration (module docstring)."""
    n = theta.shape[1]
    cables = cable_lengths(theta, phi, limits).reshape(len(dis), -1)
    y = np.concatenate([joint_positions(dis, theta, phi), cables], axis=1)
    scale = np.concatenate([[1 / section_length], np.ones(2 * n)])
    step = np.linalg.norm(np.diff(y[:, : 1 + 2 * n], axis=0) * scale, axis=1)
    keep = np.concatenate([[True], step > 1e-9])
    s = np.concatenate([[0.0], np.cumsum(step)])[keep]
    spline = CubicSpline(s, y[keep])
    grid = np.interp(np.arange((len(s) - 1) * refine + 1) / refine, np.arange(len(s)), s)
    d1, d2 = spline(grid, 1), spline(grid, 2)
    vmax, amax = _bounds(limits, n, True), _bounds(limits, n, False)
    with np.errstate(divide="ignore", over="ignore"):
        mvc = np.minimum(np.min((vmax / np.abs(d1)) ** 2, axis=1), 1e12)

    def u_range(i, x):
        """The feasible ``s̈`` at gridpoint ``i`` and ``ṡ² = x``."""
        lo, hi = -np.inf, np.inf
        for j in range(d1.shape[1]):
            a, b = d1[i, j], d2[i, j] * x
            if abs(a) < 1e-12:
                continue
            ends = sorted(((-amax[j] - b) / a, (amax[j] - b) / a))
            lo, hi = max(lo, ends[0]), min(hi, ends[1])
        return lo, hi

    for i in range(len(grid)):  # the acceleration's own velocity limit, by bisection
        lo, hi = 0.0, mvc[i]
        if u_range(i, hi)[0] > u_range(i, hi)[1]:
            for _ in range(50):
                mid = (lo + hi) / 2
                lo, hi = (mid, hi) if u_range(i, mid)[0] <= u_range(i, mid)[1] else (lo, mid)
            mvc[i] = lo
    ds = np.diff(grid)
    back = mvc.copy()
    back[-1] = 0.0
    for i in range(len(grid) - 2, -1, -1):
        back[i] = min(back[i], back[i + 1] - 2 * ds[i] * min(u_range(i + 1, back[i + 1])[0], 0.0))
    x = np.zeros(len(grid))
    for i in range(len(grid) - 1):
        x[i + 1] = min(back[i + 1], x[i] + 2 * ds[i] * max(u_range(i, x[i])[1], 0.0))
    root = np.sqrt(np.maximum(x, 0.0))
    return float(np.sum(2 * ds / np.maximum(root[:-1] + root[1:], 1e-12)))


def test_a_straight_push_is_the_trapezoid():
    limits = ActuatorLimits(module_speed=5.0, module_accel=10.0)
    dis = np.linspace(-600.0, -500.0, 201)
    zeros = np.zeros((201, 12))
    timed = time_motion(dis, zeros, zeros, 50.0, limits)
    assert timed.duration == pytest.approx(100 / 5 + 5 / 10, rel=0.01)  # cruise + ramps
    assert np.abs(timed.velocities[:, 0]).max() == pytest.approx(5.0, rel=1e-6)
    assert timed.velocities[0, 0] == 0.0 and abs(timed.velocities[-1, 0]) < 1e-6


@pytest.mark.parametrize("d", [0.238, 3.0, 40.0])
def test_two_postures_at_rest_are_the_time_optimal_move(d):
    """No posture between (a tour's joining move): full acceleration, then full braking."""
    limits = ActuatorLimits()
    dis, zeros = np.array([-620.0, -620.0 - d]), np.zeros((2, 12))
    timed = time_motion(dis, zeros, zeros, 50.0, limits)
    v, a = limits.module_speed, limits.module_accel
    optimum = d / v + v / a if d >= v * v / a else 2 * np.sqrt(d / a)  # trapezoid or triangle
    assert timed.duration == pytest.approx(optimum, rel=1e-3)
    assert np.allclose(timed.velocities, 0.0)


def test_limits_hold_and_the_postures_stay(corner_plan):
    timing, motion = corner_plan.timing, corner_plan.motion
    limits, n = timing.limits, motion.n_sections
    np.testing.assert_array_equal(
        timing.positions, joint_positions(motion.dis, motion.theta, motion.phi)
    )
    assert timing.t[0] == 0.0 and np.all(np.diff(timing.t) >= 0)
    joint_speed = _bounds(limits, n, True)[: 1 + 2 * n]
    joint_accel = _bounds(limits, n, False)[: 1 + 2 * n]
    assert np.all(np.abs(timing.velocities) <= joint_speed * (1 + 1e-6))
    assert np.all(np.abs(timing.accelerations) <= joint_accel * (1 + 1e-6))
    assert np.abs(timing.cable_velocities).max() <= limits.cable_speed * (1 + 1e-6)
    assert np.abs(timing.cable_accelerations).max() <= limits.cable_accel * (1 + 1e-6)
    # the stored rates integrate (trapezoid rule) to the positions' change, joint by joint
    dt = np.diff(timing.t)[:, None]
    travelled = ((timing.velocities[1:] + timing.velocities[:-1]) / 2 * dt).sum(axis=0)
    change = timing.positions[-1] - timing.positions[0]
    path = np.abs(np.diff(timing.positions, axis=0)).sum(axis=0)
    assert np.all(np.abs(travelled - change) <= 0.01 * path + 1e-9)
    json = corner_plan.to_json()
    assert json["duration_s"] == timing.duration
    assert [e["t"] for e in json["motion"]] == timing.t.tolist()


@pytest.mark.parametrize(
    "limits",
    [ActuatorLimits(), ActuatorLimits(module_speed=20, bend_rate=0.05, cable_speed=0.3)],
    ids=["default", "slow-bending"],
)
def test_duration_is_within_10_percent_of_the_optimum(corner_plan, limits):
    m = corner_plan.motion
    timed = time_motion(m.dis, m.theta, m.phi, 50.0, limits)
    optimum = optimal_duration(m.dis, m.theta, m.phi, limits)
    assert 0.97 * optimum <= timed.duration <= 1.10 * optimum, (timed.duration, optimum)


def test_a_cable_past_its_travel_is_refused(corner_plan):
    m = corner_plan.motion
    with pytest.raises(PlanningError, match="more than its travel of 1 cm"):
        time_motion(m.dis, m.theta, m.phi, 50.0, ActuatorLimits(cable_travel=1.0))
