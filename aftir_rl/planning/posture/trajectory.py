"""From a learned tip path to joint variables along it (filomat2018 §5).

Every cell centre of the greedy path gets a posture, and the last posture reaches the exact
target. The paper plans each with TGA (bay 1) or TSM (beyond the hatch); those of neighbouring
cells can differ by a half turn in a joint, so here each posture is *continued* from the previous
one (damped least squares, collisions repaired in the null space of the tip's Jacobian, colliding
sub-steps split; :mod:`aftir_rl.planning.posture.continuation`), with the planner's posture as a
fallback. A second chain *slides* the arm in along itself (:func:`slide`) when the first has a
colliding move; a move that still collides gets RRT-Connect
(:func:`~aftir_rl.planning.jointspace.bridge`), then is reported in ``blocked_moves``, and a cell
with no posture in ``failures``. Every move is checked densely.

Why each step, and what it does to the reference paths: docs/design.md §7.2.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.config import DEFAULT_BRIDGE_SECONDS
from aftir_rl.core.errors import PlanningError
from aftir_rl.core.robot import Posture, forward_kinematics
from aftir_rl.planning.jointspace import (
    align,
    bridge,
    densify,
    first_collision,
    pad_sections,
    sampled_clearance,
    tip_path_length,
)
from aftir_rl.planning.posture.context import PlannedPosture, PlanningContext
from aftir_rl.planning.posture.continuation import continue_posture, repair_posture, slide
from aftir_rl.planning.posture.planner import Planner

__all__ = [
    "DEFAULT_BRIDGE_SECONDS",
    "Trajectory",
    "plan_trajectory",
    "continue_posture",
    "repair_posture",
    "pad_sections",
    "slide",
]


@dataclass
class Trajectory:
    """Postures along a tip path.

    Attributes:
        waypoints: the points planned for [cm]: the path's cell centres, then the exact target.
        postures: one per waypoint, None where none was found.
        failures: ``(index, point, reason)`` for waypoints without a posture.
        blocked_moves: ``(index, fraction)``: the move from waypoint ``index`` to the next
            collides, first at ``fraction`` of the way, and RRT-Connect found no bridge.
        max_joint_step_deg: largest change of any ``θ_i`` or ``φ_i`` (of a bent section) between
            neighbouring postures, after padding [deg].
        max_dis_step_cm: largest change of ``dis`` between neighbouring postures [cm].
        fallbacks: waypoints where continuation failed and the planner's posture was used.
        moves: ``(index, via)``: the postures the arm passes between waypoint ``index`` and the
            next (continuation sub-steps or an RRT-Connect bridge), endpoints excluded.
        bridged: moves whose straight interpolation collided and RRT-Connect replaced.
        inserting: the postures were continued with the arm sliding in as the tip advances
            (the second of the two chains :func:`plan_trajectory` builds).

    """

    waypoints: list[list[float]]
    postures: list[PlannedPosture | None]
    failures: list[tuple[int, list[float], str]] = field(default_factory=list)
    blocked_moves: list[tuple[int, float]] = field(default_factory=list)
    max_joint_step_deg: float = 0.0
    max_dis_step_cm: float = 0.0
    fallbacks: list[int] = field(default_factory=list)
    moves: list[tuple[int, list[Posture]]] = field(default_factory=list)
    bridged: list[int] = field(default_factory=list)
    inserting: bool = False

    @property
    def complete(self) -> bool:
        """Every waypoint has a posture and every move between them is collision-free."""
        return not self.failures and not self.blocked_moves

    def to_json(self) -> dict[str, Any]:
        """``trajectory.json``: the postures in order (posture JSON, docs/design.md §6)."""
        return {
            "waypoints_cm": self.waypoints,
            "postures": [p.to_json() if p is not None else None for p in self.postures],
            "failures": [
                {"index": i, "point_cm": pt, "reason": why} for i, pt, why in self.failures
            ],
            "blocked_moves": [{"index": i, "fraction": f} for i, f in self.blocked_moves],
            "complete": self.complete,
            "max_joint_step_deg": self.max_joint_step_deg,
            "max_dis_step_cm": self.max_dis_step_cm,
            "fallbacks": self.fallbacks,
            "bridged_moves": self.bridged,
            "inserting": self.inserting,
            "moves": [{"from": i, "via": [p.to_dict() for p in via]} for i, via in self.moves],
        }

    @property
    def note(self) -> str:
        """``"B of M moves collide"``."""
        return f"{len(self.blocked_moves)} of {len(self.moves)} moves collide"

    def measures(self, scene: CollisionScene) -> dict[str, float]:
        """What ``bench`` and ``evaluate`` report of a trajectory.

        ``tip_error_cm`` of the last posture (nan if none); ``min_clearance_cm`` over the
        waypoints' postures and about 50 postures sampled along the whole motion, bridges
        included (:func:`~aftir_rl.planning.jointspace.sampled_clearance`: an upper bound);
        ``path_cm``, the tip's path along the densified motion.
        """
        motion, last = self.motion(), self.postures[-1]
        waypoints = min((p.clearance_cm for p in self.postures if p is not None), default=math.nan)
        return {
            "tip_error_cm": last.error_cm if last is not None else math.nan,
            "min_clearance_cm": min(waypoints, sampled_clearance(scene, motion)),
            "path_cm": tip_path_length(densify(motion), scene.arm.section_length),
        }

    def motion(self) -> list[Posture]:
        """Every posture the arm takes, in order: waypoints and the moves' via postures."""
        vias = dict(self.moves)  # keyed by the waypoint each move starts from
        out: list[Posture] = []
        for i, planned in enumerate(self.postures):
            if planned is not None:
                out += [planned.posture, *vias.get(i, [])]
        return out


