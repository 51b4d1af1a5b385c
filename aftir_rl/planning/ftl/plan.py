"""A whole follow-the-leader motion for one target, checked, in the ``trajectory.json`` contract.

:func:`plan_motion` plans a route (:func:`aftir_rl.planning.ftl.route.plan_route`, guided by the
learned cells when given), deploys it by follow-the-leader
(:func:`aftir_rl.planning.ftl.model.ftl_motion`) and checks the whole dense motion independently of
the search: every entry's backbone, sampled 2.5 cm apart, must keep the margin from the tank
(entries are less than 1 cm of backbone movement apart). A route whose deployment misses the margin
is replaced by the next search setting; a target that no setting reaches is ``complete: false`` with
the reason.

The settings are tried in a fixed order within one work budget
(:mod:`aftir_rl.planning.ftl.search`), so a plan is the same on any machine under any load.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.collision import point_clearance
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import AftirError, PlanningTimeout
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.sections import postures_min_clearance
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.model import (
    SAMPLES_PER_SECTION,
    FTLMotion,
    Route,
    ftl_deviation,
    ftl_motion,
)
from aftir_rl.planning.ftl.route import RouteResult, RouteSettings, search_route
from aftir_rl.planning.ftl.search import (
    LAST_RESORTS,
    MAIN_VARIANTS,
    MAX_EXPANDED_TOTAL,
    SEARCH_VARIANTS,
    check_budget,
)
from aftir_rl.planning.timing import TimedMotion, time_motion

__all__ = [
    "MotionPlan",
    "deploy_route",
    "postures_clearance",
    "plan_motion",
    "motion_summary",
    "warm_up",
    "DEFAULT_MARGIN",
    "SEARCH_VARIANTS",
    "MAIN_VARIANTS",
    "LAST_RESORTS",
    "MAX_EXPANDED_TOTAL",
]

#: Largest follow-the-leader deviation [cm] a motion should keep (the published FTL anchors:
#: about 2% of the shape); a motion above it is kept only when no search setting does better.
DEVIATION_GOAL = 2.5


@dataclass
class MotionPlan:
    """The result of :func:`plan_motion` (see ``to_json`` for the file contract).

    ``timed_out``: the wall-clock guard stopped the planning (``complete`` is then False and
    says nothing about the target). ``expanded``: candidate sections the route searches
    evaluated, all settings tried together (the work :data:`MAX_EXPANDED_TOTAL` bounds).
    """

    target: NDArray[np.float64]
    margin_cm: float
    section_length: float
    complete: bool
    seconds: float
    method: str = "ftl"
    reason: str | None = None
    timed_out: bool = False
    expanded: int = 0
    motion: FTLMotion | None = None
    waypoint_index: list[int] = field(default_factory=list)
    min_clearance_cm: float | None = None
    ftl_deviation_cm: tuple[float, float] | None = None
    tip_error_cm: float | None = None
    tip_path_length_cm: float | None = None
    route_departure_cm: tuple[float, float] | None = None
    corridor: str | None = None
    limits: ActuatorLimits | None = field(default=None, repr=False)
    _schedule: tuple[TimedMotion | None, str | None] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    @property
    def timing(self) -> TimedMotion | None:
        """The motion's time-optimal schedule under ``limits``, or None (see ``timing_note``).

        Computed on first use (toppra, about 30 ms on 2 cores) and kept: ``seconds`` is the
        planning alone.
        """
        return self._scheduled()[0]

    @property
    def timing_note(self) -> str | None:
        """Why the motion has no :attr:`timing` (None when it has one)."""
        return self._scheduled()[1]

    def _scheduled(self) -> tuple[TimedMotion | None, str | None]:
        if self._schedule is None:
            if self.motion is None or self.limits is None:
                self._schedule = (None, "no timing: no motion" if self.motion is None else None)
            else:
                self._schedule = _timed(self.motion, self.section_length, self.limits)
        return self._schedule

    def to_json(self) -> dict[str, Any]:
        """The ``trajectory.json`` contract of a q_table run directory."""
        out: dict[str, Any] = {
            "complete": self.complete,
            "method": self.method,
            "margin_cm": self.margin_cm,
            "section_length": self.section_length,
            "seconds": self.seconds,
            "target": self.target.tolist(),
        }
        if self.reason is not None:
            out["reason"] = self.reason
        if self.timed_out:
            out["timed_out"] = True
        if self.motion is not None:
            out.update(
                n_sections=self.motion.n_sections,
                motion=self.motion.to_list(),
                waypoint_index=self.waypoint_index,
                stage_index=list(self.motion.stage_index),
                min_clearance_cm=self.min_clearance_cm,
                ftl_deviation_cm={"max": self.ftl_deviation_cm[0], "mean": self.ftl_deviation_cm[1]}
                if self.ftl_deviation_cm
                else None,
                tip_error_cm=self.tip_error_cm,
                tip_path_length_cm=self.tip_path_length_cm,
                route_departure_cm={
                    "max": self.route_departure_cm[0],
                    "mean": self.route_departure_cm[1],
                }
                if self.route_departure_cm
                else None,
                corridor=self.corridor,
                route={
                    "lead": self.motion.route.lead,
                    "kappa": self.motion.route.kappa.tolist(),
                },
            )
            out.update(_timing_json(self.timing, self.timing_note, out["motion"]))
        return out


def _timing_json(
    timing: TimedMotion | None, note: str | None, entries: list[dict[str, Any]]
) -> dict[str, Any]:
    """``duration_s`` and ``timing`` of ``trajectory.json``; each entry gains its time ``t``."""
    if timing is None:
        return {"duration_s": None, "timing": None, "timing_note": note}
    for entry, t in zip(entries, timing.t.tolist()):
        entry["t"] = t
    return {"duration_s": timing.duration, "timing": timing.to_json()}


def _timed(
    motion: FTLMotion, section_length: float, limits: ActuatorLimits
) -> tuple[TimedMotion | None, str | None]:
    """The motion's time-optimal schedule under ``limits``, or why it has none."""
    try:
        return time_motion(motion.dis, motion.theta, motion.phi, section_length, limits), None
    except AftirError as exc:  # no robot extra, a cable past its travel, the solver
        return None, f"no timing: {exc}"


