"""Region division (st2014): closed-form planar postures chosen by the target's region.

The st2014 paper reduces the tank to the vertical plane through the ``z`` axis and the target,
sorts the target into a *region* by its horizontal distance, and solves that region's posture in
closed form instead of searching: one equal-bend arc on its rising branch (numerical method I)
or its falling branch (method II), or for far targets a quarter circle, straight joints and three
bending joints (method III); the candidate of smallest ``|dis|`` that passes the planner's checks
wins, solved exactly by bisection. Its figures are missing and its equations garbled in the scan:
the one consistent reading we implement, its sign conventions and where the paper disagrees with
itself are in docs/design.md §6.5.

The pure geometric helpers (:func:`arc_tip`, :func:`reach`, :func:`region`, :func:`solve_arc`,
:func:`method_iii_arc`, :func:`candidates`, :func:`geometric_solution`) need no tank; units are
cm and rad.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.core.errors import PlanningError
from aftir_rl.core.robot import Posture
from aftir_rl.core.tank.raster import format_point
from aftir_rl.planning.jointspace import pad_sections
from aftir_rl.planning.posture.context import Method, PlannedPosture, PlanningContext

__all__ = [
    "ARC_PEAK",
    "REACH_RATIO",
    "REGION_DIVISION",
    "Candidate",
    "arc_tip",
    "bearing",
    "candidate_posture",
    "candidates",
    "geometric_solution",
    "method_iii_arc",
    "reach",
    "region",
    "region_division",
    "solve_arc",
]

METHOD = "region_division"
ARC_PEAK = 2.3311223704144226
"""``Θ*`` [rad], where ``R_m(Θ)`` peaks: the root of ``Θ sin Θ = 1 − cos Θ`` in ``(π/2, π)``."""
REACH_RATIO = (1.0 - math.cos(ARC_PEAK)) / ARC_PEAK
"""``f_m / (mℓ)`` ≈ 0.7246: the horizontal reach of an equal-bend arc per unit length."""
FAR_REGION = 8
"""Regions ``n ≥ 8`` use method III."""
TURN_JOINTS = 3
"""Joints of method III's quarter circle, each bending ``π/6``."""
BEND_JOINTS = 3
"""Method III's ``bend``: the terminal joints that search the target."""


# --------------------------------------------------------------------------------------------
# Geometry of the equal-bend arc and of method III


def arc_tip(joints: int, bend: float, section_length: float) -> tuple[float, float]:
    """Tip ``(R, Z)`` [cm] of ``joints`` sections bending equally by ``bend`` [rad] in total.

    Relative to the arc's base, ``R`` horizontal towards the bend and ``Z`` along the base's axis;
    smooth through ``bend = 0`` (the straight arm).
    """
    length = joints * section_length
    if abs(bend) < 1e-4:
        b2 = bend * bend
        return length * bend * (0.5 - b2 / 24.0), length * (1.0 - b2 / 6.0 * (1.0 - b2 / 20.0))
    return length * 2.0 * math.sin(bend / 2) ** 2 / bend, length * math.sin(bend) / bend


def reach(joints: int, section_length: float) -> float:
    """``f_m``: the largest horizontal distance ``m`` equal-bend joints reach [cm]."""
    return REACH_RATIO * joints * section_length


def region(radius: float, section_length: float) -> int:
    """The region ``n`` of a target at horizontal distance ``radius`` [cm], ``f_{n−1} < R ≤ f_n``.

    ``f_0 = 0``, and a target on the ``z`` axis is in region 1.
    """
    return max(1, math.ceil(radius / reach(1, section_length) - 1e-12))


