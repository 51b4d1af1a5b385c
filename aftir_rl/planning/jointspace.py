"""Joint-space motion between two postures: checked interpolation and OMPL's RRT-Connect.

A posture is the joint vector ``x = (dis, θ_1..θ_N, φ_1..φ_N)`` of an arm with a fixed number of
sections. :func:`align` picks, without changing the arm, the representation nearest a reference
(``(θ, φ)`` or ``(−θ, φ + π)``), so interpolation never swings a section round by 180°.
:func:`densify` interpolates postures so that no joint changes by more than ``max_angle`` [rad]
and ``dis`` by no more than ``max_dis`` [cm] between neighbours, and :func:`first_collision`
checks them all: a dense, discrete check, not a certified sweep.

:func:`rrt_connect` is OMPL's RRT-Connect (the ``ompl`` wheel) in joint space, with our forward
kinematics and python-fcl scene as its validity checker; a path counts as solved only if our own
dense check agrees. :func:`bridge` runs it in the smallest joint space two postures share, for
the moves of :func:`~aftir_rl.planning.posture.trajectory.plan_trajectory` that collide. How far
a body point can move between checks, and the distance OMPL uses: docs/design.md §7.1.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.extras import require
from aftir_rl.core.robot import Posture, tip_position

__all__ = [
    "MotionPlan",
    "align",
    "bending_plane",
    "bridge",
    "in_plane",
    "pad_sections",
    "densify",
    "first_collision",
    "joint_distance",
    "tip_path_length",
    "rrt_connect",
    "sampled_clearance",
]

_SEEDED = False
_ANGLE_STEP = math.radians(0.1)
_DIS_STEP = 0.5


def _wrap(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def align(posture: Posture, reference: Posture, straight: float = 1e-9) -> Posture:
    """The same arm as ``posture``, written with the joint values nearest to ``reference``.

    Per section, ``(θ, φ)`` or ``(−θ, φ + π)``, whichever has ``φ`` nearer the reference's (and
    then ``φ`` unwrapped to within π of it); a straight section takes the reference's ``φ``.
    """
    if posture.n_sections != reference.n_sections:
        raise ValueError(
            f"cannot align {posture.n_sections} sections to {reference.n_sections} sections"
        )
    theta, phi = np.array(posture.theta), np.array(posture.phi)
    ref_phi = np.array(reference.phi)
    flip = np.abs(_wrap(phi - ref_phi)) > math.pi / 2
    theta = np.where(flip, -theta, theta)
    phi = np.where(flip, phi + math.pi, phi)
    phi = ref_phi + _wrap(phi - ref_phi)
    phi = np.where(np.abs(theta) <= straight, ref_phi, phi)
    return Posture(posture.dis, theta, phi)


def pad_sections(posture: Posture, n_sections: int, section_length: float) -> Posture:
    """The same arm with straight sections added at its base to reach ``n_sections``."""
    extra = n_sections - posture.n_sections
    if extra < 0:
        raise ValueError(f"cannot pad {posture.n_sections} sections down to {n_sections}")
    first_phi = posture.phi[0] if posture.phi else 0.0
    return Posture(
        posture.dis - extra * section_length,
        (0.0,) * extra + posture.theta,
        (first_phi,) * extra + posture.phi,
    )


def bending_plane(*postures: Posture, tol: float = 1e-6) -> float | None:
    """The one plane ``φ`` (mod π) that every bent section of the postures bends in, or None.

    Postures in one plane through the panel axis are planar arms: the whole arm stays in that
    plane when only ``dis`` and the (signed) ``θ_i`` change.
    """
    phis = [phi for p in postures for theta, phi in zip(p.theta, p.phi) if abs(theta) > tol]
    if not phis:
        return postures[0].phi[0] if postures and postures[0].phi else 0.0
    offsets = _wrap(2 * (np.array(phis) - phis[0])) / 2
    return float(phis[0]) if np.all(np.abs(offsets) < tol) else None


def in_plane(posture: Posture, plane: float, tol: float = 1e-6) -> Posture:
    """``posture`` written with every ``φ_i = plane`` and signed ``θ_i`` (the same arm).

    Raises:
        ValueError: a bent section does not bend in ``plane`` (nor in ``plane + π``).

    """
    theta, phi = np.array(posture.theta), np.array(posture.phi)
    offset = _wrap(phi - plane)
    bent = np.abs(theta) > tol
    off_plane = bent & (np.abs(_wrap(2 * offset)) > 2 * tol)
    if np.any(off_plane):
        raise ValueError(f"sections {np.flatnonzero(off_plane).tolist()} bend out of the plane")
    sign = np.where(np.abs(offset) > math.pi / 2, -1.0, 1.0)
    return Posture(posture.dis, np.where(bent, theta * sign, 0.0), np.full(len(theta), plane))


def joint_distance(a: Posture, b: Posture, section_length: float) -> float:
    """Euclidean distance of two joint vectors, ``dis`` in section lengths, angles in rad."""
    d = b.to_vector() - a.to_vector()
    d[0] /= section_length
    return float(np.linalg.norm(d))


def densify(
    postures: Sequence[Posture], max_angle: float = _ANGLE_STEP, max_dis: float = _DIS_STEP
) -> list[Posture]:
    """Linear interpolation between consecutive postures, in small enough steps.

    No joint moves by more than ``max_angle`` [rad], nor ``dis`` by more than ``max_dis`` [cm],
    from one posture to the next. The postures are taken as written (no wrapping of ``φ``):
    :func:`align` them first.
    """
    if not postures:
        return []
    out = [postures[0]]
    for a, b in zip(postures, postures[1:]):
        xa, xb = a.to_vector(), b.to_vector()
        delta = xb - xa
        steps = max(
            1, math.ceil(max(abs(delta[0]) / max_dis, np.max(np.abs(delta[1:])) / max_angle))
        )
        for k in range(1, steps + 1):
            out.append(Posture.from_vector(xa + delta * (k / steps)))
    return out


def first_collision(scene: CollisionScene, postures: Sequence[Posture]) -> int | None:
    """Index of the first posture that collides (or breaks a joint limit), None if none does."""
    tmax = scene.arm.theta_max + 1e-9
    for i, p in enumerate(postures):
        if max((abs(t) for t in p.theta), default=0.0) > tmax or scene.collides_fast(p):
            return i
    return None


def sampled_clearance(
    scene: CollisionScene, postures: Sequence[Posture], samples: int = 50
) -> float:
    """Smallest clearance [cm] over about ``samples`` evenly spaced postures of a densified path.

    The postures are the path's vertices; the clearance of the sampled ones (the last included)
    is an upper bound on the whole path's.
    """
    if not postures:
        return math.nan
    dense = densify(postures)
    picked = [*dense[:: max(1, len(dense) // samples)], dense[-1]]
    return min(scene.clearance(p) for p in picked)


def tip_path_length(postures: Sequence[Posture], section_length: float) -> float:
    """Length of the tip's path [cm] through the postures (densify them first)."""
    if len(postures) < 2:
        return 0.0
    n = postures[0].n_sections
    x = np.array([p.to_vector() for p in postures])
    tips = tip_position(x[:, 0], x[:, 1 : n + 1], x[:, n + 1 :], section_length)
    return float(np.sum(np.linalg.norm(np.diff(tips, axis=0), axis=1)))


