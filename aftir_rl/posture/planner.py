"""Posture planners: TGA (with region clipping or blind search) and TSM through a hatch.

- **TGA** (target guided angle, seed 004 and seed 002 §4): dimension reduction (all ``φ_i`` equal
  to the target's bearing), region clipping over the bending angles with the MDS criterion, the
  rising distance, sections added until a collision-free solution exists, then a Gauss–Newton
  refinement so the tip error is far below the search step. An optional required end direction
  (the guided angle) is what TSM needs for its first part.
- **TSM** (three-segment method, seed 002 §4) for a target beyond a hatch: P3 is a TGA posture
  planned in the hatch frame M (origin at the hatch centre, ``z_M`` along the hatch normal into
  the far bay, ``x_M`` towards the floor) from A to G; P2 is one section bending by ``θ_m`` that
  turns the arm onto the hatch axis; P1 is a TGA posture from the panel to C whose end direction
  ``u3`` makes the angle ``α`` with ``z`` at bearing ``δ``. ``α`` is searched.

  Which reading of the paper we took, where its equations are garbled:

  * P3's base: TGA in frame M returns ``dis_p3`` with the base of P3 at ``(0, 0, dis_p3)`` in M, so
    ``A = O_M + dis_p3 · n`` (``n`` the hatch normal). The paper's eq. 5 writes ``h = N_p3 l −
    dis_p3`` in a convention where ``dis`` is measured differently; ours keeps one convention for
    every ``dis`` (the base of the first section).
  * The corner: eq. 7 reuses ``h`` where the geometry needs ``d``; we take ``B = A − d · n`` with
    ``d = (l/θ_m) tan(θ_m/2)`` (eq. 6: the tangent length of an arc of length ``l`` turning by
    ``θ_m``, ``l/2`` at ``θ_m = 0``).
  * ``θ_m`` is the angle between ``u3`` and ``n`` (eq. 9 is that angle for the paper's hatch normal
    along ``x``); ``δ`` is B's bearing (eq. 10); ``d``, ``δ`` and ``θ_m`` depend on each other
    and are solved by fixed-point iteration, which converges in a few steps.
  * ``C = B − d · u3`` (eq. 11), and P2's rotation angle is the bearing of ``n`` in the end frame
    of P1 (eq. 13). P3's rotation angles, planned in M, are turned into the end frame of P2 by the
    twist between the two frames about ``n``.
  * The total: ``N = N_p1 + 1 + N_p3`` and ``dis = dis_p1`` (eq. 14's ``(N_p3 + 1) l`` belongs to
    the paper's other ``dis`` convention).

Every posture a planner returns is checked: joint limits, the panel rule, python-fcl collision with
the arm's radius, and the tip error by forward kinematics. Otherwise it raises
:class:`~aftir_rl.errors.PlanningError`, "Cannot reach the target: <why>".
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.collision import CollisionScene, point_clearance, points_clear
from aftir_rl.errors import PlanningError
from aftir_rl.posture.planar import planar_points, to_frame
from aftir_rl.posture.search import (
    Feasible,
    PlanarProblem,
    SearchResult,
    blind_search,
    refine,
    region_clipping,
)
from aftir_rl.robot import Posture, forward_kinematics, section_transforms
from aftir_rl.tank import Tank, load_tank

__all__ = ["PlannedPosture", "Planner", "METHODS", "random_free_targets"]

METHODS = (
    "auto",
    "tga",
    "tsm",
    "region_clipping",
    "blind",
    "obstacle_clipping",
    "region_division",
)
_CHUNK = 4096
_MAX_GRID = 2e6  # region clipping grids larger than this (14+ searched angles) are not tried


@dataclass
class PlannedPosture:
    """A checked posture and how it was found.

    Attributes:
        posture: the joint variables.
        section_length: ``l`` [cm].
        target: the target [cm].
        tip: the tip by forward kinematics [cm].
        error_cm: ``|tip − target|`` [cm].
        clearance_cm: smallest distance of the arm's body to the tank [cm].
        method: "tga", "tsm", "region_clipping" or "blind".
        seconds: planning wall time.
        details: search statistics (loops, evaluations, the TSM parts...).

    """

    posture: Posture
    section_length: float
    target: NDArray[np.float64]
    tip: NDArray[np.float64]
    error_cm: float
    clearance_cm: float
    method: str
    seconds: float
    details: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The posture JSON of design.md §5."""
        return {
            **self.posture.to_dict(),
            "section_length": self.section_length,
            "tip": [float(v) for v in self.tip],
            "target": [float(v) for v in self.target],
            "error_cm": self.error_cm,
            # No solid at all (open space without obstacles): no finite clearance.
            "clearance_cm": self.clearance_cm if math.isfinite(self.clearance_cm) else None,
            "method": self.method,
            "seconds": self.seconds,
        }


