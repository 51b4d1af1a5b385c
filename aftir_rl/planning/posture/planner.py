"""The planner: a planning context that dispatches to the registered methods.

``Planner(tank).plan(target, method)`` runs one method of
:mod:`aftir_rl.planning.posture.registry` on the planner's
:class:`~aftir_rl.planning.posture.context.PlanningContext` (which the planner is). ``auto`` is
TSM for a target beyond the baffle and TGA otherwise. Every posture a method returns is checked:
joint limits, the panel rule, python-fcl collision with the arm's radius, and the tip error by
forward kinematics. Otherwise it raises :class:`~aftir_rl.core.errors.PlanningError`, "Cannot reach
the target: <why>".

This module imports the methods; no method imports it.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from aftir_rl.planning.posture.context import PlannedPosture, PlanningContext, random_free_targets
from aftir_rl.planning.posture.registry import AUTO, METHOD_NAMES, get_method
from aftir_rl.planning.posture.tga import tga
from aftir_rl.planning.posture.tsm import tsm

__all__ = ["PlannedPosture", "Planner", "METHODS", "random_free_targets"]

METHODS = METHOD_NAMES
"""Every name ``plan`` takes: ``auto`` and the registered methods."""


class Planner(PlanningContext):
    """Plans postures of the tank's arm (the settings are :class:`PlanningContext`'s)."""

    def plan(self, target: ArrayLike, method: str = AUTO) -> PlannedPosture:
        """Plan a posture reaching ``target`` [cm] with ``method`` (:data:`METHODS`).

        Raises:
            ValueError: an unknown method.
            PlanningError: "Cannot reach the target: <why>".

        """
        if method != AUTO:
            return get_method(method).plan(self, self.check_target(target))
        goal = self.check_target(target)
        return get_method("tsm" if self.beyond_baffle(goal) else "tga").plan(self, goal)

    def tga(self, target: ArrayLike, end_direction: ArrayLike | None = None) -> PlannedPosture:
        """TGA (:func:`~aftir_rl.planning.posture.tga.tga`), optionally with an end direction."""
        return tga(self, target, end_direction)

    def tsm(self, target: ArrayLike) -> PlannedPosture:
        """TSM (:func:`aftir_rl.planning.posture.tsm.tsm`)."""
        return tsm(self, target)
