"""A timed motion re-run on a Cosserat rod under gravity: the clearance the arm's body keeps.

Every check of the planner is made on the constant-curvature model: sections are exact arcs and
nothing sags. :func:`simulate_motion` re-runs a timed motion (:class:`TimedRun`) on a Cosserat
rod of the arm (PyElastica, the ``physics`` extra): the rod has the arm's section length and
radius and the body's mass and stiffnesses (:class:`~aftir_rl.core.rod.RodProperties`, the tank
YAML's ``arm.rod``); the part of the rod below the tank's floor is held by the linear module and
the panel's guide where the motion puts it (the module's timed ``dis``); each section's bend is
imposed as its rest curvature (the timed bending vectors: what the cables impose); gravity pulls
along −z.

The motion is slow against the body's own vibration (a few cm/s against a first natural period
of about half a second at the defaults), so the body is taken to be at rest in equilibrium at
each instant: at every snapshot (every ``every_s`` seconds of the motion, the motion's tightest
entry and its last) the rod is relaxed under damping to equilibrium, starting from the previous
snapshot's body moved with the motion. The relaxation runs in fixed chunks of steps until the
body is estimated within :data:`TOLERANCE_CM` of equilibrium or :data:`MAX_TIME_CONSTANTS`
lowest-mode time constants have passed: the same inputs give the same answer.

The simulated body is checked against the tank with python-fcl (capsules of the arm's radius
along it), and compared with the kinematic body at the same material points. docs/robot.md
("Physics") describes the model, its validation against closed forms and the measured results.
"""

from __future__ import annotations

import math
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
from aftir_rl.core.extras import require
from aftir_rl.core.robot import Posture, forward_kinematics, section_transforms
from aftir_rl.core.rod import RodProperties
from aftir_rl.core.tank import Tank
from aftir_rl.experiments.execution import TimedRun

__all__ = [
    "PHYSICS_FILE",
    "PhysicsReport",
    "RodModel",
    "kinematic_rod",
    "simulate_motion",
]

#: The file the physics check writes beside ``trajectory.json``.
PHYSICS_FILE = "physics.json"
#: The most instants one motion is simulated at (a 40-minute tour at one every 0.5 s).
MAX_SNAPSHOTS = 5_000
#: Rod elements per section (10 cm at the default 50 cm sections).
ELEMENTS_PER_SECTION = 5
#: The relaxation stops when the body is estimated this near its equilibrium [cm].
TOLERANCE_CM = 0.01
#: ... or when this many time constants of the lowest mode have passed (reported if so).
MAX_TIME_CONSTANTS = 40.0
#: Stretch and shear modes may be this many times faster than the fastest bending mode.
STIFF_RATIO = 2.0
#: The time step as a fraction of the fastest mode's period over π (2: Verlet's bound).
STEP = 1.5
#: Steps between two looks at the body's speed.
CHUNK = 250
#: Points per rod element on the smooth curve through the nodes that the clearance is taken on.
CURVE_POINTS = 4
CM = 0.01  # m


