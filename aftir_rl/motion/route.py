"""A route that a follow-the-leader arm can follow, from the learned cell path to the exact target.

The route (:class:`aftir_rl.motion.ftl.Route`) is planned as a beam search over the bending
vector ``κ`` of one route section after another:

- **Guide.** A distance-to-go field over the tank's raster: Dijkstra over free cells
  (26-neighbourhood, Euclidean steps) from the target, restricted to a *corridor* around the
  learned cell path (the path's cells grown by ``corridor`` cells; the whole free raster when no
  path is given, or when no route is found in the corridor). A point's distance-to-go is the
  smallest ``D(c) + |p − centre(c)|`` over the corridor cells ``c`` next to it, so the route
  follows the learned cells without having to visit their centres (a constant-curvature arm
  rising from the panel cannot hug the floor as the first cells of a greedy path do).
- **Moves.** The next section's ``κ`` is the last one plus a change from a fixed set (at most
  ``max_change`` rad), bounded by ``θ_max``. Small changes between neighbouring sections keep
  the follow-the-leader deviation between stages small (:mod:`aftir_rl.motion.ftl`).
- **Clearance as a cost** (Kuntz et al.: integrate 1/clearance along the path): each section's
  backbone samples must keep ``radius + margin + slack`` from every solid, wall and the floor
  outside the panel, and pay ``clearance_weight · Σ ds / (clearance − margin)``; with the length,
  a curvature-change cost and the distance-to-go this ranks the beam.
- **Closing.** A beam state whose tip is within reach of the target is closed exactly by damped
  least squares on the bending vectors of its last sections (tip error ≤ 1e-6 cm); the closed
  route is re-checked for clearance over its whole body; one that misses the clearance by less
  than 3 cm is pushed away from the tank first (gradient ascent on a soft minimum of its
  clearance in the null space of the tip's Jacobian, the tip staying on the target). Targets
  within reach of the panel are also closed directly: one to three sections on a continuous
  lead. The cheapest closed route wins.

Units cm and rad. All candidates of one depth are evaluated in one batched call.
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import product

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.collision import point_clearance, points_clear
from aftir_rl.errors import PlanningError
from aftir_rl.motion.ftl import Route, clip_kappa, kappa_to_angles
from aftir_rl.robot import ArmSpec, body_points, section_transforms, tip_jacobian, tip_position
from aftir_rl.tank import Tank

__all__ = ["RouteSettings", "RouteResult", "GuideField", "plan_route"]

_NEIGHBOURS = np.array([d for d in product((-1, 0, 1), repeat=3) if any(d)], dtype=np.int64)


@dataclass(frozen=True)
class RouteSettings:
    """Knobs of the route search (defaults measured on the reference tank, see the README).

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
        max_seconds: wall-clock budget of one search.
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
    max_seconds: float = 20.0
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
        expanded: candidate sections evaluated.

    """

    route: Route
    n_sections: int
    clearance_cm: float
    cost: float
    corridor: str
    seconds: float
    expanded: int = 0
    notes: list[str] = field(default_factory=list)


class GuideField:
    """Distance-to-go [cm] to a target through the free space of a tank, on a fine grid.

    The grid has cells of half the raster's size (10 cm in the reference tank). A grid point is
    free when it keeps the arm's radius from every solid and wall; two neighbouring points
    (26-neighbourhood) are joined when the midpoint between them is free too, so a thin wall
    such as the 4 cm baffle cuts every edge across it except through the hatch. Distances are
    Euclidean along the edges, relaxed with numpy until they settle. ``allowed`` (on the raster)
    restricts the field to a corridor.
    """

    def __init__(
        self, tank: Tank, target: ArrayLike, allowed: NDArray[np.bool_] | None = None
    ) -> None:
        raster = tank.raster
        self.size = float(raster.cell_size) / 2
        self.origin = np.array(raster.origin, dtype=np.float64)
        self.shape = np.array(raster.shape) * 2
        free, edges = _grid_edges(tank, self.size)
        if allowed is not None:
            free = free & np.repeat(np.repeat(np.repeat(allowed, 2, 0), 2, 1), 2, 2)
        self.free, self.edges = free, edges
        target = np.asarray(target, dtype=np.float64)
        centres = self.origin + (np.indices(tuple(self.shape)).transpose(1, 2, 3, 0) + 0.5) * (
            self.size
        )
        dist = np.full(tuple(self.shape), np.inf)
        near = np.linalg.norm(centres - target, axis=-1)
        seed = free & (near <= 1.75 * self.size)
        if not seed.any():
            seed = free & (near <= near[free].min() + 1e-9) if free.any() else seed
        dist[seed] = near[seed]
        steps = np.linalg.norm(_NEIGHBOURS, axis=1) * self.size
        for _ in range(int(self.shape.sum()) * 4):
            new = dist.copy()
            for e, (d, w) in enumerate(zip(_NEIGHBOURS, steps)):
                # dist[x] <- dist[x + d] + w where the edge x -> x + d exists
                src = _shifted(dist, -d)
                new = np.minimum(new, np.where(edges[e] & free, src + w, np.inf))
            new = np.where(free, new, np.inf)
            if np.array_equal(new, dist):
                break
            dist = new
        self.dist = dist
        self.target = target

    def __call__(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance-to-go of points ``(..., 3)``; ``inf`` where no reachable grid point is near.

        A point uses its own grid cell and the neighbours joined to it by an edge (so nothing
        leaks through a thin wall), each at its distance plus the straight line to it.
        """
        p = np.asarray(points, dtype=np.float64)
        cell = np.clip(np.floor((p - self.origin) / self.size).astype(np.int64), 0, self.shape - 1)
        own = self.dist[cell[..., 0], cell[..., 1], cell[..., 2]]
        centre = self.origin + (cell + 0.5) * self.size
        best = own + np.linalg.norm(p - centre, axis=-1)
        for e, d in enumerate(_NEIGHBOURS):
            c = cell + d
            ok = np.all((c >= 0) & (c < self.shape), axis=-1)
            cc = np.where(ok[..., None], c, 0)
            joined = self.edges[e][cell[..., 0], cell[..., 1], cell[..., 2]] & ok
            dd = self.dist[cc[..., 0], cc[..., 1], cc[..., 2]]
            v = dd + np.linalg.norm(p - (self.origin + (cc + 0.5) * self.size), axis=-1)
            best = np.minimum(best, np.where(joined, v, np.inf))
        near = np.linalg.norm(p - self.target, axis=-1)
        return np.where(near < self.size, np.minimum(best, near), best)


