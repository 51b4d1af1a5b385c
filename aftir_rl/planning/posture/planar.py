"""The arm reduced to its bending plane (dimension reduction, jace §IV.A).

With every ``φ_i`` equal to the bearing ``ψ`` of the target, the arm lies in the vertical plane
through the ``z`` axis and the target; headings add up, and a point of the arm is ``(ρ, z)`` in that
plane (``x = ρ cos ψ``, ``y = ρ sin ψ``). A section starting at heading ``a`` (angle from ``+z``
towards ``+ρ``) and bending by ``b`` over arc ``s`` moves by
``s · sinc(b/2) · (sin(a + b/2), cos(a + b/2))`` with ``sinc(x) = sin x / x``: exact, and smooth
through ``b = 0``. This is the same chain as :mod:`aftir_rl.core.robot` with equal ``φ`` and is
checked against it in the tests; it is only cheaper (2D, no matrices), which matters when the search
evaluates 10⁴–10⁶ postures per loop.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.kernel.planar import planar_tips, planar_tips_serial

__all__ = ["planar_points", "planar_tip", "distance_sum", "to_frame"]


def _half_sinc(b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``sin(b/2) / (b/2)``, its series below ``|b| = 1e-4``."""
    small = np.abs(b) < 1e-4
    half = np.where(small, 1.0, b / 2)
    return np.where(small, 1.0 - b * b / 24, np.sin(half) / half)


def planar_points(
    theta: NDArray[np.float64], section_length: float, points_per_section: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Backbone points of planar arms with base at the origin (``dis = 0``).

    Args:
        theta: bending angles [rad], shape ``(B, N)``.
        section_length: ``l`` [cm].
        points_per_section: K.

    Returns:
        ``(ρ, z)``, each of shape ``(B, N·K + 1)``: the base, then K points per section.

    """
    theta = np.asarray(theta, dtype=np.float64)
    b, n = theta.shape
    k = points_per_section
    frac = np.arange(1, k + 1) / k
    heading = np.concatenate([np.zeros((b, 1)), np.cumsum(theta, axis=1)[:, :-1]], axis=1)
    bend = theta[:, :, None] * frac  # (B, N, K)
    step = section_length * frac * _half_sinc(bend)
    mid = heading[:, :, None] + bend / 2
    d_rho, d_z = step * np.sin(mid), step * np.cos(mid)
    # Section ends: cumulative sums of the full-section displacements.
    end_rho = np.concatenate([np.zeros((b, 1)), np.cumsum(d_rho[:, :, -1], axis=1)[:, :-1]], axis=1)
    end_z = np.concatenate([np.zeros((b, 1)), np.cumsum(d_z[:, :, -1], axis=1)[:, :-1]], axis=1)
    rho = (end_rho[:, :, None] + d_rho).reshape(b, n * k)
    z = (end_z[:, :, None] + d_z).reshape(b, n * k)
    zero = np.zeros((b, 1))
    return np.concatenate([zero, rho], axis=1), np.concatenate([zero, z], axis=1)


def planar_tip(
    theta: NDArray[np.float64], section_length: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tip ``(ρ, z)`` of planar arms with base at the origin, each of shape ``(B,)``.

    Compiled (:func:`aftir_rl.core.kernel.planar.planar_tips`).
    """
    theta = np.ascontiguousarray(theta, dtype=np.float64)
    rho, z = np.empty(len(theta)), np.empty(len(theta))
    (planar_tips if len(theta) > 256 else planar_tips_serial)(theta, float(section_length), rho, z)
    return rho, z


def _length(components: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Euclidean length of vectors given by their components: ``hypot`` in the plane."""
    if len(components) == 2:
        return np.hypot(*components)
    return np.sqrt(sum(c * c for c in components))


def distance_sum(
    coords: Sequence[NDArray[np.float64]], end: Sequence[float]
) -> NDArray[np.float64]:
    """MDS: the sum over points of their distance to the segment from the origin to ``end``.

    Args:
        coords: the points' coordinates, one array ``(..., P)`` per axis (``(ρ, z)`` in the
            plane, ``(x, y, z)`` in space).
        end: the segment's end, one number per axis.

    Returns:
        The sums over the last axis, shape ``(...)``.

    """
    length2 = sum(e * e for e in end)
    if length2 == 0:
        return _length(coords).sum(axis=-1)
    dot = functools.reduce(operator.add, (c * e for c, e in zip(coords, end)))
    t = np.clip(dot / length2, 0.0, 1.0)
    return _length([c - t * e for c, e in zip(coords, end)]).sum(axis=-1)


def to_frame(
    rho: NDArray[np.float64],
    z: NDArray[np.float64],
    psi: float,
    rotation: NDArray[np.float64] | None = None,
    origin: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Plane points to 3D: in the local frame ``(ρ cos ψ, ρ sin ψ, z)``, then ``R p + o``."""
    local = np.stack([rho * np.cos(psi), rho * np.sin(psi), z], axis=-1)
    if rotation is None:
        return local
    return local @ np.asarray(rotation).T + np.asarray(origin)