def motion_clearance(tank: Tank, motion: FTLMotion) -> float:
    """Smallest clearance [cm] of the arm's surface over every entry of a motion (exact)."""
    return postures_clearance(tank, motion.dis, motion.theta, motion.phi)


def postures_clearance(
    tank: Tank, dis: NDArray[np.float64], theta: NDArray[np.float64], phi: NDArray[np.float64]
) -> float:
    """Smallest clearance [cm] of the arm's surface over postures ``(T,), (T, N)`` (exact).

    Every posture's backbone sampled :data:`~aftir_rl.planning.ftl.model.SAMPLES_PER_SECTION`
    times per section, compiled (:func:`~aftir_rl.core.kernel.sections.postures_min_clearance`).
    """
    arm = tank.arm
    worst = postures_min_clearance(
        dis, theta, phi, arm.section_length, SAMPLES_PER_SECTION, kernel_grid(tank)
    )
    return float(worst) - arm.radius


def plan_motion(
    tank: Tank,
    target: ArrayLike,
    cells: Sequence[Sequence[int]] | None = None,
    margin: float = DEFAULT_MARGIN,
    start_height: float | None = None,
    prefix: Route | None = None,
    variants: Sequence[RouteSettings] = (),
    max_expanded: int = MAX_EXPANDED_TOTAL,
    max_seconds: float | None = None,
) -> MotionPlan:
    """Plan, deploy and check a follow-the-leader motion from the panel to ``target`` [cm].

    Args:
        tank: the tank.
        target: the target [cm].
        cells: the learned cell path (start first) to guide the route, or None.
        margin: clearance [cm] the arm's surface keeps along the whole motion.
        start_height: the tip's height above the floor at the start (default: the tank's start
            point, at most 20 cm).
        prefix: a route to continue, unchanged (:func:`~aftir_rl.planning.ftl.route.plan_route`).
        variants: the route-search settings to try, in order (default :data:`SEARCH_VARIANTS`).
        max_expanded: the work budget of the whole call (candidate sections evaluated, all
            searches together); each setting gets at most its own ``max_expanded`` and what
            is left of this.
        max_seconds: a wall-clock guard [s] on the whole call, or None (none).

    Returns:
        A :class:`MotionPlan`; ``complete`` is False, with ``reason``, when no motion keeps the
        margin within the budget, and ``timed_out`` too when the guard stopped it.

    Raises:
        ConfigError: ``max_expanded`` or ``max_seconds`` is not a budget.

    """
    start = time.perf_counter()
    check_budget(max_expanded, max_seconds)
    target = np.asarray(target, dtype=np.float64)
    h0 = min(float(tank.start_point[2]) if start_height is None else float(start_height), 20.0)
    tried = _Tries(tank, target, cells, margin, h0, prefix, start)
    try:
        best, reasons, used = tried.run(variants or SEARCH_VARIANTS, max_expanded, max_seconds)
    except PlanningTimeout as exc:
        return _incomplete(target, margin, tank.arm.section_length, start, str(exc), True)
    if best is not None:
        best.seconds, best.expanded = time.perf_counter() - start, used
        return best
    why = f"Cannot reach the target with a margin of {margin:g} cm: "
    plan = _incomplete(
        target, margin, tank.arm.section_length, start, why + "; ".join(dict.fromkeys(reasons))
    )
    plan.expanded = used
    return plan


