"""Cable space and actuator limits: checked against the cables' geometry, measured numerically."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.cables import cable_angles, cable_lengths, cable_matrix, cables_to_angles
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.robot import angles_to_kappa
from aftir_rl.core.tank import load_tank


def _section(theta: float, phi: float, s: float) -> np.ndarray:
    """The transform of arc ``s`` of a section bent ``theta`` in plane ``phi`` (written here)."""
    cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    if abs(theta) < 1e-12:
        radial, axial = 0.0, s
    else:
        radial, axial = s / theta * (1 - ct), s / theta * st
    return np.array(
        [
            [cp * cp * ct + sp * sp, cp * sp * (ct - 1), cp * st, radial * cp],
            [cp * sp * (ct - 1), sp * sp * ct + cp * cp, sp * st, radial * sp],
            [-cp * st, -sp * st, ct, axial],
            [0, 0, 0, 1.0],
        ]
    )


def _measured_cable(theta, phi, length, radius, beta, upto, steps=2000):
    """The length of a cable at ``radius`` and angle ``beta`` through sections ``0..upto``,
    measured as a polyline of points offset from the backbone in the sections' frames."""
    frame, points = np.eye(4), []
    offset = np.array([radius * math.cos(beta), radius * math.sin(beta), 0.0, 1.0])
    for i in range(upto + 1):
        for k in range(steps + 1):
            s = length * k / steps
            points.append((frame @ _section(theta[i] * s / length, phi[i], s) @ offset)[:3])
        frame = frame @ _section(theta[i], phi[i], length)
    points = np.array(points)
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) - (upto + 1) * length


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cable_changes_are_the_cables_measured_length(seed):
    rng = np.random.default_rng(seed)
    limits = ActuatorLimits(cable_offset=1.7, cable_stagger_deg=13.0)
    n = 4
    theta, phi = rng.uniform(0, math.pi / 2, n), rng.uniform(-math.pi, math.pi, n)
    model = cable_lengths(theta, phi, limits)
    beta = cable_angles(n, limits)
    for i in range(n):
        for j in range(3):
            measured = _measured_cable(theta, phi, 50.0, 1.7, beta[i, j], i)
            assert model[i, j] == pytest.approx(measured, abs=2e-3), (i, j)


@pytest.mark.parametrize("seed", [3, 4])
def test_cables_round_trip_within_1e_9(seed):
    rng = np.random.default_rng(seed)
    limits = ActuatorLimits(cable_offset=rng.uniform(0.5, 3), cable_stagger_deg=rng.uniform(0, 30))
    theta = rng.uniform(0, math.pi / 2, (500, 12))
    theta[rng.random((500, 12)) < 0.2] = 0.0  # straight sections too
    phi = np.where(theta > 0, rng.uniform(-math.pi, math.pi, (500, 12)), 0.0)
    changes = cable_lengths(theta, phi, limits)
    back_theta, back_phi = cables_to_angles(changes, limits)
    np.testing.assert_allclose(cable_lengths(back_theta, back_phi, limits), changes, atol=1e-9)
    np.testing.assert_allclose(back_theta, theta, atol=1e-9)
    bent = theta > 1e-6
    wrapped = np.angle(np.exp(1j * (back_phi - phi)))
    assert np.abs(wrapped[bent]).max() < 1e-9
    # three cables 120° apart: their changes sum to zero in each section
    assert np.abs(changes.sum(axis=-1)).max() < 1e-9


def test_cable_matrix_is_the_map_of_cable_lengths():
    rng = np.random.default_rng(5)
    limits = ActuatorLimits()
    theta, phi = rng.uniform(0, 1.5, (20, 7)), rng.uniform(-3, 3, (20, 7))
    flat = angles_to_kappa(theta, phi).reshape(20, -1)
    np.testing.assert_allclose(
        flat @ cable_matrix(7, limits).T, cable_lengths(theta, phi, limits).reshape(20, -1)
    )


@pytest.mark.parametrize(
    "limits, message",
    [
        ({"module_speed": -1}, "module_speed must be positive"),
        ({"bend_rate": "fast"}, "bend_rate: expected a number"),
        ({"cable_travel": 1e9}, "out of range"),
        ({"warp": 1}, "unknown key 'warp'"),
        ({"cable_stagger_deg": 400}, "within ±360"),
        ([1, 2], "expected a mapping of limits"),
    ],
)
def test_bad_limits_are_one_line(limits, message):
    with pytest.raises(ConfigError, match=message) as info:
        ActuatorLimits.from_mapping(limits, "arm.limits")
    assert "\n" not in str(info.value)


def test_a_tank_yaml_sets_the_limits(tmp_path):
    source = tmp_path / "tank.yaml"
    source.write_text(
        "box: {min: [-150, -150, 0], max: [150, 150, 150]}\n"
        "panel: {center: [0, 0, 0], radius: 12}\n"
        "start_point: [0, 0, 10]\n"
        "walls: false\n"
        "arm: {section_length: 25, limits: {module_speed: 2.5, cable_offset: 1.0}}\n"
    )
    tank = load_tank(source)
    assert tank.arm.limits.module_speed == 2.5
    assert tank.arm.limits.cable_offset == 1.0
    assert tank.arm.limits.bend_rate == ActuatorLimits().bend_rate
    source.write_text(source.read_text().replace("2.5,", "-2.5,"))
    with pytest.raises(ConfigError, match=r"arm.limits.*module_speed must be positive"):
        load_tank(source)