def plan_trajectory(
    planner: Planner,
    points: Iterable[Iterable[float]],
    target: ArrayLike,
    interpolation_steps: int = 4,
    bridge_seconds: float = DEFAULT_BRIDGE_SECONDS,
    seed: int = 0,
) -> Trajectory:
    """Postures for every point of a tip path and the exact target, and checked moves between.

    Args:
        planner: the planner of the tank.
        points: the path's cell centres [cm], start first.
        target: the exact target [cm], planned last.
        interpolation_steps: checked sub-steps of a continuation (damped least squares) move.
        bridge_seconds: RRT-Connect's budget for a move whose straight interpolation collides
            (:func:`~aftir_rl.planning.jointspace.bridge`; 0: no bridging, the move is reported as
            blocked).
        seed: OMPL's seed for the bridges (OMPL takes only the first seed of a process).

    """
    end = cast("Iterable[float]", target)  # a point (x, y, z), which ArrayLike does not say
    waypoints = [list(map(float, p)) for p in points] + [list(map(float, end))]
    planned: list[PlannedPosture | None] = []
    failures: list[tuple[int, list[float], str]] = []
    for i, point in enumerate(waypoints):
        try:
            planned.append(planner.plan(point))
        except PlanningError as exc:
            planned.append(None)
            failures.append((i, point, str(exc)))
    n = max((p.posture.n_sections for p in planned if p is not None), default=1)
    points_arr = np.array(waypoints)
    chain = _build_chain(planner, planned, points_arr, n, interpolation_steps, insert=False)
    if chain.blocked:
        pushed = _build_chain(planner, planned, points_arr, n, interpolation_steps, insert=True)
        if pushed.score < chain.score:
            chain = pushed
    out = Trajectory(waypoints, [], failures, fallbacks=chain.fallbacks, inserting=chain.insert)
    # A waypoint the planner failed on but continuation reached has a posture after all.
    out.failures = [f for f in failures if chain.postures[f[0]] is None]
    previous: int | None = None
    for i, posture in enumerate(chain.postures):
        if posture is None:
            out.postures.append(None)
            continue
        if previous is not None:
            via = chain.vias.get(previous, [])
            hit = chain.blocked.get(previous)
            if hit is not None:
                before = chain.postures[previous]
                assert before is not None  # previous is the last waypoint with a posture
                via = _bridge_move(
                    planner, before, via, posture, previous, hit, bridge_seconds, seed, out
                )
            out.moves.append((previous, via))
        out.postures.append(planner.checked(posture, points_arr[i], chain.methods[i]))
        previous = i
    out.max_joint_step_deg, out.max_dis_step_cm = _steps(out.postures)
    return out


@dataclass
class _Chain:
    """Postures continued along the waypoints, before bridging."""

    insert: bool
    postures: list[Posture | None]
    vias: dict[int, list[Posture]]  # the move from waypoint i to the next one
    methods: list[str]
    fallbacks: list[int]
    blocked: dict[int, float] = field(default_factory=dict)  # move i: where it first collides

    @property
    def score(self) -> tuple[int, int]:
        """Waypoints without a posture, then colliding moves (before bridging): lower is better."""
        return sum(p is None for p in self.postures), len(self.blocked)


def _build_chain(
    planner: PlanningContext,
    planned: Sequence[PlannedPosture | None],
    points: np.ndarray,
    n: int,
    steps: int,
    insert: bool,
) -> _Chain:
    """Continue from waypoint to waypoint, falling back to the planner's posture.

    Records the moves that collide, checked densely: a continued move in :func:`_sub_step`, one
    sub-step at a time, a move to a fallback posture here.
    """
    l = planner.arm.section_length
    chain = _Chain(insert, [None] * len(points), {}, ["continued"] * len(points), [])
    prev: int | None = None
    for i in range(len(points)):
        if prev is not None:
            before = chain.postures[prev]
            assert before is not None  # prev is the last waypoint with a posture
            chosen, via = _continue(planner, before, points[i], steps, insert=insert)
            if chosen is not None:
                chain.postures[i], chain.vias[prev], prev = chosen, via, i
                continue
        own = planned[i]
        if own is None:
            continue
        chain.methods[i] = own.method
        chain.postures[i] = posture = pad_sections(own.posture, n, l)
        if prev is not None:
            # Continued moves were checked sub-step by sub-step; a fallback's move is checked here.
            before = chain.postures[prev]
            assert before is not None  # prev is the last waypoint with a posture
            chain.fallbacks.append(i)
            chain.postures[i] = posture = align(posture, before)
            chain.vias[prev] = []
            dense = densify([before, posture])
            hit = first_collision(planner.scene, dense)
            if hit is not None:
                chain.blocked[prev] = hit / (len(dense) - 1)
        prev = i
    return chain


