"""TGA, the target guided angle (jace, and filomat2018 §4), with region clipping or blind search.

Dimension reduction (all ``φ_i`` equal to the target's bearing), region clipping over the bending
angles with the MDS criterion (:mod:`aftir_rl.planning.posture.search`), the rising distance,
sections added until a collision-free solution exists, then a Gauss–Newton refinement so the tip
error is far below the search step. An optional required end direction (the guided angle) is what
TSM needs for its first part (:mod:`aftir_rl.planning.posture.tsm`).

Three methods are registered here: ``tga`` (refined), and ``region_clipping`` and ``blind``,
which stop at the search step as the papers do (the tip anywhere in the target zone).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import PlanningError
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.planar import planar_clear
from aftir_rl.core.robot import Posture
from aftir_rl.core.tank.raster import format_point
from aftir_rl.planning.posture.context import Method, PlannedPosture, PlanningContext
from aftir_rl.planning.posture.search import (
    BLIND_LIMIT,
    Feasible,
    PlanarProblem,
    SearchResult,
    blind_grid_size,
    blind_search,
    refine,
    region_clipping,
)

__all__ = ["Frame", "search_sections", "tga", "TGA", "REGION_CLIPPING", "BLIND"]

_CHUNK = 4096
_MAX_GRID = 2e6  # region clipping grids larger than this (14+ searched angles) are not tried


@dataclass
class Frame:
    """A planning frame: plane bearing ``psi`` inside the frame ``(rotation, origin)`` of S.

    ``panel``: the panel rule applies (the frame is S, the arm's base in the panel).
    """

    psi: float
    rotation: NDArray[np.float64] | None = None
    origin: NDArray[np.float64] | None = None
    panel: bool = True


def prefilter(context: PlanningContext, frame: Frame) -> Feasible:
    """The search's feasibility check of planar postures in ``frame``: panel rule and clearance.

    Backbone samples ``context.check_points`` a section, clear of the tank by the arm's radius
    and the context's margin, after a coarse pass (4 samples a section, no margin).
    """
    l, k, tank = context.arm.section_length, context.check_points, context.tank
    limit = context.arm.radius + context.margin
    grid = kernel_grid(tank)
    rotation = np.eye(3) if frame.rotation is None else np.asarray(frame.rotation, dtype=float)
    origin = np.zeros(3) if frame.origin is None else np.asarray(frame.origin, dtype=float)
    centre, radius = tank.panel.center, float(tank.panel.radius) if frame.panel else -1.0
    panel = (float(centre[0]), float(centre[1]), float(centre[2]), radius)
    where = (float(frame.psi), np.ascontiguousarray(rotation), np.ascontiguousarray(origin))

    def check(
        th: NDArray[np.float64], d: NDArray[np.float64], points: int, clear: float
    ) -> NDArray[np.bool_]:
        # compiled: the planar points in the frame, the panel rule, the exact clearance
        ok = np.empty(len(th), dtype=bool)
        th, d = np.ascontiguousarray(th), np.ascontiguousarray(d, dtype=np.float64)
        planar_clear(th, d, (l, points), where, panel, grid, float(clear), ok)
        return ok

    def feasible(theta: NDArray[np.float64], dis: NDArray[np.float64]) -> NDArray[np.bool_]:
        out = np.zeros(len(theta), dtype=bool)
        for begin in range(0, len(theta), _CHUNK):
            part = np.arange(begin, min(begin + _CHUNK, len(theta)))
            # A coarse pass (4 points a section, no margin) rejects most candidates cheaply.
            part = part[check(theta[part], dis[part], 4, context.arm.radius)]
            if len(part):
                out[part] = check(theta[part], dis[part], k, limit)
        return out

    return feasible


def _search(context: PlanningContext, problem: PlanarProblem, search: str) -> SearchResult | None:
    """One search of ``problem`` (None also where its grid is too large to try)."""
    arm = context.arm
    if search == "blind":
        if blind_grid_size(problem.n_free, arm.theta_max, context.dtheta) > BLIND_LIMIT:
            return None
        return blind_search(problem, context.dtheta)
    n_free = problem.n_free
    num = context.num if n_free <= 5 else max(2, int(1e5 ** (1 / n_free)) - 1)
    if (num + 1) ** n_free > _MAX_GRID:
        return None  # even NUM = 2 is too large a grid (3^14 = 4.8e6 combinations)
    return region_clipping(problem, num=num, dtheta=context.dtheta)


def search_sections(
    context: PlanningContext,
    rho: float,
    z: float,
    frame: Frame,
    sections: Iterable[int],
    heading: float | None,
    search: str,
    refine_tip: bool,
    dis_range: tuple[float, float] | None = None,
    dis_limits: tuple[float, float] = (-math.inf, 0.0),
) -> tuple[NDArray[np.float64], float, SearchResult] | None:
    """First section count with a search result that refines and passes the exact check.

    Args:
        context: the planning context.
        rho: the target's distance from the base axis in the frame's plane [cm].
        z: the target's height in the frame [cm].
        frame: the planning frame.
        sections: section counts to try, in order.
        heading: required end heading [rad from the axis], or None.
        search: "region_clipping" or "blind".
        refine_tip: refine so the tip error is below the context's tolerance.
        dis_range: rising distances the search considers (default ``(−N l, 0)``).
        dis_limits: rising distances a refined posture may have.

    Returns:
        ``(theta, dis, search result)``, or None.

    """
    l = context.arm.section_length
    feasible = prefilter(context, frame)
    # With refinement the search narrows the zone to the tolerance, so that refining moves the
    # body by less than the pre-filter's margin (postures hugging the reference line are often
    # that close to an edge).
    zone = min(context.zone, context.tolerance) if refine_tip else context.zone
    for n in sections:
        problem = PlanarProblem(
            rho,
            z,
            n,
            l,
            context.arm.theta_max,
            zone=zone,
            end_heading=heading,
            dis_range=dis_range or (-n * l, 0.0),
            dis_limits=dis_limits,
            feasible=feasible,
        )
        result = _search(context, problem, search)
        if result is None:
            continue
        found = _first_valid(context, problem, result, frame, feasible, refine_tip)
        if found is not None:
            return found
    return None


def _first_valid(
    context: PlanningContext,
    problem: PlanarProblem,
    result: SearchResult,
    frame: Frame,
    feasible: Feasible,
    refine_tip: bool,
) -> tuple[NDArray[np.float64], float, SearchResult] | None:
    """The first of a search's best and runners-up that refines and passes the exact check.

    Args:
        context: the planning context.
        problem: the searched problem.
        result: its search result.
        frame: the planning frame.
        feasible: the search's feasibility check (:func:`prefilter`).
        refine_tip: refine so the tip error is below the context's tolerance (else only the
            best, as searched, is tried).

    Returns:
        ``(theta, dis, result)``, or None.

    """
    n = problem.n_sections
    dis: float | None
    for theta in [result.theta, *result.candidates]:
        if refine_tip:
            fixed = refine(problem, theta)
            if fixed is None:
                continue
            theta, dis = fixed
            if not feasible(theta[None], np.array([dis]))[0]:
                continue
        else:
            dis = result.dis if theta is result.theta else None
            if dis is None:
                continue
        if frame.rotation is None and context.scene.collides(Posture(dis, theta, (frame.psi,) * n)):
            continue
        return np.asarray(theta), float(dis), result
    return None


def tga(
    context: PlanningContext,
    target: ArrayLike,
    end_direction: ArrayLike | None = None,
    search: str = "region_clipping",
    refine_tip: bool = True,
    method: str = "tga",
) -> PlannedPosture:
    """Target guided angle posture from the panel to ``target``.

    Args:
        context: the planning context.
        target: [cm].
        end_direction: required tip direction (a vector in the target's vertical plane).
        search: "region_clipping" or "blind".
        refine_tip: refine so the tip error is below ``tolerance`` (else the search's zone).
        method: name recorded in the result.

    """
    start = time.perf_counter()
    target = context.check_target(target)
    rho = math.hypot(target[0], target[1])
    psi = math.atan2(target[1], target[0]) if rho > 1e-9 else 0.0
    heading = None
    if end_direction is not None:
        u = np.asarray(end_direction, dtype=np.float64)
        u = u / np.linalg.norm(u)
        horizontal = u[0] * math.cos(psi) + u[1] * math.sin(psi)
        if abs(-u[0] * math.sin(psi) + u[1] * math.cos(psi)) > 1e-6:
            raise PlanningError(
                "Cannot reach the target: the required end direction is not in the vertical "
                "plane through the target"
            )
        heading = math.atan2(horizontal, u[2])
    n_min = context.min_sections(float(np.linalg.norm(target)))
    sections = range(n_min, min(n_min + context.extra_sections, context.arm.max_sections) + 1)
    found = search_sections(
        context, rho, float(target[2]), Frame(psi), sections, heading, search, refine_tip
    )
    if found is None:
        raise PlanningError(
            f"Cannot reach the target: no collision-free {method.upper()} posture of "
            f"{sections.start} to {sections.stop - 1} sections reaches {format_point(target)} cm"
        )
    theta, dis, result = found
    posture = Posture(dis, theta, (psi,) * len(theta))
    details = {"loops": result.loops, "evaluations": result.evaluations, "sections": len(theta)}
    tol = context.tolerance if refine_tip else context.zone + 1e-6
    return context.checked(posture, target, method, tol, details, start)


def _blind_too_large(context: PlanningContext, target: ArrayLike) -> str:
    """Why blind search is not run on ``target`` ("" when it is): its grid's size."""
    n = math.ceil(float(np.linalg.norm(target)) / context.arm.section_length - 1e-9)
    if blind_grid_size(n, context.arm.theta_max, context.dtheta) > BLIND_LIMIT:
        return f"blind: {n} sections, grid above {BLIND_LIMIT:.0e}".replace("e+0", "e")
    return ""


TGA = Method(
    "tga",
    "target guided angle: dimension reduction, region clipping, refined (bay 1)",
    lambda context, target: tga(context, target),
    paper="jace",
    bench_sets=("jace", "icra2014", "st2014", "bay1"),
)
REGION_CLIPPING = Method(
    "region_clipping",
    "TGA's region clipping stopped at the search step, as in the paper",
    lambda context, target: tga(context, target, refine_tip=False, method="region_clipping"),
    paper="jace",
    bench_sets=("jace", "bay1"),
)
BLIND = Method(
    "blind",
    "blind search on one 1 degree grid, the paper's baseline",
    lambda context, target: tga(context, target, search="blind", refine_tip=False, method="blind"),
    paper="jace",
    bench_sets=("jace", "st2014", "bay1"),
    skip=_blind_too_large,
)
