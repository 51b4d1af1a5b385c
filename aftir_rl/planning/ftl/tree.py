"""The route tree of a tour: targets' routes that continue prefixes of each other's.

:func:`grow_tree` plans every target's follow-the-leader route, each as a continuation of a
prefix of a route already planned where it can (:func:`plan_motion`'s ``prefix``), so that
routes share their first sections; :func:`shared` says how far two routes are the same. The
tours (:mod:`aftir_rl.planning.ftl.tour`) and the coverage planner build on it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.robot import forward_kinematics
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.model import Route, kappa_to_angles
from aftir_rl.planning.ftl.plan import SEARCH_VARIANTS, plan_motion

__all__ = ["RouteTree", "grow_tree", "shared", "union_length", "BRANCH_TRIES"]

#: Prefixes of the tree a new target's route is tried from (the nearest ends first).
BRANCH_TRIES = 8


@dataclass
class RouteTree:
    """The routes planned so far (by target index), where each came from, and each target's own.

    ``own``: the route planned alone (what one deployment per target uses).
    """

    targets: NDArray[np.float64]
    routes: dict[int, Route] = field(default_factory=dict)
    own: dict[int, Route] = field(default_factory=dict)
    branches: dict[int, tuple[int | None, int]] = field(default_factory=dict)

    def prefixes(self, target: NDArray[np.float64], l: float) -> list[tuple[float, int, Route]]:
        """Distinct prefixes of the routes ending 0.5-6 sections from it, the nearest first."""
        found: dict[bytes, tuple[float, int, Route]] = {}
        for i in self.routes:
            route = self.routes[i]
            theta, phi = kappa_to_angles(route.kappa)
            ends = forward_kinematics(route.lead, theta, phi, l)[1:-1, :3, 3]  # after 1..M-1
            for d, end in enumerate(ends, start=1):
                gap = float(np.linalg.norm(end - target))
                key = np.append(route.kappa[:d].ravel(), route.lead).tobytes()
                if 0.5 * l <= gap <= 6.0 * l and key not in found:
                    found[key] = (gap, i, Route(route.lead, route.kappa[:d], l))
        return sorted(found.values(), key=lambda item: item[0])[:BRANCH_TRIES]


def shared(a: Route, b: Route) -> tuple[float, int]:
    """The arc length [cm] up to which two routes are the same, and their shared sections.

    Up to the shorter straight lead when they differ there (the arm is straight on the axis).
    """
    if a.lead != b.lead:
        return min(a.lead, b.lead), 0
    d = 0
    while d < min(len(a.kappa), len(b.kappa)) and np.array_equal(a.kappa[d], b.kappa[d]):
        d += 1
    return a.lead + d * a.section_length, d


def union_length(routes: Sequence[Route]) -> float:
    """The length [cm] of the union of routes, shared prefixes counted once.

    The straight lead to the highest first bend, and every distinct section once (routes with
    the same lead and first sections share them).
    """
    if not routes:
        return 0.0
    keys = {
        np.append(route.kappa[:d].ravel(), route.lead).tobytes()
        for route in routes
        for d in range(1, route.n_route_sections + 1)
    }
    return max(route.lead for route in routes) + len(keys) * routes[0].section_length


def _improve(tank: Tank, tree: RouteTree, j: int, margin: float) -> None:
    """Replace target ``j``'s route by the continuation of a prefix that shortens the union most."""
    target, others = tree.targets[j], [r for i, r in tree.routes.items() if i != j]
    best = union_length([*others, tree.routes[j]]) if j in tree.routes else np.inf
    for _, i, prefix in tree.prefixes(target, tank.arm.section_length):
        if i == j:
            continue
        plan = plan_motion(tank, target, margin=margin, prefix=prefix, variants=SEARCH_VARIANTS[:2])
        if plan.complete and plan.motion is not None:
            length = union_length([*others, plan.motion.route])
            if length < best - 1e-6:
                best, tree.routes[j] = length, plan.motion.route
                tree.branches[j] = (i, prefix.n_route_sections)


def grow_tree(
    tank: Tank,
    targets: NDArray[np.float64],
    margin: float,
    say: Callable[[str], None],
    sweeps: int = 2,
) -> tuple[RouteTree, list[tuple[int, str]]]:
    """The tree of routes, and the targets no motion reaches (with the reason).

    Every target first gets its own motion (``own``: what one deployment each would use). Then,
    nearest the panel first, each target's route becomes the continuation of a prefix of the
    tree that makes the union of the routes shortest, if one does better than its own; each
    further sweep tries again with every route in the tree.
    """
    tree, failures = RouteTree(targets), []
    order = np.argsort(np.linalg.norm(targets, axis=1)).tolist()
    for j in order:
        plan = plan_motion(tank, targets[j], margin=margin)
        if plan.complete and plan.motion is not None:
            tree.own[j] = plan.motion.route
        else:
            failures.append((j, plan.reason or "no motion"))
    for sweep in range(sweeps):
        for j in order:
            if sweep == 0 and j in tree.own:
                tree.routes[j], tree.branches[j] = tree.own[j], (None, 0)
            if tree.routes or sweep:
                _improve(tank, tree, j, margin)
            if sweep == sweeps - 1:
                say(f"target {j}: {'no motion' if j not in tree.routes else 'planned'}")
    return tree, sorted(f for f in failures if f[0] not in tree.routes)
