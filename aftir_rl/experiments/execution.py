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
from aftir_rl.core.cables import cable_names
from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.robot import Posture, body_points
from aftir_rl.core.tank import Tank, load_tank, resolve_run_tank
from aftir_rl.planning.timing import TimedMotion, joint_names
from aftir_rl.viz.runs import RunData, read_run

__all__ = [
    "FORMATS",
    "SPACES",
    "TimedRun",
    "check_motion",
    "check_tour",
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
    """A timed motion read from a run: its postures, their schedule and the run's context."""

    dis: NDArray[np.float64]
    theta: NDArray[np.float64]
    phi: NDArray[np.float64]
    timing: TimedMotion
    section_length: float
    margin_cm: float
    tank: str | None = None
    #: Whether the run held no timing and the motion was timed as it was read.
    timed_now: bool = False
    #: The target the run's file names [cm], if any.
    target: NDArray[np.float64] | None = None


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


def _folder(run: str | Path) -> Path:
    """The run directory of ``run`` (a run directory or its ``trajectory.json``)."""
    return Path(run).parent if Path(run).name == "trajectory.json" else Path(run)


def read_timed(run: str | Path, tank: Tank | None = None) -> TimedRun:
    """The timed motion of a run directory (or of its ``trajectory.json``), each file read once.

    A motion written without its timing (the run was made before the ``robot`` extra was
    installed) is timed now under ``tank``'s arm limits when a ``tank`` is given
    (:func:`~aftir_rl.planning.timing.time_motion`; :attr:`TimedRun.timed_now` says so).

    Raises:
        CheckpointError: no motion, no timing (and no ``tank`` to time it in, or timing it
            failed), or a file of the wrong shape (one line).

    """
    return _timed_run(_read(run), _folder(run) / "trajectory.json", tank)


def _read(run: str | Path) -> RunData:
    return read_run(_folder(run), keep=("timing", "timing_note", "margin_cm"))


def _timed_run(data: RunData, path: Path, tank: Tank | None) -> TimedRun:
    """:func:`read_timed` of a run's files, read."""
    if data.dis is None or data.theta is None or data.phi is None:
        raise CheckpointError(f"{path.parent}: no motion in trajectory.json")
    timing = data.kept.get("timing")
    if not isinstance(timing, dict):
        note = data.kept.get("timing_note")
        if tank is None:
            raise CheckpointError(
                f"{path}: the motion has no timing" + (f" ({note})"[:200] if note else "")
            )
        return _timed_now(data, tank, path)
    m, n = data.theta.shape
    try:
        limits = ActuatorLimits.from_mapping(timing.get("limits"), f"{path}: timing.limits")
        margin = float(data.kept.get("margin_cm", 1.0))
    except (TypeError, ValueError, OverflowError) as exc:
        raise CheckpointError(str(exc)) from None
    velocities, accelerations = (
        _array(timing.get(key), (m, 1 + 2 * n), key, path)
        for key in ("velocities", "accelerations")
    )
    t = _array([timing.get("t")], (1, m), "t", path)[0]
    postures = (data.dis, data.theta, data.phi)
    return TimedRun(
        *postures,
        timing=TimedMotion.from_rates(postures, t, (velocities, accelerations), limits),
        section_length=data.section_length,
        margin_cm=margin if math.isfinite(margin) else 1.0,
        tank=data.tank,
        target=data.target,
    )


def timed_run_tank(run: str | Path, tank: str | None = None) -> tuple[TimedRun, Tank]:
    """A run's timed motion and its tank: ``tank`` if given, else the one the run names.

    A run's tank is a shipped name or a YAML inside the run (:func:`resolve_run_tank`); a run
    that names none is taken to be in the default tank. A motion saved without its timing is
    timed now, in that tank (:func:`read_timed`).
    """
    data = _read(run)
    if tank is None and data.tank is not None:
        tank = resolve_run_tank(data.tank, _folder(run))
    loaded = load_tank() if tank is None else load_tank(tank)
    return _timed_run(data, _folder(run) / "trajectory.json", loaded), loaded


def _timed_now(data: RunData, tank: Tank, path: Path) -> TimedRun:
    """Time a run's saved postures under ``tank``'s arm limits (its timing was not saved)."""
    from aftir_rl.core.errors import AftirError
    from aftir_rl.planning.timing import time_motion

    assert data.dis is not None and data.theta is not None and data.phi is not None
    try:
        timing = time_motion(data.dis, data.theta, data.phi, data.section_length, tank.arm.limits)
        margin = float(data.kept.get("margin_cm", 1.0))
    except (AftirError, TypeError, ValueError, OverflowError) as exc:
        raise CheckpointError(f"{path}: the motion has no timing, and timing it now failed: "
                              f"{exc}") from None  # fmt: skip
    margin = margin if math.isfinite(margin) else 1.0
    postures = (data.dis, data.theta, data.phi)
    return TimedRun(
        *postures, timing, data.section_length, margin, data.tank, True, target=data.target
    )


def _time_problems(run: TimedRun) -> list[str]:
    """Times that start at 0 and never decrease, and stand still only where the arm does."""
    t = run.timing.t
    dt = np.diff(t)
    problems = []
    if t[0] != 0.0:
        problems.append(f"the motion starts at t = {t[0]:g} s, not 0")
    if np.any(dt < 0):
        problems.append(f"time goes back after entry {int(np.argmax(dt < 0))}")
    moved = np.abs(np.diff(run.timing.positions, axis=0)).max(axis=1) > 1e-9
    if np.any((dt <= 0) & moved):
        problems.append(f"entry {int(np.argmax((dt <= 0) & moved)) + 1} moves in no time")
    return problems


def _worst(ratio: NDArray[np.float64], names: list[str]) -> tuple[float, str, int]:
    """The largest ratio, its column's name and its row."""
    row, col = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return float(ratio[row, col]), names[col], int(row)


def _limit_problems(run: TimedRun) -> list[str]:
    """The stored rates within the limits, and the rates between entries within the slack."""
    timing, n = run.timing, run.theta.shape[1]
    joints, names, problems = 1 + 2 * n, joint_names(n), []
    speed, accel = timing.limits.rate_bounds(n, "speed"), timing.limits.rate_bounds(n, "accel")
    for label, values, bound in (
        ("speed", timing.velocities, speed[:joints]),
        ("acceleration", timing.accelerations, accel[:joints]),
    ):
        ratio, name, row = _worst(np.abs(values) / bound, names)
        if ratio > 1 + 1e-6:
            problems.append(f"{name}'s {label} at entry {row} is {ratio:.3f} times its limit")
    # independent of the stored rates: positions (from the postures) over times
    moving = np.diff(timing.t) > 0
    dt = np.diff(timing.t)[moving][:, None]
    for label, values, bound, names_of in (
        ("joint", timing.positions, speed[:joints], names),
        ("cable", timing.cables, speed[joints:], cable_names(n)),
    ):
        average = np.abs(np.diff(values, axis=0)[moving]) / dt
        if len(average):
            ratio, name, row = _worst(average / bound, names_of)
            if ratio > 1 + BETWEEN_ENTRIES:
                problems.append(
                    f"{label} {name} moves {ratio:.3f} times its speed limit after {row}"
                )
    travel = np.abs(timing.cables).max(initial=0.0)
    if travel > timing.limits.cable_travel:
        problems.append(f"a cable changes by {travel:.2f} cm, past its travel")
    return problems


def _geometry_problems(run: TimedRun, tank: Tank, margin: float) -> list[str]:
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
        if not report.panel_ok or report.clearance_cm < margin:
            what = (
                "breaks the panel rule"
                if not report.panel_ok
                else f"keeps {report.clearance_cm:.3f} cm"
            )
            return problems + [f"entry {i} {what} (margin {margin:g} cm)"]
    return problems


def check_motion(run: TimedRun, tank: Tank, margin: float = DEFAULT_MARGIN) -> list[str]:
    """What is wrong with a timed motion (empty: it passes), each as one line.

    The clearance is judged against ``margin`` [cm], the caller's: never the margin the run's
    file states (:attr:`TimedRun.margin_cm`, which a file may set to anything).
    """
    if len(run.timing.t) != len(run.dis):
        return ["the timing and the motion have different lengths"]
    return _time_problems(run) + _limit_problems(run) + _geometry_problems(run, tank, margin)


def _rows(run: TimedRun, space: str) -> tuple[list[str], list[NDArray[np.float64]]]:
    """Names and ``(positions, velocities, accelerations)`` in ``space``.

    Subnormal values (rounding residue, such as ``8.5e-311``) and negative zeros are written
    as ``0.0``.
    """
    timing, n = run.timing, run.theta.shape[1]
    if space == "joints":
        names, rows = joint_names(n), [timing.positions, timing.velocities, timing.accelerations]
    else:
        dis = (timing.positions[:, :1], timing.velocities[:, :1], timing.accelerations[:, :1])
        cables = (timing.cables, timing.cable_velocities, timing.cable_accelerations)
        names = ["dis"] + cable_names(n)
        rows = [np.concatenate(pair, axis=1) for pair in zip(dis, cables)]
    tiny = np.finfo(np.float64).tiny
    return names, [np.where(np.abs(a) < tiny, 0.0, a) + 0.0 for a in rows]


def _unit(name: str) -> str:
    """The unit of a position named by :func:`_rows`: ``cm`` (``dis``, cables) or ``rad``."""
    return "rad" if name.endswith(("_kx", "_ky")) else "cm"


def export_motion(
    run: TimedRun, fmt: str, space: str = "joints", checked_margin: float | None = DEFAULT_MARGIN
) -> str:
    """The motion as ``jointtrajectory-json`` (ROS field names and layout) or ``csv`` text.

    Both say their units: the JSON has ``units`` (each joint's position unit, and those of
    time, velocities and accelerations); a CSV column's name ends with its unit (``dis_cm``,
    ``section_1_kx_rad``, ``dis_velocity_cm_per_s``...). ``checked_margin``: the margin [cm]
    :func:`check_motion` found the motion to keep, or None for a motion exported without that
    check, which the file then says (the JSON's ``checked_margin_cm`` is null; a CSV starts
    with a ``#`` line).
    """
    names, (pos, vel, acc) = _rows(run, space)
    if fmt == "csv":
        out = io.StringIO()
        if checked_margin is None:
            out.write("# not checked: exported with --unchecked; run aftir check first\n")
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(
            [
                "time_s",
                *(f"{k}_{_unit(k)}" for k in names),
                *(f"{k}_velocity_{_unit(k)}_per_s" for k in names),
                *(f"{k}_acceleration_{_unit(k)}_per_s2" for k in names),
            ]
        )
        for i, t in enumerate(run.timing.t.tolist()):
            writer.writerow(
                [
                    repr(t),
                    *map(repr, pos[i].tolist()),
                    *map(repr, vel[i].tolist()),
                    *map(repr, acc[i].tolist()),
                ]
            )
        return out.getvalue()
    points = []
    for i, t in enumerate(run.timing.t.tolist()):
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
    units = {
        "positions": {k: _unit(k) for k in names},
        "velocities": "position unit per s",
        "accelerations": "position unit per s^2",
        "time_from_start": "s",
    }
    data = {"header": header, "joint_names": names, "points": points, "units": units}
    return json.dumps({**data, "checked_margin_cm": checked_margin}, indent=1) + "\n"


def check_tour(tank: Tank, tour: Any) -> list[str]:
    """:func:`check_motion` of a planned tour (a :class:`~aftir_rl.planning.ftl.tour.Tour`)."""
    dis, theta, phi = tour.motion
    run = TimedRun(dis, theta, phi, tour.timing, tour.section_length, tour.margin_cm)
    return check_motion(run, tank, tour.margin_cm)  # the margin the tour was planned with
