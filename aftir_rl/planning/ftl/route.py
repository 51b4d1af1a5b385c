"""A route that a follow-the-leader arm can follow, from the learned cell path to the exact target.

The route (:class:`aftir_rl.planning.ftl.model.Route`) is planned as a beam search over the bending
vector ``κ`` of one route section after another:

- **Guide**: a distance-to-go field from the target over free space, restricted to a corridor
  around the learned cells (:mod:`aftir_rl.planning.ftl.guide`);
- **Moves**: the next ``κ`` is the last one plus a bounded change (at most ``max_change`` rad),
  which keeps the follow-the-leader deviation between stages small;
- **Clearance as a cost** (Kuntz et al.) and a hard floor of ``radius + margin + slack``;
- **Closing**: a state within reach of the target is closed exactly, re-checked and, if needed,
  pushed away from the tank (:mod:`aftir_rl.planning.ftl.closing`); the cheapest route wins.

Units cm and rad; all candidates of one depth are evaluated in one batched call; the budget is
work, not time (:mod:`aftir_rl.planning.ftl.search`). The costs and rules: docs/design.md §7.3.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import PlanningError, PlanningTimeout
from aftir_rl.core.kernel import KernelTank
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.sections import extend
from aftir_rl.core.robot import ArmSpec, forward_kinematics
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.closing import close_batch, push_away, route_clearance
from aftir_rl.planning.ftl.guide import NEIGHBOURS as NEIGHBOURS  # for aftir_rl.envs.ftl.fields
from aftir_rl.planning.ftl.guide import GuideField, corridor, guide_field
from aftir_rl.planning.ftl.model import Route, kappa_to_angles
from aftir_rl.planning.ftl.search import RouteOutcome, RouteResult, RouteSettings, check_budget

__all__ = [
    "RouteSettings",
    "RouteResult",
    "RouteOutcome",
    "GuideField",
    "RouteMoves",
    "close_route",
    "move_set",
    "plan_route",
    "route_moves",
    "search_route",
    "route_clearance",
]


#: Surface clearance [cm] beyond the margin below which the search's clearance cost uses the
#: exact distance; farther samples use the clearance grid's value (within its slack).
EXACT_RANGE = 3.0


def _changes(max_change: float) -> NDArray[np.float64]:
    """The set of ``Δκ`` moves: none, and 3 sizes in 8 directions (25 moves)."""
    out = [(0.0, 0.0)]
    for r in (max_change / 3, 2 * max_change / 3, max_change):
        for a in np.arange(8) * math.pi / 4:
            out.append((r * math.cos(a), r * math.sin(a)))
    return np.array(out)


def plan_route(
    tank: Tank,
    target: ArrayLike,
    cells: Sequence[Sequence[int]] | None = None,
    settings: RouteSettings | None = None,
    arm: ArmSpec | None = None,
    prefix: Route | None = None,
) -> RouteResult:
    """Plan a follow-the-leader route from the panel to ``target`` [cm].

    Args:
        tank: the tank.
        target: the exact end point of the route [cm].
        cells: the learned cell path (start first), or None to search the whole free raster.
        settings: search knobs; default :class:`RouteSettings`.
        arm: the arm; default the tank's.
        prefix: a route the new one continues: its lead and sections are kept unchanged (an
            arm deployed along it reaches the target without retracting past its end).

    Raises:
        PlanningError: no route keeps the margin, or none was found within ``max_expanded``
            (the message says which).
        PlanningTimeout: the search ran past ``settings.max_seconds``.
        ConfigError: ``max_expanded`` or ``max_seconds`` is not a budget.

    """
    outcome = search_route(tank, target, cells, settings, arm, prefix)
    if outcome.result is None:
        raise PlanningError(f"Cannot reach the target: {outcome.reason}")
    return outcome.result


def search_route(
    tank: Tank,
    target: ArrayLike,
    cells: Sequence[Sequence[int]] | None = None,
    settings: RouteSettings | None = None,
    arm: ArmSpec | None = None,
    prefix: Route | None = None,
) -> RouteOutcome:
    """:func:`plan_route`, with the work it took whether or not it found a route.

    Raises:
        PlanningTimeout: the search ran past ``settings.max_seconds``.
        ConfigError: ``max_expanded`` or ``max_seconds`` is not a budget.

    """
    settings = settings or RouteSettings()
    check_budget(settings.max_expanded, settings.max_seconds)
    arm = arm or tank.arm
    target = np.asarray(target, dtype=np.float64)
    start = time.perf_counter()
    need = arm.radius + settings.margin
    tip_clear = float(point_clearance(tank, target[None])[0])
    if tip_clear < need:
        where = f"{tip_clear:.2f} cm from the tank" if tip_clear >= 0 else "inside a solid or wall"
        why = f"it lies {where}, closer than the arm's radius {arm.radius:g} cm plus the margin"
        return RouteOutcome(None, 0, f"{why} {settings.margin:g} cm")
    attempts: list[tuple[str, NDArray[np.bool_] | None]] = []
    if cells is not None and tank.cell_size is not None:
        attempts.append(("learned path", corridor(tank, cells, settings.corridor)))
    attempts.append(("whole tank", None))
    notes: list[str] = []
    used = 0  # candidate sections evaluated so far, both corridors
    for name, allowed in attempts:
        guide = guide_field(tank, target, allowed)
        budget = settings.max_expanded - used
        search = _Search(
            tank, arm, target, guide, settings, start, kernel_grid(tank), budget, prefix
        )
        result, work, spent = _beam(search)
        used += work
        if result is not None:
            result.corridor = name
            result.notes = notes
            result.seconds = time.perf_counter() - start
            result.expanded = used
            return RouteOutcome(result, used)
        spent_note = f"its work budget of {settings.max_expanded:,} candidate sections ran out"
        notes.append(
            f"{spent_note} in the {name} corridor" if spent else f"no route in the {name} corridor"
        )
    return RouteOutcome(None, used, _no_route(settings.margin, notes))


def _no_route(margin: float, notes: list[str]) -> str:
    """Why a search found no route, from each corridor's note."""
    what = (
        "no follow-the-leader route keeps the margin"
        if all(n.startswith("no route") for n in notes)
        else "the search found no follow-the-leader route keeping the margin"
    )
    return f"{what} of {margin:g} cm ({'; '.join(notes)})"


