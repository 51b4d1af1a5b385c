"""``AFTIR-ArmRoute-v0``: the follow-the-leader arm decided a route section at a time.

The decision level of the route planner: one action chooses the next route section among the
planner's moves (:func:`~aftir_rl.planning.ftl.route.move_set`: the last section's bend kept,
or changed by one of 3 sizes in 8 directions), and the env closes the route onto the target as
soon as the planner's closing can (:func:`~aftir_rl.planning.ftl.route.close_route`: the last
sections re-bent so that the tip ends on the target, the margin kept). The policy decides the
way through the tank; the closing places the tip. The arm follows the route exactly
(follow-the-leader); :meth:`ArmRouteEnv.motion` deploys the final route as the planner does
(:func:`~aftir_rl.planning.ftl.plan.deploy_route`) into a motion checked along its whole length.

Targets, tank and observation features are those of ``AFTIR-ArmFTL-v0`` (an inner
:class:`~aftir_rl.envs.ftl.env.ArmFTLEnv` with ``guide=True`` draws the targets with the same
seeds and computes the observation with the tip at the route's end), so the two decision
levels are compared on the same targets.
"""

from __future__ import annotations

from typing import Any, cast

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import InvalidActionError
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.planning.ftl.model import Route
from aftir_rl.planning.ftl.route import (
    RouteSettings,
    close_route,
    move_set,
    route_moves,
)

__all__ = ["ArmRouteEnv", "ROUTE_SETTINGS"]

#: The moves and clearance rule of the route env: the planner's first search setting, routes
#: that start on the floor (where the arm starts).
ROUTE_SETTINGS = RouteSettings(clearance_weight=1.0, change_weight=20.0, leads=(0.0,))

#: Distance-to-go [cm] shown for a move that is not clear (and the cap of the others).
_FAR = 1000.0