@dataclass
class MotionPlan:
    """A joint-space motion from a start to a goal posture.

    Attributes:
        postures: the path's postures, start first and goal last (OMPL's vertices after
            shortcutting, in the representation OMPL checked; in a plane search, with the start
            and goal rewritten into that representation next to them); empty when unsolved.
        solved: an exact path was found and every densified posture along it passed our check.
        seconds: planning wall time, simplification and our check included.
        checks: validity checks OMPL asked for.
        reason: why it is unsolved ("" when solved).

    """

    postures: list[Posture] = field(default_factory=list)
    solved: bool = False
    seconds: float = 0.0
    checks: int = 0
    reason: str = ""

    def joint_length(self, section_length: float) -> float:
        """Joint-space length of the path (``dis`` in section lengths, angles in rad)."""
        return sum(
            joint_distance(a, b, section_length) for a, b in zip(self.postures, self.postures[1:])
        )


def rrt_connect(
    scene: CollisionScene,
    start: Posture,
    goal: Posture,
    time_limit: float = 10.0,
    seed: int = 0,
    simplify: bool = True,
    resolution: float = 0.002,
    plane: float | None = None,
) -> MotionPlan:
    """OMPL's RRT-Connect from ``start`` to ``goal`` in the joint space of the arm.

    Args:
        scene: the collision scene (tank and arm); its ``collides_fast`` is the validity check.
        start: the start posture; ``goal`` must have as many sections.
        goal: the goal posture (aligned to ``start`` here, see :func:`align`).
        time_limit: planning time budget [s].
        seed: OMPL's random seed, set at the first call of the process only: each generator
            OMPL creates later draws its seed from that sequence, so a fresh process making the
            same calls repeats its results (``ou.RNG.setSeed`` again restarts the sequence, as
            ``bench`` does per item, although OMPL logs an error about it).
        simplify: shortcut the path with OMPL's simplifier.
        resolution: OMPL's edge-check resolution, a fraction of the space's extent.
        plane: plan in this one bending plane [rad]: every ``φ_i`` is held at ``plane`` and
            only ``dis`` and the ``θ_i`` (signed) move. Both postures must lie in it.

    Returns:
        The plan; ``solved`` is False with a reason when no path was found in time or our dense
        check of the path disagrees with OMPL's.

    """
    ob = require("ompl.base", "ompl")
    og, ou = require("ompl.geometric", "ompl"), require("ompl.util", "ompl")

    began = time.perf_counter()
    goal = align(goal, start)
    for name, p in (("start", start), ("goal", goal)):
        if first_collision(scene, [p]) is not None:
            return MotionPlan(
                seconds=time.perf_counter() - began, reason=f"the {name} posture collides"
            )
    _seed_once(ou, seed)
    frame = _JointFrame.make(scene, start, goal, plane)
    checks = [0]

    def valid(state: object) -> bool:
        checks[0] += 1
        return not scene.collides_joints(*frame.joints(state))

    space, bounds, setup, states = _simple_setup(ob, og, frame, valid, resolution)
    plan = _solve(setup, frame, simplify, time_limit)
    plan.checks = checks[0]
    # Drop OMPL's objects (and the callback's reference cycle) now, not at interpreter exit.
    del setup, states, space, bounds, valid
    gc.collect()
    plan.seconds = time.perf_counter() - began
    return plan