@dataclass
class _Frame:
    """A planning frame: plane bearing ``psi`` inside the frame ``(rotation, origin)`` of S."""

    psi: float
    rotation: NDArray[np.float64] | None = None
    origin: NDArray[np.float64] | None = None
    panel: bool = True


class Planner:
    """Plans postures of the tank's arm.

    Args:
        tank: tank name, YAML path or :class:`~aftir_rl.tank.Tank`.
        num: NUM of region clipping.
        dtheta: search step ``Δθ`` [rad].
        zone: target zone radius ``ε`` [cm].
        tolerance: largest tip error accepted after refinement [cm].
        margin: extra clearance the search keeps from solids beyond the arm's radius [cm].
        extra_sections: sections tried beyond the fewest that can span the distance.

    """

    def __init__(
        self,
        tank: str | Tank = "b737_center",
        num: int = 9,
        dtheta: float = math.radians(1.0),
        zone: float = 0.5,
        tolerance: float = 0.01,
        margin: float = 1.0,
        extra_sections: int = 3,
    ) -> None:
        self.tank = load_tank(tank)
        self.arm = self.tank.arm
        self.scene = CollisionScene(self.tank)
        self.num, self.dtheta, self.zone = num, dtheta, zone
        self.tolerance, self.margin = tolerance, margin
        self.extra_sections = extra_sections
        # Backbone samples no farther apart than twice the margin for the pre-filter, so the
        # backbone between two samples stays clear by more than the arm's radius.
        self._check_points = max(4, math.ceil(self.arm.section_length / (2 * margin)))

    # ------------------------------------------------------------------ public API
    def plan(self, target: ArrayLike, method: str = "auto") -> PlannedPosture:
        """Plan a posture reaching ``target`` [cm].

        ``auto`` uses TSM for a target beyond the baffle and TGA otherwise;
        ``obstacle_clipping`` is seed 000 (:mod:`aftir_rl.posture.obstacle_clipping`) and
        ``region_division`` seed 001 (:mod:`aftir_rl.posture.region_division`).

        Raises:
            PlanningError: "Cannot reach the target: <why>".

        """
        if method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        target = self.check_target(target)
        if method == "auto":
            method = "tsm" if self.beyond_baffle(target) else "tga"
        if method == "tsm":
            return self.tsm(target)
        if method == "obstacle_clipping":
            from aftir_rl.posture.obstacle_clipping import obstacle_clipping

            return obstacle_clipping(self, target)
        if method == "region_division":
            from aftir_rl.posture.region_division import region_division

            return region_division(self, target)
        return self.tga(target, search=("blind" if method == "blind" else "region_clipping"),
                        refine_tip=method != "blind" and method != "region_clipping",
                        method=method)  # fmt: skip

    def beyond_baffle(self, target: ArrayLike) -> bool:
        """Whether ``target`` lies on the far side of the baffle from the panel."""
        b = self.tank.baffle
        if b is None or self.tank.hatch is None:
            return False
        side = np.sign(self.tank.panel.center[b.index] - b.position)
        return bool(np.sign(np.asarray(target)[b.index] - b.position) == -side)

    def tga(
        self,
        target: ArrayLike,
        end_direction: ArrayLike | None = None,
        search: str = "region_clipping",
        refine_tip: bool = True,
        method: str = "tga",
    ) -> PlannedPosture:
        """Target guided angle posture from the panel to ``target``.

        Args:
            target: [cm].
            end_direction: required tip direction (a vector in the target's vertical plane).
            search: "region_clipping" or "blind".
            refine_tip: refine so the tip error is below ``tolerance`` (else the search's zone).
            method: name recorded in the result.

        """
        start = time.perf_counter()
        target = self.check_target(target)
        psi = math.atan2(target[1], target[0]) if math.hypot(target[0], target[1]) > 1e-9 else 0.0
        rho = math.hypot(target[0], target[1])
        heading = None
        if end_direction is not None:
            u = np.asarray(end_direction, dtype=np.float64)
            u = u / np.linalg.norm(u)
            horizontal = u[0] * math.cos(psi) + u[1] * math.sin(psi)
            if abs(-u[0] * math.sin(psi) + u[1] * math.cos(psi)) > 1e-6:
                raise PlanningError(
                    "Cannot reach the target: the required end direction is not in the vertical "
                    "plane through the target"
                )
            heading = math.atan2(horizontal, u[2])
        frame = _Frame(psi)
        n_min = max(1, math.ceil(float(np.linalg.norm(target)) / self.arm.section_length - 1e-9))
        sections = range(n_min, min(n_min + self.extra_sections, self.arm.max_sections) + 1)
        found = self._search_sections(
            rho, float(target[2]), frame, sections, heading, search, refine_tip
        )
        if found is None:
            raise PlanningError(
                f"Cannot reach the target: no collision-free {method.upper()} posture of "
                f"{sections.start} to {sections.stop - 1} sections reaches {_fmt(target)} cm"
            )
        theta, dis, result = found
        posture = Posture(dis, theta, (psi,) * len(theta))
        details = {"loops": result.loops, "evaluations": result.evaluations, "sections": len(theta)}
        tol = self.tolerance if refine_tip else self.zone + 1e-6
        return self._finalize(posture, target, method, start, tol, details)

    def tsm(self, target: ArrayLike) -> PlannedPosture:
        """Three-segment posture through the hatch to a target beyond the baffle."""
        start = time.perf_counter()
        target = self.check_target(target)
        tank, l = self.tank, self.arm.section_length
        if tank.baffle is None or tank.hatch is None:
            raise PlanningError("Cannot reach the target: TSM needs a tank with a baffle and hatch")
        if not self.beyond_baffle(target):
            raise PlanningError(
                "Cannot reach the target: TSM is for targets beyond the baffle; use TGA"
            )
        rot_m, o_m = self.hatch_frame(target)
        n = rot_m[:, 2]
        g_m = rot_m.T @ (target - o_m)
        psi_m = math.atan2(g_m[1], g_m[0])
        frame_m = _Frame(psi_m, rot_m, o_m, panel=False)
        reasons: list[str] = []
        best: tuple[Posture, dict[str, Any]] | None = None
        n3_min = max(1, math.ceil(np.linalg.norm(g_m) / l - 1e-9) - 1)
        for n3 in range(n3_min, min(n3_min + self.extra_sections, self.arm.max_sections - 2) + 1):
            # P3's base A: within half a section before the hatch first (room for P2 in bay 1),
            # then past the hatch (near targets), then deeper in bay 1.
            for dis_range in ((-0.5 * l, 0.0), (0.0, 0.5 * l), (-1.5 * l, -0.5 * l)):
                p3 = self._search_sections(
                    math.hypot(g_m[0], g_m[1]), float(g_m[2]), frame_m, [n3], None,
                    "region_clipping", True, dis_range=dis_range,
                    dis_limits=(dis_range[0] - l / 2, dis_range[1] + l / 2),
                )  # fmt: skip
                if p3 is not None:
                    break
            if p3 is None:
                reasons.append(f"no P3 posture of {n3} sections from the hatch")
                continue
            theta3, dis3, res3 = p3
            a_point = o_m + dis3 * n
            # Guided angles nearest the straight line from the panel to A first; the first
            # that gives a checked posture wins.
            alpha0 = math.atan2(math.hypot(a_point[0], a_point[1]), a_point[2])
            alphas = np.radians(np.arange(5.0, 90.1, 5.0))
            for alpha in alphas[np.argsort(np.abs(alphas - alpha0), kind="stable")]:
                out = self._tsm_p1(target, a_point, n, alpha, theta3, psi_m, rot_m, len(theta3))
                if isinstance(out, str):
                    reasons.append(out)
                    continue
                posture, _, details = out
                details.update(loops_p3=res3.loops, evaluations_p3=res3.evaluations)
                best = (posture, details)
                break
            if best is not None:
                break
        if best is None:
            counts = Counter(r.split(": ", 1)[-1] if "deg:" in r else r for r in reasons)
            why = "; ".join(f"{k} ({v}x)" if v > 1 else k for k, v in counts.most_common(3))
            raise PlanningError(
                f"Cannot reach the target: TSM found no posture to {_fmt(target)} cm ({why})"
            )
        return self._finalize(best[0], target, "tsm", start, self.tolerance, best[1])

    def hatch_frame(self, target: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Rotation (columns ``x_M, y_M, z_M`` in S) and origin of the hatch frame M."""
        b, h = self.tank.baffle, self.tank.hatch
        assert b is not None and h is not None
        z_m = np.zeros(3)
        z_m[b.index] = 1.0 if np.asarray(target)[b.index] > b.position else -1.0
        x_m = np.array([0.0, 0.0, -1.0])
        return np.column_stack([x_m, np.cross(z_m, x_m), z_m]), np.array(h.center, dtype=float)

    # ------------------------------------------------------------------ internals
    def check_target(self, target: ArrayLike) -> NDArray[np.float64]:
        """The target as an array, checked to be a free point of the tank.

        Raises:
            PlanningError: not three finite numbers, outside the box, inside a solid, or closer
                to a surface than the arm's radius.

        """
        t = np.asarray(target, dtype=np.float64)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise PlanningError(f"Cannot reach the target: expected x y z in cm, got {target!r}")
        if not self.tank.contains_point(t):
            raise PlanningError(
                f"Cannot reach the target: {_fmt(t)} cm is outside the tank box "
                f"{_fmt(self.tank.box_min)}..{_fmt(self.tank.box_max)}"
            )
        solid = self.tank.solid_at(t)
        if solid is not None:
            raise PlanningError(
                f"Cannot reach the target: {_fmt(t)} cm is inside {solid.name or 'a solid'}"
            )
        clearance = float(point_clearance(self.tank, t[None])[0])
        if clearance <= self.arm.radius:
            raise PlanningError(
                f"Cannot reach the target: {_fmt(t)} cm is {clearance:.1f} cm from a wall or "
                f"obstacle, closer than the arm's radius {self.arm.radius:g} cm"
            )
        return t

    def _feasible(self, frame: _Frame) -> Feasible:
        l, k, tank = self.arm.section_length, self._check_points, self.tank
        limit = self.arm.radius + self.margin

        def check(
            th: NDArray[np.float64], d: NDArray[np.float64], points: int, clear: float
        ) -> NDArray[np.bool_]:
            rho, z = planar_points(th, l, points)
            z = z + d[:, None]
            ok = np.ones(len(th), dtype=bool)
            if frame.panel:
                ok &= ~np.any((z < 0) & (np.abs(rho) > tank.panel.radius), axis=1)
            pts = to_frame(rho[ok], z[ok], frame.psi, frame.rotation, frame.origin)
            ok[ok] = points_clear(tank, pts, clear)
            return ok

        def feasible(theta: NDArray[np.float64], dis: NDArray[np.float64]) -> NDArray[np.bool_]:
            out = np.zeros(len(theta), dtype=bool)
            for begin in range(0, len(theta), _CHUNK):
                part = np.arange(begin, min(begin + _CHUNK, len(theta)))
                # A coarse pass (4 points a section, no margin) rejects most candidates cheaply.
                part = part[check(theta[part], dis[part], 4, self.arm.radius)]
                if len(part):
                    out[part] = check(theta[part], dis[part], k, limit)
            return out

        return feasible

    def _search_sections(
        self,
        rho: float,
        z: float,
        frame: _Frame,
        sections: Any,
        heading: float | None,
        search: str,
        refine_tip: bool,
        dis_range: tuple[float, float] | None = None,
        dis_limits: tuple[float, float] = (-math.inf, 0.0),
    ) -> tuple[NDArray[np.float64], float, SearchResult] | None:
        """First section count with a search result that refines and passes the exact check."""
        for n in sections:
            # With refinement the search narrows the zone to the tolerance, so that refining moves
            # the body by less than the pre-filter's margin (postures hugging the reference line
            # are often that close to an edge).
            zone = min(self.zone, self.tolerance) if refine_tip else self.zone
            feasible = self._feasible(frame)
            problem = PlanarProblem(
                rho, z, n, self.arm.section_length, self.arm.theta_max, zone=zone,
                end_heading=heading,
                dis_range=dis_range or (-n * self.arm.section_length, 0.0),
                dis_limits=dis_limits,
                feasible=feasible,
            )  # fmt: skip
            if search == "blind":
                size = len(np.arange(-self.arm.theta_max, self.arm.theta_max + 1e-12, self.dtheta))
                if size**problem.n_free > 5e7:
                    continue
                result = blind_search(problem, self.dtheta)
            else:
                num = (
                    self.num
                    if problem.n_free <= 5
                    else max(2, int(1e5 ** (1 / problem.n_free)) - 1)
                )
                if (num + 1) ** problem.n_free > _MAX_GRID:
                    continue  # even NUM = 2 is too large a grid (3^14 = 4.8e6 combinations)
                result = region_clipping(problem, num=num, dtheta=self.dtheta)
            if result is None:
                continue
            dis: float | None
            for theta in [result.theta, *result.candidates]:
                if refine_tip:
                    fixed = refine(problem, theta)
                    if fixed is None:
                        continue
                    theta, dis = fixed
                    if not feasible(theta[None], np.array([dis]))[0]:
                        continue
                else:
                    dis = result.dis if theta is result.theta else None
                    if dis is None:
                        continue
                if frame.rotation is None:
                    posture = Posture(dis, theta, (frame.psi,) * n)
                    if self.scene.collides(posture):
                        continue
                return np.asarray(theta), float(dis), result
        return None

    def _tsm_p1(
        self,
        target: NDArray[np.float64],
        a_point: NDArray[np.float64],
        n: NDArray[np.float64],
        alpha: float,
        theta3: NDArray[np.float64],
        psi_m: float,
        rot_m: NDArray[np.float64],
        n3: int,
    ) -> tuple[Posture, Any, dict[str, Any]] | str:
        """P1 and P2 for one guided angle ``alpha``; a reason string when impossible."""
        l = self.arm.section_length
        d = l / 2
        for _ in range(100):
            b_point = a_point - d * n
            delta = math.atan2(b_point[1], b_point[0])
            u3 = np.array([math.sin(alpha) * math.cos(delta), math.sin(alpha) * math.sin(delta),
                           math.cos(alpha)])  # fmt: skip
            theta_m = math.acos(float(np.clip(u3 @ n, -1.0, 1.0)))
            d_new = l / 2 if theta_m < 1e-9 else (l / theta_m) * math.tan(theta_m / 2)
            if abs(d_new - d) < 1e-12:
                break
            d = d_new
        if theta_m > self.arm.theta_max:
            bend = math.degrees(theta_m)
            return f"alpha {math.degrees(alpha):.0f} deg needs P2 to bend {bend:.0f} deg"
        b_point = a_point - d * n
        c_point = b_point - d * u3
        rho_c = math.hypot(b_point[0], b_point[1]) - d * math.sin(alpha)
        if float(point_clearance(self.tank, c_point[None])[0]) <= self.arm.radius:
            return f"alpha {math.degrees(alpha):.0f} deg puts C in an obstacle"
        n_min = max(1, math.ceil(float(np.linalg.norm(c_point)) / l - 1e-9))
        n_max = min(n_min + self.extra_sections, self.arm.max_sections - 1 - n3)
        p1 = self._search_sections(
            rho_c, float(c_point[2]), _Frame(delta), range(n_min, n_max + 1), alpha,
            "region_clipping", True,
        )  # fmt: skip
        if p1 is None:
            return f"alpha {math.degrees(alpha):.0f} deg: no P1 posture reaches C"
        theta1, dis1, res1 = p1
        n1 = len(theta1)
        frames = forward_kinematics(dis1, theta1, [delta] * n1, l)
        r_c = frames[-1, :3, :3]
        n_local = r_c.T @ n
        phi_m = math.atan2(n_local[1], n_local[0])
        bend_m = math.acos(float(np.clip(n_local[2], -1, 1)))
        r_a = r_c @ section_transforms(bend_m, phi_m, l)[:3, :3]
        beta = math.atan2(r_a[:, 0] @ rot_m[:, 1], r_a[:, 0] @ rot_m[:, 0])
        phi3 = psi_m - beta
        posture = Posture(
            dis1,
            tuple(theta1) + (bend_m,) + tuple(theta3),
            (delta,) * n1 + (phi_m,) + (phi3,) * n3,
        )
        report = self.scene.check(posture)
        if report.collides:
            return f"alpha {math.degrees(alpha):.0f} deg collides ({report.hit or 'panel rule'})"
        details = {
            "sections": posture.n_sections, "n_p1": n1, "n_p3": n3,
            "alpha_deg": math.degrees(alpha), "delta_deg": math.degrees(delta),
            "theta_m_deg": math.degrees(bend_m), "loops_p1": res1.loops,
            "evaluations_p1": res1.evaluations,
        }  # fmt: skip
        return posture, report, details

    def checked(
        self,
        posture: Posture,
        target: ArrayLike,
        method: str,
        tolerance: float | None = None,
        details: dict[str, Any] | None = None,
        started: float | None = None,
    ) -> PlannedPosture:
        """Check a posture found elsewhere (limits, tip, collision) like a planned one.

        Args:
            posture: the posture.
            target: the point its tip must reach [cm].
            method: name recorded in the result.
            tolerance: largest tip error [cm] (default: the planner's).
            details: recorded in the result.
            started: ``time.perf_counter()`` when planning began (the result's ``seconds``).

        Raises:
            PlanningError: it fails a check.

        """
        return self._finalize(
            posture, np.asarray(target, float), method,
            time.perf_counter() if started is None else started,
            self.tolerance if tolerance is None else tolerance, details or {},
        )  # fmt: skip

    def _finalize(
        self,
        posture: Posture,
        target: NDArray[np.float64],
        method: str,
        start: float,
        tolerance: float,
        details: dict[str, Any],
    ) -> PlannedPosture:
        """Check a posture by forward kinematics and collision, or raise PlanningError."""
        l = self.arm.section_length
        if any(abs(t) > self.arm.theta_max + 1e-9 for t in posture.theta):
            raise PlanningError("Cannot reach the target: a bending angle exceeds the joint limit")
        tip = posture.tip(l)
        error = float(np.linalg.norm(tip - target))
        if error > tolerance:
            raise PlanningError(
                f"Cannot reach the target: the tip ends {error:.3f} cm from it (tolerance "
                f"{tolerance:g} cm)"
            )
        report = self.scene.check(posture)
        if report.collides:
            why = "breaks the panel rule" if not report.panel_ok else f"touches {report.hit}"
            raise PlanningError(f"Cannot reach the target: the posture {why}")
        return PlannedPosture(
            posture, l, target, tip, error, report.clearance_cm, method,
            time.perf_counter() - start, details,
        )  # fmt: skip


def _fmt(v: ArrayLike) -> str:
    return "(" + ", ".join(f"{float(x):g}" for x in np.asarray(v).ravel()) + ")"


def random_free_targets(
    planner: Planner, n_each: int, seed: int, clearance: float = 5.0
) -> dict[str, list[NDArray[np.float64]]]:
    """Uniform random points of the tank at least ``clearance`` [cm] from any surface.

    Returns ``n_each`` points on each side of the baffle: ``{"bay1": [...], "bay2": [...]}``
    (``bay2`` beyond the baffle, planned with TSM by ``auto``).
    """
    tank, rng = planner.tank, np.random.default_rng(seed)
    out: dict[str, list[NDArray[np.float64]]] = {"bay1": [], "bay2": []}
    while min(len(v) for v in out.values()) < n_each:
        x = rng.uniform(tank.box_min, tank.box_max)
        if point_clearance(tank, x[None])[0] <= clearance:
            continue
        bay = "bay2" if planner.beyond_baffle(x) else "bay1"
        if len(out[bay]) < n_each:
            out[bay].append(x)
    return out
