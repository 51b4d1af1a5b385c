"""Time along a motion: the fastest schedule of its postures that keeps every actuator limit.

:func:`time_motion` parametrises the dense postures of a motion by time with TOPP-RA (the
``toppra`` library, the ``robot`` extra): the path is a cubic spline through the entries in the
joints ``(dis, κ_1, …, κ_N)`` and the cable changes (:mod:`aftir_rl.core.cables`), and the
module's, the bending vectors' and the cables' speed and acceleration limits
(:class:`~aftir_rl.core.actuation.ActuatorLimits`) bound it. The entries are TOPP-RA's
gridpoints, so the postures stay exactly those of the motion (and its collision check and
follow-the-leader deviation with them); each gains a time and velocities. docs/robot.md has the
details and the measurements.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.cables import cable_lengths, cable_matrix, cable_names
from aftir_rl.core.errors import PlanningError
from aftir_rl.core.extras import require
from aftir_rl.core.robot import angles_to_kappa

__all__ = ["TimedMotion", "joint_names", "joint_positions", "time_motion"]

#: Gridpoints toppra gets for a move between two postures alone (a straight line in joint space).
STRAIGHT_GRID = 33


def joint_names(n_sections: int) -> list[str]:
    """``dis`` then ``section_<i>_kx``, ``section_<i>_ky``: the joints a timed motion reports."""
    return ["dis"] + [f"section_{i + 1}_k{axis}" for i in range(n_sections) for axis in "xy"]


def joint_positions(dis: ArrayLike, theta: ArrayLike, phi: ArrayLike) -> NDArray[np.float64]:
    """Joint vectors ``(T, 1 + 2N)``: ``dis`` [cm] and the bending vectors ``κ`` [rad]."""
    kappa = angles_to_kappa(theta, phi)
    return np.concatenate(
        [np.asarray(dis, dtype=np.float64)[:, None], kappa.reshape(len(kappa), -1)], 1
    )


@dataclass
class TimedMotion:
    """Times, velocities and accelerations of a motion's entries (``T`` entries, ``N`` sections).

    Attributes:
        t: time of each entry from the start [s], non-decreasing (equal only for equal postures).
        positions, velocities, accelerations: ``(T, 1 + 2N)`` in :func:`joint_names` order
            [cm, rad; per s, per s²].
        cables, cable_velocities, cable_accelerations: ``(T, 3N)`` cable length changes
            [cm; per s, per s²] in :func:`~aftir_rl.core.cables.cable_names` order.
        limits: the limits the schedule keeps.
        seconds: the time the parametrisation took [s].

    """

    t: NDArray[np.float64]
    positions: NDArray[np.float64]
    velocities: NDArray[np.float64]
    accelerations: NDArray[np.float64]
    cables: NDArray[np.float64]
    cable_velocities: NDArray[np.float64]
    cable_accelerations: NDArray[np.float64]
    limits: ActuatorLimits
    seconds: float = 0.0

    @classmethod
    def from_rates(
        cls,
        postures: tuple[ArrayLike, ArrayLike, ArrayLike],
        t: ArrayLike,
        rates: tuple[NDArray[np.float64], NDArray[np.float64]],
        limits: ActuatorLimits,
        seconds: float = 0.0,
    ) -> TimedMotion:
        """A schedule from postures ``(dis, theta, phi)``, times and joint rates.

        ``rates``: the joints' ``(velocities, accelerations)``; the cables' follow from them (a
        linear map).
        """
        dis, theta, phi = postures
        velocities, accelerations = rates
        theta = np.asarray(theta, dtype=np.float64)
        to_cables = cable_matrix(theta.shape[1], limits).T
        return cls(
            t=np.asarray(t, dtype=np.float64),
            positions=joint_positions(dis, theta, phi),
            velocities=velocities,
            accelerations=accelerations,
            cables=cable_lengths(theta, phi, limits).reshape(len(theta), -1),
            cable_velocities=velocities[:, 1:] @ to_cables,
            cable_accelerations=accelerations[:, 1:] @ to_cables,
            limits=limits,
            seconds=seconds,
        )

    @property
    def duration(self) -> float:
        """The motion's duration [s]."""
        return float(self.t[-1])

    @property
    def n_sections(self) -> int:
        """The arm's sections ``N``."""
        return (self.positions.shape[1] - 1) // 2

    def to_json(self) -> dict[str, Any]:
        """The ``timing`` object of ``trajectory.json`` (one row per motion entry).

        The cables' rates are not stored: they are :func:`~aftir_rl.core.cables.cable_matrix`
        times the joints' (a linear map).
        """
        n = self.n_sections
        return {
            "method": "toppra",
            "duration_s": self.duration,
            "limits": self.limits.to_json(),
            "joint_names": joint_names(n),
            "t": self.t.tolist(),
            "velocities": _rounded(self.velocities),
            "accelerations": _rounded(self.accelerations),
            "seconds": self.seconds,
        }


def _rounded(rates: NDArray[np.float64]) -> list[list[float]]:
    """Rates to 9 significant digits: a smaller file, off by 5e-10 of a limit at most."""
    return [[float(f"{v:.9g}") for v in row] for row in rates.tolist()]


