"""Follow-the-leader (FTL) deployment of the arm on its linear module.

The AFTIR group's path tracking ("shift-and-copy", Niu et al.): only the leading section is
steered; when the module has pushed one section length, every section takes the joint values of
the section ahead of it. At these *stages* the body lies exactly on the curve the tip has traced.

A :class:`Route` is that curve: a straight ``lead`` [cm] up the panel's axis, then ``M``
constant-curvature route sections of length ``l``, section ``j`` bending by the vector
``κ_j = (θ_j cos φ_j, θ_j sin φ_j)`` [rad] in its base frame (docs/design.md §2). Between stages
arm sections interpolate neighbouring ``κ`` (refined by a least-squares fit in
:func:`ftl_motion`), which exact FTL cannot do for most curves; :func:`ftl_deviation` measures
the body's distance from the curve the tip traced. The formulas: docs/design.md §7.3.

Everything is in cm and radians; arrays are batched over motion entries.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.kernel.deployment import fit_shape, traced_deviation
from aftir_rl.core.kernel.geometry import fk_points
from aftir_rl.core.robot import (
    Posture,
    body_points,
    forward_kinematics,
    kappa_to_angles,
    section_transforms,
)

__all__ = [
    "Route",
    "FTLMotion",
    "kappa_to_angles",
    "clip_kappa",
    "ftl_postures",
    "ftl_motion",
    "ftl_deviation",
    "backbone_moves",
]

#: Backbone samples per section for the density and deviation checks (2.5 cm apart at l = 50).
SAMPLES_PER_SECTION = 20


@dataclass(frozen=True)
class Route:
    """The tip's route: a straight ``lead`` above the floor, then constant-curvature sections.

    Attributes:
        lead: straight travel up the panel's axis before the first bend [cm], measured from the
            floor; negative where the first bend starts inside the panel's guide.
        kappa: bending vector of each route section, shape ``(M, 2)`` [rad].
        section_length: ``l`` [cm].

    """

    lead: float
    kappa: NDArray[np.float64]
    section_length: float

    def __post_init__(self) -> None:
        k = np.asarray(self.kappa, dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "kappa", k)
        object.__setattr__(self, "lead", float(self.lead))

    @property
    def n_route_sections(self) -> int:
        """``M``, the bent route sections."""
        return int(self.kappa.shape[0])

    @property
    def length(self) -> float:
        """Arc length of the route above the floor [cm]."""
        return self.lead + self.n_route_sections * self.section_length

    def min_sections(self) -> int:
        """The fewest arm sections that deploy this route with the base below the floor."""
        return self.n_route_sections + math.ceil(self.lead / self.section_length - 1e-9)

    def final_posture(self, n_sections: int) -> Posture:
        """The arm's posture at the end of the deployment (tip at the route's end)."""
        dis, theta, phi = ftl_postures(self, n_sections, [self.length])
        return Posture(dis[0], theta[0], phi[0])

    def tip(self) -> NDArray[np.float64]:
        """The route's end point [cm]."""
        theta, phi = kappa_to_angles(self.kappa)
        return forward_kinematics(self.lead, theta, phi, self.section_length)[-1, :3, 3]


