"""The AFTIR arm: specification, posture and batched forward kinematics.

The arm is a linear module that pushes a chain of ``N`` constant-curvature sections of equal length
``l`` through the access panel. A configuration is ``q = (dis, θ_1, φ_1, …, θ_N, φ_N)``: ``dis``
[cm] is the module's travel along the panel normal, ``θ_i`` [rad] the bending angle and ``φ_i``
[rad] the bending-plane angle of section ``i``. Frame S has its origin at the centre of the access
panel, ``z`` into the tank; the base of section 1 sits at ``(0, 0, dis)`` pointing ``+z``. Each
section transform is jace eq. 7 in the end frame of the previous section, chained
``T = T_1 · T_2 ⋯ T_N``, smooth through the straight arm (Taylor series below ``|θ| = 1e-4``).

Everything is batched: angles of shape ``(..., N)`` give results of shape ``(..., ·, 3)`` with no
Python loop over the batch. The frame, the transform and its numerics: docs/design.md §2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.camera import Camera
from aftir_rl.core.rod import RodProperties

__all__ = [
    "ArmSpec",
    "Posture",
    "section_transforms",
    "forward_kinematics",
    "body_points",
    "tip_position",
    "finite_differences",
    "tip_jacobian",
    "kappa_to_angles",
    "angles_to_kappa",
]

SMALL = 1e-4


@dataclass(frozen=True)
class ArmSpec:
    """Physical parameters of the arm.

    Attributes:
        section_length: length ``l`` of every section [cm].
        max_sections: the most sections the arm has.
        radius: body radius used for collision checking [cm].
        theta_max: bound on ``|θ_i|`` [rad].
        limits: the actuators' speed, acceleration and travel limits.
        camera: the tip camera (what an inspection sees).
        rod: the body's mass and stiffnesses (the physics check's Cosserat rod).

    """

    section_length: float = 50.0
    max_sections: int = 12
    radius: float = 2.5
    theta_max: float = math.pi / 2
    limits: ActuatorLimits = ActuatorLimits()
    camera: Camera = Camera()
    rod: RodProperties = RodProperties()

    def __post_init__(self) -> None:
        if not self.section_length > 0:
            raise ValueError(f"section_length must be positive, got {self.section_length}")
        if self.max_sections < 1:
            raise ValueError(f"max_sections must be at least 1, got {self.max_sections}")
        if self.radius < 0:
            raise ValueError(f"radius must not be negative, got {self.radius}")
        if not 0 < self.theta_max <= math.pi:
            raise ValueError(f"theta_max must be in (0, pi], got {self.theta_max}")


@dataclass(frozen=True)
class Posture:
    """One configuration of the arm.

    Attributes:
        dis: linear module travel along the panel normal [cm], may be negative.
        theta: bending angle of each section [rad].
        phi: bending-plane (rotation) angle of each section [rad].

    """

    dis: float
    theta: tuple[float, ...]
    phi: tuple[float, ...]

    def __init__(self, dis: float, theta: Iterable[float], phi: Iterable[float]) -> None:
        # Written out (the dataclass keeps it) to say what it accepts: any numbers and iterables
        # of numbers (arrays, lists), stored as a float and tuples of floats.
        object.__setattr__(self, "dis", float(dis))
        object.__setattr__(self, "theta", tuple(float(t) for t in theta))
        object.__setattr__(self, "phi", tuple(float(p) for p in phi))
        if len(self.theta) != len(self.phi):
            raise ValueError(
                f"theta and phi must have one value per section, got {len(self.theta)} and "
                f"{len(self.phi)}"
            )

    def to_vector(self) -> NDArray[np.float64]:
        """The joint vector ``(dis, θ_1..θ_N, φ_1..φ_N)``."""
        return np.concatenate([[self.dis], self.theta, self.phi])

    def to_dict(self) -> dict[str, float | list[float]]:
        """``{"dis", "theta", "phi"}`` for JSON; ``Posture(**d)`` reads it back."""
        return {"dis": self.dis, "theta": list(self.theta), "phi": list(self.phi)}

    @classmethod
    def from_vector(cls, x: ArrayLike) -> Posture:
        """The posture of a joint vector ``(dis, θ_1..θ_N, φ_1..φ_N)``."""
        x = np.asarray(x, dtype=np.float64)
        n = (len(x) - 1) // 2
        if len(x) != 1 + 2 * n:
            raise ValueError(f"a joint vector has 1 + 2N values, got {len(x)}")
        return cls(x[0], x[1 : n + 1], x[n + 1 :])

    @property
    def n_sections(self) -> int:
        """Number of sections ``N``."""
        return len(self.theta)

    def tip(self, section_length: float) -> NDArray[np.float64]:
        """Tip position [cm] by forward kinematics."""
        return tip_position(self.dis, self.theta, self.phi, section_length)

    def points(self, section_length: float, points_per_section: int = 8) -> NDArray[np.float64]:
        """Body points [cm], shape ``(N·K + 1, 3)``: the base, then K points per section."""
        return body_points(self.dis, self.theta, self.phi, section_length, points_per_section)


def _bend_terms(theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return ``(1 − cos θ)/θ`` and ``sin θ/θ``, smooth through ``θ = 0``.

    With ``h = θ/2``: ``(1 − cos θ)/θ = h·(sin h / h)²`` and ``sin θ/θ = (sin h / h)·cos h``.
    """
    h = 0.5 * np.asarray(theta, dtype=np.float64)
    small = np.abs(h) < 0.5 * SMALL
    sinc_h = np.where(small, 1.0 - h * h / 6.0, np.sin(h) / np.where(small, 1.0, h))
    return h * sinc_h * sinc_h, sinc_h * np.cos(h)