@dataclass(frozen=True)
class _Search:
    """What every step of one beam search shares: the problem, its knobs, the clock, a prefix.

    ``budget``: the candidate sections this search may still evaluate.
    """

    tank: Tank
    arm: ArmSpec
    target: NDArray[np.float64]
    guide: GuideField
    settings: RouteSettings
    start: float
    kernel_tank: KernelTank
    budget: int
    prefix: Route | None = None


@dataclass
class _Beam:
    """The states kept at one depth: end frames, bending vectors so far, leads and costs."""

    rot: NDArray[np.float64]
    pos: NDArray[np.float64]
    kap_hist: NDArray[np.float64]
    lead: NDArray[np.float64]
    cost: NDArray[np.float64]


@dataclass
class _Candidates:
    """The clear one-section extensions of a beam.

    ``rep``: the state each extends; ``move``: by which move of the move set.
    """

    rep: NDArray[np.int64]
    move: NDArray[np.int64]
    end_rot: NDArray[np.float64]
    end_pos: NDArray[np.float64]
    g: NDArray[np.float64]
    h: NDArray[np.float64]
    hist: NDArray[np.float64]


#: The best closed route so far: ``(cost, route, clearance)``.
_Best = tuple[float, Route, float]


def _beam(search: _Search) -> tuple[RouteResult | None, int, bool]:
    """Beam search over the sections' bending vectors, ranked by the search's guide.

    Returns the cheapest closed route that keeps the clearance (``corridor`` left empty) or None,
    the candidate sections evaluated, and whether the budget stopped the search.
    """
    arm, settings, prefix = search.arm, search.settings, search.prefix
    if prefix is None:
        leads = np.array([v for v in settings.leads if v < arm.section_length * arm.max_sections])
        best = _close_near(search, leads)
        n0 = len(leads)  # the states before the first section: straight up the axis to each lead
        rot, pos, hist = np.repeat(np.eye(3)[None], n0, 0), np.zeros((n0, 3)), np.zeros((n0, 0, 2))
        pos[:, 2] = leads
    else:  # one state: the prefix's end
        best, leads, hist = None, np.array([prefix.lead]), prefix.kappa[None]
        end = forward_kinematics(prefix.lead, *kappa_to_angles(prefix.kappa), prefix.section_length)
        rot, pos = end[None, -1, :3, :3], end[None, -1, :3, 3]
    beam = _Beam(rot, pos, hist, leads.copy(), leads + hist.shape[1] * arm.section_length)
    best, expanded, spent = _search_depths(search, beam, best)
    if best is None:
        return None, expanded, spent
    total, route, rc = best
    found = RouteResult(
        route=route,
        n_sections=max(route.min_sections(), 1),
        clearance_cm=rc,
        cost=total,
        corridor="",
        seconds=time.perf_counter() - search.start,
        expanded=expanded,
    )
    return found, expanded, spent