def _bridge_move(
    planner: PlanningContext,
    previous: Posture,
    via: list[Posture],
    chosen: Posture,
    index: int,
    hit: float,
    bridge_seconds: float,
    seed: int,
    out: Trajectory,
) -> list[Posture]:
    """The via postures of a move that collides (first at ``hit`` of the way), bridged if can be.

    A move RRT-Connect does not bridge is recorded in ``out.blocked_moves``.
    """
    if bridge_seconds > 0:
        plan = bridge(planner.scene, previous, chosen, bridge_seconds, seed=seed)
        bridged = plan.postures[1:-1]
        # The move as stored, to ``chosen`` as written here: checked again, not assumed.
        if (
            plan.solved
            and first_collision(planner.scene, densify([previous, *bridged, chosen])) is None
        ):
            out.bridged.append(index)
            return bridged
    out.blocked_moves.append((index, hit))
    return via


def _continue(
    planner: PlanningContext,
    previous: Posture,
    point: np.ndarray,
    steps: int,
    depth: int = 4,
    insert: bool = False,
) -> tuple[Posture | None, list[Posture]]:
    """Continue ``previous`` to ``point`` in ``steps + 1`` checked sub-steps.

    A sub-step whose posture collides is repaired (:func:`repair_posture`); one whose
    interpolated move collides is split in two, down to ``depth`` halvings. With ``insert``,
    each sub-step first slides the arm along itself by the tip's advance along its heading
    (:func:`slide`). Returns the final posture (None on failure) and the sub-step postures
    before it.
    """
    start_tip = previous.tip(planner.arm.section_length)
    current, via = previous, []
    tips = start_tip + np.outer(np.arange(steps + 2) / (steps + 1), point - start_tip)
    for k in range(1, steps + 2):
        part = _sub_step(planner, current, tips[k - 1], tips[k], depth, insert)
        if part is None:
            return None, []
        via += part
        current = via[-1]
    return current, via[:-1]


def _sub_step(
    planner: PlanningContext,
    current: Posture,
    tip_from: np.ndarray,
    tip_to: np.ndarray,
    depth: int,
    insert: bool = False,
    slide_first: bool = True,
) -> list[Posture] | None:
    """Postures from ``current`` (tip at ``tip_from``) to the tip at ``tip_to``, or None.

    Each move between consecutive postures is collision-free. With ``insert`` (and
    ``slide_first``), a sub-step whose tip advances along its heading first tries sliding the
    arm in by that advance, then continues from there without sliding again at that level (the
    halves of a split sub-step may each slide).
    """
    if insert and slide_first:
        l = planner.arm.section_length
        heading = forward_kinematics(current.dis, current.theta, current.phi, l)[-1, :3, 2]
        advance = float(np.dot(tip_to - tip_from, heading))
        if 0.5 < advance <= l and current.dis + advance <= 0.0:
            pushed = slide(current, advance, l)
            if first_collision(planner.scene, densify([current, pushed])) is None:
                rest = _sub_step(planner, pushed, pushed.tip(l), tip_to, depth, True, False)
                if rest is not None:
                    return [pushed, *rest]
    nxt = continue_posture(planner, current, tip_to)
    if nxt is not None and planner.scene.collides(nxt):
        nxt = repair_posture(planner, nxt, tip_to)
    if nxt is not None:
        nxt = align(nxt, current)
        if first_collision(planner.scene, densify([current, nxt])) is None:
            return [nxt]
    if depth == 0:
        return None
    mid = (tip_from + tip_to) / 2
    first = _sub_step(planner, current, tip_from, mid, depth - 1, insert)
    if first is None:
        return None
    second = _sub_step(planner, first[-1], mid, tip_to, depth - 1, insert)
    return None if second is None else first + second


def _steps(postures: Sequence[PlannedPosture | None]) -> tuple[float, float]:
    joint, dis = 0.0, 0.0
    for a, b in zip(postures, postures[1:]):
        if a is None or b is None:
            continue
        pa, pb = a.posture, b.posture
        dtheta = np.abs(np.subtract(pb.theta, pa.theta))
        bent = (np.abs(pa.theta) > 1e-6) & (np.abs(pb.theta) > 1e-6)
        dphi = np.abs((np.subtract(pb.phi, pa.phi) + math.pi) % (2 * math.pi) - math.pi) * bent
        joint = max(joint, math.degrees(float(np.max(np.maximum(dtheta, dphi)))))
        dis = max(dis, abs(pb.dis - pa.dis))
    return joint, dis