def _seed_once(ou: Any, seed: int) -> None:
    """Quiet OMPL's log and seed its generator, at the first call of the process only."""
    ou.setLogLevel(ou.LOG_WARN)
    global _SEEDED
    if not _SEEDED:
        ou.RNG.setSeed(int(seed) + 1)  # OMPL takes 0 for "pick one"
        _SEEDED = True


@dataclass
class _JointFrame:
    """OMPL's joint space of one motion: its ends and bounds, and its states as postures."""

    scene: CollisionScene
    start: Posture
    goal: Posture  # aligned to start
    dims: int
    x0: NDArray[np.float64]  # the start's and goal's states (dis in cm)
    x1: NDArray[np.float64]
    low: NDArray[np.float64]  # the bounds (dis in section lengths)
    high: NDArray[np.float64]
    ends: list[Posture]  # the start and goal written as the path's postures
    plane: float | None = None
    family: NDArray[np.float64] | None = None  # in a plane: each section's phi and theta's sign
    sign: NDArray[np.float64] | None = None

    @classmethod
    def make(
        cls, scene: CollisionScene, start: Posture, goal: Posture, plane: float | None
    ) -> _JointFrame:
        """The joint space from ``start`` to ``goal`` (aligned to it), in ``plane`` if given."""
        n, l, tmax = start.n_sections, scene.arm.section_length, scene.arm.theta_max
        ends = [start, goal]
        x0, x1 = start.to_vector(), goal.to_vector()
        family = sign = None
        if plane is not None:
            # OMPL's state: dis and the signed in-plane bends (ValueError off the plane).
            x0, x1 = (in_plane(p, plane).to_vector()[: n + 1] for p in (start, goal))
            # One representation for the whole path: straight sections get phi = plane (the arm
            # does not move), the goal is aligned to that, and each section keeps its phi (plane
            # or plane + pi) with theta signed to match. An edge between two states then
            # interpolates theta and dis only: exactly the in-plane edge OMPL checked.
            bent = np.abs(start.theta) > 1e-9
            ends[0] = Posture(start.dis, start.theta, np.where(bent, start.phi, plane))
            ends[1] = align(goal, ends[0])
            family = np.array(ends[0].phi)
            sign = np.sign(np.cos(family - plane))
        lo_dis, hi_dis = min(x0[0], x1[0], -n * l) / l, max(x0[0], x1[0], 0.0) / l
        phi0, phi1 = x0[n + 1 :], x1[n + 1 :]
        low = np.concatenate([[lo_dis], np.full(n, -tmax), np.minimum(phi0, phi1) - math.pi])
        high = np.concatenate([[hi_dis], np.full(n, tmax), np.maximum(phi0, phi1) + math.pi])
        dims = 1 + (n if plane is not None else 2 * n)
        x0, x1, low, high = x0[:dims], x1[:dims], low[:dims], high[:dims]
        return cls(scene, start, goal, dims, x0, x1, low, high, ends, plane, family, sign)

    def joints(self, state: object) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
        """``dis`` [cm] and the ``θ``, ``φ`` arrays of an OMPL state (:meth:`posture`'s values)."""
        x: NDArray[np.float64] = np.fromiter(
            (state[i] for i in range(self.dims)),  # type: ignore[index]
            np.float64,
            self.dims,
        )
        if self.plane is not None:
            assert self.sign is not None and self.family is not None
            return float(x[0]) * self.scene.arm.section_length, x[1:] * self.sign, self.family
        n = (self.dims - 1) // 2
        return float(x[0]) * self.scene.arm.section_length, x[1 : n + 1], x[n + 1 :]

    def posture(self, state: object) -> Posture:
        """The posture of an OMPL state."""
        x = np.array([state[i] for i in range(self.dims)])  # type: ignore[index]
        x[0] *= self.scene.arm.section_length
        if self.plane is not None:
            assert self.sign is not None and self.family is not None
            return Posture(x[0], x[1:] * self.sign, self.family)
        return Posture.from_vector(x)


