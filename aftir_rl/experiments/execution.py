"""Motions a robot runs: a timed ``trajectory.json`` read, re-checked and exported.

:func:`read_timed` reads a run's ``trajectory.json`` with its ``timing``
(:mod:`aftir_rl.planning.timing`); :func:`check_motion` re-checks it independently of the planner
(time, the actuators' limits, forward kinematics, python-fcl clearance and the panel rule); and
:func:`export_motion` writes it as ROS ``trajectory_msgs/JointTrajectory`` JSON (the message's
field names, no ROS needed) or CSV, in joints or in cables. docs/robot.md describes the files.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.cables import cable_lengths, cable_matrix, cable_names
from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.files import read_json, run_file
from aftir_rl.core.robot import Posture, body_points
from aftir_rl.core.tank import Tank, load_tank, resolve_run_tank
from aftir_rl.planning.timing import joint_names, joint_positions
from aftir_rl.viz.runs import read_run

__all__ = [
    "FORMATS",
    "SPACES",
    "TimedRun",
    "check_motion",
    "export_motion",
    "read_timed",
    "timed_run_tank",
]

#: Export formats and joint spaces.
FORMATS = ("jointtrajectory-json", "csv")
SPACES = ("joints", "cables")
#: Slack of the limits between entries: the rates there are averages over an interval, which a
#: smooth schedule through entries about 1 cm apart exceeds by a few per cent at a joint's kink.
BETWEEN_ENTRIES = 0.05
#: Largest movement of a backbone point between two entries [cm] (the motion contract, with
#: 0.1 cm for rounding).
MAX_MOVE_CM = 1.1


@dataclass
class TimedRun:
    """A timed motion read from a run: postures, times, joint rates, limits and context."""

    dis: NDArray[np.float64]
    theta: NDArray[np.float64]
    phi: NDArray[np.float64]
    t: NDArray[np.float64]
    velocities: NDArray[np.float64]
    accelerations: NDArray[np.float64]
    limits: ActuatorLimits
    section_length: float
    margin_cm: float
    tank: str | None


def _array(value: Any, shape: tuple[int, int], where: str, path: Path) -> NDArray[np.float64]:
    """A finite float array of ``shape`` from JSON, or a one-line :class:`CheckpointError`."""
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        out = np.empty(0)
    if out.shape != shape or not np.all(np.isfinite(out)):
        raise CheckpointError(
            f"{path}: timing.{where}: expected {shape[0]} rows of {shape[1]} numbers"
        )
    return out


def read_timed(run: str | Path) -> TimedRun:
    """The timed motion of a run directory (or of its ``trajectory.json``).

    Raises:
        CheckpointError: no motion, no timing, or a file of the wrong shape (one line).

    """
    folder = Path(run).parent if Path(run).name == "trajectory.json" else Path(run)
    data_run = read_run(folder)
    if data_run.dis is None or data_run.theta is None or data_run.phi is None:
        raise CheckpointError(f"{folder}: no motion in trajectory.json")
    path = run_file(folder, "trajectory.json")
    data = read_json(path, "trajectory.json")
    timing = data.get("timing") if isinstance(data, dict) else None
    if not isinstance(timing, dict):
        note = data.get("timing_note") if isinstance(data, dict) else None
        raise CheckpointError(
            f"{path}: the motion has no timing" + (f" ({note})"[:200] if note else "")
        )
    m, n = data_run.theta.shape
    t = _array([timing.get("t")], (1, m), "t", path)[0]
    try:
        limits = ActuatorLimits.from_mapping(timing.get("limits"), f"{path}: timing.limits")
        margin = float(data.get("margin_cm", 1.0))
    except (TypeError, ValueError) as exc:
        raise CheckpointError(str(exc)) from None
    return TimedRun(
        dis=data_run.dis,
        theta=data_run.theta,
        phi=data_run.phi,
        t=t,
        velocities=_array(timing.get("velocities"), (m, 1 + 2 * n), "velocities", path),
        accelerations=_array(timing.get("accelerations"), (m, 1 + 2 * n), "accelerations", path),
        limits=limits,
        section_length=data_run.section_length,
        margin_cm=margin if math.isfinite(margin) else 1.0,
        tank=data_run.tank,
    )


def timed_run_tank(run: str | Path, tank: str | None = None) -> tuple[TimedRun, Tank]:
    """A run's timed motion and its tank: ``tank`` if given, else the one the run names.

    A run's tank is a shipped name or a YAML inside the run (:func:`resolve_run_tank`); a run
    that names none is taken to be in the default tank.
    """
    timed = read_timed(run)
    folder = Path(run).parent if Path(run).name == "trajectory.json" else Path(run)
    if tank is None and timed.tank is not None:
        tank = resolve_run_tank(timed.tank, folder)
    return timed, load_tank() if tank is None else load_tank(tank)


def _rate_bounds(limits: ActuatorLimits, n: int, what: str) -> NDArray[np.float64]:
    """The joints' speed or acceleration bounds ``(1 + 2N,)``."""
    module, bend = (
        (limits.module_speed, limits.bend_rate)
        if what == "speed"
        else (limits.module_accel, limits.bend_accel)
    )
    return np.concatenate([[module], np.full(2 * n, bend)])


