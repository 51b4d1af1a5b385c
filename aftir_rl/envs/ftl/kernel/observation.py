"""The observation vector and the step's reward, compiled."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aftir_rl.core.kernel.arrays import KernelArms

__all__ = ["observation", "goal_reward", "guide_columns"]


#: Reward of a success and penalty of a contact.
SUCCESS_REWARD = 10.0


CONTACT_PENALTY = 10.0


#: Progress reward per cm of distance-to-go.
PROGRESS_PER_CM = 0.1


#: Every observation column is clipped to ``[-OBS_LIMIT, OBS_LIMIT]`` (the observation space).
OBS_LIMIT = 10.0


@njit(cache=True)
def observation(
    rows: NDArray[np.int64],
    arms: KernelArms,
    section_length: float,
    samples: int,
    theta_max: float,
    clear_scale: float,
    out: NDArray[np.float32],
) -> None:
    """The goal-free part of the observation vectors of ``rows`` into ``out``'s rows, in place.

    Columns ``0 .. 35 + 3N`` (:meth:`FTLBatch.observation`) from the refreshed ``arms``; the
    guide's columns after them are filled by the caller.
    """
    kappa, k, s, theta, phi = arms.kappa, arms.k, arms.s, arms.theta, arms.phi
    points, heading = arms.points, arms.heading
    body_clearance, ray_clearance = arms.body_clearance, arms.ray_clearance
    n = theta.shape[1]
    s_max = n * section_length
    tip = points.shape[1] - 1
    for r in range(rows.shape[0]):
        b = rows[r]
        o = out[r]
        o[0] = (s[b] - s_max) / s_max
        o[1] = k[b] / n
        o[2] = kappa[b, k[b], 0] / theta_max
        o[3] = kappa[b, k[b], 1] / theta_max
        c = 4
        for j in range(n):
            o[c + j] = theta[b, j] / theta_max
            o[c + n + j] = math.sin(phi[b, j])
            o[c + 2 * n + j] = math.cos(phi[b, j])
        c += 3 * n
        for i in range(3):
            o[c + i] = points[b, tip, i] / 100.0
            o[c + 3 + i] = heading[b, i]
        c += 6
        o[c] = min(max(body_clearance[b] / 10.0, -1.0), 1.0)
        c += 1
        for r in range(ray_clearance.shape[1]):
            o[c + r] = min(max(ray_clearance[b, r] / clear_scale, -1.0), 1.0)
        c += ray_clearance.shape[1]
        for i in range(3):  # heights of the last three section ends (the base's below them)
            o[c + i] = points[b, max(n - 2 + i, 0) * samples, 2] / 100.0
        for i in range(c + 3):
            o[i] = min(max(o[i], -OBS_LIMIT), OBS_LIMIT)


@njit(cache=True)
def goal_reward(
    a: NDArray[np.float64],
    g: NDArray[np.float64],
    prev: NDArray[np.float64],
    contact: NDArray[np.bool_],
    success_tolerance: float,
    step_cost: float,
    reward: NDArray[np.float64],
    distance: NDArray[np.float64],
) -> None:
    """Rewards without the shaping term and tip-to-target distances, in place.

    ``PROGRESS_PER_CM·(|prev − g| − |a − g|)``, ``+SUCCESS_REWARD`` within ``success_tolerance``
    without contact, ``−CONTACT_PENALTY`` on contact, ``−step_cost``.
    """
    for r in range(a.shape[0]):
        dx, dy, dz = a[r, 0] - g[r, 0], a[r, 1] - g[r, 1], a[r, 2] - g[r, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        px, py, pz = prev[r, 0] - g[r, 0], prev[r, 1] - g[r, 1], prev[r, 2] - g[r, 2]
        value = PROGRESS_PER_CM * (math.sqrt(px * px + py * py + pz * pz) - d)
        if contact[r]:
            value -= CONTACT_PENALTY
        elif d < success_tolerance:
            value += SUCCESS_REWARD
        reward[r] = value - step_cost
        distance[r] = d


@njit(cache=True)
def guide_columns(
    frames: NDArray[np.float64],
    to_go: NDArray[np.float64],
    way: NDArray[np.float64],
    target: NDArray[np.float64],
    tip: NDArray[np.float64],
    heading: NDArray[np.float64],
    ahead: NDArray[np.float64],
    out: NDArray[np.float32],
    start: int,
) -> None:
    """The guide's columns of the observation from column ``start``, in place.

    ``min(to_go, 1000)/100``, then in the steering frame (``Fᵀ v``): the way, ``(target −
    tip)/100``, the heading and the unit directions to the ``ahead`` points ``(B, H, 3)``.
    """
    for b in range(to_go.shape[0]):
        o = out[b]
        f = frames[b]
        o[start] = min(to_go[b], 1000.0) / 100.0
        c = start + 1
        for v in range(3 + ahead.shape[1]):
            if v == 0:
                x, y, z = way[b, 0], way[b, 1], way[b, 2]
            elif v == 1:
                x = (target[b, 0] - tip[b, 0]) / 100.0
                y = (target[b, 1] - tip[b, 1]) / 100.0
                z = (target[b, 2] - tip[b, 2]) / 100.0
            elif v == 2:
                x, y, z = heading[b, 0], heading[b, 1], heading[b, 2]
            else:
                h = v - 3
                x = ahead[b, h, 0] - tip[b, 0]
                y = ahead[b, h, 1] - tip[b, 1]
                z = ahead[b, h, 2] - tip[b, 2]
                norm = max(math.sqrt(x * x + y * y + z * z), 1e-9)
                x, y, z = x / norm, y / norm, z / norm
            for i in range(3):
                o[c + i] = min(max(f[0, i] * x + f[1, i] * y + f[2, i] * z, -OBS_LIMIT), OBS_LIMIT)
            c += 3
