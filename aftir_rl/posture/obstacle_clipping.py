"""Collision-free path planning by region clipping among spherical obstacles (seed 000).

Seed 000 (ICRA 2014, §II–III) plans one posture ``q = (dis, θ_i, φ_i)`` that puts the tip in the
*target plane zone* while the body avoids the obstacles, with these pieces:

- **Obstacle space zones** (assumption 4): each spherical obstacle of radius ``r0`` is replaced
  by the vertical cylinder of radius ``r_oba = r0 + r_b`` through its centre. A backbone point
  must stay out of every such cylinder. Because the rising distance only moves the arm along
  ``z``, whether the body clears a vertical cylinder does not depend on ``dis``: that is the
  *projection strategy* (fig. 3–4), which lets the angles be searched first and ``dis`` be
  computed after.
- **Target space zone** (assumption 5): the vertical cylinder of radius ``r_target`` around the
  target. A combination of angles *reaches* it when its tip (base at the origin) lies inside;
  then the rising distance ``dis = z_target − z_tip`` puts the tip in the **target plane zone**
  (the horizontal disc of radius ``r_target`` at the target's height, assumption 3).
- **MDS** (eq. 5): the sum over body points of their distance to the reference segment from the
  origin to the target; the feasible, reaching combination of least MDS wins.
- **Region clipping** (§III.B, eq. 14) over *all* 2N angles (θ and φ: obstacles break the
  planar reduction of seed 004): split each interval into NUM parts, evaluate every combination
  (batched), keep the best, shrink each interval to the best value's neighbours, until the step is
  below ``Δθ``. Sections are added until a solution exists.

Readings we took where the paper is loose or inconsistent:

- ``r_oba``: §IV sets ``r0 = 2``, ``r_b = 2`` and ``r_oba = 3`` cm, but assumption 4 defines
  ``r_oba = r0 + r_b`` = 4. We use the definition, with ``r_b`` the arm's body radius (2 cm in
  ``configs/tanks/open_space*.yaml``): then a backbone outside the zone keeps the body off the
  sphere, which python-fcl confirms on every returned posture. (The paper's own Table II postures
  keep 2.8–3.5 cm from obstacles 1 and 2, consistent with its 3 cm, not with 4.)
- The obstacle zone is the vertical cylinder above the floor (``z ≥ 0`` in assumption 4: "a
  vertical pipe standing where the obstacle is"); below the floor the arm is in the panel's
  guide, and the panel rule applies there.
- Angle ranges: ``θ ∈ [−θ_max, θ_max]`` and ``φ ∈ [−π/2, π/2]`` for the first grid, which covers
  every section shape once (``(θ, φ)`` and ``(−θ, φ + π)`` are the same section); ``φ`` may
  leave that interval as the intervals shrink (it is periodic).
- Coarse loops accept tips within ``max(r_target, Σ_i (s_θ + s_φ)/2 · L_i)`` of the target's
  vertical (``L_i`` the arc length from section ``i`` to the tip): the continuity bound of §III.B,
  as in :mod:`aftir_rl.posture.search`. NUM is lowered for more sections so a loop evaluates at
  most about 2·10⁶ combinations.
- The paper stops at the search step, the tip anywhere in the target plane zone (its tips are
  0.03–0.22 cm off in Table II); ``refine=False`` does that. By default we go on clipping with a
  target zone of the planner's tolerance (0.01 cm), then take minimum-norm Gauss–Newton steps
  towards the exact target when the result still clears every zone (the least-MDS posture
  usually touches a zone, so often it does not).
- The intervals shrink to the best value's two neighbours on each side (the paper keeps one):
  measured on [30, 18, 51], one neighbour stalls (no feasible tip near the target in the next
  box) with one obstacle and finds MDS 68.2 cm without obstacles; two find 3-section postures
  for every row of Table II and MDS 51.7 cm without obstacles.

The tank's other solids and walls (if any) are checked on the backbone with the arm's radius,
and the panel rule holds. Every returned posture is checked by forward kinematics and python-fcl
(:meth:`~aftir_rl.posture.planner.Planner.checked`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.collision import points_clear
from aftir_rl.errors import PlanningError
from aftir_rl.robot import Posture, body_points, section_transforms, tip_position
from aftir_rl.tank import Sphere, Tank

if TYPE_CHECKING:
    from aftir_rl.posture.planner import PlannedPosture, Planner

__all__ = ["ObstacleProblem", "ClippingResult", "obstacle_region_clipping", "obstacle_clipping"]

_CHUNK = 1 << 17
_MAX_SECTIONS = 6  # 3^14 = 4.8e6 combinations a loop for 7 sections, even at NUM = 2


def _apply(
    frame: NDArray[np.float64], local: NDArray[np.float64], dis: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Points ``local`` ``(S, K, 3)`` in frames ``(S, 4, 4)``, raised by ``dis`` ``(S,)``."""
    r, o = frame[:, None, :3, :3], frame[:, None, :3, 3]
    lx, ly, lz = local[..., 0], local[..., 1], local[..., 2]
    out = np.empty(local.shape)
    for i in range(3):
        out[..., i] = r[..., i, 0] * lx + r[..., i, 1] * ly + r[..., i, 2] * lz + o[..., i]
    out[..., 2] += dis[:, None]
    return out


