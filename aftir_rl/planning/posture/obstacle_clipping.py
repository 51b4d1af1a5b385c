"""Collision-free path planning by region clipping among spherical obstacles (icra2014).

The icra2014 paper (§II–III) plans one posture ``q = (dis, θ_i, φ_i)`` that puts the tip in the
*target plane zone* while the body keeps its backbone out of the *obstacle space zones* (vertical
cylinders of radius ``r_oba = r0 + r_b`` through the spheres' centres, whose clearance does not
depend on ``dis``: the projection strategy). Region clipping searches all 2N angles θ and φ with
the MDS criterion, sections are added until a solution exists, and by default the result is
refined towards the exact target (``refine=False`` stops at the search step as the paper does).

The region clipping loop and the Gauss–Newton refinement are
:mod:`aftir_rl.planning.posture.clipping`'s, the MDS is
:func:`~aftir_rl.planning.posture.planar.distance_sum`, shared with the planar search. Every
returned posture is checked by forward kinematics and python-fcl. The paper's pieces and the
readings we took where it is loose or inconsistent (``r_oba``, the zone, angle ranges, the
coarse-loop zone, how far intervals shrink): docs/design.md §6.4.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import PlanningError
from aftir_rl.core.robot import Posture, tip_position
from aftir_rl.core.tank import Sphere, Tank
from aftir_rl.core.tank.raster import format_point
from aftir_rl.planning.posture.clipping import clip_regions, gauss_newton
from aftir_rl.planning.posture.context import Method, PlannedPosture, PlanningContext
from aftir_rl.planning.posture.obstacle_zones import ObstacleProblem

__all__ = [
    "OBSTACLE_CLIPPING",
    "ObstacleProblem",
    "ClippingResult",
    "obstacle_region_clipping",
    "obstacle_clipping",
]

_MAX_SECTIONS = 6  # 3^14 = 4.8e6 combinations a loop for 7 sections, even at NUM = 2


@dataclass
class ClippingResult:
    """The best combination of a search.

    Attributes:
        posture: the joint variables (tip in the target plane zone).
        mds: its distance summation [cm].
        loops: region clipping loops.
        evaluations: combinations evaluated.

    """

    posture: Posture
    mds: float
    loops: int
    evaluations: int


def obstacle_region_clipping(
    problem: ObstacleProblem, num: int = 10, dtheta: float = math.radians(0.1), max_loops: int = 40
) -> ClippingResult | None:
    """Region clipping over every ``θ_i`` and ``φ_i`` (icra2014 §III.B). None if nothing reaches.

    Args:
        problem: the problem.
        num: NUM, parts each interval is split into; lowered so that ``(NUM + 1)^2N`` stays
            below about 4·10⁶ (:func:`obstacle_clipping` does not try N ≥ 7, where even
            NUM = 2 would exceed it).
        dtheta: stop when every step is below this [rad] (and the zone is ``r_target``).
        max_loops: safety bound on loops.

    """
    n, tmax = problem.n_sections, problem.theta_max
    num = max(2, min(num, int((4e6) ** (1 / (2 * n))) - 1))
    first = (
        np.concatenate([np.full(n, -tmax), np.full(n, -math.pi / 2)]),
        np.concatenate([np.full(n, tmax), np.full(n, math.pi / 2)]),
    )
    limits = (
        np.concatenate([np.full(n, -tmax), np.full(n, -math.inf)]),
        np.concatenate([np.full(n, tmax), np.full(n, math.inf)]),
    )

    def evaluate(
        values: list[NDArray[np.float64]], zone: float, tight: float, loop: int, count: int
    ) -> tuple[ClippingResult, NDArray[np.float64], float] | None:
        x, dis, mds, gap = problem.evaluate_grid(values, zone, tight)
        if len(x) == 0:
            return None
        # Outside the tight zone, MDS alone would pick tips far short of the target (a short
        # arm hugs the reference line): take the least MDS among the nearest tips.
        near = gap <= max(tight, 2.0 * float(gap.min()))
        i = int(np.flatnonzero(near)[np.argmin(mds[near])])
        theta, phi = problem.split(x[i : i + 1])
        best = ClippingResult(Posture(dis[i], theta[0], phi[0]), float(mds[i]), loop, count)
        return best, x[i], best.mds

    clipped = clip_regions(
        first,
        limits,
        evaluate,
        problem.r_target,
        problem.zone_for_step,
        num,
        dtheta,
        max_loops,
        neighbours=2,
    )
    if clipped.best is not None:
        clipped.best.evaluations = clipped.evaluations
    return clipped.best


def refine_obstacle(
    problem: ObstacleProblem, posture: Posture, tol: float = 1e-9, iterations: int = 60
) -> Posture | None:
    """Minimum-norm Gauss–Newton steps on the 2N angles towards the exact target.

    The tip's ``(x, y)`` goes onto the target's, then ``dis`` sets its height. None unless it
    converges and the posture still clears every zone.
    """
    n, l, tmax = problem.n_sections, problem.section_length, problem.theta_max

    def tip_xy(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return tip_position(0.0, x[..., :n], x[..., n:], l)[..., :2]

    limits = (
        np.concatenate([np.full(n, -tmax), np.full(n, -math.inf)]),
        np.concatenate([np.full(n, tmax), np.full(n, math.inf)]),
    )
    start = np.concatenate([posture.theta, posture.phi])
    x = gauss_newton(tip_xy, problem.target[:2], start, limits, tol, iterations)
    assert x is not None  # two equations, damped: the step always exists
    theta, phi = x[:n], x[n:]
    tip = tip_position(0.0, theta, phi, l)
    if np.linalg.norm(tip[:2] - problem.target[:2]) >= max(tol, 1e-6):
        return None
    dis = float(problem.target[2] - tip[2])
    ok, _ = problem.feasible(theta[None], phi[None], np.array([dis]))
    if not ok[0] or not -n * l <= dis <= 0.0:
        return None
    return Posture(dis, theta, phi)


def obstacle_clipping(
    context: PlanningContext,
    target: ArrayLike,
    r_target: float = 1.0,
    num: int = 10,
    dtheta: float = math.radians(0.1),
    refine: bool = True,
) -> PlannedPosture:
    """icra2014's collision-free posture for ``target`` in the context's tank.

    The tank's spheres are the obstacles and ``r_b`` is the arm's body radius. Sections are
    added from the fewest that can span the distance until region clipping finds a solution.

    Args:
        context: the planning context (its tank, arm and checks).
        target: [cm].
        r_target: radius of the target zones [cm] (icra2014: 1 cm), where the search stops
            when ``refine`` is False, as in the paper.
        num: NUM (icra2014: 10).
        dtheta: ``Δθ`` [rad] (icra2014: 0.1°).
        refine: go on clipping until the tip is within the context's tolerance (0.01 cm), then
            Gauss–Newton steps where they keep every zone clear.

    Raises:
        PlanningError: "Cannot reach the target: <why>".

    """
    start = time.perf_counter()
    target = context.check_target(target)
    arm = context.arm
    spheres, zones, r_oba, check_tank = _obstacle_zones(context.tank, arm.radius)
    _check_outside_zones(context.tank, target, spheres, zones, r_oba)
    zone = min(r_target, context.tolerance) if refine else r_target
    tolerance = context.tolerance if refine else r_target + 1e-6
    n_min = context.min_sections(float(np.linalg.norm(target)))
    n_max = min(n_min + context.extra_sections, arm.max_sections, _MAX_SECTIONS)
    for n in range(n_min, n_max + 1):
        problem = ObstacleProblem(
            target, n, arm.section_length, arm.theta_max, zones, r_oba, zone, check_tank, arm.radius
        )
        result = obstacle_region_clipping(problem, num, dtheta)
        if result is None:
            continue
        refined = refine_obstacle(problem, result.posture) if refine else None
        posture = refined or result.posture
        details = _details(problem, result, posture, target)
        try:
            return context.checked(posture, target, "obstacle_clipping", tolerance, details, start)
        except PlanningError:
            continue
    raise _no_posture(target, n_min, n_max, r_oba)


def _obstacle_zones(
    tank: Tank, body_radius: float
) -> tuple[list[Sphere], NDArray[np.float64], NDArray[np.float64], Tank]:
    """The spheres, their zones' centres ``(K, 2)`` and radii ``r_oba`` [cm], and the rest.

    Returns:
        The tank's spherical obstacles, the ``(x, y)`` of their obstacle space zones, the zones'
        radii ``r0 + r_b``, and the tank without the spheres (its other solids and walls are
        checked on the backbone).

    """
    spheres = [s for s in tank.obstacles if isinstance(s, Sphere)]
    zones = np.array([s.center[:2] for s in spheres], dtype=np.float64).reshape(-1, 2)
    r_oba = np.array([s.radius + body_radius for s in spheres], dtype=np.float64)
    others = tuple(s for s in tank.solids if not isinstance(s, Sphere))
    check_tank = Tank(
        tank.name, tank.box_min, tank.box_max, tank.panel, obstacles=others, walls=tank.walls
    )
    return spheres, zones, r_oba, check_tank


def _check_outside_zones(
    tank: Tank,
    target: NDArray[np.float64],
    spheres: list[Sphere],
    zones: NDArray[np.float64],
    r_oba: NDArray[np.float64],
) -> None:
    """Raise :class:`PlanningError` when the target (above the floor) is in an obstacle zone."""
    if not len(zones):
        return
    near = np.hypot(zones[:, 0] - target[0], zones[:, 1] - target[1])
    inside = np.flatnonzero(near <= r_oba)
    if target[2] >= tank.panel.center[2] and len(inside):
        i = int(inside[0])
        raise PlanningError(
            f"Cannot reach the target: it lies in the obstacle space zone of "
            f"{spheres[i].name or 'an obstacle'} (the vertical cylinder of radius "
            f"{r_oba[i]:g} cm around it), which the tip may not enter"
        )


def _details(
    problem: ObstacleProblem,
    result: ClippingResult,
    posture: Posture,
    target: NDArray[np.float64],
) -> dict[str, Any]:
    """What the result records of a search: its counters, MDS, zones and errors."""
    search_tip = result.posture.tip(problem.section_length)
    return {
        "sections": problem.n_sections,
        "loops": result.loops,
        "evaluations": result.evaluations,
        "mds": result.mds,
        "r_oba": problem.r_oba.tolist(),
        "zone_clearance_cm": problem.zone_clearance(posture),
        "search_error_cm": float(np.linalg.norm(search_tip - target)),
    }


def _no_posture(
    target: NDArray[np.float64], n_min: int, n_max: int, r_oba: NDArray[np.float64]
) -> PlanningError:
    """The error when no section count from ``n_min`` to ``n_max`` gives a checked posture."""
    where = format_point(target)
    if n_min > _MAX_SECTIONS:
        return PlanningError(
            f"Cannot reach the target: {where} cm needs {n_min} sections; region clipping over "
            f"every θ and φ searches at most {_MAX_SECTIONS} sections (with more, even its "
            f"coarsest grid, 3^{2 * (_MAX_SECTIONS + 1)} combinations a loop, is too large)"
        )
    keeps_out = ""
    if len(r_oba):
        keeps_out = f" that keeps out of the obstacle zones (r_oba = {_radii(r_oba)} cm) and"
    return PlanningError(
        f"Cannot reach the target: region clipping found no posture of {n_min} to {n_max} "
        f"sections{keeps_out} reaches {where} cm"
    )


def _radii(r: NDArray[np.float64]) -> str:
    return ", ".join(f"{v:g}" for v in np.unique(r))


OBSTACLE_CLIPPING = Method(
    "obstacle_clipping",
    "region clipping over every angle among spherical obstacles' zones",
    obstacle_clipping,
    paper="icra2014",
    bench_sets=("jace", "icra2014", "bay1"),
)
