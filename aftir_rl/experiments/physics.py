"""A timed motion re-run on a Cosserat rod under gravity: the clearance the arm's body keeps.

Every other check is made on the constant-curvature model, whose sections are exact arcs that
never sag. :func:`simulate_motion` takes a timed motion (:class:`TimedRun`) to a rod of the arm
(:class:`~aftir_rl.experiments.rod_model.RodModel`: PyElastica, the ``physics`` extra) at
instants of the motion: every ``every_s`` seconds, its tightest entry and its last. The motion
is slow against the body's vibration, so at each instant the rod is relaxed to rest under the
joints' bends, the module's push and gravity. The body found is checked against the tank with
python-fcl and compared with the kinematic body; :func:`replan_for_physics` plans a motion that
lost its margin again with more. docs/robot.md ("Physics") has the model and its validation.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import PhysicsError
from aftir_rl.core.robot import Posture, body_points
from aftir_rl.core.rod import RodProperties
from aftir_rl.core.tank import Tank
from aftir_rl.experiments.execution import TimedRun
from aftir_rl.experiments.rod_model import (
    CURVE_POINTS,
    ELEMENTS_PER_SECTION,
    TOLERANCE_CM,
    RodModel,
    body_curve,
    carried_directors,
    kinematic_rod,
)
from aftir_rl.viz.runs import PHYSICS_FILE

__all__ = [
    "PHYSICS_FILE",
    "PhysicsReport",
    "replan_for_physics",
    "simulate_motion",
    "snapshot_entries",
]

#: The most instants one motion is simulated at (a 40-minute tour at one every 0.5 s).
MAX_SNAPSHOTS = 5_000


@dataclass
class PhysicsReport:
    """What the physics check found along one motion (cm, s).

    Attributes:
        entries: the motion entries simulated (the snapshots).
        t: their times [s].
        bodies: the simulated body at each, nodes ``(S, N·k + 1, 3)`` [cm].
        deviation_max: per snapshot the largest distance of a node from the kinematic body's
            point at the same arc length [cm].
        deviation_mean: the mean of those distances over the nodes above the floor [cm].
        tip_error: the distance of the simulated tip from the kinematic tip [cm].
        clearance: the simulated body's clearance from the tank [cm].
        kinematic_clearance: the kinematic body's (python-fcl, 20 capsules per section) [cm].
        steps: relaxation steps per snapshot.
        residual: how far from equilibrium each snapshot's body was estimated to be [cm].
        nearest: for the snapshot of least clearance: the body's surface point nearest the tank
            [cm], its arc length from the base [cm] and the solid's name.
        margin: the margin judged against [cm] (the caller's).
        rod: the body's properties simulated.
        floor: the tank floor's height [cm] (the mean deviation is over the nodes above it).
        section_length: the arm's ``l`` [cm].
        elements_per_section: rod elements per section.
        settings: the model's numbers (elements, time step, inertia scaling, tolerance).
        seconds: the wall time of the simulation.

    """

    entries: list[int]
    t: list[float]
    bodies: list[NDArray[np.float64]]
    deviation_max: list[float]
    deviation_mean: list[float]
    tip_error: list[float]
    clearance: list[float]
    kinematic_clearance: list[float]
    steps: list[int]
    residual: list[float]
    margin: float
    rod: RodProperties
    floor: float = 0.0
    section_length: float = 50.0
    elements_per_section: int = ELEMENTS_PER_SECTION
    settings: dict[str, Any] = field(default_factory=dict)
    nearest: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    def record(
        self,
        entry: int,
        t: float,
        bodies: tuple[NDArray[np.float64], NDArray[np.float64]],
        found: tuple[float, NDArray[np.float64], str],
        kinematic: float,
        relaxed: tuple[int, float],
    ) -> None:
        """Add one instant.

        ``bodies``: the kinematic and the simulated nodes [cm]; ``found``: the simulated body's
        clearance, its point nearest the tank and that solid's name; ``kinematic``: the
        kinematic clearance; ``relaxed``: the relaxation's steps and residual [cm].
        """
        nodes, body = bodies
        clearance, point, solid = found
        gap = np.linalg.norm(body - nodes, axis=1)
        above = nodes[:, 2] > self.floor
        if not self.clearance or clearance < min(self.clearance):
            node = int(np.argmin(np.linalg.norm(body - point, axis=1)))
            arc = node * self.section_length / self.elements_per_section
            self.nearest = {
                "entry": int(entry),
                "point_cm": np.round(point, 3).tolist(),
                "arc_cm": arc,
                "section": min(
                    int(arc // self.section_length) + 1,
                    (len(body) - 1) // self.elements_per_section,
                ),
                "solid": solid,
            }
        self.entries.append(int(entry))
        self.t.append(t)
        self.bodies.append(body)
        self.deviation_max.append(float(gap.max()))
        self.deviation_mean.append(float(gap[above].mean()) if above.any() else 0.0)
        self.tip_error.append(float(gap[-1]))
        self.clearance.append(float(clearance))
        self.kinematic_clearance.append(float(kinematic))
        self.steps.append(int(relaxed[0]))
        self.residual.append(float(relaxed[1]))

    @property
    def least_clearance(self) -> float:
        """The smallest clearance of the simulated body over the snapshots [cm]."""
        return min(self.clearance)

    @property
    def held(self) -> bool:
        """Whether the simulated body keeps the margin at every snapshot."""
        return self.least_clearance >= self.margin

    def summary(self) -> dict[str, Any]:
        """The headline numbers (cm)."""
        worst = int(np.argmin(self.clearance))
        return {
            "margin_held": self.held,
            "margin_cm": self.margin,
            "least_clearance_cm": round(self.least_clearance, 4),
            "least_clearance_entry": self.entries[worst],
            "least_clearance_t_s": round(self.t[worst], 3),
            "kinematic_least_clearance_cm": round(min(self.kinematic_clearance), 4),
            "deviation_max_cm": round(max(self.deviation_max), 4),
            "deviation_mean_cm": round(float(np.mean(self.deviation_mean)), 4),
            "tip_error_max_cm": round(max(self.tip_error), 4),
            "tip_error_final_cm": round(self.tip_error[-1], 4),
            "nearest": self.nearest,
            "snapshots": len(self.entries),
            "unsettled_snapshots": int(sum(r >= TOLERANCE_CM for r in self.residual)),
        }

    def to_json(self) -> dict[str, Any]:
        """``physics.json``: the model, the summary, and every snapshot with its body."""
        import elastica

        return {
            "model": "Cosserat rod (PyElastica), quasi-static: relaxed to equilibrium at each "
            "snapshot under gravity, below-floor part held by the module and guide",
            "pyelastica": getattr(elastica, "__version__", None)
            or getattr(getattr(elastica, "version", None), "VERSION", None),
            "units": {"length": "cm", "time": "s", "rod": "kg, m, N, s (SI)"},
            "rod": self.rod.to_json(),
            "settings": self.settings,
            "summary": self.summary(),
            "seconds": round(self.seconds, 2),
            "snapshots": [
                {
                    "entry": e,
                    "t": round(t, 4),
                    "clearance_cm": round(c, 4),
                    "kinematic_clearance_cm": round(kc, 4),
                    "deviation_max_cm": round(dm, 4),
                    "deviation_mean_cm": round(da, 4),
                    "tip_error_cm": round(te, 4),
                    "steps": s,
                    "residual_cm": round(r, 5),
                    "body": np.round(b, 3).tolist(),
                }
                for e, t, c, kc, dm, da, te, s, r, b in zip(
                    self.entries,
                    self.t,
                    self.clearance,
                    self.kinematic_clearance,
                    self.deviation_max,
                    self.deviation_mean,
                    self.tip_error,
                    self.steps,
                    self.residual,
                    self.bodies,
                )
            ],
        }


def snapshot_entries(t: NDArray[np.float64], every_s: float, also: Sequence[int] = ()) -> list[int]:
    """The entries simulated (indices into the motion's times ``t``).

    The first entry at or after each multiple of ``every_s`` [s], the entries ``also``, and the
    last: never more than there are entries.
    """
    bucket = np.floor(np.asarray(t, dtype=np.float64) / every_s)
    first = np.flatnonzero(np.concatenate([[True], bucket[1:] != bucket[:-1]]))
    chosen = set(first.tolist()) | set(also) | {len(t) - 1}
    return sorted(i for i in chosen if 0 <= i < len(t))


def simulate_motion(
    run: TimedRun,
    tank: Tank,
    margin: float = DEFAULT_MARGIN,
    every_s: float = 1.0,
    rod: RodProperties | None = None,
    *,
    elements_per_section: int = ELEMENTS_PER_SECTION,
    gravity_direction: Sequence[float] = (0.0, 0.0, -1.0),
    progress: bool = False,
) -> PhysicsReport:
    """Re-run a timed motion on a Cosserat rod of the arm under gravity.

    Args:
        run: the timed motion (:func:`~aftir_rl.experiments.execution.read_timed`).
        tank: its tank (the arm's radius and, unless ``rod`` is given, its body's properties).
        margin: the clearance [cm] the simulated body must keep (the caller's, never a file's).
        every_s: seconds of the motion between two snapshots.
        rod: the body's properties (default: ``tank.arm.rod``).
        elements_per_section: rod elements per section.
        gravity_direction: gravity's direction in frame S.
        progress: show a progress bar over the snapshots.

    Raises:
        MissingExtraError: PyElastica is not installed (the ``physics`` extra).
        PhysicsError: more than :data:`MAX_SNAPSHOTS` instants, or the rod diverged twice.

    """
    if not every_s > 0:
        raise ValueError(f"every_s must be positive, got {every_s}")
    start = time.perf_counter()
    props = rod or tank.arm.rod
    n, l = run.theta.shape[1], run.section_length
    model = RodModel(n, l, tank.arm.radius, props, gravity_direction, elements_per_section)
    scene = CollisionScene(tank, links_per_section=20)
    floor = float(tank.panel.center[2])
    entries, kinematic = _instants(run, scene, every_s)
    out = PhysicsReport([], [], [], [], [], [], [], [], [], [], margin, props, floor, l, model.k)
    previous: tuple[Any, ...] | None = None
    for i in tqdm(entries, desc="physics", unit="snapshot", disable=not progress, leave=False):
        nodes, frames = kinematic_rod(run.dis[i], run.theta[i], run.phi[i], l, model.k)
        start_dirs = None if previous is None else carried_directors(frames, *previous)
        model.set_posture(nodes, frames, start_dirs, floor)
        try:
            steps, left = model.relax()
        except PhysicsError:
            if start_dirs is None:
                raise
            model = model.fresh()  # again, from the kinematic body
            model.set_posture(nodes, frames, None, floor)
            steps, left = model.relax()
        body, dirs = model.body()
        previous = (frames, dirs)
        if i not in kinematic:  # the last entry, where it starts no interval
            kinematic[i] = _kinematic_clearance(scene, run, i)
        arcs = body_points(run.dis[i], run.theta[i], run.phi[i], l, model.k * CURVE_POINTS)
        found = scene.polyline_clearance(body_curve(body, dirs, arcs, frames))
        out.record(i, float(run.timing.t[i]), (nodes, body), found, kinematic[i], (steps, left))
    out.settings = {
        "elements_per_section": model.k,
        "time_step_s": model.dt,
        "rotational_inertia_scale": model.inertia_scale,
        "damping_per_s": 2 * model.omega1,
        "tolerance_cm": TOLERANCE_CM,
        "every_s": every_s,
        "gravity_direction": [
            float(v) for v in np.asarray(gravity_direction) / np.linalg.norm(gravity_direction)
        ],
        "steps": model.steps,
    }
    out.seconds = time.perf_counter() - start
    return out


def _instants(
    run: TimedRun, scene: CollisionScene, every_s: float
) -> tuple[list[int], dict[int, float]]:
    """The entries to simulate, and the kinematic clearance of those looked at so far.

    One every ``every_s`` seconds and the last (:func:`snapshot_entries`), and the entry of
    least kinematic clearance among four times as many: where sag matters most.
    """
    entries = snapshot_entries(run.timing.t, every_s)
    if len(entries) + 1 > MAX_SNAPSHOTS:
        raise PhysicsError(
            f"the motion lasts {run.timing.t[-1]:.0f} s: {len(entries):,} instants at one every "
            f"{every_s:g} s, more than {MAX_SNAPSHOTS:,}; simulate fewer (a larger every_s)"
        )
    kinematic = {}
    for i in snapshot_entries(run.timing.t, every_s / 4):  # the instants above among them
        kinematic[i] = _kinematic_clearance(scene, run, i)
    return sorted(set(entries) | {min(kinematic, key=kinematic.__getitem__)}), kinematic


def _kinematic_clearance(scene: CollisionScene, run: TimedRun, i: int) -> float:
    """python-fcl's clearance [cm] of the kinematic arm at entry ``i``."""
    return scene.check(Posture(run.dis[i], run.theta[i], run.phi[i])).clearance_cm


#: Margin [cm] added on top of what a simulated body lacked when a motion is planned again.
REPLAN_SLACK = 0.2
#: Times a motion is planned again, each with more margin.
REPLAN_TRIES = 3


def replan_for_physics(
    tank: Tank,
    target: Sequence[float],
    report: PhysicsReport,
    planned_margin: float,
    every_s: float = 1.0,
    rod: RodProperties | None = None,
    *,
    progress: bool = False,
) -> tuple[Any, PhysicsReport, float]:
    """Plan ``target``'s motion again with the margin the simulated body lacked, and re-check.

    The planning margin grows by what the last simulated body missed of ``report.margin``,
    plus :data:`REPLAN_SLACK`, up to :data:`REPLAN_TRIES` times, until the new motion's
    simulated body keeps ``report.margin``.

    Returns:
        The last plan (:class:`~aftir_rl.planning.ftl.plan.MotionPlan`), its physics report and
        the margin it was planned with; the report's :attr:`PhysicsReport.held` says whether it
        holds.

    Raises:
        PlanningError: no motion reaches the target with the margin asked.

    """
    from aftir_rl.core.errors import PlanningError
    from aftir_rl.planning.ftl.plan import plan_motion

    margin = planned_margin
    for _ in range(REPLAN_TRIES):
        margin = round(margin + report.margin - report.least_clearance + REPLAN_SLACK, 2)
        plan = plan_motion(tank, target, margin=margin)
        if not plan.complete or plan.motion is None:
            raise PlanningError(
                plan.reason or f"Cannot reach the target: no motion keeps {margin:g} cm"
            )
        if plan.timing is None:
            raise PhysicsError(f"the new motion has no timing ({plan.timing_note})")
        motion = plan.motion
        timed = TimedRun(
            motion.dis, motion.theta, motion.phi, plan.timing, plan.section_length, margin
        )
        report = simulate_motion(timed, tank, report.margin, every_s, rod, progress=progress)
        if report.held:
            break
    return plan, report, margin
