"""The arm as a Cosserat rod (PyElastica), relaxed to equilibrium one posture at a time.

:class:`RodModel` is the physics check's simulator (:mod:`aftir_rl.experiments.physics` runs it
along a motion): a PyElastica ``CosseratRod`` of the arm's sections with the body's mass and
stiffnesses (:class:`~aftir_rl.core.rod.RodProperties`), clamped by the linear module and the
panel's guide where the body crosses the floor, each section's bend imposed as its rest
curvature (:func:`kinematic_rod`: the constant-curvature body of a posture, as rod nodes and
element frames), relaxed under damping until it rests. :func:`body_curve` is the smooth body
through the rod's nodes that the clearance is measured on. Needs the ``physics`` extra.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import PhysicsError
from aftir_rl.core.extras import require
from aftir_rl.core.robot import forward_kinematics, section_transforms
from aftir_rl.core.rod import RodProperties

__all__ = [
    "ELEMENTS_PER_SECTION",
    "TOLERANCE_CM",
    "RodModel",
    "body_curve",
    "carried_directors",
    "explicit_step",
    "kinematic_rod",
]

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


def body_curve(
    nodes: NDArray[np.float64],
    directors: NDArray[np.float64],
    arcs: NDArray[np.float64],
    frames: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The simulated body as ``CURVE_POINTS`` points per element, on curves rather than chords.

    A rod element is straight; the body it stands for is curved, and its chord lies up to the
    sagitta inside the arc (0.39 cm for a 10 cm element of a section bent 90° over 50 cm). Each
    element carries the kinematic arc's bow over its chord: the arc's points (``arcs``, the
    kinematic body at ``CURVE_POINTS`` points per element, :func:`body_points` order) less their
    chord, turned from the kinematic element's frame (``frames``, :func:`kinematic_rod`'s) into
    the simulated one's (``directors``, PyElastica's layout), put on the simulated chord
    (``nodes``). With no load the curve is the kinematic body exactly; under load the bow of each
    element is the one its sections impose, turned with it.
    """
    m, e = CURVE_POINTS, len(nodes) - 1
    ends = np.arange(0, e * m + 1, m)
    frac = (np.arange(m) / m)[None, :, None]
    starts, stops = arcs[ends[:-1]], arcs[ends[1:]]
    points = arcs[:-1].reshape(e, m, 3)
    bow = points - (starts[:, None] + frac * (stops - starts)[:, None])  # (E, m, 3) in frame S
    turn = directors.transpose(2, 1, 0) @ frames.transpose(0, 2, 1)  # R_sim · R_kinᵀ, (E, 3, 3)
    chord = nodes[:-1, None] + frac * (nodes[1:] - nodes[:-1])[:, None]
    curve = chord + np.einsum("eij,emj->emi", turn, bow)
    return np.vstack([curve.reshape(-1, 3), nodes[-1:]])


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
        direction = np.asarray(gravity_direction, dtype=np.float64)
        if isinstance(elements_per_section, bool) or not 1 <= elements_per_section <= 50:
            raise ValueError(f"elements_per_section must be 1 to 50, got {elements_per_section}")
        if direction.shape != (3,) or not np.linalg.norm(direction) > 0:
            raise ValueError(f"gravity_direction must be a non-zero 3-vector, got {direction}")
        direction = direction / np.linalg.norm(direction)
        self.k, self.l, self.props = int(elements_per_section), float(section_length), rod
        n = n_sections * self.k
        ds = self.l * CM / self.k
        area = math.pi * (radius * CM) ** 2
        self.held = _Held(n + 1)

        guide, arm = _elastica_classes(ea)

        # Element 0 is the end of the linear module's rod, always held: the arm's base (node 1)
        # is clamped where the module holds it, and the arm's elements are 1..N·k.
        self.system = arm()
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
        self.system.constrain(self.rod).using(guide, held=self.held)
        if rod.gravity > 0:
            self.system.add_forcing_to(self.rod).using(
                ea.GravityForces, acc_gravity=rod.gravity * direction
            )
        self.dt, self.inertia_scale, self.shear, self.axial = explicit_step(rod, ds, radius)
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
        # PyElastica's own curvature of a director chain, so that the rest curvature imposed is
        # measured exactly as the rod measures its own (private in PyElastica 1.0)
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
        clamp, joint = _clamp(nodes[:, 2], floor)
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
        nodes = self.rod.position_collection[:, 1:].T / CM
        return nodes, self.rod.director_collection[..., 1:].copy()


def _elastica_classes(ea: Any) -> tuple[type, type]:
    """The guide's constraint and the simulator: PyElastica classes, made once it is imported."""

    class Guide(ea.ConstraintBase):
        """The module and the panel's guide: what lies below the clamp is held in place."""

        def __init__(self, held: _Held, **kwargs: Any) -> None:
            super().__init__(**kwargs)
            self.held = held

        def constrain_values(self, system: Any, time: Any) -> None:
            system.position_collection[:, self.held.nodes] = self.held.positions
            system.director_collection[:, :, self.held.elements] = self.held.directors

        def constrain_rates(self, system: Any, time: Any) -> None:
            system.velocity_collection[:, self.held.nodes] = 0.0
            system.omega_collection[:, self.held.elements] = 0.0

    class Arm(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        """The simulator: one rod, its constraint, gravity and damping."""

    return Guide, Arm


def explicit_step(
    rod: RodProperties, ds: float, radius: float
) -> tuple[float, float, float, float]:
    """The time step [s], rotational-inertia scale and the stretch and shear stiffness used.

    The stiffest modes (a node's stretch, shear and bend, an element's rotation) bound the
    explicit step. A body at rest does not feel its inertia, so the rotational inertia is raised
    until rotation is no faster than bending, and a stretch or shear stiffness above
    ``STIFF_RATIO²`` times bending's ``(2/ds)²·E·I`` is lowered to it: the body stays as good as
    inextensible (its own weight stretches it by under 1e-4 of its length) and the step is set
    by bending. ``ds`` is the element length [m], ``radius`` the body's [cm].
    """
    m = rod.mass_per_length
    bend = (2 / ds) ** 2 * math.sqrt(rod.bending_stiffness / m)
    cap = STIFF_RATIO**2 * (2 / ds) ** 2 * rod.bending_stiffness
    shear, axial = min(rod.shear_stiffness, cap), min(rod.axial_stiffness, cap)
    translation = max(bend, 2 / ds * math.sqrt(max(axial, shear) / m))
    inertia = m * (radius * CM) ** 2 / 4  # per metre, about a cross axis (a solid cylinder)
    stiffest = max(4 * shear, 16 * rod.bending_stiffness / ds**2, 8 * rod.twist_stiffness / ds**2)
    rotation = math.sqrt(stiffest / inertia)
    return STEP / translation, max(1.0, (rotation / translation) ** 2), shear, axial


def _clamp(z: NDArray[np.float64], floor: float) -> tuple[int, float]:
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


def carried_directors(
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
