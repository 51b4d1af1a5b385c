"""Inspection coverage: viewpoints whose routes let the tip camera see a share of a bay's surface.

:func:`plan_coverage` samples the bay's surface by area, plans a tree of follow-the-leader
routes to a lattice of candidate viewpoints (:func:`~aftir_rl.planning.ftl.tree.grow_tree`),
tells which samples the camera sees from the poses along each route (the compiled
:func:`~aftir_rl.core.kernel.visibility.seen_by_groups`), picks routes greedily by the area
they add until the share is reached, and tours the picks
(:func:`~aftir_rl.planning.ftl.tour.tour_of_tree`). Along a follow-the-leader motion the tip
passes every point of its route, so the tour sees what its routes see. The share a motion
achieves is measured apart by :func:`aftir_rl.experiments.coverage.measure_coverage`.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.camera import Camera
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import ConfigError, PlanningError
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.visibility import seen_by_groups
from aftir_rl.core.robot import body_points
from aftir_rl.core.tank import Tank
from aftir_rl.core.tank.surface import SurfaceSamples, surface_samples
from aftir_rl.planning.ftl.model import Route, kappa_to_angles
from aftir_rl.planning.ftl.tour import Tour, tour_of_tree
from aftir_rl.planning.ftl.tree import RouteTree, grow_tree, shared

__all__ = ["CoveragePlan", "plan_coverage", "route_poses", "seen_by_routes", "viewpoint_lattice"]

#: Spacing [cm] of the camera poses along a route.
POSE_STEP = 2.0
#: The pick aims this many standard errors of the samples' share above the goal.
AIM_ERRORS = 1.5
#: A lattice whose routes fall short of the goal is tried again this much finer, down to
#: :data:`MIN_SPACING` [cm].
REFINE = 0.7
MIN_SPACING = 14.0
#: Candidate viewpoints stay this far [cm] from every surface.
VIEWPOINT_CLEARANCE = 10.0


@dataclass
class CoveragePlan:
    """A coverage tour and what its planner expects it to see.

    Attributes:
        tour: the tour of the chosen viewpoints (its ``targets``).
        goal: the share of the surface asked for.
        estimate: the share of the samples the chosen routes see (the planner's estimate).
        candidates: the candidate viewpoints ``(C, 3)`` [cm], and ``planned`` how many had a route.
        spacing: the spacing of their lattice [cm].
        samples: the surface samples the estimate counts.
        seconds: planning time [s].

    """

    tour: Tour
    goal: float
    estimate: float
    candidates: NDArray[np.float64]
    planned: int
    spacing: float
    samples: SurfaceSamples
    seconds: float

    def report_json(self) -> dict[str, Any]:
        """``coverage.json``: the goal, the estimate and how it was made."""
        return {
            "goal": self.goal,
            "estimate": self.estimate,
            "viewpoints": len(self.tour.order),
            "candidates": len(self.candidates),
            "candidates_planned": self.planned,
            "spacing_cm": self.spacing,
            "surface_samples": len(self.samples.points),
            "surface_area_cm2": self.samples.area_cm2,
            "seconds": self.seconds,
        }


def viewpoint_lattice(
    tank: Tank, box: tuple[ArrayLike, ArrayLike], spacing: float, seed: int = 0
) -> NDArray[np.float64]:
    """Points of a lattice over ``box`` (shifted by ``seed``) that are clear and reachable.

    At least :data:`VIEWPOINT_CLEARANCE` from every surface, in a raster cell reachable from
    the start.
    """
    lo, hi = (np.asarray(b, dtype=np.float64) for b in box)
    lo, hi = lo + VIEWPOINT_CLEARANCE, hi - VIEWPOINT_CLEARANCE
    if np.any(hi <= lo) or not spacing > 0:
        raise ConfigError(f"{tank.name}: no room for viewpoints in {lo.tolist()}..{hi.tolist()}")
    shift = np.random.default_rng(seed).uniform(0.0, 1.0, 3)
    axes = []
    for a, b, u in zip(lo, hi, shift):
        n = max(1, int(np.floor((b - a) / spacing)))
        axes.append(a + (b - a) * (np.arange(n) + u) / n)
    points = np.array(list(itertools.product(*axes)), dtype=np.float64)
    points = points[tank.distance(points) >= VIEWPOINT_CLEARANCE]
    cells = [tank.raster.point_to_cell(p) for p in points]
    keep = [i for i, c in enumerate(cells) if tank.reachable[c] > 0]
    return points[keep].round(2)


def route_poses(route: Route, step: float = POSE_STEP) -> tuple[NDArray[np.float64], ...]:
    """Tip positions ``(P, 3)`` along a route's bent sections and the unit tangents there."""
    theta, phi = kappa_to_angles(route.kappa)
    k = max(2, int(np.ceil(route.section_length / step)))
    points = body_points(route.lead, theta, phi, route.section_length, k)
    looks = np.diff(points, axis=0)
    looks /= np.linalg.norm(looks, axis=1, keepdims=True)
    return points[1:], looks


def seen_by_routes(
    tank: Tank, routes: list[Route], samples: SurfaceSamples, camera: Camera | None = None
) -> NDArray[np.bool_]:
    """``(R, S)``: which samples the camera sees from some pose along each route."""
    poses = [route_poses(route) for route in routes]
    starts = np.cumsum([0] + [len(p) for p, _ in poses]).astype(np.int64)
    out = np.zeros((len(routes), len(samples.points)), dtype=np.bool_)
    if routes:
        seen_by_groups(
            np.vstack([p for p, _ in poses]),
            np.vstack([w for _, w in poses]),
            starts,
            samples.points,
            samples.normals,
            (camera or tank.arm.camera).cosines(),
            kernel_grid(tank),
            out,
        )
    return out


def _greedy(seen: NDArray[np.bool_], goal: float) -> tuple[list[int], float]:
    """Rows picked one by one by the columns they add until ``goal`` of them are covered."""
    covered, picks = np.zeros(seen.shape[1], dtype=np.bool_), []
    while len(seen) and covered.mean() < goal:
        gain = seen[:, ~covered].sum(axis=1)
        best = int(np.argmax(gain))
        if gain[best] == 0:
            break
        picks.append(best)
        covered |= seen[best]
    return picks, float(covered.mean())


def _most_shared(routes: dict[int, Route], k: int) -> tuple[int | None, int]:
    """The route that shares most sections with route ``k``, and how many (``None``, 0: none)."""
    best = max(((shared(routes[k], r)[1], i) for i, r in routes.items() if i != k), default=(0, 0))
    return (best[1], best[0]) if best[0] else (None, 0)


def plan_coverage(
    tank: Tank,
    box: tuple[ArrayLike, ArrayLike],
    goal: float = 0.9,
    spacing: float = 30.0,
    samples: int = 3000,
    seed: int = 0,
    margin: float = DEFAULT_MARGIN,
    solver_seconds: float = 2.0,
    progress: Callable[[str], None] | None = None,
) -> CoveragePlan:
    """A tour whose tip camera sees ``goal`` of the surface in ``box`` (or as much as it can).

    ``samples`` surface points are drawn by area; candidate viewpoints lie on a lattice of
    ``spacing`` cm, made :data:`REFINE` times finer while their routes see too little (the
    lattice whose routes see most is kept); ``seed`` sets both.

    Raises :class:`~aftir_rl.core.errors.PlanningError` when no candidate has a route that
    sees any of the surface.
    """
    start, say = time.perf_counter(), progress or (lambda text: None)
    if not 0 < goal <= 1:
        raise ConfigError(f"coverage goal must be in (0, 1], got {goal:g}")
    surface = surface_samples(tank, box, samples, seed)
    # aimed a little above the goal: a fresh sample of the surface should measure at least it
    aim = min(1.0, goal + AIM_ERRORS * np.sqrt(goal * (1 - goal) / len(surface.points)))
    best: tuple[float, Any] | None = None
    while True:
        candidates = viewpoint_lattice(tank, box, spacing, seed)
        say(f"{len(surface.points)} surface samples, {len(candidates)} candidate viewpoints")
        # one sweep: a viewpoint may take its own route anyway (step 2 of docs/robot.md)
        tree, _ = grow_tree(tank, candidates, margin, lambda text: None, sweeps=1)
        # a viewpoint's route: the tree's (sharing more) or its own (seeing other things)
        rows = [(j, tree.routes[j]) for j in sorted(tree.routes)]
        rows += [(j, r) for j, r in sorted(tree.own.items()) if r is not tree.routes.get(j)]
        picks, estimate = _greedy(seen_by_routes(tank, [r for _, r in rows], surface), aim)
        say(f"{len(rows)} routes; {len(picks)} viewpoints see {100 * estimate:.1f}% of it")
        if picks and (best is None or estimate > best[0]):
            best = (estimate, (candidates, tree, rows, picks, spacing))
        if estimate >= aim or spacing * REFINE < MIN_SPACING:
            break
        spacing *= REFINE  # short of the goal: a finer lattice
    if best is None:
        raise PlanningError("no candidate viewpoint has a route that sees any of the surface")
    estimate, (candidates, tree, rows, picks, spacing) = best
    chosen = [rows[p] for p in picks]
    routes = dict(enumerate(route for _, route in chosen))
    sub = RouteTree(
        candidates[[j for j, _ in chosen]],
        routes=routes,
        own={k: tree.own[j] for k, (j, _) in enumerate(chosen) if j in tree.own},
        branches={k: _most_shared(routes, k) for k in routes},
    )
    tour = tour_of_tree(tank, sub, margin, solver_seconds, trips=False)
    seconds = time.perf_counter() - start
    tour.seconds = seconds
    return CoveragePlan(
        tour, goal, estimate, candidates, len(tree.routes), spacing, surface, seconds
    )
