"""Forward kinematics of the FTL arms, their steering frames and one step of shift-and-copy."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from aftir_rl.core.robot import SMALL

__all__ = ["rotate", "fk_row", "fk_points", "steering_frames", "advance"]


@njit(cache=True)
def rotate(r: NDArray[np.float64], theta: float, cp: float, sp: float) -> None:
    """``r ← r @ E``, ``E`` the rotation of an arc bent by ``θ`` in the plane at ``φ``."""
    ct, st = math.cos(theta), math.sin(theta)
    off = cp * sp * (ct - 1.0)
    e00, e01, e02 = cp * cp * ct + sp * sp, off, cp * st
    e10, e11, e12 = off, sp * sp * ct + cp * cp, sp * st
    e20, e21, e22 = -cp * st, -sp * st, ct
    for i in range(3):
        a, b, c = r[i, 0], r[i, 1], r[i, 2]
        r[i, 0] = a * e00 + b * e10 + c * e20
        r[i, 1] = a * e01 + b * e11 + c * e21
        r[i, 2] = a * e02 + b * e12 + c * e22


@njit(cache=True)
def fk_row(
    dis: float,
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: int,
    rot: NDArray[np.float64],
    points: NDArray[np.float64],
) -> None:
    """:func:`~aftir_rl.core.robot.body_points` of one posture into ``points (N·K + 1, 3)``.

    ``rot (3, 3)`` is scratch space.
    """
    l = section_length
    points[0, 0], points[0, 1], points[0, 2] = 0.0, 0.0, dis
    ox, oy, oz = 0.0, 0.0, dis
    rot[:] = 0.0
    rot[0, 0], rot[1, 1], rot[2, 2] = 1.0, 1.0, 1.0
    for i in range(theta.shape[0]):
        th, cp, sp = theta[i], math.cos(phi[i]), math.sin(phi[i])
        # sample j bends by h_j = j·h₁ (half its angle): sin, cos by the addition formulas
        h1 = 0.5 * th / samples
        s1, c1 = math.sin(h1), math.cos(h1)
        sj, cj = 0.0, 1.0
        for j in range(1, samples + 1):
            sj, cj = sj * c1 + cj * s1, cj * c1 - sj * s1
            h = h1 * j
            sinc_h = 1.0 - h * h / 6.0 if abs(h) < 0.5 * SMALL else sj / h
            arc = l * (j / samples)
            radial = arc * (h * sinc_h * sinc_h)
            lx, ly, lz = radial * cp, radial * sp, arc * (sinc_h * cj)
            row = 1 + i * samples + j - 1
            points[row, 0] = rot[0, 0] * lx + rot[0, 1] * ly + rot[0, 2] * lz + ox
            points[row, 1] = rot[1, 0] * lx + rot[1, 1] * ly + rot[1, 2] * lz + oy
            points[row, 2] = rot[2, 0] * lx + rot[2, 1] * ly + rot[2, 2] * lz + oz
        end = i * samples + samples
        ox, oy, oz = points[end, 0], points[end, 1], points[end, 2]
        rotate(rot, th, cp, sp)


@njit(cache=True)
def fk_points(
    dis: NDArray[np.float64],
    theta: NDArray[np.float64],
    phi: NDArray[np.float64],
    section_length: float,
    samples: int,
    points: NDArray[np.float64],
) -> None:
    """:func:`~aftir_rl.core.robot.body_points` of many postures, into ``points (B, N·K + 1, 3)``.

    ``dis (B,)``, ``theta`` and ``phi`` ``(B, N)``.
    """
    rot = np.empty((3, 3))
    for b in range(theta.shape[0]):
        fk_row(dis[b], theta[b], phi[b], section_length, samples, rot, points[b])


@njit(cache=True)
def steering_frames(
    kappa: NDArray[np.float64], k: NDArray[np.int64], out: NDArray[np.float64]
) -> None:
    """Rotations ``(B, 3, 3)`` of the frames the steered sections bend in, in place.

    The product of the end rotations of the route's frozen sections ``0..k−1`` (arc length
    irrelevant: a rotation depends on ``θ, φ`` only).
    """
    for b in range(kappa.shape[0]):
        r = out[b]
        r[:] = 0.0
        r[0, 0], r[1, 1], r[2, 2] = 1.0, 1.0, 1.0
        for j in range(k[b]):
            th = math.hypot(kappa[b, j, 0], kappa[b, j, 1])
            ph = math.atan2(kappa[b, j, 1], kappa[b, j, 0]) if th > 1e-12 else 0.0
            rotate(r, th, math.cos(ph), math.sin(ph))


@njit(cache=True)
def advance(
    action: NDArray[np.float64],
    kappa: NDArray[np.float64],
    k: NDArray[np.int64],
    s: NDArray[np.float64],
    steer_target: bool,
    kappa_step: float,
    push_step: float,
    theta_max: float,
    section_length: float,
) -> None:
    """Steer and push every arm by its action ``(B, 3)`` in ``[-1, 1]``, in place.

    The steered ``κ`` (the route's last) changes by ``action[:2]·kappa_step`` or, with
    ``steer_target``, approaches ``action[:2]·θ_max`` by at most ``kappa_step`` per component,
    its norm kept within ``θ_max``; the tip's arc length ``s`` changes by
    ``action[2]·push_step`` within ``[0, N·l]``. A tip that enters a new section starts it with
    the steered ``κ`` (``push_step ≤ l``: at most one per step).
    """
    n = kappa.shape[1]
    s_max = n * section_length
    for b in range(kappa.shape[0]):
        kb = k[b]
        l0, l1 = kappa[b, kb, 0], kappa[b, kb, 1]
        if steer_target:
            w0, w1 = action[b, 0] * theta_max, action[b, 1] * theta_max
            norm = math.hypot(w0, w1)
            if norm > theta_max:
                scale = theta_max / max(norm, 1e-12)
                w0, w1 = w0 * scale, w1 * scale
            q0 = l0 + min(max(w0 - l0, -kappa_step), kappa_step)
            q1 = l1 + min(max(w1 - l1, -kappa_step), kappa_step)
        else:
            q0, q1 = l0 + action[b, 0] * kappa_step, l1 + action[b, 1] * kappa_step
            norm = math.hypot(q0, q1)
            if norm > theta_max:
                scale = theta_max / max(norm, 1e-12)
                q0, q1 = q0 * scale, q1 * scale
        kappa[b, kb, 0], kappa[b, kb, 1] = q0, q1
        s[b] = min(max(s[b] + action[b, 2] * push_step, 0.0), s_max)
        new_k = min(int(math.floor(s[b] / section_length)), n - 1)
        if new_k > kb:
            kappa[b, new_k, 0], kappa[b, new_k, 1] = q0, q1
        k[b] = new_k