def kinematic_rod(
    dis: float, theta: NDArray[np.float64], phi: NDArray[np.float64], l: float, k: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The constant-curvature body as a rod of ``k`` elements per section.

    Returns:
        The nodes [cm], ``(N·k + 1, 3)``, at arc lengths ``l·j/k``, and each element's frame
        ``(N·k, 3, 3)`` (columns: ``d1, d2, d3`` in frame S, ``d3`` along the body) taken at the
        element's middle, where the arc's tangent is parallel to the element's chord.

    """
    theta, phi = np.asarray(theta, dtype=np.float64), np.asarray(phi, dtype=np.float64)
    ends = forward_kinematics(dis, theta, phi, l)  # (N + 1, 4, 4)
    frac = np.arange(1, k + 1) / k
    mid = (np.arange(k) + 0.5) / k
    at_nodes = section_transforms(theta[:, None] * frac, phi[:, None], l * frac)  # (N, k, 4, 4)
    at_mids = section_transforms(theta[:, None] * mid, phi[:, None], l * mid)
    nodes = (ends[:-1, None] @ at_nodes)[..., :3, 3].reshape(-1, 3)
    frames = (ends[:-1, None] @ at_mids)[..., :3, :3].reshape(-1, 3, 3)
    return np.vstack([ends[0, :3, 3], nodes]), frames


def _curve(nodes: NDArray[np.float64], directors: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points ``CURVE_POINTS`` per element on the cubic Hermite curve through the nodes.

    The tangent at a node is the mean of its elements' ``d3`` (directors ``(3, 3, E)`` as
    PyElastica stores them: rows ``d1, d2, d3``), scaled by the element's length; a chord of
    the smooth body lies up to its sagitta (0.1 cm at 5 cm elements bent 90° over 50 cm) inside
    the arc, the curve within 1e-3 cm.
    """
    d3 = directors[2].T  # (E, 3)
    tangents = np.vstack([d3[:1], (d3[:-1] + d3[1:]) / 2, d3[-1:]])
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    p0, p1 = nodes[:-1], nodes[1:]
    h = np.linalg.norm(p1 - p0, axis=1, keepdims=True)
    m0, m1 = tangents[:-1] * h, tangents[1:] * h
    s = (np.arange(CURVE_POINTS) / CURVE_POINTS)[:, None, None]
    h00, h10, h01, h11 = (
        2 * s**3 - 3 * s**2 + 1,
        s**3 - 2 * s**2 + s,
        -2 * s**3 + 3 * s**2,
        s**3 - s**2,
    )
    pts = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1  # (CURVE_POINTS, E, 3)
    return np.vstack([pts.transpose(1, 0, 2).reshape(-1, 3), nodes[-1:]])


class RodModel:
    """The arm as a PyElastica Cosserat rod, relaxed to equilibrium posture by posture.

    Args:
        n_sections: the arm's sections, N.
        section_length: ``l`` [cm].
        radius: the body's radius [cm] (its inertia; the stiffnesses are ``rod``'s).
        rod: mass, stiffnesses and gravity.
        gravity_direction: the direction of gravity in frame S (default −z).
        elements_per_section: rod elements per section.

    """

    def __init__(
        self,
        n_sections: int,
        section_length: float,
        radius: float,
        rod: RodProperties,
        gravity_direction: Sequence[float] = (0.0, 0.0, -1.0),
        elements_per_section: int = ELEMENTS_PER_SECTION,
    ) -> None:
        ea = require("elastica", "physics")
        self._args = (
            n_sections,
            section_length,
            radius,
            rod,
            gravity_direction,
            elements_per_section,
        )
        self.k, self.l, self.props = int(elements_per_section), float(section_length), rod
        n = n_sections * self.k
        ds = self.l * CM / self.k
        area = math.pi * (radius * CM) ** 2
        direction = np.asarray(gravity_direction, dtype=np.float64)
        direction = direction / np.linalg.norm(direction)
        self.held = _Held(n + 1)

        class Guide(ea.ConstraintBase):  # type: ignore[name-defined]
            """The module and the panel's guide: what lies below the floor is held in place."""

            def __init__(self, held: _Held, **kwargs: Any) -> None:
                super().__init__(**kwargs)
                self.held = held

            def constrain_values(self, system: Any, time: Any) -> None:
                system.position_collection[:, self.held.nodes] = self.held.positions
                system.director_collection[:, :, self.held.elements] = self.held.directors

            def constrain_rates(self, system: Any, time: Any) -> None:
                system.velocity_collection[:, self.held.nodes] = 0.0
                system.omega_collection[:, self.held.elements] = 0.0

        class Arm(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):  # type: ignore[name-defined]
            pass

        # Element 0 is the end of the linear module's rod, always held: the arm's base (node 1)
        # is clamped where the module holds it, and the arm's elements are 1..N·k.
        self.system = Arm()
        self.rod = ea.CosseratRod.straight_rod(
            n + 1,
            np.array([0.0, 0.0, -ds]),
            np.array([0.0, 0.0, 1.0]),
            np.array([1.0, 0.0, 0.0]),
            (n + 1) * ds,
            radius * CM,
            rod.mass_per_length / area,
            youngs_modulus=1.0,  # the stiffness matrices are set below
            shear_modulus=1.0,
        )
        self.system.append(self.rod)
        self.system.constrain(self.rod).using(Guide, held=self.held)
        if rod.gravity > 0:
            self.system.add_forcing_to(self.rod).using(
                ea.GravityForces, acc_gravity=rod.gravity * direction
            )
        # Time step and damping. The stiffest modes (a node's stretch, shear and bend, an
        # element's rotation) bound the explicit step. A body at rest does not feel its inertia,
        # so the rotational inertia is raised until rotation is no faster than bending, and a
        # stretch or shear stiffness above STIFF_RATIO² times the bending one's (2/ds)²·E·I is
        # lowered to it: the body stays as good as inextensible (its own weight stretches it by
        # under 1e-4 of its length) and the step is set by bending.
        m = rod.mass_per_length
        bend = (2 / ds) ** 2 * math.sqrt(rod.bending_stiffness / m)
        cap = STIFF_RATIO**2 * (2 / ds) ** 2 * rod.bending_stiffness
        self.shear = min(rod.shear_stiffness, cap)
        self.axial = min(rod.axial_stiffness, cap)
        translation = max(bend, 2 / ds * math.sqrt(max(self.axial, self.shear) / m))
        inertia = m * (radius * CM) ** 2 / 4  # per metre, about a cross axis (a solid cylinder)
        rotation = math.sqrt(
            max(4 * self.shear, 16 * rod.bending_stiffness / ds**2, 8 * rod.twist_stiffness / ds**2)
            / inertia  # fmt: skip
        )
        self.inertia_scale = max(1.0, (rotation / translation) ** 2)
        self.dt = STEP / translation
        self.length_m = n * ds
        self._module = (np.array([0.0, 0.0, -ds]), np.eye(3))  # below the base; Q = I
        self.omega1 = self._lowest_mode(self.length_m)
        self.system.dampen(self.rod).using(
            ea.AnalyticalLinearDamper, uniform_damping_constant=2 * self.omega1, time_step=self.dt
        )
        self.system.finalize()
        r = self.rod
        self._bend = np.diag([rod.bending_stiffness, rod.bending_stiffness, rod.twist_stiffness])[
            ..., None
        ]
        r.bend_matrix[...] = self._bend
        r.shear_matrix[...] = np.diag([self.shear, self.shear, self.axial])[..., None]
        r.mass_second_moment_of_inertia[...] *= self.inertia_scale
        r.inv_mass_second_moment_of_inertia[...] /= self.inertia_scale
        self.stepper = ea.PositionVerlet()
        self._strains = ea.rod.cosserat_rod._compute_bending_twist_strains
        self.time = 0.0
        self.steps = 0

    def fresh(self) -> RodModel:
        """A new model of the same rod (after a divergence), keeping the count of steps."""
        model = RodModel(*self._args)
        model.steps = self.steps
        return model

    def _lowest_mode(self, free_m: float) -> float:
        """The first bending frequency [rad/s] of a straight cantilever ``free_m`` long."""
        free_m = max(free_m, 2 * self.l * CM / self.k)
        return (
            3.516 / free_m**2 * math.sqrt(self.props.bending_stiffness / self.props.mass_per_length)
        )

    def set_posture(
        self,
        nodes: NDArray[np.float64],
        frames: NDArray[np.float64],
        start: NDArray[np.float64] | None = None,
        floor: float = 0.0,
    ) -> None:
        """Impose a kinematic body (:func:`kinematic_rod`, cm) as rest shape and guide.

        The rod's rest curvature and stretch become the kinematic body's, so that with no load
        it rests exactly there. The module and the panel's guide clamp the body at the floor
        (``floor``, z [cm]), or at the base where the base is above it: the base, the nodes below
        the clamp and the first node at or above it are held where the kinematic body has them,
        and the bending stiffness at that node is scaled so that its joint is as compliant as
        the free rod from the clamp to the middle of the next element (a clamp between nodes,
        to second order in the element length). The rod starts from the kinematic body, or
        with ``start`` (directors ``(3, 3, N·k)``, PyElastica's layout) from the body those
        directors make with the kinematic body's element lengths, chained from the base: a start
        that is only bent, never stretched or sheared, which the explicit steps take calmly.
        """
        x, q = self._with_module(nodes, np.ascontiguousarray(frames.transpose(2, 1, 0)))
        r = self.rod
        ds = self.l * CM / self.k
        self._strains(q, r.rest_voronoi_lengths, r.rest_kappa)
        chord = np.diff(x, axis=1)
        r.rest_sigma[...] = np.einsum("ije,je->ie", q, chord) / ds - np.array([[0.0], [0.0], [1.0]])
        clamp, joint = _clamp(nodes[:, 2], floor, self.l / self.k)
        r.bend_matrix[...] = self._bend
        if clamp < len(nodes) - 1:
            r.bend_matrix[..., clamp] *= 1.0 / joint  # the Voronoi of rod node clamp + 1
        held = np.arange(clamp + 2)  # the module's node, the arm's nodes 0..clamp
        self.held.set(held, x, q)
        if start is not None:
            q = np.ascontiguousarray(np.dstack([q[..., :1], start]))
            steps = np.linalg.norm(chord, axis=0) * q[2]  # each element's chord along its d3
            x = np.ascontiguousarray(
                x[:, :1] + np.hstack([np.zeros((3, 1)), np.cumsum(steps, axis=1)])
            )
        r.position_collection[...] = x
        r.director_collection[...] = q
        r.velocity_collection[...] = 0.0
        r.omega_collection[...] = 0.0

    def _with_module(
        self, nodes: NDArray[np.float64], q: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Nodes [cm] and directors of the arm with the module's element in front (SI)."""
        base = nodes[0] * CM
        x = np.hstack([(base + self._module[0])[:, None], nodes.T * CM])
        return np.ascontiguousarray(x), np.ascontiguousarray(
            np.dstack([self._module[1][..., None], q])
        )

    def relax(self, tolerance_cm: float = TOLERANCE_CM) -> tuple[int, float]:
        """Step until the body is within ``tolerance_cm`` of rest (or the step budget).

        Returns the steps taken and the estimated distance from equilibrium [cm].
        """
        free = self.held.free_length(self.l * CM / self.k, self.length_m)
        if free <= 0:
            return 0, 0.0
        omega = self._lowest_mode(free)
        budget = int(MAX_TIME_CONSTANTS / min(omega, self.omega1) / self.dt) + CHUNK
        steps, left = 0, math.inf
        while steps < budget:
            for _ in range(CHUNK):
                self.time = self.stepper.step(self.system, self.time, self.dt)
            steps += CHUNK
            x = self.rod.position_collection
            if not np.isfinite(x).all() or np.abs(x - x[:, 1:2]).max() > 2 * self.length_m:
                raise PhysicsError(
                    "the simulated rod diverged (its body left every finite bound); the rod "
                    "properties may be far outside what the model is made for"
                )
            # a mode decaying at the damped rate keeps moving about speed/rate further
            left = float(np.abs(self.rod.velocity_collection).max()) / self.omega1 / CM
            if left < tolerance_cm:
                break
        self.steps += steps
        return steps, left

    def body(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The arm's nodes [cm] ``(N·k + 1, 3)`` and directors ``(3, 3, N·k)`` now."""
        return self.rod.position_collection[:, 1:].T / CM, self.rod.director_collection[
            ..., 1:
        ].copy()


def _clamp(z: NDArray[np.float64], floor: float, ds: float) -> tuple[int, float]:
    """Where the body is clamped: the first node at or above ``floor`` (z of the nodes, cm).

    Returns its index ``c`` and the length of free rod its joint stands for, from the clamp to
    the middle of element ``c``, in element lengths (in [1/2, 3/2)): the clamp is where the body
    crosses the floor, or the base if that is above it. ``c`` is the last node if none is above.
    """
    above = np.flatnonzero(z >= floor)
    if not above.size:
        return len(z) - 1, 1.0
    c = int(above[0])
    if c == 0:
        return 0, 0.5
    # where the body crosses the floor, between nodes c - 1 and c, as a fraction of an element
    cross = (floor - z[c - 1]) / max(z[c] - z[c - 1], 1e-12)
    return c, 0.5 + (1.0 - min(max(cross, 0.0), 1.0))


class _Held:
    """The nodes and elements the guide holds, and where (SI units, PyElastica's layout)."""

    def __init__(self, n_elements: int) -> None:
        self.n = n_elements
        self.set(np.array([0]), np.zeros((3, n_elements + 1)), np.zeros((3, 3, n_elements)))

    def set(self, nodes: NDArray[np.int64], x: NDArray[np.float64], q: NDArray[np.float64]) -> None:
        """Hold ``nodes`` (consecutive from 0) and the elements between them at ``x``, ``q``."""
        self.nodes = nodes
        self.elements = nodes[:-1]
        self.positions = x[:, self.nodes].copy()
        self.directors = q[:, :, self.elements].copy()

    def free_length(self, ds: float, total: float) -> float:
        """The length of the arm above the last held node [m] (``total``: the arm's)."""
        return total - ds * (len(self.nodes) - 2)


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
    settings: dict[str, Any] = field(default_factory=dict)
    nearest: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

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

    """
    if not every_s > 0:
        raise ValueError(f"every_s must be positive, got {every_s}")
    start = time.perf_counter()
    props = rod or tank.arm.rod
    n = run.theta.shape[1]
    model = RodModel(n, run.section_length, tank.arm.radius, props, gravity_direction,
                     elements_per_section)  # fmt: skip
    scene = CollisionScene(tank, links_per_section=20)
    k, l = model.k, run.section_length
    floor = float(tank.panel.center[2])
    entries = snapshot_entries(run.timing.t, every_s)
    if len(entries) + 1 > MAX_SNAPSHOTS:
        raise PhysicsError(
            f"the motion lasts {run.timing.t[-1]:.0f} s: {len(entries):,} instants at one every "
            f"{every_s:g} s, more than {MAX_SNAPSHOTS:,}; simulate fewer (a larger every_s)"
        )
    # The tightest entry of the kinematic motion joins the snapshots: where sag matters most.
    kin_clear = {}
    for i in snapshot_entries(run.timing.t, every_s / 4):
        kin_clear[i] = scene.check(Posture(run.dis[i], run.theta[i], run.phi[i])).clearance_cm
    entries = sorted(set(entries) | {min(kin_clear, key=kin_clear.__getitem__)})
    out = PhysicsReport([], [], [], [], [], [], [], [], [], [], margin, props)
    previous: tuple[Any, ...] | None = None
    worst = math.inf
    for i in tqdm(entries, desc="physics", unit="snapshot", disable=not progress, leave=False):
        nodes, frames = kinematic_rod(run.dis[i], run.theta[i], run.phi[i], l, k)
        start_dirs = None if previous is None else _moved_directors(frames, *previous)
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
        above = nodes[:, 2] > floor
        gap = np.linalg.norm(body - nodes, axis=1)
        clearance, point, solid = scene.polyline_clearance(_curve(body, dirs))
        if i not in kin_clear:
            kin_clear[i] = scene.check(Posture(run.dis[i], run.theta[i], run.phi[i])).clearance_cm
        out.entries.append(int(i))
        out.t.append(float(run.timing.t[i]))
        out.bodies.append(body)
        out.deviation_max.append(float(gap.max()))
        out.deviation_mean.append(float(gap[above].mean()) if above.any() else 0.0)
        out.tip_error.append(float(gap[-1]))
        out.clearance.append(float(clearance))
        out.kinematic_clearance.append(float(kin_clear[i]))
        out.steps.append(int(steps))
        out.residual.append(float(left))
        if clearance < worst:
            worst = clearance
            arc = float(np.argmin(np.linalg.norm(body - point, axis=1))) * l / k
            out.nearest = {
                "entry": int(i),
                "point_cm": np.round(point, 3).tolist(),
                "arc_cm": arc,
                "section": min(int(arc // l) + 1, n),
                "solid": solid,
            }
    out.settings = {
        "elements_per_section": k,
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


def _moved_directors(
    frames: NDArray[np.float64],
    p_frames: NDArray[np.float64],
    p_dirs: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The previous body's directors carried along with the kinematic motion.

    Each element's turn away from the kinematic frame (``R_sim = D · R_kin`` in frame S) is kept
    and applied to the new kinematic frame: ``Q = (D · R_new)ᵀ`` in PyElastica's layout.
    """
    turn = p_dirs.transpose(2, 1, 0) @ p_frames.transpose(0, 2, 1)  # D = R_sim · R_kinᵀ
    return np.ascontiguousarray((turn @ frames).transpose(2, 1, 0))


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
                f"Cannot reach the target: no motion keeps {margin:g} cm ({plan.reason})"
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