@dataclass(frozen=True)
class _Tries:
    """One :func:`plan_motion` call's problem, and the clock it started."""

    tank: Tank
    target: NDArray[np.float64]
    cells: Sequence[Sequence[int]] | None
    margin: float
    h0: float
    prefix: Route | None
    start: float

    def run(
        self, variants: Sequence[RouteSettings], max_expanded: int, max_seconds: float | None
    ) -> tuple[MotionPlan | None, list[str], int]:
        """Try the settings in order within the budget: the best plan, the reasons, the work.

        Raises:
            PlanningTimeout: the wall-clock guard stopped a search.

        """
        tank, target, cells, margin = self.tank, self.target, self.cells, self.margin
        reasons: list[str] = []
        best: MotionPlan | None = None
        best_deviation = float("inf")  # the largest FTL deviation of best [cm]
        used = 0  # candidate sections evaluated by the searches so far
        for settings in variants:
            if used >= max_expanded:
                reasons.append(f"the work budget of {max_expanded:,} candidate sections ran out")
                break
            knobs = _knobs(settings, margin, max_expanded - used, max_seconds, self.start)
            outcome = search_route(tank, target, cells, knobs, tank.arm, self.prefix)
            used += outcome.expanded
            if outcome.result is None:
                reasons.append(str(outcome.reason))
                if "closer than" in str(outcome.reason):
                    break
                continue
            deployed = _deploy(tank, target, cells, margin, outcome.result, self.h0)
            if isinstance(deployed, str):
                reasons.append(deployed)
                continue
            plan, deviation = deployed
            if best is None or deviation < best_deviation:
                best, best_deviation = plan, deviation
            if best_deviation <= DEVIATION_GOAL:
                break
        return best, reasons, used


def _knobs(
    settings: RouteSettings, margin: float, left: int, max_seconds: float | None, start: float
) -> RouteSettings:
    """``settings`` with the margin, at most ``left`` work, and what is left of the guard."""
    guard = settings.max_seconds
    if max_seconds is not None:
        left_s = max(max_seconds - (time.perf_counter() - start), 1e-3)
        guard = left_s if guard is None else min(guard, left_s)
    return replace(
        settings, margin=margin, max_expanded=min(settings.max_expanded, left), max_seconds=guard
    )


def _incomplete(
    target: NDArray[np.float64],
    margin: float,
    section_length: float,
    start: float,
    reason: str,
    timed_out: bool = False,
) -> MotionPlan:
    """The plan of a target no search setting reached, or of a call the guard stopped.

    A complete motion found before the guard is dropped too: which one would have won depends
    on the settings the guard cut off.
    """
    return MotionPlan(
        target=target,
        margin_cm=margin,
        section_length=section_length,
        complete=False,
        seconds=time.perf_counter() - start,
        reason=reason,
        timed_out=timed_out,
    )


def deploy_route(
    tank: Tank, target: ArrayLike, route: Route, margin: float = DEFAULT_MARGIN
) -> MotionPlan:
    """The follow-the-leader motion along ``route`` (a planner's or a policy's), checked.

    Deployed and checked as :func:`plan_motion` deploys the route it found: the whole motion
    keeps ``margin`` [cm] (python-fcl's exact distance) or the plan is incomplete, with why.
    """
    start = time.perf_counter()
    target = np.asarray(target, dtype=np.float64)
    h0 = min(float(tank.start_point[2]), 20.0)
    found = RouteResult(
        route=route,
        n_sections=max(route.min_sections(), 1),
        clearance_cm=float("nan"),
        cost=float("nan"),
        corridor="",
        seconds=0.0,
    )
    deployed = _deploy(tank, target, None, margin, found, h0)
    l = tank.arm.section_length
    if isinstance(deployed, str):
        why = f"Cannot reach the target with a margin of {margin:g} cm: {deployed}"
        return _incomplete(target, margin, l, start, why)
    plan = deployed[0]
    plan.seconds = time.perf_counter() - start
    return plan