def _shifted(a: NDArray[np.float64], d: NDArray[np.int64]) -> NDArray[np.float64]:
    """``out[x] = a[x - d]`` with ``inf`` where ``x - d`` is outside."""
    out = np.full_like(a, np.inf)
    src = tuple(slice(max(0, -k), a.shape[i] - max(0, k)) for i, k in enumerate(d))
    dst = tuple(slice(max(0, k), a.shape[i] - max(0, -k)) for i, k in enumerate(d))
    out[dst] = a[src]
    return out


#: Per tank (by value, held weakly) and grid size: free grid points and edges.
_EDGE_CACHE: weakref.WeakKeyDictionary[
    Tank, dict[float, tuple[NDArray[np.bool_], NDArray[np.bool_]]]
] = weakref.WeakKeyDictionary()


def _grid_edges(tank: Tank, size: float) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Free grid points and, per neighbour direction, whether the edge's midpoint is free."""
    cache = _EDGE_CACHE.setdefault(tank, {})
    if size not in cache:
        shape = tuple(int(n) * 2 for n in tank.raster.shape)
        origin = np.array(tank.raster.origin, dtype=np.float64)
        centres = origin + (np.indices(shape).transpose(1, 2, 3, 0) + 0.5) * size
        r = tank.arm.radius
        free = point_clearance(tank, centres) >= r
        edges = np.zeros((len(_NEIGHBOURS),) + shape, dtype=bool)
        for e, d in enumerate(_NEIGHBOURS):
            mid = centres + 0.5 * size * d
            target_free = _shifted(free.astype(np.float64), -d) == 1.0
            edges[e] = free & target_free & (point_clearance(tank, mid) >= r)
        cache[size] = (free, edges)
    return cache[size]


def _corridor(tank: Tank, cells: Sequence[Sequence[int]], grow: int) -> NDArray[np.bool_]:
    mask = np.zeros(tank.raster.shape, dtype=bool)
    shape = np.array(tank.raster.shape)
    for c in cells:
        lo = np.clip(np.asarray(c) - grow, 0, shape)
        hi = np.clip(np.asarray(c) + grow + 1, 0, shape)
        mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = True
    return mask


