"""Inspection tours: one deployment that visits many targets, retracting only where routes part.

:func:`plan_tour` grows a tree of follow-the-leader routes (:mod:`~aftir_rl.planning.ftl.tree`: a
target's route continues a prefix of another's where it can), so the arm at one target retracts only
to where the next target's route departs from its own. The cost of going from target ``i`` to ``j``
is the time-optimal duration of retracting ``i`` to their common prefix plus deploying ``j`` from it
(:mod:`aftir_rl.planning.timing`, each leg from rest to rest); the visiting order is a
travelling-salesman tour over those costs from the panel and back, solved by OR-Tools (the ``robot``
extra). A target near another may instead be visited by a side trip from it
(:mod:`~aftir_rl.planning.ftl.side_trip`: the last sections bend there and back). docs/robot.md has
the details and measurements.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import PlanningError
from aftir_rl.core.extras import require
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.model import FTLMotion, Route, ftl_motion, kappa_to_angles
from aftir_rl.planning.ftl.plan import postures_clearance
from aftir_rl.planning.ftl.side_trip import (
    SideTrip,
    choose_side_trips,
    host_postures,
    side_trips,
    straight_move,
)
from aftir_rl.planning.ftl.tree import RouteTree, grow_tree, shared
from aftir_rl.planning.timing import TimedMotion, joint_positions, time_motion

__all__ = ["Tour", "plan_tour", "tour_of_tree"]


@dataclass
class Tour:
    """A planned tour: the order, the one motion that visits every target, its time.

    Attributes:
        targets: the targets asked for [cm], ``(K, 3)``.
        order: the reached targets' indices in visiting order.
        motion: ``dis (T,)``, ``theta``, ``phi (T, N)`` of the whole deployment, in order.
        timing: its schedule (each leg from rest to rest).
        arrivals: the motion entry at which each target of ``order`` is reached.
        legs: per leg ``{"from", "to", "depart_cm", "duration_s"}`` (``None``: the panel).
        branches: per reached target the target whose route it continues and the sections
            shared (``None`` and 0 for a route of its own).
        separate_s: the duration of one deployment and retraction per target along its own route
            (planned alone; the tree's route where it has none).
        failures: ``(index, reason)`` of the targets no motion reaches.
        min_clearance_cm: the least clearance of the arm's surface along the motion.
        section_length: ``l`` [cm].
        margin_cm: the margin the motion keeps.
        seconds: planning time [s].
        side_trips: the targets visited by a side trip, each with the target it is made from.

    """

    targets: NDArray[np.float64]
    order: list[int]
    motion: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
    timing: TimedMotion
    arrivals: list[int]
    legs: list[dict[str, Any]]
    branches: dict[int, tuple[int | None, int]]
    separate_s: float
    failures: list[tuple[int, str]]
    min_clearance_cm: float
    section_length: float
    margin_cm: float
    seconds: float = 0.0
    side_trips: dict[int, int] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """The tour's duration [s]."""
        return self.timing.duration

    def trajectory_json(self) -> dict[str, Any]:
        """The tour as ``trajectory.json`` (the motion contract, every entry with its time)."""
        dis, theta, phi = self.motion
        entries = [
            {"dis": float(d), "theta": th.tolist(), "phi": ph.tolist(), "t": float(t)}
            for d, th, ph, t in zip(dis, theta, phi, self.timing.t)
        ]
        return {
            "complete": not self.failures,
            "method": "ftl-tour",
            "margin_cm": self.margin_cm,
            "section_length": self.section_length,
            "seconds": self.seconds,
            "n_sections": int(theta.shape[1]),
            "targets": self.targets.tolist(),
            "motion": entries,
            "waypoint_index": self.arrivals,
            "min_clearance_cm": self.min_clearance_cm,
            "duration_s": self.duration,
            "timing": self.timing.to_json(),
        }

    def report_json(self) -> dict[str, Any]:
        """``tour.json``: order, legs, branches, durations and their ratio."""
        return {
            "targets": self.targets.tolist(),
            "order": self.order,
            "legs": self.legs,
            "branches": [
                {"target": j, "continues": i, "sections_shared": d}
                for j, (i, d) in self.branches.items()
            ],
            "side_trips": [{"target": j, "from": h} for j, h in self.side_trips.items()],
            "failures": [{"target": i, "reason": r} for i, r in self.failures],
            "duration_s": self.duration,
            "separate_deployments_s": self.separate_s,
            "ratio": self.duration / self.separate_s if self.separate_s else None,
            "min_clearance_cm": self.min_clearance_cm,
            "seconds": self.seconds,
        }


#: Where a leg from or to the panel turns: before every deployment's first entry.
PANEL = -np.inf


def _part(motion: FTLMotion, s0: float) -> slice:
    """The entries of a deployment from its last entry at or before arc length ``s0`` [cm]."""
    first = int(np.searchsorted(motion.s, s0 + 1e-9, side="right")) - 1
    return slice(max(first, 0), len(motion))


def _order(costs: NDArray[np.float64], seconds: float) -> list[int]:
    """The cheapest cycle from node 0 through every node (OR-Tools routing), without node 0."""
    cp = require("ortools.constraint_solver.pywrapcp", "robot")
    enums = require("ortools.constraint_solver.routing_enums_pb2", "robot")
    millis = np.rint(costs * 1000).astype(np.int64)
    manager = cp.RoutingIndexManager(len(costs), 1, 0)
    model = cp.RoutingModel(manager)
    arc = model.RegisterTransitCallback(
        lambda a, b: int(millis[manager.IndexToNode(a), manager.IndexToNode(b)])
    )
    model.SetArcCostEvaluatorOfAllVehicles(arc)
    params = cp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = enums.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = enums.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    params.time_limit.FromMilliseconds(int(seconds * 1000))
    solution = model.SolveWithParameters(params)
    if solution is None:  # none within the time: the cheapest next target each time
        return _nearest_first(costs)
    node, out = model.Start(0), []
    while not model.IsEnd(node):
        out.append(manager.IndexToNode(node))
        node = solution.Value(model.NextVar(node))
    return [n for n in out if n != 0]


def _nearest_first(costs: NDArray[np.float64]) -> list[int]:
    """A cycle from node 0 that goes to the cheapest unvisited node each time."""
    out, left = [0], set(range(1, len(costs)))
    while left:
        out.append(min(left, key=lambda n: costs[out[-1], n]))
        left.remove(out[-1])
    return out[1:]


def _joined(pieces: list[tuple[Any, ...]], postures: tuple[Any, ...], limits: Any) -> TimedMotion:
    """One schedule of the pieces in turn (each from rest to rest: the path reverses between).

    A piece is ``(dis, theta, phi, target reached or None, its schedule)``; each after the
    first starts with the last entry of the one before, which is kept once (``postures``: the
    pieces' postures so joined).
    """
    timed = [p[4] for p in pieces]
    kept = [slice(1 if k else 0, None) for k in range(len(timed))]
    offsets = np.concatenate([[0.0], np.cumsum([x.duration for x in timed])])
    t = np.concatenate([x.t[keep] + off for x, keep, off in zip(timed, kept, offsets)])
    velocities = np.concatenate([x.velocities[keep] for x, keep in zip(timed, kept)])
    accelerations = np.concatenate([x.accelerations[keep] for x, keep in zip(timed, kept)])
    seconds = sum(x.seconds for x in timed)
    return TimedMotion.from_rates(postures, t, (velocities, accelerations), limits, seconds)


def plan_tour(
    tank: Tank,
    targets: ArrayLike,
    margin: float = DEFAULT_MARGIN,
    solver_seconds: float = 2.0,
    progress: Callable[[str], None] | None = None,
    trips: bool = True,
) -> Tour:
    """One follow-the-leader deployment that visits every reachable target and comes back.

    With ``trips``, targets near another one are visited by side trips from it where that is
    quicker. Targets no motion reaches are left out and listed in ``failures``; raises
    :class:`~aftir_rl.core.errors.PlanningError` when none is reached.
    """
    start, say = time.perf_counter(), progress or (lambda text: None)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    tree, failures = grow_tree(tank, targets, margin, say)
    if not tree.routes:
        raise PlanningError("no target of the tour has a motion: " + failures[0][1])
    roots = sum(i is None for i, _ in tree.branches.values())
    say(f"route tree: {len(tree.routes)} routes from {roots} of their own")
    tour = tour_of_tree(tank, tree, margin, solver_seconds, trips)
    tour.failures, tour.seconds = failures, time.perf_counter() - start
    return tour


def tour_of_tree(
    tank: Tank,
    tree: RouteTree,
    margin: float = DEFAULT_MARGIN,
    solver_seconds: float = 2.0,
    trips: bool = True,
) -> Tour:
    """The tour that visits every target of a planned tree (``seconds``: this call's time).

    ``trips``: visit targets by side trips where that is quicker
    (:mod:`~aftir_rl.planning.ftl.side_trip`; a coverage tour, which sees along its routes,
    does not).

    Raises :class:`~aftir_rl.core.errors.PlanningError` where the joined motion keeps less
    than ``margin``.
    """
    start = time.perf_counter()
    n = max(route.min_sections() for route in [*tree.routes.values(), *tree.own.values()])
    motions = _deployments(tank, tree.routes, n)
    tour = _assemble(tank, tree, motions, margin, solver_seconds, trips)
    if tour.min_clearance_cm < margin:  # where two legs meet, a joining move grazes the tank
        raise PlanningError(
            f"the joined tour keeps only {tour.min_clearance_cm:.2f} cm of the margin {margin:g} cm"
        )
    tour.seconds = time.perf_counter() - start
    return tour


def _deployments(tank: Tank, routes: dict[int, Route], n: int) -> dict[int, FTLMotion]:
    """Each route's deployment with ``n`` sections (the tour's arm).

    Without the entries that repeat the one before: deployments with more sections than their
    route needs repeat a posture at some stages (to 1e-13 cm), and a schedule needs time to move.
    """
    arm = tank.arm
    h0 = min(float(tank.start_point[2]), 20.0)
    out = {}
    for j, route in routes.items():
        m = ftl_motion(route, n, h0, theta_max=arm.theta_max)
        q = joint_positions(m.dis, m.theta, m.phi)
        keep = np.concatenate([[True], np.abs(np.diff(q, axis=0)).max(axis=1) > 1e-9])
        out[j] = replace(m, s=m.s[keep], dis=m.dis[keep], theta=m.theta[keep],
                         phi=m.phi[keep], stage_index=())  # fmt: skip
    return out


@dataclass
class _Legs:
    """The legs between targets: where two routes part, and the timed parts of deployments."""

    tank: Tank
    tree: RouteTree
    motions: dict[int, FTLMotion]
    suffix: dict[tuple[int, float], TimedMotion] = field(default_factory=dict)

    def depart(self, a: int | None, b: int | None) -> float:
        """Where the leg from ``a`` to ``b`` turns back (``None``: the panel)."""
        if a is None or b is None:
            return PANEL
        return shared(self.tree.routes[a], self.tree.routes[b])[0]

    def timed_from(self, j: int, s0: float) -> TimedMotion:
        """The time-optimal schedule of target ``j``'s deployment from arc length ``s0`` [cm]."""
        if (j, s0) not in self.suffix:
            m, part, arm = self.motions[j], _part(self.motions[j], s0), self.tank.arm
            self.suffix[j, s0] = time_motion(m.dis[part], m.theta[part], m.phi[part],
                                             arm.section_length, arm.limits)  # fmt: skip
        return self.suffix[j, s0]

    def duration_from(self, j: int, s0: float) -> float:
        """The duration of :meth:`timed_from` [s]."""
        return self.timed_from(j, s0).duration

    def costs(self, index: list[int]) -> NDArray[np.float64]:
        """Leg durations between the panel (node 0) and the targets ``index`` (nodes 1..)."""
        out = np.zeros((len(index) + 1,) * 2)
        for a, i in enumerate([None, *index]):
            for b, j in enumerate([None, *index]):
                if a != b:
                    s0 = self.depart(i, j)
                    out[a, b] = sum(self.duration_from(k, s0) for k in (i, j) if k is not None)
        return out

    def pieces(
        self, order: list[int], trips: dict[int, SideTrip]
    ) -> tuple[list[tuple[Any, ...]], list[dict[str, Any]]]:
        """The motion's pieces in turn (``(dis, theta, phi, target reached or None)``) and legs.

        ``order``: the targets visited by their routes; ``trips``: the others, by target, each
        made (there and back) right after its host is reached.
        """
        pieces, legs = [], []
        stops: list[int | None] = [None, *order, None]
        for a, b in zip(stops[:-1], stops[1:]):
            s0 = self.depart(a, b)
            ends = [j for j in (a, b) if j is not None]
            legs.append({"from": a, "to": b, "depart_cm": s0 if s0 > PANEL else None,
                         "duration_s": sum(self.duration_from(j, s0) for j in ends)})  # fmt: skip
            for j, step in ((a, -1), (b, 1)):  # retract a to s0, then deploy b from it
                if j is not None:
                    m, part = self.motions[j], _part(self.motions[j], s0)
                    arrays = (m.dis[part][::step], m.theta[part][::step], m.phi[part][::step])
                    timed = self.timed_from(j, s0)
                    pieces.append((*arrays, j if step == 1 else None,
                                   timed if step == 1 else _backwards(timed)))  # fmt: skip
            for trip in (t for t in trips.values() if t.host == b):
                dis, theta, phi = trip.path
                pieces.append((dis, theta, phi, trip.target, trip.timed))
                pieces.append((dis[::-1], theta[::-1], phi[::-1], None, _backwards(trip.timed)))
                legs.append({"from": b, "to": trip.target, "depart_cm": None,
                             "duration_s": 2 * trip.duration, "side_trip": True})  # fmt: skip
        return _bridged(pieces, self.tank), legs


def _visits(
    legs_of: _Legs, margin: float, solver_seconds: float, trips: bool
) -> tuple[list[int], dict[int, SideTrip]]:
    """The targets visited by their routes, in order, and those visited by side trips."""
    index = sorted(legs_of.motions)
    if len(index) < 2:
        return index, {}
    costs = legs_of.costs(index)
    order = [index[n - 1] for n in _order(costs, solver_seconds)]
    if not trips:
        return order, {}
    hosts = host_postures({j: (m.dis, m.theta, m.phi) for j, m in legs_of.motions.items()})
    found = side_trips(legs_of.tank, hosts, legs_of.tree.targets, margin)
    kept, chosen = choose_side_trips(costs, index, order, found)
    if chosen and len(kept) > 2:  # the order of the targets left, solved again
        nodes = [0, *(index.index(j) + 1 for j in kept)]
        again = [kept[n - 1] for n in _order(costs[np.ix_(nodes, nodes)], solver_seconds)]
        kept = min(kept, again, key=lambda o: _cycle(costs, index, o))
    return kept, chosen


def _cycle(costs: NDArray[np.float64], index: list[int], order: list[int]) -> float:
    """The legs' duration of visiting ``order`` from the panel and back [s]."""
    stops = [0, *(index.index(j) + 1 for j in order), 0]
    return float(sum(costs[a, b] for a, b in zip(stops[:-1], stops[1:])))


def _assemble(
    tank: Tank,
    tree: RouteTree,
    motions: dict[int, FTLMotion],
    margin: float,
    solver_seconds: float,
    trips: bool,
) -> Tour:
    """Order the targets by the legs' durations and join their motions into one."""
    legs_of = _Legs(tank, tree, motions)
    order, chosen = _visits(legs_of, margin, solver_seconds, trips)
    pieces, legs = legs_of.pieces(order, chosen)
    arrivals, total, visited = [], 0, []
    for n, piece in enumerate(pieces):
        total += len(piece[0]) - (1 if n else 0)
        if piece[3] is not None:
            arrivals.append(total - 1)
            visited.append(piece[3])
    dis, theta, phi = (
        np.concatenate([p[c][1 if n else 0 :] for n, p in enumerate(pieces)]) for c in range(3)
    )
    return Tour(
        targets=tree.targets,
        order=visited,
        motion=(dis, theta, phi),
        timing=_joined(pieces, (dis, theta, phi), tank.arm.limits),
        arrivals=arrivals,
        legs=legs,
        branches={j: tree.branches[j] for j in order},
        separate_s=_separate_s(tank, tree, legs_of),
        failures=[],
        min_clearance_cm=postures_clearance(tank, dis, theta, phi),
        section_length=tank.arm.section_length,
        margin_cm=margin,
        side_trips={j: trip.host for j, trip in chosen.items()},
    )


def _separate_s(tank: Tank, tree: RouteTree, legs: _Legs) -> float:
    """One deployment and retraction per target along its own route (the baseline).

    A target whose tour route is its own reuses the tour's timed deployment.
    """
    n, arm = next(iter(legs.motions.values())).theta.shape[1], tank.arm
    other = {j: r for j, r in tree.own.items() if j in legs.motions and r is not tree.routes[j]}
    total = sum(legs.duration_from(j, PANEL) for j in legs.motions if j not in other)
    for m in _deployments(tank, other, n).values():
        total += time_motion(m.dis, m.theta, m.phi, arm.section_length, arm.limits).duration
    return 2 * total


def _bridged(pieces: list[tuple[Any, ...]], tank: Tank) -> list[tuple[Any, ...]]:
    """The pieces, with a straight joint-space move where one does not start where the last ends.

    (The same prefix deployed to slightly different postures, or a straight arm at two
    heights.) Dense (:func:`~aftir_rl.planning.ftl.side_trip.straight_move`); timed like the
    pieces.
    """
    arm, out = tank.arm, [pieces[0]]
    for nxt in pieces[1:]:
        prev = out[-1]
        a = joint_positions(prev[0][-1:], prev[1][-1:], prev[2][-1:])[0]
        b = joint_positions(nxt[0][:1], nxt[1][:1], nxt[2][:1])[0]
        if np.abs(a - b).max() > 1e-9:
            dis, theta, phi = straight_move(a, b, arm)
            timed = time_motion(dis, theta, phi, arm.section_length, arm.limits)
            out.append((dis, theta, phi, None, timed))
        out.append(nxt)
    return out


def _backwards(timed: TimedMotion) -> TimedMotion:
    """A schedule run backwards: the same path from its end (the limits are symmetric)."""
    return TimedMotion.from_rates(
        (
            timed.positions[::-1, 0],
            *kappa_to_angles(timed.positions[::-1, 1:].reshape(len(timed.t), -1, 2)),
        ),
        timed.duration - timed.t[::-1],
        (-timed.velocities[::-1], timed.accelerations[::-1]),
        timed.limits,
        timed.seconds,
    )