def _bisect(fn: Callable[[float], float], lo: float, hi: float) -> float:
    """A root of ``fn`` in ``[lo, hi]``, where ``fn`` changes sign, to float precision."""
    f_lo = fn(lo)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        f_mid = fn(mid)
        if (f_mid > 0) == (f_lo > 0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def solve_arc(
    radius: float,
    joints: int,
    section_length: float,
    falling: bool,
    theta_max: float = math.pi / 2,
) -> float | None:
    """Total bend ``Θ`` [rad] with ``R_m(Θ) = radius`` on one branch, or None.

    Args:
        radius: the target's horizontal distance ``R_G`` [cm].
        joints: ``m``.
        section_length: ``ℓ`` [cm].
        falling: the falling branch ``Θ* < Θ < 2π`` (method II), else the rising ``Θ ≤ Θ*`` (I).
        theta_max: bound on each joint's bend ``Θ/m`` [rad].

    """
    top = joints * theta_max

    def gap(bend: float) -> float:
        return arc_tip(joints, bend, section_length)[0] - radius

    if not falling:
        hi = min(ARC_PEAK, top)
        if radius <= 0.0:
            return 0.0
        return _bisect(gap, 0.0, hi) if gap(hi) >= 0.0 else None
    hi = min(top, 2.0 * math.pi - 1e-9)
    if hi <= ARC_PEAK or gap(ARC_PEAK) < 0.0 or gap(hi) > 0.0:
        return None
    return _bisect(gap, ARC_PEAK, hi)


def method_iii_arc(radius: float, section_length: float) -> tuple[int, float] | None:
    """Method III's straight joints ``str`` (eq. 9) and the magnitude of ``Θ`` [rad], or None.

    ``f3 + str·ℓ + 3ℓ sin Θ/Θ = radius``; None when the target is too near for ``str ≥ 0``.
    """
    l = section_length
    f3 = arc_tip(TURN_JOINTS, math.pi / 2, l)[0]
    straight = math.floor((radius - f3) / l) - (BEND_JOINTS - 1)
    if straight < 0:
        return None
    rest = radius - f3 - straight * l
    bend = _bisect(lambda b: arc_tip(BEND_JOINTS, b, l)[1] - rest, 0.0, math.pi)
    return straight, bend


@dataclass(frozen=True)
class Candidate:
    """One closed-form solution of region division, in the paper's terms.

    Attributes:
        method: numerical method, "I", "II" or "III".
        region: the target's region ``n``.
        theta: bending angle of each of the paper's ``m`` joints [rad].
        bend: total bend of the searched arc, the paper's θ [rad]; method III's is negative
            upwards.
        rise: height of the tip above the base of the first joint [cm].
        dis: the base's vertical move ``z_G − rise`` [cm] (positive: raised).

    """

    method: str
    region: int
    theta: tuple[float, ...]
    bend: float
    rise: float
    dis: float

    @property
    def joints(self) -> int:
        """The paper's number of joints ``m``."""
        return len(self.theta)

    @property
    def descending(self) -> float:
        """The paper's descending distance ``rise − z_G`` [cm]."""
        return -self.dis

    @property
    def label(self) -> str:
        """Short name for messages, e.g. "method I, 4 joints"."""
        return f"method {self.method}, {self.joints} joints"


def _arc_candidates(
    radius: float, z: float, n: int, l: float, theta_max: float, max_joints: int
) -> list[Candidate]:
    out = []
    for m in range(n, max_joints + 1):
        for method, falling in (("I", False), ("II", True)):
            bend = solve_arc(radius, m, l, falling, theta_max)
            if bend is None:
                continue
            rise = arc_tip(m, bend, l)[1]
            out.append(Candidate(method, n, (bend / m,) * m, bend, rise, z - rise))
    return out


def _far_candidates(radius: float, z: float, n: int, l: float, theta_max: float) -> list[Candidate]:
    solved = method_iii_arc(radius, l)
    if solved is None or solved[1] / BEND_JOINTS > theta_max:
        return []
    straight, bend = solved
    f3 = arc_tip(TURN_JOINTS, math.pi / 2, l)[0]
    drop = arc_tip(BEND_JOINTS, bend, l)[0]
    turn = (math.pi / 6,) * TURN_JOINTS + (0.0,) * straight
    out = []
    for sign in (1.0, -1.0):  # downwards, then upwards
        rise = f3 - sign * drop
        theta = turn + (sign * bend / BEND_JOINTS,) * BEND_JOINTS
        out.append(Candidate("III", n, theta, sign * bend, rise, z - rise))
    return out


def candidates(
    target: ArrayLike,
    section_length: float,
    theta_max: float = math.pi / 2,
    max_joints: int = 16,
) -> list[Candidate]:
    """Every closed-form candidate of the target's region, smallest ``|dis|`` first.

    Methods I and II for regions ``n ≤ 7`` (``n ≤ m ≤ max_joints`` joints), method III for
    ``n ≥ 8``. No tank is involved.
    """
    x, y, z = (float(v) for v in np.asarray(target, dtype=np.float64))
    radius = math.hypot(x, y)
    n = region(radius, section_length)
    if n >= FAR_REGION:
        found = _far_candidates(radius, z, n, section_length, theta_max)
    else:
        found = _arc_candidates(radius, z, n, section_length, theta_max, max_joints)
    return sorted(found, key=lambda c: (abs(c.dis), c.joints))


def geometric_solution(
    target: ArrayLike,
    section_length: float = 25.0,
    theta_max: float = math.pi / 2,
    max_joints: int = 16,
) -> Candidate:
    """The paper's answer without a tank: the candidate with the smallest ``|dis|``.

    Raises:
        PlanningError: no candidate exists (a region beyond ``max_joints``).

    """
    found = candidates(target, section_length, theta_max, max_joints)
    if not found:
        raise PlanningError(
            f"Cannot reach the target: no region-division arc of at most {max_joints} joints"
        )
    return found[0]


def bearing(target: ArrayLike) -> float:
    """The reference plane's bearing ``ψ = atan2(y, x)`` [rad], 0 on the ``z`` axis."""
    x, y = (float(v) for v in np.asarray(target, dtype=np.float64)[:2])
    return math.atan2(y, x) if math.hypot(x, y) > 1e-12 else 0.0


def candidate_posture(candidate: Candidate, psi: float, section_length: float) -> Posture:
    """The candidate as a posture with ``dis ≤ 0``: straight sections replace a raised base."""
    posture = Posture(candidate.dis, candidate.theta, (psi,) * candidate.joints)
    if candidate.dis <= 0.0:
        return posture
    extra = math.ceil(candidate.dis / section_length - 1e-12)
    return pad_sections(posture, candidate.joints + extra, section_length)


# --------------------------------------------------------------------------------------------
# The method


def region_division(context: PlanningContext, target: ArrayLike) -> PlannedPosture:
    """Region-division posture of the context's arm reaching ``target`` [cm] (st2014).

    The candidates of the target's region are tried in order of ``|dis|``; the first whose
    posture passes every check of the context is returned, with ``method`` "region_division" and
    ``details``: ``numerical_method``, ``region``, ``joints`` (the paper's ``m``), ``bend_deg``,
    ``rotation_deg`` (in ``[0, 360)``), ``descending_cm``, ``base_sections`` (straight sections
    added for a raised base) and ``candidates_tried``.

    Raises:
        PlanningError: "Cannot reach the target: <why>".

    """
    start = time.perf_counter()
    goal = context.check_target(target)
    arm = context.arm
    psi = bearing(goal)
    found = candidates(goal, arm.section_length, arm.theta_max, arm.max_sections)
    reasons: list[str] = []
    for tried, cand in enumerate(found, start=1):
        posture = candidate_posture(cand, psi, arm.section_length)
        if posture.n_sections > arm.max_sections:
            reasons.append(f"{cand.label}: needs {posture.n_sections} sections")
            continue
        try:
            details = _details(cand, psi, posture, tried)
            return context.checked(posture, goal, METHOD, details=details, started=start)
        except PlanningError as exc:
            reasons.append(f"{cand.label}: {str(exc).split(': ', 1)[-1]}")
    raise PlanningError(_failure(goal, found, reasons))


def _details(cand: Candidate, psi: float, posture: Posture, tried: int) -> dict[str, Any]:
    return {
        "numerical_method": cand.method,
        "region": cand.region,
        "joints": cand.joints,
        "bend_deg": math.degrees(cand.bend),
        "rotation_deg": math.degrees(psi) % 360.0,
        "descending_cm": cand.descending,
        "base_sections": posture.n_sections - cand.joints,
        "candidates_tried": tried,
    }


def _failure(goal: np.ndarray, found: Sequence[Candidate], reasons: Sequence[str]) -> str:
    where = format_point(goal)
    if not found:
        return (
            f"Cannot reach the target: region division has no arc to {where} cm within the "
            "arm's joint limits and sections"
        )
    counts = Counter(r.split(": ", 1)[1] for r in reasons)
    why = "; ".join(f"{k} ({v}x)" if v > 1 else k for k, v in counts.most_common(3))
    return (
        f"Cannot reach the target: none of the {len(found)} region-division postures to {where} cm "
        f"passes the checks ({why})"
    )


REGION_DIVISION = Method(
    METHOD,
    "closed-form planar postures chosen by the target's region (single cabin)",
    region_division,
    paper="st2014",
    bench_sets=("st2014",),
)
