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
from aftir_rl.core.robot import ArmSpec, body_points, tip_jacobian, tip_position
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.model import Route, clip_kappa, kappa_to_angles

__all__ = ["route_clearance", "close_batch", "push_away"]


def route_clearance(tank: Tank, arm: ArmSpec, route: Route, per_section: int = 20) -> float:
    """Smallest clearance [cm] of the final body of ``route`` (its surface, radius included)."""
    theta, phi = kappa_to_angles(route.kappa)
    pts = body_points(route.lead, theta, phi, route.section_length, per_section)
    return float(point_clearance(tank, pts).min()) - arm.radius


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
    routes already threaded through the tank by the beam). Returns ``(lead, κ)`` of each
    candidate, or None where it did not converge to 1e-6 cm.
    """
    kap = np.array(kappa, dtype=np.float64)
    lead = np.array(lead, dtype=np.float64)
    lo, hi = lead_range if lead_range is not None else (lead, lead)
    lead = np.clip(lead, lo, hi)
    c, m = kap.shape[:2]
    j0 = max(0, m - free)
    nk = 2 * (m - j0)

    def joints(p: NDArray[np.float64]) -> tuple[ArrayLike, ArrayLike, ArrayLike]:
        # the last sections' κ, flattened in p (C, R, nk), after the fixed ones of each route
        fixed = np.broadcast_to(kap[:, None, :j0], p.shape[:2] + (j0, 2))
        theta, phi = kappa_to_angles(np.concatenate([fixed, p.reshape(p.shape[:2] + (-1, 2))], 2))
        return lead[:, None], theta, phi

    for _ in range(iterations):
        # forward differences of the tip in the free κ (C, 3, nk)
        tip, jac_t = tip_jacobian(kap[:, j0:].reshape(c, nk), l, central=False, joints=joints)
        err = target - tip
        norm = np.linalg.norm(err, axis=1)
        done = norm < 1e-7
        if done.all():
            break
        dk, dlead = _dls_step(jac_t, err, norm, done, l, lead_range is not None)
        kap[:, j0:] = clip_kappa(kap[:, j0:] + dk.reshape(c, -1, 2), theta_max)
        lead = np.clip(lead + dlead, lo, hi)
    theta, phi = kappa_to_angles(kap)
    ok = np.linalg.norm(target - tip_position(lead, theta, phi, l), axis=1) < 1e-6
    return [(float(lead[i]), kap[i]) if ok[i] else None for i in range(c)]


def _dls_step(
    jac_t: NDArray[np.float64],
    err: NDArray[np.float64],
    norm: NDArray[np.float64],
    done: NDArray[np.bool_],
    l: float,
    free_lead: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One bounded damped least-squares step of each route: ``(Δκ (C, nk), Δlead (C,))``.

    Args:
        jac_t: the tip's Jacobian in the free ``κ``, ``(C, 3, nk)``.
        err: the tip errors ``target − tip``, ``(C, 3)``.
        norm: their lengths [cm].
        done: the routes already on the target (they do not move).
        l: section length [cm].
        free_lead: the lead moves too.

    """
    c, nk = jac_t.shape[0], jac_t.shape[2]
    unit_z = np.array([0.0, 0.0, 1.0])
    jac_k = np.swapaxes(jac_t, 1, 2)  # (C, nk, 3)
    # the lead's column is in cm, the angles' in cm/rad: scale it like 1/l rad per cm
    lead_weight = 1.0 if free_lead else 0.0
    jac = np.concatenate([jac_k, np.broadcast_to(unit_z * l * lead_weight, (c, 1, 3))], axis=1)
    damping = np.where(norm > 5, 1e-6, 1e-8) * l * l
    a = np.swapaxes(jac, 1, 2) @ jac + damping[:, None, None] * np.eye(3)
    step = np.einsum("cvi,ci->cv", jac, np.linalg.solve(a, err[..., None])[..., 0])
    step[done] = 0.0
    dk, dlead = step[:, :nk], step[:, nk] * l
    size = np.linalg.norm(dk, axis=1)
    scale = np.minimum(
        np.minimum(1.0, 0.3 / np.maximum(size, 1e-12)), 10.0 / np.maximum(np.abs(dlead), 1e-12)
    )
    return dk * scale[:, None], dlead * scale


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