def _changes(max_change: float) -> NDArray[np.float64]:
    """The set of ``Δκ`` moves: none, and 3 sizes in 8 directions (25 moves)."""
    out = [(0.0, 0.0)]
    for r in (max_change / 3, 2 * max_change / 3, max_change):
        for a in np.arange(8) * math.pi / 4:
            out.append((r * math.cos(a), r * math.sin(a)))
    return np.array(out)


def _section_samples(
    rot: NDArray[np.float64], pos: NDArray[np.float64], kappa: NDArray[np.float64], l: float, k: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Samples ``(B, k, 3)`` of one new section per state, and its end frame ``(B,3,3), (B,3)``."""
    theta, phi = kappa_to_angles(kappa)
    frac = np.arange(1, k + 1) / k
    local = section_transforms(theta[:, None] * frac, phi[:, None], l * frac)  # (B, k, 4, 4)
    pts = np.einsum("bij,bkj->bki", rot, local[..., :3, 3]) + pos[:, None, :]
    end_rot = rot @ local[:, -1, :3, :3]
    return pts, end_rot, pts[:, -1, :]


def route_clearance(tank: Tank, arm: ArmSpec, route: Route, per_section: int = 20) -> float:
    """Smallest clearance [cm] of the final body of ``route`` (its surface, radius included)."""
    theta, phi = kappa_to_angles(route.kappa)
    pts = body_points(route.lead, theta, phi, route.section_length, per_section)
    return float(point_clearance(tank, pts).min()) - arm.radius


def _close_batch(
    lead: NDArray[np.float64],
    kappa: NDArray[np.float64],
    target: NDArray[np.float64],
    l: float,
    theta_max: float,
    free: int = 3,
    iterations: int = 40,
    lead_range: tuple[ArrayLike, ArrayLike] | None = (-25.0, 60.0),
) -> list[tuple[float, NDArray[np.float64]] | None]:
    """Put each route's tip on ``target``: damped least squares on its lead and last ``κ``.

    ``kappa`` is ``(C, M, 2)``: C candidate routes of one depth, solved together (one batched
    forward kinematics per iteration). The lead moves the whole route along the panel's axis
    (its derivative is ``(0, 0, 1)``): with sections of fixed length, a continuous lead is what
    lets a route end exactly at any distance. Steps are bounded (0.3 rad, 10 cm), ``κ`` stays
    within the joint limit and the lead within ``lead_range`` (None: the lead stays as given, for
    routes already threaded through the tank by the beam). Returns ``(lead, κ)`` of each
    candidate, or None where it did not converge to 1e-6 cm.
    """
    kap = np.array(kappa, dtype=np.float64)
    lead = np.array(lead, dtype=np.float64)
    lo, hi = lead_range if lead_range is not None else (lead, lead)
    lead = np.clip(lead, lo, hi)
    c, m = kap.shape[:2]
    j0 = max(0, m - free)
    nk = 2 * (m - j0)
    unit_z = np.array([0.0, 0.0, 1.0])

    def joints(p: NDArray[np.float64]) -> tuple[ArrayLike, ArrayLike, ArrayLike]:
        # the last sections' κ, flattened in p (C, R, nk), after the fixed ones of each route
        fixed = np.broadcast_to(kap[:, None, :j0], p.shape[:2] + (j0, 2))
        theta, phi = kappa_to_angles(np.concatenate([fixed, p.reshape(p.shape[:2] + (-1, 2))], 2))
        return lead[:, None], theta, phi

    for _ in range(iterations):
        # forward differences of the tip in the free κ (C, 3, nk)
        tip, jac_t = tip_jacobian(kap[:, j0:].reshape(c, nk), l, central=False, joints=joints)
        err = target - tip
        norm = np.linalg.norm(err, axis=1)
        done = norm < 1e-7
        if done.all():
            break
        jac_k = np.swapaxes(jac_t, 1, 2)  # (C, nk, 3)
        # the lead's column is in cm, the angles' in cm/rad: scale it like 1/l rad per cm
        free_lead = 1.0 if lead_range is not None else 0.0
        jac = np.concatenate([jac_k, np.broadcast_to(unit_z * l * free_lead, (c, 1, 3))], axis=1)
        damping = np.where(norm > 5, 1e-6, 1e-8) * l * l
        a = np.swapaxes(jac, 1, 2) @ jac + damping[:, None, None] * np.eye(3)
        step = np.einsum("cvi,ci->cv", jac, np.linalg.solve(a, err[..., None])[..., 0])
        step[done] = 0.0
        dk, dlead = step[:, :nk], step[:, nk] * l
        size = np.linalg.norm(dk, axis=1)
        scale = np.minimum(
            np.minimum(1.0, 0.3 / np.maximum(size, 1e-12)), 10.0 / np.maximum(np.abs(dlead), 1e-12)
        )
        kap[:, j0:] = clip_kappa(kap[:, j0:] + (dk * scale[:, None]).reshape(c, -1, 2), theta_max)
        lead = np.clip(lead + dlead * scale, lo, hi)
    theta, phi = kappa_to_angles(kap)
    ok = np.linalg.norm(target - tip_position(lead, theta, phi, l), axis=1) < 1e-6
    return [(float(lead[i]), kap[i]) if ok[i] else None for i in range(c)]


def _push_away(
    tank: Tank,
    arm: ArmSpec,
    route: Route,
    target: NDArray[np.float64],
    goal: float,
    iterations: int = 12,
    step: float = 0.04,
) -> Route:
    """Raise a route's clearance while its end stays on ``target`` (clearance as an objective).

    Gradient ascent on a soft minimum of the body's clearance over every ``κ`` and the lead,
    projected into the null space of the tip's Jacobian, then put back on the target by a few
    Gauss-Newton steps. Stops when the clearance reaches ``goal`` [cm] or stops improving;
    returns the best route seen (the input if nothing better).
    """
    l = route.section_length
    x0 = np.concatenate([[route.lead / l], route.kappa.reshape(-1)])
    n = len(x0)
    eps = 1e-5

    def unpack(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        kap = clip_kappa(x[..., 1:].reshape(x.shape[:-1] + (-1, 2)), arm.theta_max)
        return x[..., 0] * l, kap

    def evaluate(xs: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        lead, kap = unpack(xs)
        theta, phi = kappa_to_angles(kap)
        pts = body_points(lead, theta, phi, l, 10)
        clear = point_clearance(tank, pts) - arm.radius  # (B, P)
        soft = -np.log(np.sum(np.exp(-2.0 * (clear - clear.min(axis=1, keepdims=True))), axis=1))
        return clear.min(axis=1) + soft / 2.0, pts[:, -1, :]

    x, best_x, best_c = x0.copy(), x0.copy(), route_clearance(tank, arm, route)
    for _ in range(iterations):
        trial = x[None, :] + eps * np.vstack([np.zeros(n), np.eye(n)])
        value, tips = evaluate(trial)
        grad = (value[1:] - value[0]) / eps
        jac = ((tips[1:] - tips[0]) / eps).T  # (3, n)
        pinv = np.linalg.pinv(jac)
        direction = grad - pinv @ (jac @ grad)
        norm = np.linalg.norm(direction)
        if norm < 1e-9:
            break
        x = x + step * direction / norm
        for _ in range(4):  # back onto the target
            lead, kap = unpack(x)
            theta, phi = kappa_to_angles(kap)
            err = target - tip_position(lead, theta, phi, l)
            if np.linalg.norm(err) < 1e-8:
                break
            x = x + pinv @ err
        lead, kap = unpack(x)
        x = np.concatenate([[lead / l], kap.reshape(-1)])
        theta, phi = kappa_to_angles(kap)
        if np.linalg.norm(target - tip_position(lead, theta, phi, l)) > 1e-6 or lead < -25.0:
            break
        c = route_clearance(tank, arm, Route(float(lead), kap, l))
        if c <= best_c + 1e-3:
            break
        best_x, best_c = x.copy(), c
        if c >= goal:
            break
    lead, kap = unpack(best_x)
    return Route(float(lead), kap, l)


def plan_route(
    tank: Tank,
    target: ArrayLike,
    cells: Sequence[Sequence[int]] | None = None,
    settings: RouteSettings | None = None,
    arm: ArmSpec | None = None,
) -> RouteResult:
    """Plan a follow-the-leader route from the panel to ``target`` [cm].

    Args:
        tank: the tank.
        target: the exact end point of the route [cm].
        cells: the learned cell path (start first), or None to search the whole free raster.
        settings: search knobs; default :class:`RouteSettings`.
        arm: the arm; default the tank's.

    Raises:
        PlanningError: no route keeps the margin (the message says why).

    """
    settings = settings or RouteSettings()
    arm = arm or tank.arm
    target = np.asarray(target, dtype=np.float64)
    start = time.perf_counter()
    need = arm.radius + settings.margin
    tip_clear = float(point_clearance(tank, target[None])[0])
    if tip_clear < need:
        raise PlanningError(
            f"Cannot reach the target: it lies {tip_clear:.2f} cm from the tank, closer than "
            f"the arm's radius {arm.radius:g} cm plus the margin {settings.margin:g} cm"
        )
    attempts: list[tuple[str, NDArray[np.bool_] | None]] = []
    if cells is not None and tank.cell_size is not None:
        attempts.append(("learned path", _corridor(tank, cells, settings.corridor)))
    attempts.append(("whole tank", None))
    notes: list[str] = []
    for name, allowed in attempts:
        guide = GuideField(tank, target, allowed)
        result = _beam(tank, arm, target, guide, settings, start)
        if result is not None:
            result.corridor = name
            result.notes = notes
            result.seconds = time.perf_counter() - start
            return result
        notes.append(f"no route in the {name} corridor")
    raise PlanningError(
        "Cannot reach the target: no follow-the-leader route keeps the margin of "
        f"{settings.margin:g} cm ({'; '.join(notes)})"
    )


def _beam(
    tank: Tank,
    arm: ArmSpec,
    target: NDArray[np.float64],
    guide: GuideField,
    settings: RouteSettings,
    start: float,
) -> RouteResult | None:
    l, k = arm.section_length, settings.samples
    need = arm.radius + settings.margin + settings.slack
    changes = _changes(settings.max_change)
    leads = np.array([v for v in settings.leads if v < l * arm.max_sections])
    # states
    n0 = len(leads)
    rot = np.repeat(np.eye(3)[None], n0, axis=0)
    pos = np.stack([np.zeros(n0), np.zeros(n0), leads], axis=1)
    kap_hist = np.zeros((n0, 0, 2))
    lead = leads.copy()
    cost = leads.copy()
    best: tuple[float, Route, float] | None = None
    expanded = 0
    max_depth = arm.max_sections

    def _keep(
        best: tuple[float, Route, float] | None,
        kap: NDArray[np.float64],
        lead: float,
        cost: float,
        extra: int,
    ) -> tuple[float, Route, float] | None:
        """The better of ``best`` and a closed route (``best`` if it misses the margin)."""
        route = Route(lead, kap, l)
        if route.min_sections() > arm.max_sections:
            return best
        rc = route_clearance(tank, arm, route)
        need = settings.margin + 0.5 * settings.slack
        if need - 3.0 < rc < need:
            # a near miss: move the body away from the tank, the tip staying on the target
            route = _push_away(tank, arm, route, target, need)
            rc = route_clearance(tank, arm, route)
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

    # near targets: one to three sections from the panel, closed directly from a few shapes
    # (bent towards the target, or an S), since the straight arm is a saddle of the tip distance
    toward = np.array(
        [math.cos(math.atan2(target[1], target[0])), math.sin(math.atan2(target[1], target[0]))]
    )
    for extra in (1, 2, 3):
        shapes = [np.outer(np.ones(extra), toward) * a for a in (0.3, 0.8)]
        shapes += [np.outer((-1.0) ** np.arange(extra), toward) * a for a in (0.5, 1.0)]
        starts = np.array([shape for shape in shapes for _ in leads])
        seeds = np.tile(leads, len(shapes))
        closed = _close_batch(seeds, starts, target, l, arm.theta_max, extra)
        for out in closed:
            if out is not None:
                best = _keep(best, out[1], out[0], max(out[0], 0.0), extra)
    for depth in range(max_depth):
        if time.perf_counter() - start > settings.max_seconds or len(cost) == 0:
            break
        last = kap_hist[:, -1, :] if depth else np.zeros((len(cost), 2))
        b, c = len(cost), len(changes)
        new_k = clip_kappa(last[:, None, :] + changes[None, :, :], arm.theta_max).reshape(-1, 2)
        rep = np.repeat(np.arange(b), c)
        pts, end_rot, end_pos = _section_samples(rot[rep], pos[rep], new_k, l, k)
        expanded += len(rep)
        # sections needed so far: bent + straight below the floor must fit in the arm
        n_needed = depth + 1 + np.ceil(lead[rep] / l - 1e-9)
        # the cheap bounded test first, exact distances (for the cost) only for the survivors
        ok = (n_needed <= arm.max_sections) & points_clear(tank, pts, need)
        if not np.any(ok):
            break
        idx = np.flatnonzero(ok)
        rep, new_k, pts, end_rot, end_pos = (
            rep[idx],
            new_k[idx],
            pts[idx],
            end_rot[idx],
            end_pos[idx],
        )
        clear = point_clearance(tank, pts) - arm.radius  # surface clearance (B*C, k)
        dk = new_k - (kap_hist[rep, -1, :] if depth else 0.0)
        g = (
            cost[rep]
            + l
            + settings.clearance_weight
            * (l / k)
            * np.sum(1.0 / np.maximum(clear - settings.margin, 0.25), axis=1)
            + settings.change_weight * l * np.einsum("ij,ij->i", dk, dk) / 10.0
        )
        h = guide(end_pos)
        hist = np.concatenate([kap_hist[rep], new_k[:, None, :]], axis=1)
        if best is not None and depth >= 1 and np.min(g + h) > best[0]:
            break
        # prune: finite guide, then best per (position, heading) bin, then the beam width
        f = g + h
        keep = np.flatnonzero(np.isfinite(f))
        if len(keep) == 0:
            break
        heading = end_rot[keep, :, 2]
        key = np.concatenate(
            [np.floor(end_pos[keep] / settings.bin_cm), np.round(heading / settings.bin_heading)],
            axis=1,
        ).astype(np.int64)
        order = keep[np.argsort(f[keep])]
        key = key[np.argsort(f[keep])]
        _, first = np.unique(key, axis=0, return_index=True)
        order = order[np.sort(first)][: settings.beam_width]
        rot, pos, kap_hist = end_rot[order], end_pos[order], hist[order]
        lead, cost = lead[rep[order]], g[order]
        # closing: append one or two sections to the most promising states near the target
        dist = np.linalg.norm(pos - target, axis=1)
        togo = h[order]  # through free space: a wall between tip and target does not count as near
        fits = depth + 1 + np.ceil(lead / l - 1e-9) <= arm.max_sections - 1
        for extra, band in ((1, (0.3, 0.98)), (2, (0.6, 1.95))):
            # states from which `extra` sections of length l can end on the target: not too
            # near (a section cannot fold back on itself) and not too far; nearest to go first
            near = np.flatnonzero(
                (dist > band[0] * l)
                & (dist < band[1] * l)
                & (togo < 2.2 * l)
                & fits
                & (depth + 1 + extra + np.ceil(lead / l - 1e-9) <= arm.max_sections)
            )
            picks = list(near[np.argsort(togo[near])][: settings.closings])
            if not picks:
                continue
            starts = np.concatenate(
                [kap_hist[picks], np.repeat(kap_hist[picks][:, -1:], extra, axis=1)], axis=1
            )
            # the lead of a route the beam has threaded through the tank stays (moving it shifts
            # the whole route along the panel's axis), unless lead_shift allows a little
            window = (
                (
                    np.maximum(lead[picks] - settings.lead_shift, -25.0),
                    lead[picks] + settings.lead_shift,
                )
                if settings.lead_shift > 0
                else None
            )
            closed = _close_batch(
                lead[picks], starts, target, l, arm.theta_max, free=extra + 1, lead_range=window
            )
            for i, out in zip(picks, closed):
                if out is not None:
                    best = _keep(best, out[1], out[0], float(cost[i]), extra)
    if best is None:
        return None
    total, route, rc = best
    return RouteResult(
        route=route,
        n_sections=max(route.min_sections(), 1),
        clearance_cm=rc,
        cost=total,
        corridor="",
        seconds=time.perf_counter() - start,
        expanded=expanded,
    )
