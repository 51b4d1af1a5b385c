"""Posture generation: region clipping, blind search, TGA, TSM, obstacle clipping, region division.

:class:`PlanningContext` is what every method receives, :data:`REGISTRY` lists the methods and
:class:`Planner` dispatches to them (see :mod:`aftir_rl.core.papers` for the papers they come from).
"""

from aftir_rl.planning.posture.context import (
    PlannedPosture,
    PlanningContext,
    PostureMethod,
    random_free_targets,
)
from aftir_rl.planning.posture.planner import METHODS, Planner
from aftir_rl.planning.posture.registry import REGISTRY
from aftir_rl.planning.posture.search import (
    PlanarProblem,
    SearchResult,
    blind_search,
    refine,
    region_clipping,
)

__all__ = [
    "METHODS",
    "REGISTRY",
    "PlannedPosture",
    "Planner",
    "PlanningContext",
    "PostureMethod",
    "PlanarProblem",
    "SearchResult",
    "blind_search",
    "random_free_targets",
    "refine",
    "region_clipping",
]