@dataclass
class _Grid:
    """A product grid's per-section choices, shared prefix frames and local body points."""

    sizes: list[int]
    pairs: list[NDArray[np.float64]]
    prefix: list[NDArray[np.float64]]
    local_pts: list[NDArray[np.float64]]


@dataclass
class ObstacleProblem:
    """One seed 000 problem: a target, N sections and the obstacle zones.

    Attributes:
        target: the target [cm].
        n_sections: N.
        section_length: ``l`` [cm].
        theta_max: bound on ``|θ_i|`` [rad].
        zones_xy: centres of the obstacle space zones in the plane XOY, shape ``(M, 2)`` [cm].
        r_oba: radius ``r0 + r_b`` of each obstacle space zone, shape ``(M,)`` [cm].
        r_target: radius of the target zones [cm].
        tank: the tank whose walls, other solids and panel rule also apply.
        radius: the arm's body radius for those [cm].
        points_per_section: backbone points per section for zones, MDS and checks.

    """

    target: NDArray[np.float64]
    n_sections: int
    section_length: float
    theta_max: float
    zones_xy: NDArray[np.float64]
    r_oba: NDArray[np.float64]
    r_target: float
    tank: Tank
    radius: float
    points_per_section: int = 10

    def split(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(θ, φ)`` from combinations ``x`` of shape ``(B, 2N)``."""
        return x[:, : self.n_sections], x[:, self.n_sections :]

    def zone_for_step(self, step: NDArray[np.float64]) -> float:
        """Reaching radius that accepts the nearest grid point of any exact solution."""
        n, l = self.n_sections, self.section_length
        reach = (n - np.arange(n)) * l
        return max(self.r_target, float(np.sum((step[:n] + step[n:]) / 2 * reach)))

    def evaluate_grid(
        self, values: list[NDArray[np.float64]], zone: float, tight: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Every combination of the per-angle ``values`` (θ_1..θ_N, then φ_1..φ_N).

        The grid is a product, so the frame at the end of sections ``1..i`` is shared by all
        combinations with the same first ``i`` choices: it is computed once per prefix, and the
        tips of all ``Π (NUM + 1)²`` combinations come from one broadcast product. Body points
        are only computed for the combinations that reach the zone.

        Returns:
            The reaching, feasible combinations ``(S, 2N)``, their ``dis``, MDS and horizontal
            tip distance to the target [cm]: those within ``tight`` of the target's vertical
            when any of them is feasible.

        """
        n, l, k = self.n_sections, self.section_length, self.points_per_section
        frac = np.arange(1, k + 1) / k
        pairs, local, local_pts = [], [], []
        for i in range(n):
            th, ph = (g.ravel() for g in np.meshgrid(values[i], values[n + i], indexing="ij"))
            pairs.append(np.stack([th, ph], axis=1))
            local.append(section_transforms(th, ph, l))
            points = section_transforms(th[:, None] * frac, ph[:, None], l * frac)[..., :3, 3]
            local_pts.append(points)
        prefix = [np.eye(4)[None]]
        for i in range(n - 1):
            prefix.append((prefix[-1][:, None] @ local[i][None]).reshape(-1, 4, 4))
        last = prefix[-1]
        tips = (last[:, None, :3, :3] @ local[-1][None, :, :3, 3, None])[..., 0]
        tips = (tips + last[:, None, :3, 3]).reshape(-1, 3)
        gap = np.hypot(tips[:, 0] - self.target[0], tips[:, 1] - self.target[1])
        dis = self.target[2] - tips[:, 2]
        ok = (gap <= zone) & (dis <= 0.0) & (dis >= -n * l)
        grid = _Grid([len(p) for p in pairs], pairs, prefix, local_pts)
        out = self._survivors(np.flatnonzero(ok & (gap <= tight)), dis, gap, grid)
        if len(out[0]) or tight >= zone:
            return out
        return self._survivors(np.flatnonzero(ok), dis, gap, grid)

    def _survivors(
        self,
        idx: NDArray[np.intp],
        dis: NDArray[np.float64],
        gap: NDArray[np.float64],
        grid: _Grid,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Feasibility and MDS of the combinations ``idx`` of ``grid``, in chunks."""
        n = self.n_sections
        xs, ds, ms = [np.zeros((0, 2 * n))], [np.zeros(0)], [np.zeros(0)]
        gs = [np.zeros(0)]
        for begin in range(0, len(idx), _CHUNK):
            part = idx[begin : begin + _CHUNK]
            choice = np.unravel_index(part, grid.sizes)
            d = dis[part]
            base = np.zeros((len(part), 1, 3))
            base[:, 0, 2] = d
            pts, flat = [base], np.zeros(len(part), dtype=np.intp)
            for i in range(n):
                frame = grid.prefix[i][flat]
                local = grid.local_pts[i][choice[i]]
                pts.append(_apply(frame, local, d))
                flat = flat * grid.sizes[i] + choice[i]
            good, mds = self.feasible_points(np.concatenate(pts, axis=1))
            chosen = [grid.pairs[i][choice[i]] for i in range(n)]
            x = np.concatenate([np.stack([c[:, 0] for c in chosen], axis=1),
                                np.stack([c[:, 1] for c in chosen], axis=1)], axis=1)  # fmt: skip
            xs.append(x[good])
            ds.append(d[good])
            ms.append(mds[good])
            gs.append(gap[part][good])
        return np.concatenate(xs), np.concatenate(ds), np.concatenate(ms), np.concatenate(gs)

    def feasible(
        self, theta: NDArray[np.float64], phi: NDArray[np.float64], dis: NDArray[np.float64]
    ) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
        """Which postures clear the zones, walls, other solids and panel rule, and their MDS."""
        pts = body_points(dis, theta, phi, self.section_length, self.points_per_section)
        return self.feasible_points(pts)

    def feasible_points(
        self, pts: NDArray[np.float64]
    ) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
        """:meth:`feasible` on backbone points ``(B, P, 3)`` (``dis`` applied), MDS inf if not."""
        x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]
        ok = np.ones(len(pts), dtype=bool)
        # Between two samples ``h = l/K`` apart the backbone can dip into a circle by up to
        # ``r − √(r² − h²/4)`` plus the arc's sagitta (under 0.1 cm): keep that much more.
        h = self.section_length / self.points_per_section
        c, r = self.tank.panel.center, self.tank.panel.radius
        inside = z >= c[2]
        for (cx, cy), r_oba in zip(self.zones_xy, self.r_oba):
            dip = r_oba - math.sqrt(max(r_oba**2 - h * h / 4, 0.0)) + 0.1
            limit = (r_oba + dip) ** 2
            ok &= ~np.any(inside & ((x - cx) ** 2 + (y - cy) ** 2 <= limit), axis=1)
        outside = (z < c[2]) & ((x - c[0]) ** 2 + (y - c[1]) ** 2 > r * r)
        ok &= ~np.any(outside, axis=1)
        idx = np.flatnonzero(ok)
        if len(idx) and (self.tank.walls or self.tank.solids):
            ok[idx] = points_clear(self.tank, pts[idx], self.radius)
        mds = np.full(len(pts), np.inf)
        mds[ok] = self.mds(pts[ok])
        return ok, mds

    def mds(self, pts: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance summation of body points ``(B, P, 3)`` to the reference segment (eq. 5)."""
        t = self.target
        x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]
        s = np.clip((x * t[0] + y * t[1] + z * t[2]) / float(t @ t), 0.0, 1.0)
        d2 = (x - s * t[0]) ** 2 + (y - s * t[1]) ** 2 + (z - s * t[2]) ** 2
        return np.sum(np.sqrt(d2), axis=1)

    def zone_clearance(self, posture: Posture) -> float:
        """Smallest horizontal distance of the backbone above the floor to a zone's axis [cm]."""
        pts = posture.points(self.section_length, self.points_per_section)
        pts = pts[pts[:, 2] >= self.tank.panel.center[2]]
        if len(self.zones_xy) == 0 or len(pts) == 0:
            return math.inf
        d = np.hypot(pts[:, None, 0] - self.zones_xy[:, 0], pts[:, None, 1] - self.zones_xy[:, 1])
        return float(d.min())


@dataclass
class ClippingResult:
    """The best combination of a search.

    Attributes:
        posture: the joint variables (tip in the target plane zone).
        mds: its distance summation [cm].
        loops: region clipping loops.
        evaluations: combinations evaluated.

    """

    posture: Posture
    mds: float
    loops: int
    evaluations: int


def obstacle_region_clipping(
    problem: ObstacleProblem, num: int = 10, dtheta: float = math.radians(0.1), max_loops: int = 40
) -> ClippingResult | None:
    """Region clipping over every ``θ_i`` and ``φ_i`` (seed 000 §III.B). None if nothing reaches.

    Args:
        problem: the problem.
        num: NUM, parts each interval is split into; lowered so that ``(NUM + 1)^2N`` stays
            below about 4·10⁶ (:func:`obstacle_clipping` does not try N ≥ 7, where even
            NUM = 2 would exceed it).
        dtheta: stop when every step is below this [rad] (and the zone is ``r_target``).
        max_loops: safety bound on loops.

    """
    n, tmax = problem.n_sections, problem.theta_max
    num = max(2, min(num, int((4e6) ** (1 / (2 * n))) - 1))
    lo = np.concatenate([np.full(n, -tmax), np.full(n, -math.pi / 2)])
    hi = np.concatenate([np.full(n, tmax), np.full(n, math.pi / 2)])
    best, evaluations, prev = None, 0, math.inf
    for loop in range(1, max_loops + 1):
        step = (hi - lo) / num
        values = [np.linspace(a, b, num + 1) for a, b in zip(lo, hi)]
        zone = problem.zone_for_step(step)
        evaluations += (num + 1) ** (2 * n)
        # Prefer tips within a tenth of the bound when any is feasible: MDS ranks a loose
        # zone's combinations poorly (a short tip has a small MDS), as in region_clipping.
        tight = max(problem.r_target, 0.1 * zone)
        x, dis, mds, gap = problem.evaluate_grid(values, zone, tight)
        if len(x) == 0:
            break
        # Outside the tight zone, MDS alone would pick tips far short of the target (a short
        # arm hugs the reference line): take the least MDS among the nearest tips.
        near = gap <= max(tight, 2.0 * float(gap.min()))
        i = int(np.flatnonzero(near)[np.argmin(mds[near])])
        theta, phi = problem.split(x[i : i + 1])
        best = ClippingResult(Posture(dis[i], theta[0], phi[0]), float(mds[i]), loop, evaluations)
        fine = np.max(step) < dtheta and 0.1 * zone <= problem.r_target
        if fine or abs(prev - best.mds) < 1e-9:
            break
        prev = best.mds
        lo, hi = x[i] - 2 * step, x[i] + 2 * step
        lo[:n], hi[:n] = np.maximum(lo[:n], -tmax), np.minimum(hi[:n], tmax)
    if best is not None:
        best.evaluations = evaluations
    return best


def refine_obstacle(
    problem: ObstacleProblem, posture: Posture, tol: float = 1e-9, iterations: int = 60
) -> Posture | None:
    """Minimum-norm Gauss–Newton steps on the 2N angles towards the exact target.

    The tip's ``(x, y)`` goes onto the target's, then ``dis`` sets its height. None unless it
    converges and the posture still clears every zone.
    """
    n, l, h = problem.n_sections, problem.section_length, 1e-7
    x = np.concatenate([posture.theta, posture.phi])
    for _ in range(iterations):
        probe = np.repeat(x[None], 2 * len(x) + 1, axis=0)
        probe[1 : len(x) + 1] += np.eye(len(x)) * h
        probe[len(x) + 1 :] -= np.eye(len(x)) * h
        theta, phi = problem.split(probe)
        tips = tip_position(0.0, theta, phi, l)[:, :2]
        error = tips[0] - problem.target[:2]
        if np.linalg.norm(error) < tol:
            break
        jac = ((tips[1 : len(x) + 1] - tips[len(x) + 1 :]) / (2 * h)).T
        x = x - jac.T @ np.linalg.solve(jac @ jac.T + 1e-12 * np.eye(2), error)
        x[:n] = np.clip(x[:n], -problem.theta_max, problem.theta_max)
    theta, phi = x[:n], x[n:]
    tip = tip_position(0.0, theta, phi, l)
    if np.linalg.norm(tip[:2] - problem.target[:2]) >= max(tol, 1e-6):
        return None
    dis = float(problem.target[2] - tip[2])
    ok, _ = problem.feasible(theta[None], phi[None], np.array([dis]))
    if not ok[0] or not -n * l <= dis <= 0.0:
        return None
    return Posture(dis, theta, phi)


def obstacle_clipping(
    planner: Planner,
    target: ArrayLike,
    r_target: float = 1.0,
    num: int = 10,
    dtheta: float = math.radians(0.1),
    refine: bool = True,
) -> PlannedPosture:
    """Seed 000's collision-free posture for ``target`` in the planner's tank.

    The tank's spheres are the obstacles and ``r_b`` is the arm's body radius. Sections are
    added from the fewest that can span the distance until region clipping finds a solution.

    Args:
        planner: the planner (its tank, arm and checks).
        target: [cm].
        r_target: radius of the target zones [cm] (seed 000: 1 cm), where the search stops
            when ``refine`` is False, as in the paper.
        num: NUM (seed 000: 10).
        dtheta: ``Δθ`` [rad] (seed 000: 0.1°).
        refine: go on clipping until the tip is within the planner's tolerance (0.01 cm), then
            Gauss–Newton steps where they keep every zone clear.

    Raises:
        PlanningError: "Cannot reach the target: <why>".

    """
    start = time.perf_counter()
    target = planner.check_target(target)
    arm, tank = planner.arm, planner.tank
    spheres = [s for s in tank.obstacles if isinstance(s, Sphere)]
    zones = np.array([s.center[:2] for s in spheres], dtype=np.float64).reshape(-1, 2)
    r_oba = np.array([s.radius + arm.radius for s in spheres], dtype=np.float64)
    others = tuple(s for s in tank.solids if not isinstance(s, Sphere))
    check_tank = Tank(tank.name, tank.box_min, tank.box_max, tank.panel, obstacles=others,
                      walls=tank.walls)  # fmt: skip
    if len(zones):
        near = np.hypot(zones[:, 0] - target[0], zones[:, 1] - target[1])
        inside = np.flatnonzero(near <= r_oba)
        if target[2] >= tank.panel.center[2] and len(inside):
            i = int(inside[0])
            raise PlanningError(
                f"Cannot reach the target: it lies in the obstacle space zone of "
                f"{spheres[i].name or 'an obstacle'} (the vertical cylinder of radius "
                f"{r_oba[i]:g} cm around it), which the tip may not enter"
            )
    zone = min(r_target, planner.tolerance) if refine else r_target
    tolerance = planner.tolerance if refine else r_target + 1e-6
    n_min = max(1, math.ceil(float(np.linalg.norm(target)) / arm.section_length - 1e-9))
    n_max = min(n_min + planner.extra_sections, arm.max_sections, _MAX_SECTIONS)
    for n in range(n_min, n_max + 1):
        problem = ObstacleProblem(target, n, arm.section_length, arm.theta_max, zones, r_oba,
                                  zone, check_tank, arm.radius)  # fmt: skip
        result = obstacle_region_clipping(problem, num, dtheta)
        if result is None:
            continue
        refined = refine_obstacle(problem, result.posture) if refine else None
        posture = refined or result.posture
        search_tip = result.posture.tip(arm.section_length)
        details = {
            "sections": n, "loops": result.loops, "evaluations": result.evaluations,
            "mds": result.mds, "r_oba": r_oba.tolist(),
            "zone_clearance_cm": problem.zone_clearance(posture),
            "search_error_cm": float(np.linalg.norm(search_tip - target)),
        }  # fmt: skip
        try:
            return planner.checked(posture, target, "obstacle_clipping", tolerance, details,
                                   start)  # fmt: skip
        except PlanningError:
            continue
    where = ", ".join(f"{v:g}" for v in target)
    if n_min > _MAX_SECTIONS:
        raise PlanningError(
            f"Cannot reach the target: ({where}) cm needs {n_min} sections; region clipping over "
            f"every θ and φ searches at most {_MAX_SECTIONS} sections (with more, even its "
            f"coarsest grid, 3^{2 * (_MAX_SECTIONS + 1)} combinations a loop, is too large)"
        )
    keeps_out = ""
    if len(r_oba):
        keeps_out = f" that keeps out of the obstacle zones (r_oba = {_radii(r_oba)} cm) and"
    raise PlanningError(
        f"Cannot reach the target: region clipping found no posture of {n_min} to {n_max} "
        f"sections{keeps_out} reaches ({where}) cm"
    )


def _radii(r: NDArray[np.float64]) -> str:
    return ", ".join(f"{v:g}" for v in np.unique(r))
