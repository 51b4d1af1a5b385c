"""TSM, the three-segment method (filomat2018 §4), for a target beyond a hatch.

P3 is a TGA posture planned in the hatch frame M (origin at the hatch centre, ``z_M`` along the
hatch normal into the far bay, ``x_M`` towards the floor) from A to G; P2 is one section bending
by ``θ_m`` that turns the arm onto the hatch axis; P1 is a TGA posture from the panel to C whose
end direction ``u3`` makes the angle ``α`` with ``z`` at bearing ``δ``. ``α`` is searched; the
corner ``B = A − d · n`` (``n`` the hatch normal) with ``d = (l/θ_m) tan(θ_m/2)``, ``δ`` and
``θ_m`` are solved together by fixed-point iteration. The total is ``N = N_p1 + 1 + N_p3``
sections and ``dis = dis_p1``.

The reading of the paper we took where its equations are garbled (P3's base, the corner, the
angles, the rotation of P3 into P2's end frame, the total): docs/design.md §6.3.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import CollisionReport, point_clearance
from aftir_rl.core.errors import PlanningError
from aftir_rl.core.robot import Posture, forward_kinematics, section_transforms
from aftir_rl.core.tank.raster import format_point
from aftir_rl.planning.posture.context import Method, PlannedPosture, PlanningContext
from aftir_rl.planning.posture.search import SearchResult
from aftir_rl.planning.posture.tga import Frame, search_sections

__all__ = ["hatch_frame", "tsm", "TSM"]


def hatch_frame(
    context: PlanningContext, target: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rotation (columns ``x_M, y_M, z_M`` in S) and origin of the hatch frame M."""
    b, h = context.tank.baffle, context.tank.hatch
    assert b is not None and h is not None
    z_m = np.zeros(3)
    z_m[b.index] = 1.0 if np.asarray(target)[b.index] > b.position else -1.0
    x_m = np.array([0.0, 0.0, -1.0])
    return np.column_stack([x_m, np.cross(z_m, x_m), z_m]), np.array(h.center, dtype=float)


def tsm(context: PlanningContext, target: ArrayLike) -> PlannedPosture:
    """Three-segment posture through the hatch to a target beyond the baffle."""
    start = time.perf_counter()
    target = context.check_target(target)
    _check_tsm_target(context, target)
    rot_m, o_m = hatch_frame(context, target)
    g_m = rot_m.T @ (target - o_m)
    psi_m = math.atan2(g_m[1], g_m[0])
    frame_m = Frame(psi_m, rot_m, o_m, panel=False)
    reasons: list[str] = []
    best: tuple[Posture, dict[str, Any], CollisionReport] | None = None
    n3_min = max(1, context.min_sections(float(np.linalg.norm(g_m))) - 1)
    rho_m = math.hypot(g_m[0], g_m[1])
    for n3 in range(n3_min, min(n3_min + context.extra_sections, context.arm.max_sections - 2) + 1):
        p3 = _p3(context, rho_m, float(g_m[2]), frame_m, n3)
        if p3 is None:
            reasons.append(f"no P3 posture of {n3} sections from the hatch")
            continue
        best = _through_hatch(context, p3, o_m, rot_m, psi_m, reasons)
        if best is not None:
            break
    if best is None:
        counts = Counter(r.split(": ", 1)[-1] if "deg:" in r else r for r in reasons)
        why = "; ".join(f"{k} ({v}x)" if v > 1 else k for k, v in counts.most_common(3))
        raise PlanningError(
            f"Cannot reach the target: TSM found no posture to {format_point(target)} cm ({why})"
        )
    posture, details, report = best
    return context.checked(posture, target, "tsm", context.tolerance, details, start, report)


def _check_tsm_target(context: PlanningContext, target: NDArray[np.float64]) -> None:
    """Raise :class:`PlanningError` unless the tank has a hatch and the target lies beyond it."""
    tank = context.tank
    if tank.baffle is None or tank.hatch is None:
        raise PlanningError("Cannot reach the target: TSM needs a tank with a baffle and hatch")
    if not context.beyond_baffle(target):
        raise PlanningError(
            "Cannot reach the target: TSM is for targets beyond the baffle; use TGA"
        )


def _p3(
    context: PlanningContext, rho_m: float, z_m: float, frame_m: Frame, n3: int
) -> tuple[NDArray[np.float64], float, SearchResult] | None:
    """P3: a TGA posture of ``n3`` sections in the hatch frame M to the target ``(rho_m, z_m)``.

    P3's base A is searched within half a section before the hatch first (room for P2 in bay 1),
    then past the hatch (near targets), then deeper in bay 1.
    """
    l = context.arm.section_length
    p3 = None
    for dis_range in ((-0.5 * l, 0.0), (0.0, 0.5 * l), (-1.5 * l, -0.5 * l)):
        limits = (dis_range[0] - l / 2, dis_range[1] + l / 2)
        p3 = search_sections(
            context,
            rho_m,
            z_m,
            frame_m,
            [n3],
            None,
            "region_clipping",
            True,
            dis_range=dis_range,
            dis_limits=limits,
        )
        if p3 is not None:
            break
    return p3


