"""What every posture method receives: the planning context, and what every method returns.

:class:`PlanningContext` holds the tank, its arm and python-fcl scene, the search settings, and
the checks every planned posture passes: the target is a free point of the tank
(:meth:`~PlanningContext.check_target`), and the posture keeps the joint limits, the panel rule,
clears the tank with the arm's radius and puts the tip on the target by forward kinematics
(:meth:`~PlanningContext.checked`). A posture that fails raises
:class:`~aftir_rl.core.errors.PlanningError`, "Cannot reach the target: <why>".

A method is anything with the :class:`PostureMethod` protocol: a name, a line of help, the paper
it comes from, the benchmark sets it is measured on, and ``plan(context, target)``. The methods
live one module each beside this one and import only this module and the search;
:mod:`~aftir_rl.planning.posture.registry` lists them and
:class:`~aftir_rl.planning.posture.planner.Planner` dispatches to them (docs/design.md §6).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import CollisionReport, CollisionScene, point_clearance
from aftir_rl.core.errors import ConfigError, PlanningError
from aftir_rl.core.robot import Posture
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.core.tank.raster import format_point

__all__ = [
    "PlannedPosture",
    "PlanningContext",
    "PostureMethod",
    "Method",
    "random_free_targets",
]


@dataclass
class PlannedPosture:
    """A checked posture and how it was found.

    Attributes:
        posture: the joint variables.
        section_length: ``l`` [cm].
        target: the target [cm].
        tip: the tip by forward kinematics [cm].
        error_cm: ``|tip − target|`` [cm].
        clearance_cm: smallest distance of the arm's body to the tank [cm].
        method: the name of the method that found it.
        seconds: planning wall time.
        details: search statistics (loops, evaluations, the TSM parts...).

    """

    posture: Posture
    section_length: float
    target: NDArray[np.float64]
    tip: NDArray[np.float64]
    error_cm: float
    clearance_cm: float
    method: str
    seconds: float
    details: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The posture JSON of docs/design.md §6."""
        return {
            **self.posture.to_dict(),
            "section_length": self.section_length,
            "tip": [float(v) for v in self.tip],
            "target": [float(v) for v in self.target],
            "error_cm": self.error_cm,
            # No solid at all (open space without obstacles): no finite clearance.
            "clearance_cm": self.clearance_cm if math.isfinite(self.clearance_cm) else None,
            "method": self.method,
            "seconds": self.seconds,
        }


class PlanningContext:
    """The tank, arm, collision scene, search settings and checks that every method receives.

    Args:
        tank: tank name, YAML path or :class:`~aftir_rl.core.tank.Tank`.
        num: NUM of region clipping.
        dtheta: search step ``Δθ`` [rad].
        zone: target zone radius ``ε`` [cm].
        tolerance: largest tip error accepted after refinement [cm].
        margin: extra clearance the search keeps from solids beyond the arm's radius [cm].
        extra_sections: sections tried beyond the fewest that can span the distance.

    """

    def __init__(
        self,
        tank: str | Tank = DEFAULT_TANK,
        num: int = 9,
        dtheta: float = math.radians(1.0),
        zone: float = 0.5,
        tolerance: float = 0.01,
        margin: float = 1.0,
        extra_sections: int = 3,
    ) -> None:
        self.tank = load_tank(tank)
        self.arm = self.tank.arm
        self.scene = CollisionScene(self.tank)
        self.num, self.dtheta, self.zone = num, dtheta, zone
        self.tolerance, self.margin = tolerance, margin
        self.extra_sections = extra_sections
        # Backbone samples no farther apart than twice the margin for the pre-filter, so the
        # backbone between two samples stays clear by more than the arm's radius.
        self.check_points = max(4, math.ceil(self.arm.section_length / (2 * margin)))

    def min_sections(self, distance: float) -> int:
        """The fewest sections that span ``distance`` [cm] (at least one)."""
        return max(1, math.ceil(distance / self.arm.section_length - 1e-9))

    def beyond_baffle(self, target: ArrayLike) -> bool:
        """Whether ``target`` lies on the far side of the baffle from the panel."""
        b = self.tank.baffle
        if b is None or self.tank.hatch is None:
            return False
        side = np.sign(self.tank.panel.center[b.index] - b.position)
        return bool(np.sign(np.asarray(target)[b.index] - b.position) == -side)

    def check_target(self, target: ArrayLike) -> NDArray[np.float64]:
        """The target as an array, checked to be a free point of the tank.

        Raises:
            PlanningError: not three finite numbers, outside the box, inside a solid, or closer
                to a surface than the arm's radius.

        """
        t = np.asarray(target, dtype=np.float64)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise PlanningError(f"Cannot reach the target: expected x y z in cm, got {target!r}")
        if not self.tank.contains_point(t):
            raise PlanningError(
                f"Cannot reach the target: {format_point(t)} cm is outside the tank box "
                f"{format_point(self.tank.box_min)}..{format_point(self.tank.box_max)}"
            )
        solid = self.tank.solid_at(t)
        if solid is not None:
            raise PlanningError(
                f"Cannot reach the target: {format_point(t)} cm is inside {solid.name or 'a solid'}"
            )
        clearance = float(point_clearance(self.tank, t[None])[0])
        if clearance <= self.arm.radius:
            raise PlanningError(
                f"Cannot reach the target: {format_point(t)} cm is {clearance:.1f} cm from a wall "
                f"or obstacle, closer than the arm's radius {self.arm.radius:g} cm"
            )
        return t

    def checked(
        self,
        posture: Posture,
        target: ArrayLike,
        method: str,
        tolerance: float | None = None,
        details: dict[str, Any] | None = None,
        started: float | None = None,
        report: CollisionReport | None = None,
    ) -> PlannedPosture:
        """Check a posture by forward kinematics and collision, or raise PlanningError.

        Args:
            posture: the posture.
            target: the point its tip must reach [cm].
            method: name recorded in the result.
            tolerance: largest tip error [cm] (default: the context's).
            details: recorded in the result.
            started: ``time.perf_counter()`` when planning began (the result's ``seconds``).
            report: the scene's check of this very posture, where the caller has it already.

        Raises:
            PlanningError: a bending angle beyond the joint limit, the tip farther than the
                tolerance, a collision or the panel rule broken.

        """
        start = time.perf_counter() if started is None else started
        goal = np.asarray(target, float)
        tolerance = self.tolerance if tolerance is None else tolerance
        l = self.arm.section_length
        if any(abs(t) > self.arm.theta_max + 1e-9 for t in posture.theta):
            raise PlanningError("Cannot reach the target: a bending angle exceeds the joint limit")
        tip = posture.tip(l)
        error = float(np.linalg.norm(tip - goal))
        if error > tolerance:
            raise PlanningError(
                f"Cannot reach the target: the tip ends {error:.3f} cm from it (tolerance "
                f"{tolerance:g} cm)"
            )
        report = self.scene.check(posture) if report is None else report
        if report.collides:
            why = "breaks the panel rule" if not report.panel_ok else f"touches {report.hit}"
            raise PlanningError(f"Cannot reach the target: the posture {why}")
        seconds = time.perf_counter() - start
        clearance = report.clearance_cm
        return PlannedPosture(
            posture, l, goal, tip, error, clearance, method, seconds, details or {}
        )


