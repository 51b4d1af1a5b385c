"""A whole follow-the-leader motion for one target, checked, in the ``trajectory.json`` contract.

:func:`plan_motion` plans a route (:func:`aftir_rl.planning.ftl.route.plan_route`, guided by the
learned
cells when given), deploys it by follow-the-leader (:func:`aftir_rl.planning.ftl.model.ftl_motion`)
and
checks the whole dense motion independently of the search: every entry's backbone, sampled
2.5 cm apart, must keep the margin from the tank (entries are less than 1 cm of backbone movement
apart). A route whose deployment misses the margin is replaced by the next search setting; a
target that no setting reaches is ``complete: false`` with the reason.

The rule for the search settings: :data:`SEARCH_VARIANTS` are tried in a fixed order, each
search bounded by its own work budget (``RouteSettings.max_expanded``, candidate sections
evaluated) and all of them by one total (:data:`MAX_EXPANDED_TOTAL`), never by the clock, so a
target's plan is the same on any machine under any load. A wall-clock guard (``max_seconds``,
off by default) only stops a runaway call: its plan says ``timed_out``, never "no route".
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.actuation import ActuatorLimits
from aftir_rl.core.collision import point_clearance
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import AftirError, ConfigError, PlanningTimeout
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
from aftir_rl.planning.timing import TimedMotion, time_motion

__all__ = [
    "MotionPlan",
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

_FINE = RouteSettings(beam_width=800, bin_cm=4.0, bin_heading=0.2, slack=0.5, change_weight=5.0)
_DEEP_LEADS = (-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0)

#: Route-search settings tried in turn (the margin is set per call): the first whose motion
#: keeps the margin and the deviation goal wins; otherwise the complete one of least deviation.
#: :data:`LAST_RESORTS` follow them.
MAIN_VARIANTS: tuple[RouteSettings, ...] = (
    RouteSettings(clearance_weight=1.0, change_weight=20.0),
    RouteSettings(clearance_weight=1.0, change_weight=40.0, max_change=0.5),
    RouteSettings(clearance_weight=1.0, change_weight=5.0),
    RouteSettings(clearance_weight=0.5, change_weight=5.0, beam_width=250, max_change=1.0),
    RouteSettings(
        clearance_weight=1.0, change_weight=20.0, beam_width=400, bin_cm=6.0, bin_heading=0.3
    ),
    # more room for the deviation between stages, for routes whose deployment grazes
    RouteSettings(clearance_weight=1.0, change_weight=20.0, slack=3.0),
    RouteSettings(clearance_weight=2.0, change_weight=40.0, slack=3.0, max_change=0.5),
)

#: The last resorts: a wider, finer beam with sharper turns for tight spots' routes; the first
#: and last also bend deeper in the panel's guide (the arm leaves the panel at a slant, for
#: targets low and beside it), the second moves the lead when closing.
LAST_RESORTS: tuple[RouteSettings, ...] = (
    replace(_FINE, max_change=1.2, leads=_DEEP_LEADS),
    replace(_FINE, max_change=1.2, lead_shift=15.0, closings=30),
    replace(_FINE, max_change=1.5, leads=_DEEP_LEADS),
)

#: Every setting :func:`plan_motion` tries by default, in this order.
SEARCH_VARIANTS = MAIN_VARIANTS + LAST_RESORTS

#: Default total work budget of one :func:`plan_motion` call: candidate sections evaluated by
#: all its route searches together. Above the most that all of :data:`SEARCH_VARIANTS` can
#: evaluate on a 12-section arm (2,120,300), so it never cuts them short there; a setting is
#: given at most what is left of it.
MAX_EXPANDED_TOTAL = 2_500_000

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
    if not max_expanded >= 1:
        raise ConfigError(f"max_expanded must be 1 candidate section or more, got {max_expanded!r}")
    if max_seconds is not None and not 0 < max_seconds < math.inf:
        raise ConfigError(
            f"max_seconds must be a positive number of seconds or None, got {max_seconds!r}"
        )
    target = np.asarray(target, dtype=np.float64)
    arm = tank.arm
    h0 = min(float(tank.start_point[2]) if start_height is None else float(start_height), 20.0)
    reasons: list[str] = []
    best: MotionPlan | None = None
    best_deviation = float("inf")  # the largest FTL deviation of best [cm]
    used = 0  # candidate sections evaluated by the searches so far
    for settings in variants or SEARCH_VARIANTS:
        if used >= max_expanded:
            reasons.append(f"the work budget of {max_expanded:,} candidate sections ran out")
            break
        guard = None if max_seconds is None else max_seconds - (time.perf_counter() - start)
        knobs = replace(
            settings,
            margin=margin,
            max_expanded=min(settings.max_expanded, max_expanded - used),
            max_seconds=_tighter(settings.max_seconds, guard),
        )
        try:
            outcome = search_route(tank, target, cells, knobs, arm, prefix)
        except PlanningTimeout as exc:
            return _timed_out(target, margin, arm.section_length, start, str(exc))
        used += outcome.expanded
        found = outcome.result
        if found is None:
            reasons.append(str(outcome.reason))
            if "closer than" in str(outcome.reason):
                break
            continue
        deployed = _deploy(tank, target, cells, margin, found, h0)
        if isinstance(deployed, str):
            reasons.append(deployed)
            continue
        plan, deviation = deployed
        if best is None or deviation < best_deviation:
            best, best_deviation = plan, deviation
        if best_deviation <= DEVIATION_GOAL:
            break
    if best is not None:
        best.seconds, best.expanded = time.perf_counter() - start, used
        return best
    plan = _unreachable(target, margin, arm.section_length, start, reasons)
    plan.expanded = used
    return plan


def _tighter(a: float | None, b: float | None) -> float | None:
    """The smaller of two optional wall-clock guards [s] (None: no guard); at least 1 ms."""
    if a is None or b is None:
        return a if b is None else max(b, 1e-3)
    return max(min(a, b), 1e-3)


def _timed_out(
    target: NDArray[np.float64],
    margin: float,
    section_length: float,
    start: float,
    why: str,
) -> MotionPlan:
    """The plan of a call the wall-clock guard stopped: incomplete, ``timed_out``, and why.

    A complete motion found before the guard is dropped too: which one would have won depends
    on the settings the guard cut off.
    """
    return MotionPlan(
        target=target,
        margin_cm=margin,
        section_length=section_length,
        complete=False,
        seconds=time.perf_counter() - start,
        reason=why,
        timed_out=True,
    )


def _unreachable(
    target: NDArray[np.float64],
    margin: float,
    section_length: float,
    start: float,
    reasons: list[str],
) -> MotionPlan:
    """The incomplete plan that gives the (distinct) reasons no search setting reached."""
    return MotionPlan(
        target=target,
        margin_cm=margin,
        section_length=section_length,
        complete=False,
        seconds=time.perf_counter() - start,
        reason="Cannot reach the target with a margin of "
        f"{margin:g} cm: " + "; ".join(dict.fromkeys(reasons)),
    )


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
