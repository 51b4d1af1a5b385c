"""Closing a route on its target and pushing it away from the tank.

:func:`close_batch` puts the tips of many candidate routes exactly on the target (damped least
squares on the lead and the last bending vectors); :func:`push_away` raises a closed route's
clearance with its end kept on the target; :func:`route_clearance` measures a route's body.
Used by :func:`aftir_rl.planning.ftl.route.plan_route`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.sections import close, postures_min_clearance
from aftir_rl.core.robot import ArmSpec, body_points, tip_position
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.model import Route, clip_kappa, kappa_to_angles

__all__ = ["route_clearance", "close_batch", "push_away"]


def route_clearance(tank: Tank, arm: ArmSpec, route: Route, per_section: int = 20) -> float:
    """Smallest clearance [cm] of the final body of ``route`` (its surface, radius included).

    Exact, compiled (:func:`~aftir_rl.core.kernel.sections.postures_min_clearance`).
    """
    theta, phi = kappa_to_angles(route.kappa)
    lead = np.array([route.lead], dtype=np.float64)
    l, grid = route.section_length, kernel_grid(tank)
    return postures_min_clearance(lead, theta[None], phi[None], l, per_section, grid) - arm.radius


def close_batch(
    lead: NDArray[np.float64],
    kappa: NDArray[np.float64],
    target: NDArray[np.float64],
    l: float,
    theta_max: float,
    free: int = 3,
    iterations: int = 40,
    lead_range: tuple[ArrayLike, ArrayLike] | None = (-25.0, 60.0),
) -> list[tuple[float, NDArray[np.float64]] | None]:
    """Put each route's tip on ``target``: damped least squares on its lead and last ``κ``.

    ``kappa`` is ``(C, M, 2)``: C candidate routes of one depth, solved together (one batched
    forward kinematics per iteration). The lead moves the whole route along the panel's axis
    (its derivative is ``(0, 0, 1)``): with sections of fixed length, a continuous lead is what
    lets a route end exactly at any distance. Steps are bounded (0.3 rad, 10 cm), ``κ`` stays
    within the joint limit and the lead within ``lead_range`` (None: the lead stays as given, for
    routes already threaded through the tank by the beam). Compiled, one loop per candidate
    (:func:`aftir_rl.core.kernel.sections.close`). Returns ``(lead, κ)`` of each candidate, or
    None where it did not converge to 1e-6 cm.
    """
    kap = np.array(kappa, dtype=np.float64)
    lead = np.array(lead, dtype=np.float64).reshape(-1)
    if lead_range is None:
        lo, hi = lead.copy(), lead.copy()
    else:
        lo = np.broadcast_to(np.asarray(lead_range[0], dtype=np.float64), lead.shape).copy()
        hi = np.broadcast_to(np.asarray(lead_range[1], dtype=np.float64), lead.shape).copy()
    ok = np.zeros(len(lead), dtype=bool)
    if len(lead):
        close(lead, kap, np.asarray(target, dtype=np.float64), float(l), float(theta_max),
              int(free), int(iterations), lo, hi, lead_range is not None, ok)  # fmt: skip
    return [(float(lead[i]), kap[i]) if ok[i] else None for i in range(len(lead))]


def push_away(
    tank: Tank,
    arm: ArmSpec,
    route: Route,
    target: NDArray[np.float64],
    goal: float,
    iterations: int = 12,
    step: float = 0.04,
) -> Route:
    """Raise a route's clearance while its end stays on ``target`` (clearance as an objective).

    Gradient ascent on a soft minimum of the body's clearance over every ``κ`` and the lead,
    projected into the null space of the tip's Jacobian, then put back on the target by a few
    Gauss-Newton steps. Stops when the clearance reaches ``goal`` [cm] or stops improving;
    returns the best route seen (the input if nothing better).
    """
    l = route.section_length
    x0 = np.concatenate([[route.lead / l], route.kappa.reshape(-1)])
    x, best_x, best_c = x0.copy(), x0.copy(), route_clearance(tank, arm, route)
    for _ in range(iterations):
        direction, pinv = _ascent_direction(tank, arm, x, l)
        norm = np.linalg.norm(direction)
        if norm < 1e-9:
            break
        x, lead, kap = _onto_target(x + step * direction / norm, pinv, target, l, arm.theta_max)
        theta, phi = kappa_to_angles(kap)
        if np.linalg.norm(target - tip_position(lead, theta, phi, l)) > 1e-6 or lead < -25.0:
            break
        c = route_clearance(tank, arm, Route(float(lead), kap, l))
        if c <= best_c + 1e-3:
            break
        best_x, best_c = x.copy(), c
        if c >= goal:
            break
    lead, kap = _unpack(best_x, l, arm.theta_max)
    return Route(float(lead), kap, l)


def _unpack(
    x: NDArray[np.float64], l: float, theta_max: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lead [cm] and bending vectors (clipped to ``theta_max``) of parameters ``(lead/l, κ...)``."""
    kap = clip_kappa(x[..., 1:].reshape(x.shape[:-1] + (-1, 2)), theta_max)
    return x[..., 0] * l, kap


def _soft_clearance(
    tank: Tank, arm: ArmSpec, xs: NDArray[np.float64], l: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A soft minimum of each body's clearance [cm] and its tip, for parameter rows ``xs``."""
    lead, kap = _unpack(xs, l, arm.theta_max)
    theta, phi = kappa_to_angles(kap)
    pts = body_points(lead, theta, phi, l, 10)
    clear = point_clearance(tank, pts) - arm.radius  # (B, P)
    soft = -np.log(np.sum(np.exp(-2.0 * (clear - clear.min(axis=1, keepdims=True))), axis=1))
    return clear.min(axis=1) + soft / 2.0, pts[:, -1, :]


def _ascent_direction(
    tank: Tank, arm: ArmSpec, x: NDArray[np.float64], l: float, eps: float = 1e-5
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The soft clearance's gradient in the tip's null space, and the tip Jacobian's pseudo-inverse.

    Both by forward differences of step ``eps`` in the parameters ``x``.
    """
    n = len(x)
    trial = x[None, :] + eps * np.vstack([np.zeros(n), np.eye(n)])
    value, tips = _soft_clearance(tank, arm, trial, l)
    grad = (value[1:] - value[0]) / eps
    jac = ((tips[1:] - tips[0]) / eps).T  # (3, n)
    pinv = np.linalg.pinv(jac)
    return grad - pinv @ (jac @ grad), pinv


def _onto_target(
    x: NDArray[np.float64],
    pinv: NDArray[np.float64],
    target: NDArray[np.float64],
    l: float,
    theta_max: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A few Gauss-Newton steps that put the tip back on ``target``.

    Returns:
        The parameters (``κ`` clipped to the joint limit), and their lead [cm] and ``κ``.

    """
    for _ in range(4):
        lead, kap = _unpack(x, l, theta_max)
        theta, phi = kappa_to_angles(kap)
        err = target - tip_position(lead, theta, phi, l)
        if np.linalg.norm(err) < 1e-8:
            break
        x = x + pinv @ err
    lead, kap = _unpack(x, l, theta_max)
    return np.concatenate([[lead / l], kap.reshape(-1)]), lead, kap
