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

__all__ = ["RouteTree", "grow_tree", "shared", "BRANCH_TRIES"]

#: Prefixes of the tree a new target's route is tried from (the nearest ends first).
BRANCH_TRIES = 8


@dataclass
class RouteTree:
    """The routes planned so far (by target index) and where each came from."""

    targets: NDArray[np.float64]
    routes: dict[int, Route] = field(default_factory=dict)
    branches: dict[int, tuple[int | None, int]] = field(default_factory=dict)

    def prefixes(
        self, target: NDArray[np.float64], l: float, among: Sequence[int] | None = None
    ) -> list[tuple[float, int, Route]]:
        """Distinct prefixes of the routes (or ``among``'s) ending 0.5-6 sections from it."""
        found: dict[bytes, tuple[float, int, Route]] = {}
        for i in self.routes if among is None else among:
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


def _branch(
    tank: Tank, tree: RouteTree, j: int, margin: float, among: Sequence[int] | None = None
) -> bool:
    """Plan target ``j``'s route as a continuation of a prefix of the tree; whether one was."""
    target = tree.targets[j]
    for _, i, prefix in tree.prefixes(target, tank.arm.section_length, among):
        if i == j:
            continue
        plan = plan_motion(tank, target, margin=margin, prefix=prefix, variants=SEARCH_VARIANTS[:2])
        if plan.complete and plan.motion is not None:
            tree.routes[j] = plan.motion.route
            tree.branches[j] = (i, prefix.n_route_sections)
            return True
    return False


def grow_tree(
    tank: Tank, targets: NDArray[np.float64], margin: float, say: Callable[[str], None]
) -> tuple[RouteTree, list[tuple[int, str]]]:
    """The tree of routes, and the targets no motion reaches (with the reason).

    Nearest the panel first, each target continues a prefix of the tree where it can, else gets
    a route of its own (a root); then every route that shares no section with the largest
    family of routes tries again from that family's prefixes.
    """
    tree, failures = RouteTree(targets), []
    order = np.argsort(np.linalg.norm(targets, axis=1)).tolist()
    for j in order:
        if not tree.routes or not _branch(tank, tree, j, margin):
            plan = plan_motion(tank, targets[j], margin=margin)
            if plan.complete and plan.motion is not None:
                tree.routes[j], tree.branches[j] = plan.motion.route, (None, 0)
            else:
                failures.append((j, plan.reason or "no motion"))
        say(f"target {j}: {'no motion' if j not in tree.routes else 'planned'}")

    # the routes that do not share a section with the trunk most share try again from it
    def family(k: int) -> list[int]:
        return [i for i in tree.routes if shared(tree.routes[i], tree.routes[k])[1] > 0]

    trunk = max(tree.routes, key=lambda k: len(family(k)))
    for j in order:
        if j in tree.routes and j not in family(trunk):
            _branch(tank, tree, j, margin, among=family(trunk))
    return tree, sorted(failures)
