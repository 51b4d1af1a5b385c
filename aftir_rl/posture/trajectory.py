"""From a learned tip path to joint variables along it (seed 002 §5).

Every cell centre of the greedy path gets a posture, and the last posture reaches the exact
target. The paper plans each one with TGA (bay 1) or TSM (beyond the hatch) and relies on similar
targets giving similar postures. Measured here, that does not hold across the hatch: TGA and TSM
postures of neighbouring cells differ by up to 180 deg in a joint and 4 sections. So each posture
is *continued* from the previous one: damped least squares on ``(dis, θ, φ)`` moves the tip to the
next waypoint in a few sub-steps, every sub-step checked (limits, panel rule, python-fcl), with
the number of sections held fixed (the most any waypoint's planned posture needs). Where the
continuation fails, the planner's own posture for that waypoint is used and the move to it is
checked like any other; the result says which waypoints needed that and which moves collide.

Between two neighbouring postures the arm moves by linear interpolation of ``(dis, θ, φ)`` (``φ``
the short way round). A posture with fewer sections is first written with straight sections
added at its base and ``dis`` lowered by their length, which is the same arm: the linear module
pushes a new section out. Every interpolated posture is collision-checked; a cell with no posture
or a colliding move is reported with the reason, not hidden.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.errors import PlanningError
from aftir_rl.posture.planner import PlannedPosture, Planner
from aftir_rl.robot import Posture, tip_position

__all__ = ["Trajectory", "plan_trajectory", "continue_posture", "pad_sections", "interpolate"]


@dataclass
class Trajectory:
    """Postures along a tip path.

    Attributes:
        waypoints: the points planned for [cm]: the path's cell centres, then the exact target.
        postures: one per waypoint, None where none was found.
        failures: ``(index, point, reason)`` for waypoints without a posture.
        blocked_moves: ``(index, fraction)``: interpolated postures between waypoint ``index``
            and the next that collide.
        max_joint_step_deg: largest change of any ``θ_i`` or ``φ_i`` (of a bent section) between
            neighbouring postures, after padding [deg].
        max_dis_step_cm: largest change of ``dis`` between neighbouring postures [cm].
        fallbacks: waypoints where continuation failed and the planner's posture was used.

    """

    waypoints: list[list[float]]
    postures: list[PlannedPosture | None]
    failures: list[tuple[int, list[float], str]] = field(default_factory=list)
    blocked_moves: list[tuple[int, float]] = field(default_factory=list)
    max_joint_step_deg: float = 0.0
    max_dis_step_cm: float = 0.0
    fallbacks: list[int] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        """Every waypoint has a posture and every interpolated move is collision-free."""
        return not self.failures and not self.blocked_moves

    def to_json(self) -> dict[str, Any]:
        """``trajectory.json``: the postures in order (posture JSON of design.md §5)."""
        return {
            "waypoints_cm": self.waypoints,
            "postures": [p.to_json() if p is not None else None for p in self.postures],
            "failures": [
                {"index": i, "point_cm": pt, "reason": why} for i, pt, why in self.failures
            ],
            "blocked_moves": [{"index": i, "fraction": f} for i, f in self.blocked_moves],
            "complete": self.complete,
            "max_joint_step_deg": self.max_joint_step_deg,
            "max_dis_step_cm": self.max_dis_step_cm,
            "fallbacks": self.fallbacks,
        }


def pad_sections(posture: Posture, n_sections: int, section_length: float) -> Posture:
    """The same arm with straight sections added at its base to reach ``n_sections``."""
    extra = n_sections - posture.n_sections
    if extra < 0:
        raise ValueError(f"cannot pad {posture.n_sections} sections down to {n_sections}")
    first_phi = posture.phi[0] if posture.phi else 0.0
    return Posture(
        posture.dis - extra * section_length,
        (0.0,) * extra + posture.theta,
        (first_phi,) * extra + posture.phi,
    )


def interpolate(a: Posture, b: Posture, fraction: float) -> Posture:
    """Linear interpolation of two postures with the same number of sections (φ the short way)."""
    dphi = (np.subtract(b.phi, a.phi) + math.pi) % (2 * math.pi) - math.pi
    return Posture(
        a.dis + fraction * (b.dis - a.dis),
        tuple(np.add(a.theta, fraction * np.subtract(b.theta, a.theta))),
        tuple(np.add(a.phi, fraction * dphi)),
    )


def continue_posture(
    planner: Planner,
    start: Posture,
    target: ArrayLike,
    tolerance: float = 0.01,
    iterations: int = 40,
    damping: float = 1.0,
) -> Posture | None:
    """Move the tip of ``start`` onto ``target`` by damped least squares on ``(dis, θ, φ)``.

    Joint limits hold throughout (``|θ| ≤ θ_max``, ``dis ≤ 0``), and sections that end below the
    floor (inside the guide, when the ones below them are straight) are not bent. Returns None if
    the tip does not get within ``tolerance`` [cm].
    """
    l, tmax = planner.arm.section_length, planner.arm.theta_max
    n = start.n_sections
    x = np.concatenate([[start.dis], start.theta, start.phi])
    goal = np.asarray(target, dtype=np.float64)
    h = 1e-6
    for _ in range(iterations):
        probe = np.repeat(x[None], 2 * len(x) + 1, axis=0)
        probe[1 : len(x) + 1] += np.eye(len(x)) * h
        probe[len(x) + 1 :] -= np.eye(len(x)) * h
        tips = tip_position(probe[:, 0], probe[:, 1 : n + 1], probe[:, n + 1 :], l)
        error = tips[0] - goal
        if np.linalg.norm(error) < tolerance * 0.1:
            break
        jac = ((tips[1 : len(x) + 1] - tips[len(x) + 1 :]) / (2 * h)).T  # (3, 1 + 2N)
        # Sections still wholly inside the guide (ending below the floor) must stay straight.
        ends = x[0] + l * np.arange(1, n + 1)
        frozen = np.concatenate([[False], ends <= 0.0, ends <= 0.0])
        jac[:, frozen] = 0.0
        step = -jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(3), error)
        x = x + step
        x[1 : n + 1] = np.clip(x[1 : n + 1], -tmax, tmax)
        x[0] = min(x[0], 0.0)
    posture = Posture(x[0], x[1 : n + 1], x[n + 1 :])
    if np.linalg.norm(posture.tip(l) - goal) >= tolerance:
        return None
    return posture


def plan_trajectory(
    planner: Planner,
    points: Sequence[ArrayLike],
    target: ArrayLike,
    interpolation_steps: int = 4,
) -> Trajectory:
    """Postures for every point of a tip path and the exact target, and checked moves between.

    Args:
        planner: the planner of the tank.
        points: the path's cell centres [cm], start first.
        target: the exact target [cm], planned last.
        interpolation_steps: sub-steps of each move, each one checked.

    """
    waypoints = [list(map(float, p)) for p in points] + [list(map(float, target))]
    l = planner.arm.section_length
    planned: list[PlannedPosture | None] = []
    failures: list[tuple[int, list[float], str]] = []
    for i, point in enumerate(waypoints):
        try:
            planned.append(planner.plan(point))
        except PlanningError as exc:
            planned.append(None)
            failures.append((i, point, str(exc)))
    n = max((p.posture.n_sections for p in planned if p is not None), default=1)
    postures: list[PlannedPosture | None] = []
    fallbacks: list[int] = []
    blocked: list[tuple[int, float]] = []
    previous: Posture | None = None
    for i, point in enumerate(waypoints):
        own = planned[i]
        chosen: Posture | None = None
        if previous is not None:
            chosen, moves = _continue(planner, previous, np.array(point), interpolation_steps)
            if chosen is None and own is not None:
                fallbacks.append(i)
                chosen = pad_sections(own.posture, n, l)
                for k in range(1, interpolation_steps + 1):
                    fraction = k / (interpolation_steps + 1)
                    if planner.scene.collides(interpolate(previous, chosen, fraction)):
                        blocked.append((i - 1, fraction))
        elif own is not None:
            chosen = pad_sections(own.posture, n, l)
        if chosen is None:
            postures.append(None)
            continue
        continued = previous is not None and i not in fallbacks
        method = "continued" if continued or own is None else own.method
        postures.append(planner.checked(chosen, np.array(point), method))
        previous = chosen
    joint_step, dis_step = _steps(postures)
    return Trajectory(waypoints, postures, failures, blocked, joint_step, dis_step, fallbacks)


def _continue(
    planner: Planner, previous: Posture, point: np.ndarray, steps: int
) -> tuple[Posture | None, int]:
    """Continue ``previous`` to ``point`` in ``steps + 1`` checked sub-steps."""
    start_tip = previous.tip(planner.arm.section_length)
    current = previous
    for k in range(1, steps + 2):
        goal = start_tip + (point - start_tip) * k / (steps + 1)
        nxt = continue_posture(planner, current, goal)
        if nxt is None or planner.scene.collides(nxt):
            return None, k
        current = nxt
    return current, steps + 1


def _steps(postures: Sequence[PlannedPosture | None]) -> tuple[float, float]:
    joint, dis = 0.0, 0.0
    for a, b in zip(postures, postures[1:]):
        if a is None or b is None:
            continue
        pa, pb = a.posture, b.posture
        dtheta = np.abs(np.subtract(pb.theta, pa.theta))
        bent = (np.abs(pa.theta) > 1e-6) & (np.abs(pb.theta) > 1e-6)
        dphi = np.abs((np.subtract(pb.phi, pa.phi) + math.pi) % (2 * math.pi) - math.pi) * bent
        joint = max(joint, math.degrees(float(np.max(np.maximum(dtheta, dphi)))))
        dis = max(dis, abs(pb.dis - pa.dis))
    return joint, dis