def _keep(
    search: _Search,
    best: _Best | None,
    kap: NDArray[np.float64],
    lead: float,
    cost: float,
    extra: int,
) -> _Best | None:
    """The better of ``best`` and a route closed by ``extra`` sections (``best`` if it misses)."""
    arm, settings, l = search.arm, search.settings, search.arm.section_length
    route = Route(lead, kap, l)
    if route.min_sections() > arm.max_sections:
        return best
    rc = route_clearance(search.tank, arm, route)
    need = settings.margin + 0.5 * settings.slack
    if need - 3.0 < rc < need and search.prefix is None:  # (it would move a prefix too)
        # a near miss: move the body away from the tank, the tip staying on the target
        route = push_away(search.tank, arm, route, search.target, need)
        rc = route_clearance(search.tank, arm, route)
        kap, lead = route.kappa, route.lead
    if rc < need:
        return best
    dk_all = np.diff(np.vstack([np.zeros((1, 2)), kap]), axis=0)
    change = np.hypot(dk_all[:, 0], dk_all[:, 1])
    total = (
        cost
        + extra * l
        + settings.clearance_weight * extra * l / max(rc - settings.margin, 0.25)
        + settings.change_weight * l * float(np.sum(change[-extra - 1 :] ** 2)) / 10
    )
    return (total, route, rc) if best is None or total < best[0] else best


def _close_near(search: _Search, leads: NDArray[np.float64]) -> _Best | None:
    """Near targets: one to three sections from the panel, closed directly from a few shapes.

    Bent towards the target, or an S: the straight arm is a saddle of the tip distance.
    """
    arm, target, l = search.arm, search.target, search.arm.section_length
    best: _Best | None = None
    toward = np.array(
        [math.cos(math.atan2(target[1], target[0])), math.sin(math.atan2(target[1], target[0]))]
    )
    for extra in (1, 2, 3):
        shapes = [np.outer(np.ones(extra), toward) * a for a in (0.3, 0.8)]
        shapes += [np.outer((-1.0) ** np.arange(extra), toward) * a for a in (0.5, 1.0)]
        starts = np.array([shape for shape in shapes for _ in leads])
        seeds = np.tile(leads, len(shapes))
        closed = close_batch(seeds, starts, target, l, arm.theta_max, extra)
        for out in closed:
            if out is not None:
                best = _keep(search, best, out[1], out[0], max(out[0], 0.0), extra)
    return best


def _search_depths(
    search: _Search, beam: _Beam, best: _Best | None
) -> tuple[_Best | None, int, bool]:
    """Grow the beam a section a depth, closing promising states.

    Returns the best closed route, the candidate sections evaluated, and whether the budget
    stopped the search (a depth that would pass ``search.budget`` is not expanded).

    Raises:
        PlanningTimeout: the call ran past ``max_seconds`` (checked before each depth).

    """
    settings, expanded = search.settings, 0
    changes = _changes(settings.max_change)
    first = 0 if search.prefix is None else search.prefix.n_route_sections
    for depth in range(first, search.arm.max_sections):
        if len(beam.cost) == 0:
            break
        if expanded + len(beam.cost) * len(changes) > search.budget:
            return best, expanded, True
        elapsed = time.perf_counter() - search.start
        if settings.max_seconds is not None and elapsed > settings.max_seconds:
            raise PlanningTimeout(
                f"Planning timed out: the route search passed its wall-clock guard of "
                f"{settings.max_seconds:g} s ({elapsed:.1f} s, {expanded:,} candidate sections "
                "evaluated in this corridor)"
            )
        count, cand = _expand(search, beam, changes, depth)
        expanded += count
        if cand is None:
            break
        if best is not None and depth >= 1 and np.min(cand.g + cand.h) > best[0]:
            break
        pruned = _prune(search, beam, cand)
        if pruned is None:
            break
        beam, togo = pruned
        best = _close_beam(search, beam, togo, depth, best)
    return best, expanded, False


