"""The obstacle zones of icra2014: one problem of collision-free region clipping among spheres.

A problem is a target, N sections and the *obstacle space zones* (the vertical cylinders of
radius ``r_oba = r0 + r_b`` through the spheres' centres; the readings we took are in
docs/design.md §6.4): which postures keep their backbone out of every zone, clear the
tank's other solids and walls and keep the panel rule, and their MDS. A product grid of angles is
evaluated in one broadcast product, with body points only for the combinations that reach the
target zone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.collision import panel_violation, points_clear
from aftir_rl.core.robot import Posture, body_points, section_transforms
from aftir_rl.core.tank import Tank
from aftir_rl.planning.posture.clipping import reach, zone_bound
from aftir_rl.planning.posture.planar import distance_sum

__all__ = ["ObstacleProblem"]

_CHUNK = 1 << 17


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
    """One icra2014 problem: a target, N sections and the obstacle zones.

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
        n = self.n_sections
        return zone_bound(self.r_target, step[:n] + step[n:], reach(n, self.section_length, n))

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
            x = np.concatenate(
                [
                    np.stack([c[:, 0] for c in chosen], axis=1),
                    np.stack([c[:, 1] for c in chosen], axis=1),
                ],
                axis=1,
            )
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
        inside = z >= self.tank.panel.center[2]
        for (cx, cy), r_oba in zip(self.zones_xy, self.r_oba):
            dip = r_oba - math.sqrt(max(r_oba**2 - h * h / 4, 0.0)) + 0.1
            limit = (r_oba + dip) ** 2
            ok &= ~np.any(inside & ((x - cx) ** 2 + (y - cy) ** 2 <= limit), axis=1)
        ok &= ~panel_violation(self.tank, pts)
        idx = np.flatnonzero(ok)
        if len(idx) and (self.tank.walls or self.tank.solids):
            ok[idx] = points_clear(self.tank, pts[idx], self.radius)
        mds = np.full(len(pts), np.inf)
        mds[ok] = self.mds(pts[ok])
        return ok, mds

    def mds(self, pts: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance summation of body points ``(B, P, 3)`` to the reference segment (eq. 5)."""
        return distance_sum((pts[..., 0], pts[..., 1], pts[..., 2]), tuple(self.target))

    def zone_clearance(self, posture: Posture) -> float:
        """Smallest horizontal distance of the backbone above the floor to a zone's axis [cm]."""
        pts = posture.points(self.section_length, self.points_per_section)
        pts = pts[pts[:, 2] >= self.tank.panel.center[2]]
        if len(self.zones_xy) == 0 or len(pts) == 0:
            return math.inf
        d = np.hypot(pts[:, None, 0] - self.zones_xy[:, 0], pts[:, None, 1] - self.zones_xy[:, 1])
        return float(d.min())