class ArmRouteEnv(gym.Env[NDArray[np.float32], np.int64]):
    """The arm's route chosen a section at a time, closed onto the target by the planner.

    ## Action Space

    ``Discrete(25)``: the next section's bend is the last one's plus move ``a`` of
    :func:`~aftir_rl.planning.ftl.route.move_set` (0: unchanged). :meth:`action_masks` says
    which moves keep the clearance (``radius + margin + slack`` from the tank, sampled along
    the section); a move that does not ends the episode in contact.

    ## Observation Space

    ``Box(-10, 10, float32)``: ``AFTIR-ArmFTL-v0``'s ``observation`` with ``guide=True`` and the
    tip at the route's end (the arm, the tip's pose, clearances, the way to the target), then
    for each of the 25 moves: whether it is clear, the distance-to-go through free space from
    its end (cm/100, 10 where it is not clear), whether the route would then close, and the
    share of moves clear after it (:func:`~aftir_rl.planning.ftl.route.route_moves` with ``ahead``).

    ## Episode End

    Terminated in success when the route closes onto the target (the tip on it, the margin
    kept), in contact when a move is not clear, at a dead end when no move is clear from the
    route's end (``info["dead_end"]``; the arm's sections used up included). Never truncated.

    ## Rewards

    ``+1`` on success, ``-1`` on contact or at a dead end, 0 otherwise.

    ## Arguments

    ``settings`` (:data:`ROUTE_SETTINGS`): the route search's knobs (moves, margin, slack);
    every other keyword argument goes to the inner ``AFTIR-ArmFTL-v0`` (``tank``, ``bay``,
    ``target``...).
    """

    metadata = {"render_modes": []}

    def __init__(self, settings: RouteSettings = ROUTE_SETTINGS, **kwargs: Any) -> None:
        self.inner = ArmFTLEnv(**{**kwargs, "guide": True, "steer": "target"})
        self.tank, self.arm = self.inner.tank, self.inner.tank.arm
        self.settings = settings
        self.moves = move_set(settings)
        n_moves = len(self.moves)
        inner_space = cast(gym.spaces.Dict, self.inner.observation_space)["observation"]
        n_obs = int(np.prod(inner_space.shape or (0,))) + 4 * n_moves  # (no observation yet)
        self.action_space = gym.spaces.Discrete(n_moves)
        self.observation_space = gym.spaces.Box(-10.0, 10.0, (n_obs,), np.float32)
        self.route = Route(0.0, np.zeros((0, 2)), self.arm.section_length)
        self.closed: tuple[Route, float] | None = None
        self._moves = route_moves(self.tank, self.route, np.zeros(3), settings)
        self._obs = np.zeros(n_obs, dtype=np.float32)

    @property
    def target(self) -> NDArray[np.float64]:
        """The episode's target [cm]."""
        return self.inner.target

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """A new target (drawn as ``AFTIR-ArmFTL-v0`` draws it), the route empty."""
        super().reset(seed=seed)
        _, info = self.inner.reset(seed=seed, options=options)
        self.route = Route(0.0, np.zeros((0, 2)), self.arm.section_length)
        self.closed = close_route(self.tank, self.route, self.target, self.settings)
        return self._observe(), {"target": info["target"]}

    def action_masks(self) -> NDArray[np.bool_]:
        """Which moves keep the clearance from here (sb3-contrib's ``MaskablePPO`` reads it)."""
        return self._moves.ok.copy()

    def step(
        self, action: int | np.integer[Any]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        """Add the section of move ``action``; close the route if the planner's closing can."""
        a = int(action)
        if not 0 <= a < len(self.moves):
            raise InvalidActionError(f"action must be a move 0 to {len(self.moves) - 1}, got {a}")
        info: dict[str, Any] = {"is_success": False, "contact": False}
        if self.closed is not None:  # closable before any move (a target near the panel)
            info["is_success"] = True
            return self._observe(), 1.0, True, False, info
        if not self._moves.ok[a]:
            info["contact"] = True
            return self._observe(), -1.0, True, False, info
        kappa = np.vstack([self.route.kappa, self._moves.kappa[a][None]])
        self.route = Route(0.0, kappa, self.arm.section_length)
        self.closed = close_route(self.tank, self.route, self.target, self.settings)
        obs = self._observe()
        if self.closed is not None:
            info["is_success"] = True
            return obs, 1.0, True, False, info
        if not self._moves.ok.any():  # the arm used up, or no clear move from here
            info["dead_end"] = True
            return obs, -1.0, True, False, info
        return obs, 0.0, False, False, info

    def moves_kappa(self) -> NDArray[np.float64]:
        """The next section's ``κ`` ``(25, 2)`` [rad] per move from here (0 where not clear)."""
        return self._moves.kappa.copy()

    def observation(self) -> NDArray[np.float32]:
        """The observation of the route as it is (what the last reset or step returned)."""
        return self._obs.copy()

    def restore(self, route: Route) -> None:
        """Put the episode back at ``route`` (a route it passed through): for search over moves."""
        self.route = route
        self.closed = close_route(self.tank, route, self.target, self.settings)
        self._observe()

    def final_route(self) -> Route | None:
        """The closed route (the tip on the target), or None before success."""
        return None if self.closed is None else self.closed[0]

    def _observe(self) -> NDArray[np.float32]:
        """The inner env's observation with the tip at the route's end, then the moves."""
        b, k = self.inner.batch, self.route.n_route_sections
        n = b.kappa.shape[1]
        b.kappa[0] = 0.0
        b.kappa[0, :k] = self.route.kappa
        if k < n:
            b.kappa[0, k] = self.route.kappa[-1] if k else 0.0
        b.k[0], b.s[0] = min(k, n - 1), k * self.arm.section_length
        b.refresh()
        moves = route_moves(self.tank, self.route, self.target, self.settings, ahead=True)
        self._moves = moves
        togo = np.where(moves.ok, np.minimum(moves.togo, _FAR), _FAR) / 100.0
        inner = b.observation()[0]
        parts = [inner, moves.ok, togo, moves.closes, moves.onward]
        self._obs = np.concatenate(parts).astype(np.float32)
        return self._obs