def _simple_setup(
    ob: Any, og: Any, frame: _JointFrame, valid: Callable[[object], bool], resolution: float
) -> tuple[Any, Any, Any, list[Any]]:
    """OMPL's RRT-Connect in the frame's space: the space, its bounds, the setup, start and goal."""
    space = ob.RealVectorStateSpace(frame.dims)
    bounds = ob.RealVectorBounds(frame.dims)
    for i, (lo, hi) in enumerate(zip(frame.low, frame.high)):
        bounds.setLow(i, float(lo))
        bounds.setHigh(i, float(hi))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    setup.setStateValidityChecker(valid)
    states = []
    for x in (frame.x0, frame.x1):
        state = space.allocState()
        for i, v in enumerate(x):
            state[i] = float(v / frame.scene.arm.section_length if i == 0 else v)
        states.append(state)
    setup.setStartAndGoalStates(states[0], states[1])
    setup.getSpaceInformation().setStateValidityCheckingResolution(resolution)
    setup.setPlanner(og.RRTConnect(setup.getSpaceInformation()))
    return space, bounds, setup, states


def _solve(setup: Any, frame: _JointFrame, simplify: bool, time_limit: float) -> MotionPlan:
    """Run the planner; keep its (simplified) exact path if our dense check agrees with it."""
    status = setup.solve(float(time_limit))
    if not setup.haveExactSolutionPath():
        return MotionPlan(
            checks=0, reason=f"RRT-Connect found no path in {time_limit:g} s ({status})"
        )
    if simplify:
        setup.simplifySolution(max(0.1, time_limit / 10))
    path = setup.getSolutionPath()
    # OMPL's own states, written as checked: no re-alignment, which would change the edges.
    inner = [frame.posture(path.getState(i)) for i in range(1, path.getStateCount() - 1)]
    if frame.plane is not None:  # the start and goal in the path's representation, same arms
        inner = [frame.ends[0], *inner, frame.ends[1]]
    postures = [frame.start, *inner, frame.goal]
    if first_collision(frame.scene, densify(postures)) is None:
        return MotionPlan(postures=postures, solved=True, checks=0)
    return MotionPlan(checks=0, reason="OMPL's path collides between its edge checks")