def _expand(
    search: _Search, beam: _Beam, changes: NDArray[np.float64], depth: int
) -> tuple[int, _Candidates | None]:
    """Every move of every state: how many were evaluated, and the clear ones (or None)."""
    arm, settings = search.arm, search.settings
    l, k = arm.section_length, settings.samples
    need = arm.radius + settings.margin + settings.slack
    last = beam.kap_hist[:, -1, :] if depth else np.zeros((len(beam.cost), 2))
    b, c = len(beam.cost), len(changes)
    count = b * c
    # sections needed so far: bent + straight below the floor must fit in the arm
    allowed = depth + 1 + np.ceil(beam.lead / l - 1e-9) <= arm.max_sections
    new_k, end_pos, cost = np.empty((count, 2)), np.empty((count, 3)), np.empty(count)
    end_rot, ok = np.empty((count, 3, 3)), np.empty(count, dtype=bool)
    clearance = (need, arm.radius, settings.margin, arm.radius + settings.margin + EXACT_RANGE)
    extend(
        beam.rot, beam.pos, np.ascontiguousarray(last), allowed, changes,
        (arm.theta_max, l, k), clearance, search.kernel_tank,
        new_k, end_rot, end_pos, cost, ok,
    )  # fmt: skip
    if not np.any(ok):
        return count, None
    idx = np.flatnonzero(ok)
    rep, new_k, end_rot, end_pos = idx // c, new_k[idx], end_rot[idx], end_pos[idx]
    dk = new_k - (beam.kap_hist[rep, -1, :] if depth else 0.0)
    g = (
        beam.cost[rep]
        + l
        + settings.clearance_weight * (l / k) * cost[idx]
        + settings.change_weight * l * np.einsum("ij,ij->i", dk, dk) / 10.0
    )
    h = search.guide(end_pos)
    hist = np.concatenate([beam.kap_hist[rep], new_k[:, None, :]], axis=1)
    return count, _Candidates(rep, idx % c, end_rot, end_pos, g, h, hist)


def _prune(
    search: _Search, beam: _Beam, cand: _Candidates
) -> tuple[_Beam, NDArray[np.float64]] | None:
    """The next beam and its distance-to-go (None if none is finite): best per bin, then width."""
    settings = search.settings
    f = cand.g + cand.h
    keep = np.flatnonzero(np.isfinite(f))
    if len(keep) == 0:
        return None
    heading = cand.end_rot[keep, :, 2]
    key = np.concatenate(
        [np.floor(cand.end_pos[keep] / settings.bin_cm), np.round(heading / settings.bin_heading)],
        axis=1,
    ).astype(np.int64)
    sort = np.argsort(f[keep])
    order, key = keep[sort], key[sort]
    # one int64 per bin (14 bits a coordinate, 6 a heading component): unique in 1-D
    packed = np.zeros(len(key), dtype=np.int64)
    for column, bits in zip(key.T, (14, 14, 14, 6, 6, 6)):
        packed = (packed << bits) + (column + (1 << (bits - 1)))
    _, first = np.unique(packed, return_index=True)
    order = order[np.sort(first)][: settings.beam_width]
    rot, pos, hist = cand.end_rot[order], cand.end_pos[order], cand.hist[order]
    return _Beam(rot, pos, hist, beam.lead[cand.rep[order]], cand.g[order]), cand.h[order]


def _close_beam(
    search: _Search, beam: _Beam, togo: NDArray[np.float64], depth: int, best: _Best | None
) -> _Best | None:
    """Close the states nearest the target (``togo``: through free space) with 0 to 2 sections."""
    for extra, picks in _close_bands(search, beam, togo, depth):
        best = _close_picks(search, beam, picks, extra, best)
    return best