def section_transforms(theta: ArrayLike, phi: ArrayLike, arc: ArrayLike) -> NDArray[np.float64]:
    """Homogeneous transforms of constant-curvature arcs (jace eq. 7).

    Args:
        theta: bending angle over the arc [rad], any shape.
        phi: bending-plane angle [rad], broadcastable with ``theta``.
        arc: arc length [cm], broadcastable with ``theta``.

    Returns:
        Array of shape ``broadcast(theta, phi, arc).shape + (4, 4)``.

    """
    theta, phi, arc = np.broadcast_arrays(
        np.asarray(theta, dtype=np.float64),
        np.asarray(phi, dtype=np.float64),
        np.asarray(arc, dtype=np.float64),
    )
    cp, sp = np.cos(phi), np.sin(phi)
    one_minus_cos, sinc = _bend_terms(theta)
    radial = arc * one_minus_cos
    out = np.zeros(theta.shape + (4, 4))
    out[..., :3, :3] = _bend_rotations(theta, cp, sp)
    out[..., 0, 3] = radial * cp
    out[..., 1, 3] = radial * sp
    out[..., 2, 3] = arc * sinc
    out[..., 3, 3] = 1.0
    return out


def _bend_rotations(
    theta: NDArray[np.float64], cp: NDArray[np.float64], sp: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Rotations ``(..., 3, 3)`` of arcs bent by ``θ`` in the plane at ``φ`` (given as cos, sin)."""
    ct, st = np.cos(theta), np.sin(theta)
    off = cp * sp * (ct - 1.0)
    rows = (
        cp * cp * ct + sp * sp,
        off,
        cp * st,
        off,
        sp * sp * ct + cp * cp,
        sp * st,
        -cp * st,
        -sp * st,
        ct,
    )
    return np.stack(rows, axis=-1).reshape(theta.shape + (3, 3))


def _as_batch(
    dis: ArrayLike, theta: ArrayLike, phi: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    if theta.ndim == 0 or theta.shape != phi.shape:
        raise ValueError(
            f"theta and phi must have the same shape (..., N), got {theta.shape} and {phi.shape}"
        )
    dis = np.broadcast_to(np.asarray(dis, dtype=np.float64), theta.shape[:-1])
    return dis, theta, phi


def forward_kinematics(
    dis: ArrayLike, theta: ArrayLike, phi: ArrayLike, section_length: float
) -> NDArray[np.float64]:
    """Frames along the arm.

    Args:
        dis: module travel [cm], shape ``(...)`` or scalar.
        theta: bending angles [rad], shape ``(..., N)``.
        phi: bending-plane angles [rad], shape ``(..., N)``.
        section_length: ``l`` [cm].

    Returns:
        Shape ``(..., N + 1, 4, 4)``: frame 0 is the base of section 1 at ``(0, 0, dis)``, frame
        ``i`` the end of section ``i`` in frame S.

    """
    dis, theta, phi = _as_batch(dis, theta, phi)
    return _chain(dis, section_transforms(theta, phi, section_length))


def _chain(dis: NDArray[np.float64], local: NDArray[np.float64]) -> NDArray[np.float64]:
    """Frames ``(..., N + 1, 4, 4)`` from the base at ``(0, 0, dis)`` and section transforms."""
    n = local.shape[-3]
    frames = np.empty(local.shape[:-3] + (n + 1, 4, 4))
    base = np.broadcast_to(np.eye(4), local.shape[:-3] + (4, 4)).copy()
    base[..., 2, 3] = dis
    frames[..., 0, :, :] = base
    for i in range(n):
        frames[..., i + 1, :, :] = frames[..., i, :, :] @ local[..., i, :, :]
    return frames


def body_points(
    dis: ArrayLike,
    theta: ArrayLike,
    phi: ArrayLike,
    section_length: float,
    points_per_section: int = 8,
) -> NDArray[np.float64]:
    """Points along the arm's backbone [cm].

    Args:
        dis: module travel [cm] (as :func:`forward_kinematics` takes it, as are the next three).
        theta: bending angles [rad].
        phi: bending-plane angles [rad].
        section_length: ``l`` [cm].
        points_per_section: K, the points per section at arc lengths ``l·j/K``, ``j = 1..K``.

    Returns:
        Shape ``(..., N·K + 1, 3)``: the base point, then K points per section, ending at the tip.

    """
    if points_per_section < 1:
        raise ValueError(f"points_per_section must be at least 1, got {points_per_section}")
    dis, theta, phi = _as_batch(dis, theta, phi)
    k, n, lead = points_per_section, theta.shape[-1], theta.shape[:-1]
    frac = np.arange(1, k + 1, dtype=np.float64) / k
    arc = section_length * frac
    # Sample positions in their section's base frame, (..., N, 3, K): the arc of bend θ·j/K.
    one_minus_cos, sinc = _bend_terms(theta[..., None] * frac)
    cp, sp = np.cos(phi), np.sin(phi)
    local = np.empty(lead + (n, 3, k))
    local[..., 0, :] = arc * one_minus_cos * cp[..., None]
    local[..., 1, :] = arc * one_minus_cos * sp[..., None]
    local[..., 2, :] = arc * sinc
    # Base rotation of every section: the product of the rotations of the sections before it.
    end_rot = _bend_rotations(theta, cp, sp)
    base_rot = np.empty(lead + (n, 3, 3))
    rot = np.broadcast_to(np.eye(3), lead + (3, 3))
    for i in range(n):
        base_rot[..., i, :, :] = rot
        rot = rot @ end_rot[..., i, :, :]
    world = base_rot @ local  # offsets from each section's base, (..., N, 3, K)
    ends = world[..., :, -1]
    origin = np.cumsum(ends, axis=-2) - ends  # section bases relative to the arm's base
    origin[..., 2] += dis[..., None]
    world += origin[..., None]
    base = np.zeros(lead + (1, 3))
    base[..., 0, 2] = dis
    return np.concatenate([base, world.swapaxes(-1, -2).reshape(lead + (-1, 3))], axis=-2)


def tip_position(
    dis: ArrayLike, theta: ArrayLike, phi: ArrayLike, section_length: float
) -> NDArray[np.float64]:
    """Tip position [cm], shape ``(..., 3)``."""
    return forward_kinematics(dis, theta, phi, section_length)[..., -1, :3, 3]


def finite_differences(
    fn: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    x: ArrayLike,
    h: float,
    central: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``fn(x)`` and its Jacobian by finite differences, batched.

    Args:
        fn: maps parameters ``(..., R, P)`` to values ``(..., R, K)``, row by row.
        x: the parameters, shape ``(..., P)``.
        h: the step.
        central: central differences (``2P + 1`` rows evaluated), else forward (``P + 1``).

    Returns:
        ``fn(x)`` of shape ``(..., K)`` and the Jacobian ``(..., K, P)`` (a transposed view).

    """
    x = np.asarray(x, dtype=np.float64)
    p = x.shape[-1]
    step = np.eye(p) * h
    rows = [x[..., None, :], x[..., None, :] + step]
    if central:
        rows.append(x[..., None, :] - step)
    values = fn(np.concatenate(rows, axis=-2))
    if central:
        diff = (values[..., 1 : p + 1, :] - values[..., p + 1 :, :]) / (2 * h)
    else:
        diff = (values[..., 1:, :] - values[..., :1, :]) / h
    return values[..., 0, :], np.swapaxes(diff, -1, -2)


def _joint_vector(x: NDArray[np.float64]) -> tuple[ArrayLike, ArrayLike, ArrayLike]:
    n = (x.shape[-1] - 1) // 2
    return x[..., 0], x[..., 1 : n + 1], x[..., n + 1 :]


def tip_jacobian(
    x: ArrayLike,
    section_length: float,
    h: float = 1e-6,
    central: bool = True,
    joints: Callable[[NDArray[np.float64]], tuple[ArrayLike, ArrayLike, ArrayLike]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The tip [cm] and its Jacobian by finite differences of :func:`tip_position`.

    Args:
        x: the joint vector ``(dis, θ_1..θ_N, φ_1..φ_N)``, or other parameters with ``joints``;
            shape ``(..., P)``.
        section_length: ``l`` [cm].
        h: the step.
        central: central differences, else forward.
        joints: maps parameters ``(..., R, P)`` to ``(dis, θ, φ)`` (default: the joint vector).

    Returns:
        The tip ``(..., 3)`` and the Jacobian ``(..., 3, P)``.

    """
    split = _joint_vector if joints is None else joints

    def tips(p: NDArray[np.float64]) -> NDArray[np.float64]:
        dis, theta, phi = split(p)
        return tip_position(dis, theta, phi, section_length)

    return finite_differences(tips, x, h, central)


def kappa_to_angles(kappa: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(θ, φ)`` of bending vectors ``κ`` (..., 2); ``θ ≥ 0``, ``φ = 0`` where straight."""
    k = np.asarray(kappa, dtype=np.float64)
    theta = np.hypot(k[..., 0], k[..., 1])
    phi = np.where(theta > 1e-12, np.arctan2(k[..., 1], k[..., 0]), 0.0)
    return theta, phi


def angles_to_kappa(theta: ArrayLike, phi: ArrayLike) -> NDArray[np.float64]:
    """Bending vectors ``κ = (θ cos φ, θ sin φ)`` (..., 2) of angles ``θ, φ`` (...)."""
    theta, phi = np.asarray(theta, dtype=np.float64), np.asarray(phi, dtype=np.float64)
    return np.stack([theta * np.cos(phi), theta * np.sin(phi)], axis=-1)