def _time_problems(run: TimedRun) -> list[str]:
    """Times that start at 0 and never decrease, and stand still only where the arm does."""
    dt = np.diff(run.t)
    problems = []
    if run.t[0] != 0.0:
        problems.append(f"the motion starts at t = {run.t[0]:g} s, not 0")
    if np.any(dt < 0):
        problems.append(f"time goes back after entry {int(np.argmax(dt < 0))}")
    q = joint_positions(run.dis, run.theta, run.phi)
    moved = np.abs(np.diff(q, axis=0)).max(axis=1) > 1e-9
    if np.any((dt <= 0) & moved):
        problems.append(f"entry {int(np.argmax((dt <= 0) & moved)) + 1} moves in no time")
    return problems


def _worst(ratio: NDArray[np.float64], names: list[str]) -> tuple[float, str, int]:
    """The largest ratio, its column's name and its row."""
    row, col = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return float(ratio[row, col]), names[col], int(row)


def _limit_problems(run: TimedRun) -> list[str]:
    """The stored rates within the limits, and the rates between entries within the slack."""
    n = run.theta.shape[1]
    names, problems = joint_names(n), []
    speed, accel = _rate_bounds(run.limits, n, "speed"), _rate_bounds(run.limits, n, "accel")
    for label, values, bound, slack in (
        ("speed", run.velocities, speed, 1e-6),
        ("acceleration", run.accelerations, accel, 1e-6),
    ):
        ratio, name, row = _worst(np.abs(values) / bound, names)
        if ratio > 1 + slack:
            problems.append(f"{name}'s {label} at entry {row} is {ratio:.3f} times its limit")
    # independent of the stored rates: positions over times
    moving = np.diff(run.t) > 0
    q = joint_positions(run.dis, run.theta, run.phi)
    cables = cable_lengths(run.theta, run.phi, run.limits).reshape(len(q), -1)
    dt = np.diff(run.t)[moving][:, None]
    for label, values, bound, names_of in (
        ("joint", q, speed, names),
        ("cable", cables, np.full(3 * n, run.limits.cable_speed), cable_names(n)),
    ):
        average = np.abs(np.diff(values, axis=0)[moving]) / dt
        if len(average):
            ratio, name, row = _worst(average / bound, names_of)
            if ratio > 1 + BETWEEN_ENTRIES:
                problems.append(
                    f"{label} {name} moves {ratio:.3f} times its speed limit after {row}"
                )
    if np.abs(cables).max(initial=0.0) > run.limits.cable_travel:
        problems.append(f"a cable changes by {np.abs(cables).max():.2f} cm, past its travel")
    return problems