def ftl_postures(
    route: Route, n_sections: int, s: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Postures ``(dis (T,), θ (T, N), φ (T, N))`` with the tip at arc lengths ``s`` (T,) [cm]."""
    l, m, n = route.section_length, route.n_route_sections, int(n_sections)
    if n < route.min_sections():
        raise ValueError(f"the route needs at least {route.min_sections()} sections, got {n}")
    s = np.atleast_1d(np.asarray(s, dtype=np.float64))
    u = np.clip((s - route.lead) / l, 0.0, float(m))
    k = np.minimum(np.floor(u).astype(np.int64), m)
    f = u - k
    pad = np.concatenate(
        [np.zeros((n, 2)), route.kappa, route.kappa[-1:] if m else np.zeros((1, 2))]
    )
    idx = k[:, None] + np.arange(n)[None, :]
    kap = (1.0 - f)[:, None, None] * pad[idx] + f[:, None, None] * pad[idx + 1]
    theta, phi = kappa_to_angles(kap)
    return s - n * l, theta, phi


def backbone_moves(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Largest displacement of any backbone sample between consecutive entries ``(T - 1,)``."""
    return np.linalg.norm(np.diff(points, axis=0), axis=-1).max(axis=-1)


@dataclass(frozen=True)
class FTLMotion:
    """A dense FTL motion: entry ``t`` is the posture with the tip at arc length ``s[t]``.

    Attributes:
        route: the route it deploys.
        n_sections: arm sections ``N``.
        s: tip arc length along the route of every entry [cm].
        dis, theta, phi: the postures, shapes ``(T,)``, ``(T, N)``, ``(T, N)``.
        stage_index: entry index of every whole-section stage (the shift-and-copy postures).

    """

    route: Route
    n_sections: int
    s: NDArray[np.float64]
    dis: NDArray[np.float64]
    theta: NDArray[np.float64]
    phi: NDArray[np.float64]
    stage_index: tuple[int, ...]

    def __len__(self) -> int:
        return int(self.s.shape[0])

    def points(self, per_section: int = SAMPLES_PER_SECTION) -> NDArray[np.float64]:
        """Backbone samples of every entry, shape ``(T, N·K + 1, 3)``."""
        return body_points(self.dis, self.theta, self.phi, self.route.section_length, per_section)

    def tips(self) -> NDArray[np.float64]:
        """Tip of every entry, ``(T, 3)``."""
        return forward_kinematics(self.dis, self.theta, self.phi, self.route.section_length)[
            :, -1, :3, 3
        ]

    def posture(self, t: int) -> Posture:
        """Entry ``t`` as a :class:`Posture`."""
        return Posture(self.dis[t], self.theta[t], self.phi[t])

    def to_list(self) -> list[dict[str, float | list[float]]]:
        """The ``motion`` list of ``trajectory.json``: ``{"dis", "theta", "phi"}`` per entry."""
        return [
            {"dis": float(d), "theta": th.tolist(), "phi": ph.tolist()}
            for d, th, ph in zip(self.dis, self.theta, self.phi)
        ]


def route_points(route: Route, u: ArrayLike) -> NDArray[np.float64]:
    """Points of the route at arc lengths ``u`` [cm] from the floor; below the lead, the axis."""
    l, m = route.section_length, route.n_route_sections
    u = np.asarray(u, dtype=np.float64)
    theta, phi = kappa_to_angles(route.kappa)
    frames = forward_kinematics(route.lead, theta, phi, l)  # (M + 1, 4, 4)
    j = np.clip(np.floor((u - route.lead) / l).astype(np.int64), 0, max(m - 1, 0))
    q = np.clip(u - route.lead - j * l, 0.0, l)
    if m == 0:
        return np.stack([np.zeros_like(u), np.zeros_like(u), u], axis=-1)
    local = section_transforms(theta[j] * q / l, phi[j], q)[..., :3, 3]
    world = np.einsum("...ij,...j->...i", frames[j, :3, :3], local) + frames[j, :3, 3]
    axis = np.stack([np.zeros_like(u), np.zeros_like(u), u], axis=-1)
    return np.where((u <= route.lead)[..., None], axis, world)


#: Weight of the tip against one body sample in the between-stage fit (the tip leads).
TIP_WEIGHT = 10.0

#: Body samples per section of the between-stage fit.
FIT_SAMPLES = 5


def _fit_goals(route: Route, n: int, s: NDArray[np.float64]) -> NDArray[np.float64]:
    """Route points ``(F, N·per + 1, 3)`` at the arc lengths of the fit's samples, per tip ``s``.

    Sample 0 is the body's base; ``per`` (:data:`FIT_SAMPLES`) follow in each section.
    """
    l, per = route.section_length, FIT_SAMPLES
    along = np.arange(n)[:, None] + (np.arange(1, per + 1) / per)[None, :]
    u = (s - n * l)[:, None] + np.concatenate([[0.0], along.reshape(-1)])[None, :] * l
    return route_points(route, u)


def _fit_shape(
    route: Route,
    n: int,
    s: float,
    kappa: NDArray[np.float64],
    goal: NDArray[np.float64],
    iterations: int = 4,
) -> NDArray[np.float64]:
    """Refine the interpolated ``κ`` (N, 2) of the sections above the floor by Gauss-Newton.

    Minimises the distance of the body's samples to the route at the same arc length (``goal``,
    :func:`_fit_goals`): the best constant-curvature approximation of the body sliding along the
    curve (approximate FTL). Compiled (:func:`aftir_rl.core.kernel.deployment.fit_shape`).
    """
    l, per = route.section_length, FIT_SAMPLES
    dis = s - n * l
    free = np.flatnonzero(dis + (np.arange(n) + 1) * l > route.lead + 1e-9)
    if len(free) == 0:
        return kappa
    # the leader: the tip is held on the route far more firmly than the body
    weight = np.ones(n * per + 1)
    weight[-1] = TIP_WEIGHT
    kap = np.array(kappa, dtype=np.float64)
    fit_shape(float(dis), kap, int(free[0]), np.ascontiguousarray(goal), weight, l, per, iterations)
    return kap


def ftl_motion(
    route: Route,
    n_sections: int,
    start_height: float,
    max_move: float = 0.9,
    fit: bool = True,
    keys_per_stage: int = 10,
    theta_max: float = math.pi / 2,
) -> FTLMotion:
    """The whole deployment, dense enough that no backbone point moves more than ``max_move``.

    Starts straight with the tip ``start_height`` above the floor (or at the end of the lead, if
    that is lower) and ends at the route's end. Between stages the shape is shift-and-copy's
    interpolation (``fit=False``) or, by default, that interpolation refined at
    ``keys_per_stage`` points of each stage by a least-squares fit of the body to the route
    (:func:`_fit_shape`), linear in ``κ`` between those points. Steps are halved where a backbone
    sample would move farther than ``max_move`` [cm] between entries (samples 2.5 cm apart at
    ``l = 50``). Fitted shapes are kept within the joint limit ``theta_max``.
    """
    l, n, m = route.section_length, int(n_sections), route.n_route_sections
    s0 = min(float(start_height), route.lead)
    stages = route.lead + l * np.arange(m + 1)
    keys = np.unique(
        np.concatenate([[s0], route.lead + l * np.linspace(0, m, m * keys_per_stage + 1)])
    )
    _, th, ph = ftl_postures(route, n, keys)
    key_kappa = np.stack([th * np.cos(ph), th * np.sin(ph)], axis=-1)  # (K, N, 2)
    if fit:
        frac = ((keys - route.lead) / l) % 1.0
        fitted = np.flatnonzero(
            (keys > route.lead) & ~(np.isclose(frac, 0.0) | np.isclose(frac, 1.0))
        )
        goals = _fit_goals(route, n, keys[fitted])  # one batched route query for every key
        for i, goal in zip(fitted, goals):
            key_kappa[i] = clip_kappa(_fit_shape(route, n, keys[i], key_kappa[i], goal), theta_max)

    def at(s: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        flat = key_kappa.reshape(len(keys), -1)
        kap = np.stack([np.interp(s, keys, flat[:, c]) for c in range(flat.shape[1])], axis=-1)
        theta, phi = kappa_to_angles(kap.reshape(len(s), n, 2))
        return s - n * l, theta, phi

    s = np.unique(np.concatenate([np.arange(s0, route.length, max_move), stages, [s0]]))
    s = s[(s >= s0 - 1e-9) & (s <= route.length + 1e-9)]
    for _ in range(12):
        dis, theta, phi = at(s)
        points = np.empty((len(s), n * SAMPLES_PER_SECTION + 1, 3))
        fk_points(dis, theta, phi, l, SAMPLES_PER_SECTION, points)  # compiled body_points
        moves = backbone_moves(points)
        bad = np.flatnonzero(moves > max_move)
        if len(bad) == 0:
            break
        s = np.sort(np.concatenate([s, 0.5 * (s[bad] + s[bad + 1])]))
    else:  # pragma: no cover - 12 halvings cover any bend of a 50 cm section
        raise RuntimeError("could not make the motion dense enough")
    stage_index = tuple(int(np.argmin(np.abs(s - v))) for v in stages if v >= s0 - 1e-9)
    return FTLMotion(route, n, s, dis, theta, phi, stage_index)


def clip_kappa(kappa: NDArray[np.float64], limit: float) -> NDArray[np.float64]:
    """Bending vectors ``(..., 2)`` shortened to at most ``limit`` [rad] (the joint limit)."""
    norm = np.hypot(kappa[..., 0], kappa[..., 1])
    return kappa * np.where(norm > limit, limit / np.maximum(norm, 1e-12), 1.0)[..., None]


def ftl_deviation(motion: FTLMotion, half_window: int = 12) -> tuple[float, float]:
    """``(max, mean)`` distance [cm] of the body from the curve the tip has traced.

    The traced curve is the tip's path over the motion so far, continued down the panel's axis
    below the first tip position (where the body comes from). A body sample at arc length ``u``
    along the route is compared with the traced polyline's ``half_window`` segments on either side
    of the entry whose tip was at arc length ``u`` (entries are at most 1 cm of tip travel apart,
    so that is where its nearest point lies).
    """
    l, n = motion.route.section_length, motion.n_sections
    tips = np.ascontiguousarray(motion.tips())
    k = n * SAMPLES_PER_SECTION
    back = n * l * (1.0 - np.arange(k + 1) / k)
    worst, total = 0.0, 0.0
    chunk = 256  # memory-bounded: 256 entries' backbones (0.7 MB at 12 sections) at a time
    points = np.empty((chunk, k + 1, 3))
    for lo in range(0, len(motion), chunk):
        hi = min(lo + chunk, len(motion))
        dis, theta, phi = motion.dis[lo:hi], motion.theta[lo:hi], motion.phi[lo:hi]
        fk_points(dis, theta, phi, l, SAMPLES_PER_SECTION, points[: hi - lo])
        w, t = traced_deviation(points[: hi - lo], tips, motion.s, back, half_window, lo)
        worst, total = max(worst, w), total + t
    return worst, total / (len(motion) * (k + 1))
