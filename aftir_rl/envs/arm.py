"""``AFTIR-Arm-v0`` and ``AFTIR-ArmReach-v0``: the continuum arm itself, for Stable-Baselines3."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from aftir_rl.core.collision import CollisionScene, panel_violation
from aftir_rl.core.errors import InvalidActionError, TargetError
from aftir_rl.core.kernel import fk_points
from aftir_rl.core.robot import Posture
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.envs.ftl.targets import bay_region, draw_targets

__all__ = ["ArmEnv"]


class ArmEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """The arm in the tank, moved by bounded increments of its joint variables.

    ## Description

    The linear module and the ``n_sections`` bending sections of the AFTIR arm, in the reference
    tank. Each step changes ``dis`` and every ``θ_i``, ``φ_i`` by a bounded increment; the task is
    to bring the tip within ``success_tolerance`` of a target without touching the tank.

    ## Action Space

    ``Box(-1, 1, (1 + 2N,), float32)``: increments of ``dis``, ``θ_1..θ_N``, ``φ_1..φ_N``, scaled
    inside the env by ``dis_step`` [cm] and ``angle_step`` [rad]. ``θ`` is clipped to
    ``±θ_max`` and ``dis`` to ``[-N·l, 0]`` (the linear module stays outside the tank). Sections
    that end below the floor are inside the panel's guide and stay straight.

    ## Observation Space

    ``Box(-20, 20, (6N + 15,), float32)``: ``dis/l``, ``θ/θ_max``, ``sin φ``, ``cos φ``, the tip,
    the target and their difference (cm / 100), the body clearance (cm / 10, capped at 1) and the
    distance to the target (cm / 100), then ``sin θ``, ``cos θ``, the section ends' heights
    (cm / 100) and the difference again at a finer scale (cm / 10, clipped to ±3) for the last
    centimetres.

    ## Starting State

    The arm straight along the panel axis, its tip ``start_height`` [cm] above the floor.

    ## Rewards

    ``(d_prev − d) / 10`` for progress towards the target [per cm], ``+10`` on success, ``−10`` on
    a collision (python-fcl through :class:`~aftir_rl.core.collision.CollisionScene`, or the panel
    rule).

    ## Episode End

    Terminated on success or collision; truncated by ``max_episode_steps`` (registration).

    ## Arguments

    - ``tank``: tank name or YAML path.
    - ``n_sections``: sections of the arm.
    - ``target``: a fixed target [cm], or None to draw one per episode from ``self.np_random``:
      the tip of a random collision-free posture of the arm, so every target is reachable.
    - ``target_region``: ``(min, max)`` corners [cm] the drawn targets must lie in.
    - ``free_targets``: draw targets as ``AFTIR-ArmFTL-v0`` does instead (uniformly among the
      points of ``target_region``, or of ``bay`` 1 / 2, at least 10 cm from every surface and
      20 cm from the start), so both envs pose the same task (``AFTIR-ArmFull-v0``).
    - ``success_tolerance``: [cm].
    - ``dis_step``, ``angle_step``: largest increments per step [cm], [rad].
    - ``render_mode``: ``"rgb_array"``.

    ``reset(options={"target": (x, y, z)})`` sets the target for that episode.

    ## Version History

    - v0: initial version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        tank: str | Path | Tank = DEFAULT_TANK,
        n_sections: int = 3,
        target: tuple[float, float, float] | None = None,
        target_region: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None,
        success_tolerance: float = 2.0,
        dis_step: float = 3.0,
        angle_step: float = 0.1,
        start_height: float = 10.0,
        free_targets: bool = False,
        bay: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        self.tank = load_tank(tank)
        self.arm = self.tank.arm
        if not 1 <= n_sections <= self.arm.max_sections:
            raise ValueError(f"n_sections must be in 1..{self.arm.max_sections}, got {n_sections}")
        self.n = int(n_sections)
        self.l = self.arm.section_length
        self.scene = CollisionScene(self.tank, links_per_section=5)
        self.success_tolerance = float(success_tolerance)
        self.dis_step, self.angle_step = float(dis_step), float(angle_step)
        self.start_height = float(start_height)
        self.render_mode = render_mode
        self.fixed_target = None if target is None else self._check_target(target)
        self.target_region = (
            bay_region(self.tank, bay)
            if target_region is None
            else (np.array(target_region[0], float), np.array(target_region[1], float))
        )
        self.free_targets = bool(free_targets)
        self._free_targets = bool(free_targets)
        self.action_space = spaces.Box(-1.0, 1.0, (1 + 2 * self.n,), np.float32)
        self.observation_space = spaces.Box(-20.0, 20.0, (6 * self.n + 15,), np.float32)
        # Fast pre-check (see _collides): backbone samples farther than radius + margin from
        # everything clear every capsule (CollisionScene.sample_margin), so the pre-check is
        # conservative, and fcl decides everything closer.
        self._k = 8
        self._margin = self.scene.sample_margin(self._k)
        self._state = np.zeros(1 + 2 * self.n)
        self.target = np.zeros(3) if self.fixed_target is None else self.fixed_target
        self._tips: list[NDArray[np.float64]] = []

    # ------------------------------------------------------------------ helpers
    def _check_target(self, target: Any) -> NDArray[np.float64]:
        t = np.asarray(target, dtype=np.float64)
        if t.shape != (3,) or not self.tank.contains_point(t) or self.tank.solid_at(t) is not None:
            raise TargetError(f"target {target!r} is not a free point inside the tank box")
        return t

    @property
    def tip(self) -> NDArray[np.float64]:
        """The tip's position [cm]."""
        return self._tip.copy()

    def body(self, points_per_section: int = 10) -> NDArray[np.float64]:
        """Backbone points of the current posture [cm]."""
        return self._points(self._state, points_per_section)

    @property
    def posture(self) -> Posture:
        """The current joint variables."""
        s = self._state
        return Posture.from_vector(s)

    def _points(self, state: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        """Backbone samples of a state, ``k`` per section (compiled :func:`body_points`)."""
        out = np.empty((1, self.n * k + 1, 3))
        s = np.ascontiguousarray(state, dtype=np.float64)
        fk_points(s[:1], s[None, 1 : self.n + 1], s[None, self.n + 1 :], self.l, k, out)
        return out[0]

    def _collides(self, state: NDArray[np.float64], pts: NDArray[np.float64]) -> tuple[bool, float]:
        """Collision by python-fcl, skipped when sampled points are clearly far from the tank.

        Args:
            state: joint variables.
            pts: its body points, ``self._k`` per section.

        Returns:
            The verdict and a clearance estimate [cm] for the observation.

        """
        clear = self.arm.radius + self._margin
        if self.scene.far_from_everything(pts, clear):
            # Every backbone sample is more than radius + margin from every solid's bounds and the
            # walls; the panel rule still needs checking (it is not a distance).
            return bool(panel_violation(self.tank, pts[None])[0]), clear
        report = self.scene.check(Posture.from_vector(state))
        return report.collides, max(report.clearance_cm, 0.0)

    def _draw_target(self) -> NDArray[np.float64]:
        if self._free_targets:
            start = np.array([0.0, 0.0, self.start_height])
            return draw_targets([self.np_random], self.tank, self.target_region, 10.0, start)[0]
        lo, hi = self.target_region
        for _ in range(10_000):
            state = self._random_state()
            tip = self._points(state, 1)[-1]
            pts = self._points(state, self._k)
            if np.all(tip >= lo) and np.all(tip <= hi) and not self._collides(state, pts)[0]:
                return tip
        raise TargetError("no reachable target found in target_region; widen it")

    def _random_state(self) -> NDArray[np.float64]:
        rng = self.np_random
        theta = rng.uniform(-self.arm.theta_max, self.arm.theta_max, self.n) * rng.uniform(0, 1)
        phi = np.full(self.n, rng.uniform(-math.pi, math.pi)) + rng.normal(0, 0.3, self.n)
        dis = rng.uniform(-self.n * self.l * 0.6, -self.l * 0.1)
        return self._guide(np.concatenate([[dis], theta, phi]))

    def _guide(self, state: NDArray[np.float64]) -> NDArray[np.float64]:
        """Straighten the sections still inside the guide (ending below the floor)."""
        ends = state[0] + self.l * np.arange(1, self.n + 1)
        state[1 : self.n + 1][ends <= self.tank.panel.center[2]] = 0.0
        return state

    def _obs(self, clearance: float, pts: NDArray[np.float64]) -> NDArray[np.float32]:
        s = self._state
        theta, phi = s[1 : self.n + 1], s[self.n + 1 :]
        frames_z = pts[self._k :: self._k, 2]
        tip = self._tip
        diff = self.target - tip
        return np.concatenate(
            [
                [s[0] / self.l],
                theta / self.arm.theta_max,
                np.sin(phi),
                np.cos(phi),
                tip / 100,
                self.target / 100,
                diff / 100,
                [min(clearance, 10.0) / 10, np.linalg.norm(diff) / 100],
                np.sin(theta),
                np.cos(theta),
                frames_z / 100,
                np.minimum(np.maximum(diff / 10, -3.0), 3.0),
            ]
        ).astype(np.float32)

    # ------------------------------------------------------------------ Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Straighten the arm just inside the panel and set a target."""
        super().reset(seed=seed)
        options = options or {}
        unknown = sorted(set(options) - {"target"})
        if unknown:
            raise ValueError(f"unknown reset option {unknown[0]!r}; use 'target'")
        if options.get("target") is not None:
            self.target = self._check_target(options["target"])
        elif self.fixed_target is not None:
            self.target = self.fixed_target
        else:
            self.target = self._draw_target()
        self._state = np.zeros(1 + 2 * self.n)
        self._state[0] = self.start_height - self.n * self.l
        pts = self._points(self._state, self._k)
        self._tip = pts[-1]
        self._distance = float(np.linalg.norm(self.target - self._tip))
        self._tips = [self._tip.copy()]
        _, clearance = self._collides(self._state, pts)
        info = {"distance_cm": self._distance, "target": self.target.copy()}
        return self._obs(clearance, pts), info

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        """Apply a joint increment; see the class docstring for rewards and termination."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise InvalidActionError(
                f"invalid action of shape {a.shape}: expected {self.action_space.shape} finite "
                "values in [-1, 1]"
            )
        # np.minimum/np.maximum and min/max: np.clip's wrapper costs more than the step's maths
        a = np.minimum(np.maximum(a, -1.0), 1.0)
        s = self._state.copy()
        s[0] = min(max(s[0] + a[0] * self.dis_step, -self.n * self.l), 0.0)
        t_max = self.arm.theta_max
        s[1 : self.n + 1] = np.minimum(
            np.maximum(s[1 : self.n + 1] + a[1 : self.n + 1] * self.angle_step, -t_max), t_max
        )
        s[self.n + 1 :] = (s[self.n + 1 :] + a[self.n + 1 :] * self.angle_step + math.pi) % (
            2 * math.pi
        ) - math.pi
        s = self._guide(s)
        pts = self._points(s, self._k)
        collided, clearance = self._collides(s, pts)
        self._state = s
        self._tip = pts[-1]
        self._tips.append(self._tip.copy())
        distance = float(np.linalg.norm(self.target - self._tip))
        reward = (self._distance - distance) / 10.0
        self._distance = distance
        success = distance < self.success_tolerance and not collided
        if collided:
            reward -= 10.0
        elif success:
            reward += 10.0
        info = {"is_success": success, "collision": collided, "distance_cm": distance}
        return self._obs(clearance, pts), reward, bool(collided or success), False, info

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]
        """The tank, the arm, its tip path and the target (``rgb_array``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        if getattr(self, "_renderer", None) is None:  # kept: blitting, a few ms per frame
            from aftir_rl.viz.plotting import PathRenderer

            self._renderer = PathRenderer(self.tank, title="AFTIR-Arm")
        return self._renderer.render(
            np.array(self._tips), self.target, arms=[self._points(self._state, 10)]
        )
