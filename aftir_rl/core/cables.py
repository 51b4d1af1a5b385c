"""Cable space: the length changes of the three cables that bend each section.

Constant curvature with cables routed through the proximal sections (Jones & Walker, IEEE T-RO
2006; Webster & Jones, IJRR 2010, §3): a cable at distance ``r`` from the backbone and angle ``β``
round it shortens by ``r·θ·cos(φ − β)`` in a section bent by ``θ`` in the plane ``φ``. The
section frames do not twist (docs/design.md §2), so a cable keeps its angle along the arm, and
section ``i``'s cables, which end at its tip, pass through sections ``1..i``:
``ΔL_ij = −r Σ_{k≤i} κ_k · (cos β_ij, sin β_ij)``, linear in the bending vectors ``κ``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.robot import angles_to_kappa, kappa_to_angles

__all__ = ["cable_angles", "cable_lengths", "cable_matrix", "cable_names", "cables_to_angles"]


def cable_angles(n_sections: int, limits: ActuatorLimits) -> NDArray[np.float64]:
    """Angles ``β (N, 3)`` [rad] of each section's cables: 120° apart, turned by the stagger."""
    sections, cables = np.arange(n_sections)[:, None], np.arange(3)[None, :]
    return 2 * np.pi * cables / 3 + sections * limits.cable_stagger


def cable_names(n_sections: int) -> list[str]:
    """``section_<i>_cable_<j>`` (1-based sections, cables 0-2), in :func:`cable_lengths` order."""
    return [f"section_{i + 1}_cable_{j}" for i in range(n_sections) for j in range(3)]


def cable_matrix(n_sections: int, limits: ActuatorLimits) -> NDArray[np.float64]:
    """The linear map ``(3N, 2N)`` from the bending vectors (flattened) to the cable changes."""
    beta = cable_angles(n_sections, limits)
    units = np.stack([np.cos(beta), np.sin(beta)], axis=-1)  # (N, 3, 2)
    out = np.zeros((n_sections, 3, n_sections, 2))
    for i in range(n_sections):
        out[i, :, : i + 1, :] = -limits.cable_offset * units[i][:, None, :]
    return out.reshape(3 * n_sections, 2 * n_sections)


def cable_lengths(theta: ArrayLike, phi: ArrayLike, limits: ActuatorLimits) -> NDArray[np.float64]:
    """Cable length changes ``(..., N, 3)`` [cm] from the straight arm, of ``θ, φ (..., N)``."""
    kappa = np.cumsum(angles_to_kappa(theta, phi), axis=-2)  # through the proximal sections
    beta = cable_angles(kappa.shape[-2], limits)
    along = kappa[..., 0:1] * np.cos(beta) + kappa[..., 1:2] * np.sin(beta)
    return -limits.cable_offset * along


def cables_to_angles(
    changes: ArrayLike, limits: ActuatorLimits
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``θ, φ (..., N)`` of cable changes ``(..., N, 3)``: the inverse of :func:`cable_lengths`.

    Section by section from the base: the proximal sections' share is taken off each cable, and
    the rest gives the section's ``κ`` (three unit vectors 120° apart sum ``u uᵀ`` to ``3/2·I``).
    """
    dl = np.asarray(changes, dtype=np.float64)
    beta = cable_angles(dl.shape[-2], limits)
    cos, sin, r = np.cos(beta), np.sin(beta), limits.cable_offset
    kappa = np.empty(dl.shape[:-1] + (2,))
    proximal = np.zeros(dl.shape[:-2] + (2,))
    for i in range(dl.shape[-2]):
        own = dl[..., i, :] + r * (proximal[..., 0:1] * cos[i] + proximal[..., 1:2] * sin[i])
        kappa[..., i, 0] = -2.0 / (3.0 * r) * (own * cos[i]).sum(axis=-1)
        kappa[..., i, 1] = -2.0 / (3.0 * r) * (own * sin[i]).sum(axis=-1)
        proximal = proximal + kappa[..., i, :]
    return kappa_to_angles(kappa)