def _deploy(
    tank: Tank,
    target: NDArray[np.float64],
    cells: Sequence[Sequence[int]] | None,
    margin: float,
    found: RouteResult,
    h0: float,
) -> tuple[MotionPlan, float] | str:
    """Deploy a planned route by follow-the-leader and check its whole motion.

    Args:
        tank: the tank.
        target: the target [cm].
        cells: the learned cell path, or None.
        margin: clearance [cm] the arm's surface keeps along the whole motion.
        found: the planned route.
        h0: the tip's height above the floor at the start [cm].

    Returns:
        The complete plan and its largest FTL deviation [cm], or why the motion misses the
        margin.

    """
    arm = tank.arm
    motion = ftl_motion(found.route, found.n_sections, h0, theta_max=arm.theta_max)
    clearance = motion_clearance(tank, motion)
    if clearance < margin:
        return f"a deployment kept only {clearance:.2f} cm"
    tips = motion.tips()
    deviation = ftl_deviation(motion)
    plan = MotionPlan(
        target=target,
        margin_cm=margin,
        section_length=arm.section_length,
        complete=True,
        seconds=0.0,
        motion=motion,
        min_clearance_cm=clearance,
        ftl_deviation_cm=deviation,
        tip_error_cm=float(np.linalg.norm(tips[-1] - target)),
        tip_path_length_cm=float(np.linalg.norm(np.diff(tips, axis=0), axis=1).sum()),
        corridor=found.corridor,
        limits=arm.limits,
    )
    if cells is not None and tank.cell_size is not None:
        plan.waypoint_index, plan.route_departure_cm = _waypoints(tank, cells, tips)
    return plan, deviation[0]


def _waypoints(
    tank: Tank, cells: Sequence[Sequence[int]], tips: NDArray[np.float64]
) -> tuple[list[int], tuple[float, float]]:
    """Per cell, the entry whose tip is in (or nearest to) it, in order; route departure."""
    raster = tank.raster
    half = raster.cell_size / 2
    index, departure = [], []
    lo_idx = 0
    for c in cells:
        centre = raster.cell_center(c)
        outside = np.linalg.norm(np.maximum(np.abs(tips[lo_idx:] - centre) - half, 0.0), axis=1)
        i = lo_idx + int(np.argmin(outside))
        index.append(i)
        lo_idx = i
        departure.append(float(np.linalg.norm(tips - centre, axis=1).min()))
    return index, (max(departure), float(np.mean(departure)))


_WARM: set[str] = set()


def warm_up(tank: Tank) -> None:
    """Compile (or load from numba's cache) the planner's kernels once per process.

    A fresh install compiles them on first use (about half a minute on 2 cores); a caller with a
    time budget calls this before starting its clock. Plans one motion straight up from the
    panel to the first height with room (whatever its outcome) the first time in a process.
    """
    if "ftl" in _WARM:
        return
    _WARM.add("ftl")
    centre = np.asarray(tank.panel.center, dtype=np.float64)
    floor, height = float(tank.box_min[2]), float(tank.box_max[2]) - float(tank.box_min[2])
    heights = [floor + f * height for f in (0.5, 0.35, 0.65, 0.2)]
    points = np.array([[centre[0], centre[1], z] for z in heights])
    room = point_clearance(tank, points) >= tank.arm.radius + DEFAULT_MARGIN + 1.0
    if room.any():
        plan_motion(tank, points[int(np.argmax(room))])


def motion_summary(plan: Any) -> dict[str, Any]:
    """What ``path.json`` says of a :class:`~aftir_rl.planning.ftl.plan.MotionPlan`."""
    return {
        "complete": plan.complete,
        "seconds": plan.seconds,
        "reason": plan.reason,
        "entries": len(plan.motion) if plan.motion is not None else 0,
        "n_sections": plan.motion.n_sections if plan.motion is not None else None,
        "min_clearance_cm": plan.min_clearance_cm,
        "ftl_deviation_cm": plan.ftl_deviation_cm,
        "tip_error_cm": plan.tip_error_cm,
        "route_departure_cm": plan.route_departure_cm,
    }