def _through_hatch(
    context: PlanningContext,
    p3: tuple[NDArray[np.float64], float, SearchResult],
    o_m: NDArray[np.float64],
    rot_m: NDArray[np.float64],
    psi_m: float,
    reasons: list[str],
) -> tuple[Posture, dict[str, Any], CollisionReport] | None:
    """P1 and P2 in front of a P3: the first guided angle that gives a checked posture.

    Guided angles nearest the straight line from the panel to A are tried first; the reasons
    the others fail are appended to ``reasons``. Returns the posture, its details and the
    scene's check of it.
    """
    theta3, dis3, res3 = p3
    n = rot_m[:, 2]
    a_point = o_m + dis3 * n
    alpha0 = math.atan2(math.hypot(a_point[0], a_point[1]), a_point[2])
    alphas = np.radians(np.arange(5.0, 90.1, 5.0))
    for alpha in alphas[np.argsort(np.abs(alphas - alpha0), kind="stable")]:
        out = _p1(context, a_point, n, alpha, theta3, psi_m, rot_m)
        if isinstance(out, str):
            reasons.append(out)
            continue
        out[1].update(loops_p3=res3.loops, evaluations_p3=res3.evaluations)
        return out
    return None


def _p1(
    context: PlanningContext,
    a_point: NDArray[np.float64],
    n: NDArray[np.float64],
    alpha: float,
    theta3: NDArray[np.float64],
    psi_m: float,
    rot_m: NDArray[np.float64],
) -> tuple[Posture, dict[str, Any], CollisionReport] | str:
    """P1 and P2 for one guided angle ``alpha`` and the scene's check; why not, if impossible."""
    l, n3 = context.arm.section_length, len(theta3)
    d, delta, u3, theta_m = _corner(a_point, n, alpha, l)
    if theta_m > context.arm.theta_max:
        bend = math.degrees(theta_m)
        return f"alpha {math.degrees(alpha):.0f} deg needs P2 to bend {bend:.0f} deg"
    b_point = a_point - d * n
    c_point = b_point - d * u3
    rho_c = math.hypot(b_point[0], b_point[1]) - d * math.sin(alpha)
    if float(point_clearance(context.tank, c_point[None])[0]) <= context.arm.radius:
        return f"alpha {math.degrees(alpha):.0f} deg puts C in an obstacle"
    n_min = context.min_sections(float(np.linalg.norm(c_point)))
    n_max = min(n_min + context.extra_sections, context.arm.max_sections - 1 - n3)
    sections = range(n_min, n_max + 1)
    z_c = float(c_point[2])
    p1 = search_sections(
        context, rho_c, z_c, Frame(delta), sections, alpha, "region_clipping", True
    )
    if p1 is None:
        return f"alpha {math.degrees(alpha):.0f} deg: no P1 posture reaches C"
    theta1, dis1, res1 = p1
    n1 = len(theta1)
    bend_m, phi_m, phi3 = _p2_turn(dis1, theta1, delta, n, l, rot_m, psi_m)
    posture = Posture(
        dis1,
        tuple(theta1) + (bend_m,) + tuple(theta3),
        (delta,) * n1 + (phi_m,) + (phi3,) * n3,
    )
    report = context.scene.check(posture)
    if report.collides:
        return f"alpha {math.degrees(alpha):.0f} deg collides ({report.hit or 'panel rule'})"
    details = {
        "sections": posture.n_sections,
        "n_p1": n1,
        "n_p3": n3,
        "alpha_deg": math.degrees(alpha),
        "delta_deg": math.degrees(delta),
        "theta_m_deg": math.degrees(bend_m),
        "loops_p1": res1.loops,
        "evaluations_p1": res1.evaluations,
    }
    return posture, details, report


def _corner(
    a_point: NDArray[np.float64], n: NDArray[np.float64], alpha: float, l: float
) -> tuple[float, float, NDArray[np.float64], float]:
    """The corner B's tangent length ``d``, bearing ``δ``, P1's end direction ``u3`` and ``θ_m``.

    ``d``, ``δ`` and ``θ_m`` depend on each other: fixed-point iteration (at most 100 steps).
    """
    d = l / 2
    for _ in range(100):
        b_point = a_point - d * n
        delta = math.atan2(b_point[1], b_point[0])
        u3 = np.array(
            [math.sin(alpha) * math.cos(delta), math.sin(alpha) * math.sin(delta), math.cos(alpha)]
        )
        theta_m = math.acos(float(np.clip(u3 @ n, -1.0, 1.0)))
        d_new = l / 2 if theta_m < 1e-9 else (l / theta_m) * math.tan(theta_m / 2)
        if abs(d_new - d) < 1e-12:
            break
        d = d_new
    return d, delta, u3, theta_m


def _p2_turn(
    dis1: float,
    theta1: NDArray[np.float64],
    delta: float,
    n: NDArray[np.float64],
    l: float,
    rot_m: NDArray[np.float64],
    psi_m: float,
) -> tuple[float, float, float]:
    """P2's bend and rotation angle onto the hatch axis ``n``, and P3's rotation angle after it.

    Returns:
        ``(θ_m, φ_m, φ_3)``: P2 bends by ``θ_m`` at ``φ_m`` in the end frame of P1 (eq. 13); P3's
        angles, planned in M, turn by the twist between M and P2's end frame about ``n``.

    """
    frames = forward_kinematics(dis1, theta1, [delta] * len(theta1), l)
    r_c = frames[-1, :3, :3]
    n_local = r_c.T @ n
    phi_m = math.atan2(n_local[1], n_local[0])
    bend_m = math.acos(float(np.clip(n_local[2], -1, 1)))
    r_a = r_c @ section_transforms(bend_m, phi_m, l)[:3, :3]
    beta = math.atan2(r_a[:, 0] @ rot_m[:, 1], r_a[:, 0] @ rot_m[:, 0])
    return bend_m, phi_m, psi_m - beta


TSM = Method(
    "tsm",
    "three-segment method through the hatch, for targets beyond the baffle",
    tsm,
    paper="filomat2018",
    bench_sets=("filomat2018", "bay2"),
)