def bridge(
    scene: CollisionScene,
    start: Posture,
    goal: Posture,
    time_limit: float = 10.0,
    seed: int = 0,
) -> MotionPlan:
    """RRT-Connect from ``start`` to ``goal`` in the smallest joint space the two share.

    Two reductions keep the search small; each leaves a path that is a path of the full arm:

    - leading sections that are straight in both postures (the ones still in the guide, or
      padding) stay straight: the arm is planned without them, its base raised by their length;
    - when every bent section of both postures bends in one plane through the panel axis (TGA
      postures do), the search runs in that plane: ``dis`` and the signed ``θ_i`` only.

    The plane search gets half the budget and a failed one leaves the rest to the full reduced
    space. A path that OMPL accepts but our dense check does not is planned again with a 4x
    finer edge resolution while time is left. Each attempt also simplifies its path for a tenth
    of its budget, so a call can run that much over ``time_limit``. The returned postures have
    ``start``'s sections; the path ends at ``goal`` aligned to ``start`` (:func:`align`).
    """
    began = time.perf_counter()
    n, l = start.n_sections, scene.arm.section_length
    goal = align(goal, start)
    keep = 0
    while keep < n - 1 and abs(start.theta[keep]) < 1e-9 and abs(goal.theta[keep]) < 1e-9:
        keep += 1

    def strip(p: Posture) -> Posture:
        return Posture(p.dis + keep * l, p.theta[keep:], p.phi[keep:])

    a, b = strip(start), strip(goal)
    plane = bending_plane(a, b)
    attempts = [plane, None] if plane is not None else [None]
    plan = MotionPlan(reason="no time left")
    for k, attempt in enumerate(attempts):
        resolution = 0.002
        while True:
            left = time_limit - (time.perf_counter() - began)
            budget = left / 2 if (k == 0 and len(attempts) == 2) else left
            if budget <= 0.05:
                break
            plan = rrt_connect(scene, a, b, budget, seed, resolution=resolution, plane=attempt)
            if plan.solved or "between its edge checks" not in plan.reason:
                break
            resolution /= 4
        if plan.solved:
            break
    if plan.solved:  # the same representation as OMPL's states, so the same edges
        plan.postures = [start, *(pad_sections(p, n, l) for p in plan.postures[1:-1]), goal]
        if first_collision(scene, densify(plan.postures)) is not None:
            plan.postures, plan.solved = [], False
            plan.reason = "the bridge collides once written with all sections"
    plan.seconds = time.perf_counter() - began
    return plan
