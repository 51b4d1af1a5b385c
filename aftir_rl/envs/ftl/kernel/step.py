"""The compiled step of the arms' state: steer the leading section, push (one loop per arm)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["advance"]


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