def _geometry_problems(run: TimedRun, tank: Tank) -> list[str]:
    """Joint limits, dense entries, and python-fcl clearance with the panel rule at each entry."""
    if np.abs(run.theta).max() > tank.arm.theta_max + 1e-9:
        return [f"a section bends past theta_max ({tank.arm.theta_max:g} rad)"]
    problems = []
    l = run.section_length
    for lo in range(0, len(run.dis) - 1, 256):
        hi = min(lo + 257, len(run.dis))
        pts = body_points(run.dis[lo:hi], run.theta[lo:hi], run.phi[lo:hi], l, 10)
        move = np.linalg.norm(np.diff(pts, axis=0), axis=2).max(axis=1)
        if move.max() > MAX_MOVE_CM:
            problems.append(
                f"the backbone moves {move.max():.2f} cm after entry {lo + int(move.argmax())}"
            )
            break
    scene = CollisionScene(tank, links_per_section=20)
    for i in range(len(run.dis)):
        report = scene.check(Posture(run.dis[i], tuple(run.theta[i]), tuple(run.phi[i])))
        if not report.panel_ok or report.clearance_cm < run.margin_cm:
            what = (
                "breaks the panel rule"
                if not report.panel_ok
                else f"keeps {report.clearance_cm:.3f} cm"
            )
            return problems + [f"entry {i} {what} (margin {run.margin_cm:g} cm)"]
    return problems


def check_motion(run: TimedRun, tank: Tank) -> list[str]:
    """What is wrong with a timed motion (empty: it passes), each as one line."""
    if len(run.t) != len(run.dis):
        return ["the timing and the motion have different lengths"]
    return _time_problems(run) + _limit_problems(run) + _geometry_problems(run, tank)


def _rows(run: TimedRun, space: str) -> tuple[list[str], list[NDArray[np.float64]]]:
    """Names and ``(positions, velocities, accelerations)`` in ``space``."""
    n = run.theta.shape[1]
    q = joint_positions(run.dis, run.theta, run.phi)
    if space == "joints":
        return joint_names(n), [q, run.velocities, run.accelerations]
    to_cables = cable_matrix(n, run.limits)  # linear: rates map like lengths
    cables = cable_lengths(run.theta, run.phi, run.limits).reshape(len(q), -1)
    return ["dis"] + cable_names(n), [
        np.concatenate([q[:, :1], cables], axis=1),
        np.concatenate([run.velocities[:, :1], run.velocities[:, 1:] @ to_cables.T], axis=1),
        np.concatenate([run.accelerations[:, :1], run.accelerations[:, 1:] @ to_cables.T], axis=1),
    ]


def export_motion(run: TimedRun, fmt: str, space: str = "joints") -> str:
    """The motion as ``jointtrajectory-json`` (ROS field names and layout) or ``csv`` text."""
    names, (pos, vel, acc) = _rows(run, space)
    if fmt == "csv":
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(
            [
                "time_s",
                *names,
                *(f"{k}_velocity" for k in names),
                *(f"{k}_acceleration" for k in names),
            ]
        )
        for i in range(len(run.t)):
            writer.writerow(
                [
                    repr(float(run.t[i])),
                    *map(repr, pos[i].tolist()),
                    *map(repr, vel[i].tolist()),
                    *map(repr, acc[i].tolist()),
                ]
            )
        return out.getvalue()
    points = []
    for i, t in enumerate(run.t.tolist()):
        sec = int(math.floor(t))
        points.append(
            {
                "positions": pos[i].tolist(),
                "velocities": vel[i].tolist(),
                "accelerations": acc[i].tolist(),
                "effort": [],
                "time_from_start": {
                    "sec": sec,
                    "nanosec": min(int(round((t - sec) * 1e9)), 999_999_999),
                },
            }
        )
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "panel"}
    return json.dumps({"header": header, "joint_names": names, "points": points}, indent=1) + "\n"
