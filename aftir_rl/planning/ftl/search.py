"""The route search's settings and budget, and the rule for the settings a motion tries.

The budget is work, not time: the candidate sections a search evaluates
(:attr:`RouteSettings.max_expanded`), so a route is the same on any machine under any load.
:func:`~aftir_rl.planning.ftl.plan.plan_motion` tries :data:`SEARCH_VARIANTS` in a fixed order,
all within one total (:data:`MAX_EXPANDED_TOTAL`). A wall-clock guard (``max_seconds``, off by
default) only stops a runaway call, as :class:`~aftir_rl.core.errors.PlanningTimeout`
(``timed_out`` in a motion plan), never as "no route".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from aftir_rl.core.errors import ConfigError
from aftir_rl.planning.ftl.model import Route

__all__ = [
    "MAX_EXPANDED",
    "MAX_EXPANDED_TOTAL",
    "RouteSettings",
    "RouteResult",
    "RouteOutcome",
    "MAIN_VARIANTS",
    "LAST_RESORTS",
    "SEARCH_VARIANTS",
    "check_budget",
]

#: Default work budget of one route search (:func:`~aftir_rl.planning.ftl.route.plan_route`):
#: candidate sections evaluated, both corridors together. Above the most a search can evaluate
#: on a 12-section arm with the widest setting of :data:`SEARCH_VARIANTS` (2 corridors x 25
#: moves x (8 leads + 11 depths x 800 states) = 440,400), so it never cuts such a search short;
#: on the reference tank's 4 targets and 300 random ones (150 a bay) a search evaluated at
#: most 104,600 (per target, all settings tried: median 22,200, most 442,975).
MAX_EXPANDED = 500_000


@dataclass(frozen=True)
class RouteSettings:
    """Knobs of the route search (defaults measured on the reference tank, see docs/benchmarks.md).

    Attributes:
        margin: clearance the arm's surface keeps from everything [cm].
        slack: extra clearance asked of the route, for the deviation between FTL stages [cm].
        beam_width: states kept per depth.
        max_change: largest change of ``κ`` between neighbouring sections [rad].
        leads: straight travel above the floor before the first bend [cm]; negative: the
            first bend starts inside the panel's guide (its rim is checked like any surface).
        corridor: cells the learned path is grown by to make the corridor.
        clearance_weight: weight of ``∫ ds / (clearance − margin)``.
        change_weight: weight of ``Σ |Δκ|²·l``.
        samples: backbone samples per section in the search.
        max_expanded: work budget of one search, both corridors together: the candidate
            sections it may evaluate (a depth that would pass it is not expanded; the search
            keeps what it found). Work, not time: the route is the same under any load.
        max_seconds: a wall-clock guard [s] on one call, or None (the default: none). Past it
            the search raises :class:`~aftir_rl.core.errors.PlanningTimeout` (never "no route").
        bin_cm, bin_heading: the beam keeps the best state per cell of this size [cm] and
            heading bin [rad], so that it stays diverse.
        closings: beam states per depth that are tried for closing on the target.
        lead_shift: how far [cm] a closing may move the lead of a route the beam has built.

    """

    margin: float = 1.0
    slack: float = 1.5
    beam_width: int = 160
    max_change: float = 0.75
    leads: tuple[float, ...] = (-20.0, -10.0, 0.0, 15.0, 30.0)
    corridor: int = 2
    clearance_weight: float = 4.0
    change_weight: float = 20.0
    samples: int = 10
    max_expanded: int = MAX_EXPANDED
    max_seconds: float | None = None
    bin_cm: float = 12.0
    closings: int = 10
    lead_shift: float = 0.0
    bin_heading: float = 0.5


@dataclass
class RouteResult:
    """A planned route and what the search saw.

    Attributes:
        route: the route (its end is the target).
        n_sections: arm sections that deploy it.
        clearance_cm: smallest clearance of the route's body (surface, radius included) [cm].
        cost: the search's cost of the route.
        corridor: ``"learned path"`` or ``"whole tank"``: where the guide field came from.
        seconds: planning time [s].
        expanded: candidate sections evaluated, both corridors together (the work that
            ``max_expanded`` bounds).

    """

    route: Route
    n_sections: int
    clearance_cm: float
    cost: float
    corridor: str
    seconds: float
    expanded: int = 0
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class RouteOutcome:
    """What a route search did: the route or why none, and the work it took.

    Attributes:
        result: the route, or None.
        expanded: candidate sections evaluated, both corridors together.
        reason: why there is no route (None when there is one).

    """

    result: RouteResult | None
    expanded: int
    reason: str | None = None


def check_budget(max_expanded: int, max_seconds: float | None) -> None:
    """Raise :class:`~aftir_rl.core.errors.ConfigError` unless both are budgets."""
    if not max_expanded >= 1:
        raise ConfigError(f"max_expanded must be 1 candidate section or more, got {max_expanded!r}")
    if max_seconds is not None and not 0 < max_seconds < math.inf:
        raise ConfigError(
            f"max_seconds must be a positive number of seconds or None, got {max_seconds!r}"
        )


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

#: Every setting :func:`~aftir_rl.planning.ftl.plan.plan_motion` tries by default, in this order.
SEARCH_VARIANTS = MAIN_VARIANTS + LAST_RESORTS

#: Default total work budget of one :func:`~aftir_rl.planning.ftl.plan.plan_motion` call:
#: candidate sections evaluated by all its route searches together. Above the most that all of
#: :data:`SEARCH_VARIANTS` can evaluate on a 12-section arm (2,120,300), so it never cuts them
#: short there; a setting is given at most what is left of it.
MAX_EXPANDED_TOTAL = 2_500_000
