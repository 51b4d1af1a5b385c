"""Posture generation: region clipping, blind search, TGA and TSM (seeds 004, 000, 002)."""

from aftir_rl.posture.planner import METHODS, PlannedPosture, Planner
from aftir_rl.posture.search import (
    PlanarProblem,
    SearchResult,
    blind_search,
    refine,
    region_clipping,
)

__all__ = [
    "METHODS",
    "PlannedPosture",
    "Planner",
    "PlanarProblem",
    "SearchResult",
    "blind_search",
    "refine",
    "region_clipping",
]