def _close_bands(
    search: _Search, beam: _Beam, togo: NDArray[np.float64], depth: int, closings: int | None = None
) -> list[tuple[int, list[int]]]:
    """The states worth closing with each number of extra sections, nearest to go first.

    At most ``closings`` (default the settings') per number of extra sections.
    """
    l, max_sections = search.arm.section_length, search.arm.max_sections
    dist = np.linalg.norm(beam.pos - search.target, axis=1)
    in_guide = np.ceil(beam.lead / l - 1e-9)  # sections still straight below the floor
    # a prefix's sections stay: re-bending two sections needs two of this search's own
    own = depth + 1 - (search.prefix.n_route_sections if search.prefix is not None else 0)
    limit = search.settings.closings if closings is None else closings
    bands = []
    for extra, band in ((0, (0.0, 0.3)), (1, (0.3, 0.98)), (2, (0.6, 1.95))):
        if extra == 0 and own < 2:
            continue
        # states from which `extra` sections of length l can end on the target: not too
        # near (a section cannot fold back on itself) and not too far; nearest to go first.
        # A state already within 0.3 l re-bends its own last two sections (extra 0).
        near = np.flatnonzero(
            (dist >= band[0] * l)
            & (dist < band[1] * l)
            & (togo < 2.2 * l)
            & (depth + 1 + extra + in_guide <= max_sections)
        )
        picks = list(near[np.argsort(togo[near])][:limit])
        if picks:
            bands.append((extra, picks))
    return bands


def _close_picks(
    search: _Search, beam: _Beam, picks: list[int], extra: int, best: _Best | None
) -> _Best | None:
    """Close the states ``picks`` with ``extra`` more sections; the better of ``best`` and them."""
    kap_hist, lead = beam.kap_hist, beam.lead
    shift = search.settings.lead_shift if search.prefix is None else 0.0
    starts = np.concatenate(
        [kap_hist[picks], np.repeat(kap_hist[picks][:, -1:], extra, axis=1)], axis=1
    )
    # the lead of a route the beam has threaded through the tank stays (moving it shifts
    # the whole route along the panel's axis), unless lead_shift allows a little
    window: tuple[ArrayLike, ArrayLike] | None = None
    if shift > 0:
        window = (np.maximum(lead[picks] - shift, -25.0), lead[picks] + shift)
    target, l, tmax = search.target, search.arm.section_length, search.arm.theta_max
    free = max(extra + 1, 2)
    closed = close_batch(lead[picks], starts, target, l, tmax, free=free, lead_range=window)
    for i, out in zip(picks, closed):
        if out is not None:
            best = _keep(search, best, out[1], out[0], float(beam.cost[i]), extra)
    return best


# ---------------------------------------------------------------- one state at a time


def move_set(settings: RouteSettings | None = None) -> NDArray[np.float64]:
    """The search's moves ``Δκ`` ``(25, 2)`` [rad] under ``settings``: none, 3 sizes x 8 ways."""
    return _changes((settings or RouteSettings()).max_change)


@dataclass(frozen=True)
class RouteMoves:
    """The next section of a route, for each move of :func:`move_set`.

    Attributes:
        kappa: the new section's ``κ`` ``(25, 2)`` [rad] (the last one plus the move, its norm
            kept within ``θ_max``).
        ok: whether the new section keeps ``radius + margin + slack`` from the tank and fits in
            the arm ``(25,)``.
        end_pos: the new route end ``(25, 3)`` [cm].
        togo: the guide's distance-to-go from there ``(25,)`` [cm] (inf where it is cut off).
        closes: with ``ahead``, whether :func:`close_route` closes the route grown by the move
            ``(25,)`` (else all False).
        onward: with ``ahead``, the share of clear moves from the move's end ``(25,)`` (else 0).

    """

    kappa: NDArray[np.float64]
    ok: NDArray[np.bool_]
    end_pos: NDArray[np.float64]
    togo: NDArray[np.float64]
    closes: NDArray[np.bool_]
    onward: NDArray[np.float64]