class PostureMethod(Protocol):
    """A posture planning method, as the registry lists it.

    Attributes:
        name: what ``--method`` takes and results record.
        summary: one line for ``--help``.
        paper: short name of the paper it comes from (:mod:`aftir_rl.core.papers`), or None.
        bench_sets: the benchmark target sets it is measured on (``python -m aftir_rl.bench``).

    """

    @property
    def name(self) -> str:
        """What ``--method`` takes."""
        ...

    @property
    def summary(self) -> str:
        """One line for ``--help``."""
        ...

    @property
    def paper(self) -> str | None:
        """The paper's short name, or None."""
        ...

    @property
    def bench_sets(self) -> tuple[str, ...]:
        """The benchmark target sets."""
        ...

    def plan(self, context: PlanningContext, target: ArrayLike) -> PlannedPosture:
        """A checked posture reaching ``target`` [cm], or PlanningError."""
        ...

    def unavailable(self, context: PlanningContext, target: ArrayLike) -> str:
        """Why the method is not run on ``target`` at all ("" when it is)."""
        ...


@dataclass(frozen=True)
class Method:
    """A :class:`PostureMethod` made of functions; each method module defines its own."""

    name: str
    summary: str
    planner: Callable[[PlanningContext, ArrayLike], PlannedPosture]
    paper: str | None = None
    bench_sets: tuple[str, ...] = ()
    skip: Callable[[PlanningContext, ArrayLike], str] | None = None

    def plan(self, context: PlanningContext, target: ArrayLike) -> PlannedPosture:
        """A checked posture reaching ``target`` [cm], or PlanningError."""
        return self.planner(context, target)

    def unavailable(self, context: PlanningContext, target: ArrayLike) -> str:
        """Why the method is not run on ``target`` at all ("" when it is)."""
        return "" if self.skip is None else self.skip(context, target)


def random_free_targets(
    context: PlanningContext, n_each: int, seed: int, clearance: float = 5.0
) -> dict[str, list[NDArray[np.float64]]]:
    """Uniform random points of the tank at least ``clearance`` [cm] from any surface.

    Returns ``n_each`` points on each side of the baffle: ``{"bay1": [...], "bay2": [...]}``
    (``bay2`` beyond the baffle, planned with TSM by ``auto``).
    """
    tank, rng = context.tank, np.random.default_rng(seed)
    if tank.baffle is None:
        raise ConfigError(
            f"{tank.name}: random_free_targets draws on both sides of a tank's baffle and hatch; "
            "this tank has none (draw in Tank.bay(n) instead)"
        )
    out: dict[str, list[NDArray[np.float64]]] = {"bay1": [], "bay2": []}
    for _ in range(1000 * (n_each + 1)):
        if min(len(v) for v in out.values()) >= n_each:
            return out
        x = rng.uniform(tank.box_min, tank.box_max)
        if point_clearance(tank, x[None])[0] <= clearance:
            continue
        bay = "bay2" if context.beyond_baffle(x) else "bay1"
        if len(out[bay]) < n_each:
            out[bay].append(x)
    if min(len(v) for v in out.values()) >= n_each:
        return out
    raise ConfigError(f"{tank.name}: found too few points {clearance:g} cm clear in each bay")
