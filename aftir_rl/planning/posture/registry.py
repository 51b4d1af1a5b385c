"""Every posture method, by name: the one list that ``plan``, ``bench`` and the planner read.

Adding a method: write its module beside the others (a
:class:`~aftir_rl.planning.posture.context.Method` or anything with the
:class:`~aftir_rl.planning.posture.context.PostureMethod` protocol) and add it here. The methods
import :mod:`aftir_rl.planning.posture.context` and the search helpers (TSM builds on TGA's),
never this module nor the planner.
"""

from __future__ import annotations

from aftir_rl.planning.posture.context import PostureMethod
from aftir_rl.planning.posture.obstacle_clipping import OBSTACLE_CLIPPING
from aftir_rl.planning.posture.region_division import REGION_DIVISION
from aftir_rl.planning.posture.tga import BLIND, REGION_CLIPPING, TGA
from aftir_rl.planning.posture.tsm import TSM

__all__ = ["REGISTRY", "AUTO", "METHOD_NAMES", "get_method"]

REGISTRY: dict[str, PostureMethod] = {
    m.name: m for m in (BLIND, REGION_CLIPPING, TGA, TSM, OBSTACLE_CLIPPING, REGION_DIVISION)
}
"""The methods, in the order ``bench`` lists them."""

AUTO = "auto"
"""Not a method: TSM for a target beyond the baffle, TGA otherwise."""

METHOD_NAMES: tuple[str, ...] = (AUTO, *REGISTRY)
"""What ``--method`` accepts."""


def get_method(name: str) -> PostureMethod:
    """The method called ``name``.

    Raises:
        ValueError: no such method.

    """
    if name not in REGISTRY:
        raise ValueError(f"method must be one of {', '.join(METHOD_NAMES)}, got {name!r}")
    return REGISTRY[name]
