"""Moving a posture's tip while the body stays clear: continuation, repair and sliding.

What :mod:`aftir_rl.planning.posture.trajectory` builds its chains of postures from:

- :func:`continue_posture`: damped least squares on ``(dis, θ, φ)`` moves the tip to the next
  waypoint, joint limits held and sections still in the guide left straight;
- :func:`repair_posture`: a colliding posture moves in the null space of the tip's Jacobian
  (the tip stays put) down the gradient of its penetration into a band around the tank;
- :func:`slide`: the arm pushed further in along its own backbone (an approximate
  follow-the-leader step).

The tip's Jacobian is :func:`~aftir_rl.core.robot.tip_jacobian`'s, compiled
(:func:`~aftir_rl.core.kernel.sections.joint_tip_jacobian`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.kernel.sections import joint_tip_jacobian
from aftir_rl.core.robot import Posture, body_points, finite_differences
from aftir_rl.planning.jointspace import align
from aftir_rl.planning.posture.context import PlanningContext

__all__ = ["continue_posture", "repair_posture", "slide"]


def _within_limits(context: PlanningContext, x: np.ndarray) -> np.ndarray:
    """``x`` with ``|θ| ≤ θ_max`` and ``dis ≤ 0`` (the linear module stays outside)."""
    n = (len(x) - 1) // 2
    x[1 : n + 1] = np.clip(x[1 : n + 1], -context.arm.theta_max, context.arm.theta_max)
    x[0] = min(x[0], 0.0)
    return x


def _tip_jacobian(x: np.ndarray, n: int, l: float) -> tuple[np.ndarray, np.ndarray]:
    """Tip [cm] and its Jacobian ``(3, 1 + 2N)`` (:func:`~aftir_rl.core.robot.tip_jacobian`).

    Sections still inside the guide (ending below the floor) are frozen straight.
    """
    tip, jac = np.empty(3), np.empty((3, len(x)))
    joint_tip_jacobian(np.ascontiguousarray(x, dtype=np.float64), l, 1e-6, tip, jac)
    ends = x[0] + l * np.arange(1, n + 1)
    jac[:, np.concatenate([[False], ends <= 0.0, ends <= 0.0])] = 0.0
    return tip, jac


def continue_posture(
    context: PlanningContext,
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
    goal = np.asarray(target, dtype=np.float64)
    x = _solve_tip(context, start.to_vector(), goal, tolerance * 0.1, iterations, damping)
    posture = Posture.from_vector(x)
    if np.linalg.norm(posture.tip(context.arm.section_length) - goal) >= tolerance:
        return None
    return posture


def _solve_tip(
    context: PlanningContext,
    x: np.ndarray,
    goal: np.ndarray,
    tol: float,
    iterations: int,
    damping: float,
) -> np.ndarray:
    n = (len(x) - 1) // 2
    for _ in range(iterations):
        tip, jac = _tip_jacobian(x, n, context.arm.section_length)
        error = tip - goal
        if np.linalg.norm(error) < tol:
            break
        step = jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(3), error)
        x = _within_limits(context, x - step)
    return x


class _Penalty:
    """Penetration of a posture's backbone into the band ``r + margin`` around the tank.

    ``Σ max(0, r + margin − d_j)²`` over backbone samples ``j``, batched over postures.
    """

    def __init__(self, context: PlanningContext, margin: float) -> None:
        self.tank, self.l = context.tank, context.arm.section_length
        self.limit = context.arm.radius + margin

    def __call__(self, x: np.ndarray) -> np.ndarray:
        n = (x.shape[1] - 1) // 2
        pts = body_points(x[:, 0], x[:, 1 : n + 1], x[:, n + 1 :], self.l, 10)
        depth = np.maximum(0.0, self.limit - point_clearance(self.tank, pts))
        return np.sum(depth**2, axis=1)


def _null_space_step(
    context: PlanningContext, x: np.ndarray, objective: _Penalty, max_step: float, h: float = 1e-4
) -> np.ndarray | None:
    """One descent step on ``objective`` that leaves the tip where it is (to first order)."""
    n = (len(x) - 1) // 2
    _, gradient = finite_differences(lambda p: objective(p)[:, None], x, h)
    grad = gradient[0]
    _, jac = _tip_jacobian(x, n, context.arm.section_length)
    step = -(grad - np.linalg.pinv(jac) @ (jac @ grad))
    size = np.max(np.abs(step))
    if size < 1e-12:
        return None
    return _within_limits(context, x + step * min(1.0, max_step / size))


def repair_posture(
    context: PlanningContext,
    posture: Posture,
    target: ArrayLike,
    margin: float = 1.0,
    iterations: int = 60,
    max_step: float = 0.05,
    tolerance: float = 0.01,
) -> Posture | None:
    """Push a colliding posture clear of the tank while its tip stays on ``target``.

    Redundancy resolution: the arm has ``1 + 2N`` joints for a 3D tip, so it can move in the
    null space of the tip's Jacobian without moving the tip. Each iteration descends the penalty
    ``Σ max(0, r + margin − d_j)²`` over backbone samples ``j`` (``d_j`` their signed distance to
    the tank, :func:`~aftir_rl.core.collision.point_clearance`, with the guide below the panel),
    projected onto that null space, then puts the tip back by damped least squares. Returns the
    first posture python-fcl clears, or None.
    """
    l = context.arm.section_length
    goal = np.asarray(target, dtype=np.float64)
    x = posture.to_vector()
    objective = _Penalty(context, margin)
    for _ in range(iterations):
        candidate = Posture.from_vector(x)
        if np.linalg.norm(candidate.tip(l) - goal) < tolerance and not context.scene.collides(
            candidate
        ):
            return candidate
        stepped = _null_space_step(context, x, objective, max_step)
        if stepped is None:
            return None
        x = _solve_tip(context, stepped, goal, tolerance * 0.1, 10, 1.0)
    return None


def slide(posture: Posture, delta: float, section_length: float) -> Posture:
    """The arm pushed ``delta`` [cm] further in, sliding along its own backbone (approximately).

    ``dis`` grows by ``delta`` and section ``k`` takes ``1 − δ/l`` of its own bend and ``δ/l``
    of section ``k + 1``'s (as bending vectors ``θ(cos φ, sin φ)``); the last section keeps its
    own. At ``δ = l``, when the first section is straight (in the guide), this is exact: the
    body in the tank is the old one, lengthened at the tip by one more section bent like the
    last. In between, a section spans two old sections of different curvature and can only
    approximate them.

    Raises:
        ValueError: ``delta`` is not in ``[0, l]``.

    """
    if not 0.0 <= delta <= section_length:
        raise ValueError(f"can slide by 0 to {section_length:g} cm, not {delta:g}")
    t = delta / section_length
    theta, phi = np.array(posture.theta), np.array(posture.phi)
    bend = np.stack([theta * np.cos(phi), theta * np.sin(phi)])
    bend[:, :-1] = (1 - t) * bend[:, :-1] + t * bend[:, 1:]
    moved = Posture(posture.dis + delta, np.hypot(*bend), np.arctan2(bend[1], bend[0]))
    return align(moved, posture)