def _path_parameter(stacked: NDArray[np.float64], section_length: float) -> NDArray[np.float64]:
    """Cumulative joint-space distance ``s`` of the entries (``dis`` in section lengths)."""
    n = (stacked.shape[1] - 1) // 5
    scale = np.concatenate([[1.0 / section_length], np.ones(2 * n)])
    step = np.linalg.norm(np.diff(stacked[:, : 1 + 2 * n], axis=0) * scale, axis=1)
    return np.concatenate([[0.0], np.cumsum(step)])


def time_motion(
    dis: ArrayLike,
    theta: ArrayLike,
    phi: ArrayLike,
    section_length: float,
    limits: ActuatorLimits | None = None,
) -> TimedMotion:
    """The time-optimal schedule of a motion's postures under ``limits`` (TOPP-RA).

    ``dis (T,)``, ``theta``, ``phi (T, N)``: the entries in order, at rest at the first and the
    last. Raises :class:`PlanningError` when a cable leaves its travel or the solver fails, and
    :class:`~aftir_rl.core.errors.MissingExtraError` without the ``robot`` extra.
    """
    start = time.perf_counter()
    ta = require("toppra", "robot")
    limits = limits or ActuatorLimits()
    theta = np.asarray(theta, dtype=np.float64)
    joints = joint_positions(dis, theta, phi)
    cables = cable_lengths(theta, phi, limits).reshape(len(joints), -1)
    worst = int(np.abs(cables).max(axis=0).argmax()) if cables.size else 0
    if cables.size and np.abs(cables[:, worst]).max() > limits.cable_travel:
        name = cable_names(theta.shape[1])[worst]
        raise PlanningError(
            f"{name} changes by {np.abs(cables[:, worst]).max():.1f} cm, more than its travel "
            f"of {limits.cable_travel:g} cm"
        )
    stacked = np.concatenate([joints, cables], axis=1)
    ss = _path_parameter(stacked, section_length)
    keep = np.concatenate([[True], np.diff(ss) > 1e-9])  # entries that move
    velocity, acceleration = np.zeros_like(joints), np.zeros_like(joints)
    t = np.zeros(len(joints))
    if keep.sum() >= 2:
        grid, points = ss[keep], stacked[keep]
        if len(grid) == 2:  # at rest at both ends: toppra needs gridpoints between to move
            u = np.linspace(0.0, 1.0, STRAIGHT_GRID)[:, None]
            grid, points = (
                grid[0] + u[:, 0] * (grid[1] - grid[0]),
                (1 - u) * points[0] + u * points[1],
            )
        sd, sdd, path = _toppra(ta, grid, points, limits)
        index = np.searchsorted(np.flatnonzero(keep), np.arange(len(joints)), side="right") - 1
        t = np.concatenate(
            [[0.0], np.cumsum(2 * np.diff(grid) / np.maximum(sd[:-1] + sd[1:], 1e-300))]
        )
        accel_grid = np.concatenate([sdd, sdd[-1:]])  # a gridpoint's interval (the last: its own)
        if len(grid) > keep.sum():  # without the gridpoint put between
            t, sd, accel_grid = t[[0, -1]], sd[[0, -1]], accel_grid[[0, -1]]
        m = joints.shape[1]
        first, second = path(ss[keep], 1)[:, :m], path(ss[keep], 2)[:, :m]
        velocity = (first * sd[:, None])[index]
        acceleration = (second * sd[:, None] ** 2 + first * accel_grid[:, None])[index]
        # entries that do not move share their gridpoint's time; only the last moves on
        same = np.concatenate([index[1:] == index[:-1], [False]])
        velocity[same], acceleration[same], t = 0.0, 0.0, t[index]
    return TimedMotion.from_rates(
        (dis, theta, phi), t, (velocity, acceleration), limits, time.perf_counter() - start
    )


def _toppra(
    ta: Any, ss: NDArray[np.float64], stacked: NDArray[np.float64], limits: ActuatorLimits
) -> tuple[NDArray[np.float64], NDArray[np.float64], Any]:
    """TOPP-RA's ``ṡ`` at the gridpoints ``ss``, ``s̈`` per interval, and the spline path."""
    n = (stacked.shape[1] - 1) // 5
    speed_bound, accel_bound = limits.rate_bounds(n, "speed"), limits.rate_bounds(n, "accel")
    path = ta.SplineInterpolator(ss, stacked)
    speed = ta.constraint.JointVelocityConstraint(np.stack([-speed_bound, speed_bound], 1))
    accel = ta.constraint.JointAccelerationConstraint(
        np.stack([-accel_bound, accel_bound], 1),
        discretization_scheme=ta.constraint.DiscretizationType.Interpolation,
    )
    solver = ta.algorithm.TOPPRA(
        [speed, accel], path, gridpoints=ss, parametrizer="ParametrizeConstAccel"
    )
    result = solver.compute_parameterization(0, 0)
    sdd, sd = result[0], result[1]
    if sd is None or sdd is None or not np.all(np.isfinite(sd)):
        raise PlanningError("TOPP-RA found no schedule for this motion within the limits")
    return np.maximum(sd, 0.0), sdd, path