def _one_state(
    tank: Tank, route: Route, target: ArrayLike, settings: RouteSettings | None
) -> tuple[_Search, _Beam]:
    """A search of ``target`` and the beam of one state, the end of ``route``.

    No prefix: the state's own sections may be re-bent when it is closed, as the search's are.
    """
    settings = settings or RouteSettings()
    target = np.asarray(target, dtype=np.float64)
    guide = guide_field(tank, target)
    search = _Search(
        tank, tank.arm, target, guide, settings, time.perf_counter(), kernel_grid(tank),
        settings.max_expanded,
    )  # fmt: skip
    end = forward_kinematics(route.lead, *kappa_to_angles(route.kappa), route.section_length)
    cost = np.array([route.lead + route.n_route_sections * route.section_length])
    rot, pos = end[None, -1, :3, :3], end[None, -1, :3, 3]
    return search, _Beam(rot, pos, route.kappa[None], np.array([route.lead]), cost)


def route_moves(
    tank: Tank,
    route: Route,
    target: ArrayLike,
    settings: RouteSettings | None = None,
    ahead: bool = False,
) -> RouteMoves:
    """Every move of :func:`move_set` from the end of ``route``, checked as the search does.

    One state of the beam search of :func:`plan_route`: the same moves, clearance rule and
    guide (the distance-to-go through free space to ``target``). With ``ahead``, one step of
    look-ahead too: for each clear move, whether the route then closes and how many moves stay
    clear after it (the search's own expansion and closing, batched over the moves).
    """
    search, beam = _one_state(tank, route, target, settings)
    changes = _changes(search.settings.max_change)
    n, depth = len(changes), route.n_route_sections
    kappa, end_pos = np.zeros((n, 2)), np.full((n, 3), np.nan)
    ok, togo = np.zeros(n, dtype=bool), np.full(n, np.inf)
    closes, onward = np.zeros(n, dtype=bool), np.zeros(n)
    cand = _expand(search, beam, changes, depth)[1] if depth < search.arm.max_sections else None
    if cand is not None:
        m = cand.move
        ok[m], end_pos[m], togo[m], kappa[m] = True, cand.end_pos, cand.h, cand.hist[:, -1]
        if ahead:
            closes, onward = _ahead(search, beam, cand, changes, depth)
    return RouteMoves(kappa, ok, end_pos, togo, closes, onward)


def _ahead(
    search: _Search,
    beam: _Beam,
    cand: _Candidates,
    changes: NDArray[np.float64],
    depth: int,
) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """For each move of ``cand`` (one state's clear moves): does it close, share of moves on."""
    n = len(changes)
    closes, onward = np.zeros(n, dtype=bool), np.zeros(n)
    lead = beam.lead[cand.rep]
    cost = lead + (depth + 1) * search.arm.section_length
    after = _Beam(cand.end_rot, cand.end_pos, cand.hist, lead, cost)
    if depth + 1 < search.arm.max_sections:
        _, more = _expand(search, after, changes, depth + 1)
        if more is not None:
            onward[cand.move] = np.bincount(more.rep, minlength=len(cand.move)) / n
    for extra, picks in _close_bands(search, after, cand.h, depth + 1, closings=n):
        for i in picks:
            if not closes[cand.move[i]]:
                closes[cand.move[i]] = _close_picks(search, after, [i], extra, None) is not None
    return closes, onward


def close_route(
    tank: Tank, route: Route, target: ArrayLike, settings: RouteSettings | None = None
) -> tuple[Route, float] | None:
    """``route`` closed onto ``target`` as the search closes one of its states, or None.

    With 0 to 2 more sections (0: its own last two re-bent, when it has two or more), or from
    the panel with 1 to 3 (no section yet), when its end is near enough the target (the bands
    of :func:`plan_route`'s closing); the closed route keeps ``margin + slack/2`` [cm] (a near
    miss pushed away from the tank first, as the search does). Returns it with its clearance.
    """
    search, beam = _one_state(tank, route, target, settings)
    depth = route.n_route_sections - 1
    if depth < 0:
        best = _close_near(search, np.array([route.lead]))
    else:
        best = _close_beam(search, beam, search.guide(beam.pos), depth, None)
    return None if best is None else (best[1], best[2])
