"""Region clipping and blind search over bending angles (jace §IV and icra2014 §III.B).

Both search the planar problem of :mod:`aftir_rl.planning.posture.planar`: bending angles
``θ_1..θ_N`` of an arm whose base rises by ``dis`` along ``z``. Among the combinations whose tip
reaches the target zone (a vertical cylinder around the target; ``dis`` then puts the tip at its
height) and are feasible, the one of least MDS wins. **Blind search** evaluates one grid of step
``Δθ`` in chunks; **region clipping** evaluates ``(NUM + 1)ᴺ`` combinations per loop and shrinks
every interval around the best, with a zone that tightens to ``ε`` as the grid does;
:func:`refine` then closes the remaining gap by Gauss–Newton. An optional end heading (TSM's
guided angle) fixes the last angle: ``θ_N = heading − Σ θ_{i<N}``.

The zone rule we read into the coarse loops, and the numbers: docs/design.md §6.1.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.kernel.planar import planar_grid, planar_mds, planar_refine
from aftir_rl.planning.posture.clipping import clip_regions, reach, zone_bound
from aftir_rl.planning.posture.planar import planar_tip

__all__ = [
    "BLIND_LIMIT",
    "PlanarProblem",
    "SearchResult",
    "blind_grid_size",
    "blind_search",
    "refine",
    "region_clipping",
]

BLIND_LIMIT = 5e7
"""Blind search is not run where its grid would exceed this many combinations."""

Feasible = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.bool_]]


@dataclass
class PlanarProblem:
    """One planar reaching problem.

    Attributes:
        rho: target's distance from the base axis in the plane [cm].
        z: target's height above the base point ``dis = 0`` [cm].
        n_sections: N.
        section_length: ``l`` [cm].
        theta_max: bound on ``|θ_i|`` [rad].
        zone: target zone radius ``ε`` [cm].
        end_heading: required heading of the tip [rad from the axis], or None.
        dis_range: rising distances the search considers ``(min, max)`` [cm].
        dis_limits: rising distances a refined posture may have ``(min, max)`` [cm]; refinement
            may move ``dis`` a little past ``dis_range``, but never past these.
        feasible: ``feasible(theta (B, N), dis (B,)) -> mask (B,)``: collision, panel rule...
        mds_points: body points per section for the MDS.

    """

    rho: float
    z: float
    n_sections: int
    section_length: float
    theta_max: float
    zone: float = 0.5
    end_heading: float | None = None
    dis_range: tuple[float, float] = (-math.inf, 0.0)
    dis_limits: tuple[float, float] = (-math.inf, 0.0)
    feasible: Feasible | None = None
    mds_points: int = 8

    @property
    def heading(self) -> float:
        """The end heading as the compiled kernels take it: NaN for none."""
        return math.nan if self.end_heading is None else float(self.end_heading)

    @property
    def n_free(self) -> int:
        """Number of searched angles."""
        return self.n_sections - (self.end_heading is not None)

    def full_theta(
        self, free: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """All N angles from the searched ones, and whether the derived last one is in bounds."""
        if self.end_heading is None:
            return free, np.ones(len(free), dtype=bool)
        last = self.end_heading - free.sum(axis=1)
        return np.column_stack([free, last]), np.abs(last) <= self.theta_max + 1e-12

    def evaluate(
        self,
        free: NDArray[np.float64],
        zone: float,
        tight_zone: float | None = None,
        want: int | None = None,
        max_checks: int = 1 << 62,
    ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
        """Reaching, feasible combinations in increasing MDS: their indices, ``dis`` and MDS.

        Args:
            free: searched angles, shape ``(B, n_free)``.
            zone: reaching radius [cm].
            tight_zone: if given, combinations within it are used when any of them is feasible,
                the whole ``zone`` only otherwise.
            want: stop after this many feasible combinations (checked in increasing MDS, so they
                are the best ones); None checks all.
            max_checks: check feasibility of at most about this many combinations per zone.

        """
        theta, ok = self.full_theta(free)
        rho, z = planar_tip(theta, self.section_length)
        dis = self.z - z
        ok &= (dis >= self.dis_range[0]) & (dis <= self.dis_range[1])
        gap = np.abs(rho - self.rho)
        idx, mds = self._select(theta, dis, gap, ok, (zone, tight_zone), want, max_checks)
        return idx, dis[idx], mds

    def evaluate_grid(
        self,
        values: list[NDArray[np.float64]],
        zone: float,
        tight_zone: float | None = None,
        want: int | None = None,
        max_checks: int = 1 << 62,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`evaluate` over the grid of every combination of ``values``, compiled.

        ``values`` has one array per searched angle; the grid's tips come from
        :func:`aftir_rl.core.kernel.planar.planar_grid`.

        Returns:
            The chosen combinations' full angles ``(K, N)``, their ``dis`` and MDS.

        """
        goal = (float(self.rho), float(self.z), self.heading, float(self.theta_max))
        radius = zone if tight_zone is None else max(zone, tight_zone)
        grid = np.array(values, dtype=np.float64)
        theta, dis, gap = planar_grid(grid, goal, self.section_length, self.dis_range, radius)
        idx, mds = self._select(theta, dis, gap, None, (zone, tight_zone), want, max_checks)
        return theta[idx], dis[idx], mds

    def _select(
        self,
        theta: NDArray[np.float64],
        dis: NDArray[np.float64],
        gap: NDArray[np.float64],
        ok: NDArray[np.bool_] | None,
        zones: tuple[float, float | None],
        want: int | None,
        max_checks: int = 1 << 62,
    ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """Indices and MDS of the reaching, feasible postures in increasing MDS (:meth:`evaluate`).

        Reaching: ``ok`` (None: every row) and ``gap`` within the tight zone, else within the
        whole zone.
        """
        zone, tight_zone = zones
        radii = [zone] if tight_zone is None or tight_zone >= zone else [tight_zone, zone]
        done = np.zeros(len(theta), dtype=bool)
        for radius in radii:
            near = gap <= radius if ok is None else ok & (gap <= radius)
            idx = np.flatnonzero(near & ~done)
            done[idx] = True
            mds = self.mds(theta[idx], dis[idx])
            order = np.argsort(mds, kind="stable")
            idx, mds = idx[order], mds[order]
            if self.feasible is not None:
                keep = self._feasible_first(theta[idx], dis[idx], want, max_checks)
                idx, mds = idx[keep], mds[keep]
            if len(idx):
                break
        return idx, mds

    def _feasible_first(
        self, theta: NDArray[np.float64], dis: NDArray[np.float64], want: int | None, limit: int
    ) -> NDArray[np.intp]:
        """Indices of the feasible rows, checked in order in growing chunks.

        The checks stop once ``want`` are found or about ``limit`` rows are checked. The first
        chunk is ``4 want`` rows (the best are often feasible), then the rows up to 256, then
        chunks doubling from 512.
        """
        assert self.feasible is not None
        keep: list[NDArray[np.intp]] = []
        first = 256 if want is None else min(4 * want, 256)
        found, begin, end, step = 0, 0, first, 256
        while begin < len(theta):
            part = np.arange(begin, min(end, len(theta)))
            part = part[self.feasible(theta[part], dis[part])]
            keep.append(part)
            found += len(part)
            if want is not None and found >= want or end >= limit:
                break
            if end < 256:
                begin, end = end, 256
            else:
                step = min(step * 2, 8192)
                begin, end = end, end + step
        return np.concatenate(keep) if keep else np.zeros(0, dtype=np.intp)

    def mds(self, theta: NDArray[np.float64], dis: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance summation of the body points to the reference segment, shape ``(B,)``.

        :func:`~aftir_rl.planning.posture.planar.distance_sum` of the
        :func:`~aftir_rl.planning.posture.planar.planar_points`, compiled
        (:func:`aftir_rl.core.kernel.planar.planar_mds`).
        """
        out = np.empty(len(theta))
        theta, dis = np.ascontiguousarray(theta), np.ascontiguousarray(dis, dtype=np.float64)
        planar_mds(theta, dis, self.section_length, self.mds_points, (self.rho, self.z), out)
        return out

    def zone_for_step(self, step: NDArray[np.float64]) -> float:
        """Zone radius that accepts the nearest grid point of any exact solution (see module)."""
        arcs = reach(self.n_sections, self.section_length, self.n_free)
        if self.end_heading is not None:
            arcs = arcs + self.section_length
        return zone_bound(self.zone, step, arcs)


@dataclass
class SearchResult:
    """Best combination of a search.

    Attributes:
        theta: bending angles [rad], shape ``(N,)``.
        dis: rising distance [cm].
        mds: distance summation [cm].
        loops: region clipping loops (1 for blind search).
        evaluations: combinations evaluated.
        seconds: wall time.
        candidates: runners-up of the last loop (angles), best first, for fallbacks.
        sampled: blind search ran on a sample of its grid of ``grid_size`` combinations.
        grid_size: combinations in the full grid.

    """

    theta: NDArray[np.float64]
    dis: float
    mds: float
    loops: int
    evaluations: int
    seconds: float
    candidates: list[NDArray[np.float64]] = field(default_factory=list)
    sampled: bool = False
    grid_size: int = 0


def region_clipping(
    problem: PlanarProblem,
    num: int = 9,
    dtheta: float = math.radians(1.0),
    max_loops: int = 60,
    n_candidates: int = 8,
    max_checks: int = 1 << 12,
) -> SearchResult | None:
    """Region clipping search (jace §IV.B). Returns None if no combination reaches the zone.

    Args:
        problem: the planar problem.
        num: NUM, parts each angle's interval is split into (``NUM + 1`` values).
        dtheta: stop when every step is below this [rad].
        max_loops: safety bound on loops.
        n_candidates: runners-up kept for fallbacks.
        max_checks: feasibility checks per loop at most, in increasing MDS (when the best
            combinations hug an obstacle most neighbours are infeasible; past this the loop
            keeps the best it has).

    """
    start = time.perf_counter()
    tmax, m = problem.theta_max, problem.n_free
    if m == 0:
        return blind_search(problem, dtheta)

    def evaluate(
        values: list[NDArray[np.float64]], radius: float, tight: float, loop: int, count: int
    ) -> tuple[SearchResult, NDArray[np.float64], float] | None:
        theta, dis, mds = problem.evaluate_grid(values, radius, tight, n_candidates, max_checks)
        if len(theta) == 0:
            return None
        best = SearchResult(theta[0], float(dis[0]), float(mds[0]), loop, count, 0.0)
        best.candidates = list(theta[1:n_candidates])
        return best, theta[0, :m], best.mds

    limits = (np.full(m, -tmax), np.full(m, tmax))
    clipped = clip_regions(
        limits,
        limits,
        evaluate,
        problem.zone,
        problem.zone_for_step,
        num,
        dtheta,
        max_loops,
        min_step=dtheta / 100,
    )
    if clipped.best is None:
        return None
    clipped.best.evaluations = clipped.evaluations
    clipped.best.seconds = time.perf_counter() - start
    return clipped.best


def blind_grid_size(n_free: int, theta_max: float, dtheta: float) -> int:
    """Combinations of blind search's grid of step ``dtheta`` over ``n_free`` angles."""
    return len(np.arange(-theta_max, theta_max + 1e-12, dtheta)) ** n_free


def blind_search(
    problem: PlanarProblem,
    dtheta: float = math.radians(1.0),
    max_evaluations: int | None = None,
    chunk: int = 1 << 18,
) -> SearchResult | None:
    """Blind search on one grid of step ``dtheta`` (jace Table II, type A).

    Args:
        problem: the planar problem; its ``zone`` is the reaching tolerance.
        dtheta: grid step [rad].
        max_evaluations: evaluate only this many combinations, evenly strided over the grid
            (the result says ``sampled``); None evaluates the whole grid.
        chunk: combinations evaluated per numpy batch.

    """
    start = time.perf_counter()
    m = problem.n_free
    values = np.arange(-problem.theta_max, problem.theta_max + 1e-12, dtheta)
    total = len(values) ** m
    if max_evaluations is not None and max_evaluations < total:
        flat_all = np.unique(np.linspace(0, total - 1, max_evaluations).astype(np.int64))
        sampled = True
    else:
        flat_all, sampled = None, False
    count = total if flat_all is None else len(flat_all)
    best_theta, best_dis, best_mds = None, 0.0, math.inf
    for begin in range(0, count, chunk):
        if flat_all is None:
            flat = np.arange(begin, min(begin + chunk, count), dtype=np.int64)
        else:
            flat = flat_all[begin : begin + chunk]
        free = (
            values[np.stack(np.unravel_index(flat, (len(values),) * m), axis=-1)]
            if m
            else (np.zeros((1, 0)))
        )
        idx, dis, mds = problem.evaluate(free, problem.zone, want=1)
        if len(idx):
            i = 0
            if mds[i] < best_mds:
                best_theta = problem.full_theta(free[idx[i : i + 1]])[0][0]
                best_dis, best_mds = float(dis[i]), float(mds[i])
    if best_theta is None:
        return None
    return SearchResult(
        theta=best_theta,
        dis=best_dis,
        mds=best_mds,
        loops=1,
        evaluations=count,
        seconds=time.perf_counter() - start,
        sampled=sampled,
        grid_size=total,
    )


def refine(
    problem: PlanarProblem, theta: NDArray[np.float64], tol: float = 1e-9, iterations: int = 60
) -> tuple[NDArray[np.float64], float] | None:
    """Close the tip's remaining gap with minimum-norm Gauss–Newton steps on the searched angles.

    The planar tip matches the target's ``ρ`` (the only equation; ``dis`` sets the height and the
    end heading, if any, holds by construction). Minimum-norm steps keep the posture next to the
    search's answer: :func:`~aftir_rl.planning.posture.clipping.gauss_newton`'s steps, compiled
    (:func:`aftir_rl.core.kernel.planar.planar_refine`).

    Returns:
        ``(theta, dis)`` with ``|ρ_tip − ρ_t| < tol`` and every angle in bounds, or None.

    """
    m, tmax = problem.n_free, problem.theta_max
    free = np.array(theta[:m], dtype=np.float64)
    if m:
        goal = (float(problem.rho), problem.heading)
        if not planar_refine(free, goal, problem.section_length, tmax, tol, iterations, 1e-7):
            return None
    full, ok = problem.full_theta(free[None])
    rho_tip, z = planar_tip(full, problem.section_length)
    if not ok[0] or abs(rho_tip[0] - problem.rho) >= tol:
        return None
    dis = float(problem.z - z[0])
    if m and not problem.dis_limits[0] - 1e-9 <= dis <= problem.dis_limits[1] + 1e-9:
        return None
    return full[0], dis
