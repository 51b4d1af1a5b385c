"""``AFTIR-ArmRoute-v1``: the follow-the-leader arm decided a route section at a time.

The decision level of the route planner: the first action chooses the route's lead (how far the
arm travels straight above the floor, or bends inside the panel's guide, before its first
section), every later one the next route section among the planner's moves
(:func:`~aftir_rl.planning.ftl.route.move_set`: the last section's bend kept, or changed by one
of 3 sizes in 8 directions), and the env closes the route onto the target as
soon as the planner's closing can (:func:`~aftir_rl.planning.ftl.route.close_route`: the last
sections re-bent so that the tip ends on the target) and the closed route's motion keeps the
margin: the arm deployed along it as the planner deploys its own
(:func:`~aftir_rl.planning.ftl.plan.deploy_route`), checked by python-fcl along its whole length
(:meth:`ArmRouteEnv.motion`). The policy decides the way through the tank; the closing places
the tip.

Targets, tank and observation features are those of ``AFTIR-ArmFTL-v0`` (an inner
:class:`~aftir_rl.envs.ftl.env.ArmFTLEnv` with ``guide=True`` draws the targets with the same
seeds and computes the observation with the tip at the route's end), so the two decision
levels are compared on the same targets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, cast

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError, InvalidActionError
from aftir_rl.core.robot import body_points, forward_kinematics, kappa_to_angles
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.envs.ftl.pool import stream_spec
from aftir_rl.envs.registration import REGISTRATIONS, ROUTE, ROUTE_IDS
from aftir_rl.planning.ftl.model import Route
from aftir_rl.planning.ftl.plan import MotionPlan, deploy_route
from aftir_rl.planning.ftl.route import (
    RouteSettings,
    close_route,
    move_set,
    route_moves,
)

__all__ = [
    "ArmRouteEnv",
    "ROUTE_LEADS",
    "ROUTE_MAX_CHANGE",
    "ROUTE_SETTINGS",
    "STREAM_TANK_EPISODES",
    "route_env",
]

#: The largest change of ``κ`` between neighbouring sections [rad] of the env's moves: turns
#: as sharp as the planner's last resorts' first (its main searches change at most 0.75).
ROUTE_MAX_CHANGE = 1.0

#: The moves and clearance rule of the route env: the planner's first search setting with
#: :data:`ROUTE_MAX_CHANGE` (its ``leads`` are not used: the env's ``leads`` are the first
#: decision).
ROUTE_SETTINGS = RouteSettings(
    clearance_weight=1.0, change_weight=20.0, leads=(0.0,), max_change=ROUTE_MAX_CHANGE
)

#: The leads [cm] the first action chooses among: the route search's own and two deeper in
#: the panel's guide (those of its last resorts: the arm leaves the panel at a slant, for
#: targets low and beside it).
ROUTE_LEADS: tuple[float, ...] = (-40.0, -30.0, *RouteSettings().leads)

#: Episodes in each wing of a stream unless ``tank_episodes`` says otherwise.
STREAM_TANK_EPISODES = 5

#: Distance-to-go [cm] shown for a move that is not clear (and the cap of the others).
_FAR = 1000.0


class ArmRouteEnv(gym.Env[NDArray[np.float32], np.int64]):
    """The arm's route chosen a section at a time, closed onto the target by the planner.

    ## Action Space

    ``Discrete(25)``. The first action chooses the lead: action ``j`` is ``leads[j]`` (with one
    lead there is no such step). Every later action adds a section: its bend is the last one's
    plus move ``a`` of :func:`~aftir_rl.planning.ftl.route.move_set` (0: unchanged).
    :meth:`action_masks` says which actions are open: the leads at the first step, then the
    moves that keep the clearance (``radius + margin + slack`` from the tank, sampled along the
    section). A closed action ends the episode: a move that does not keep it in contact, an
    action past the leads at the first step with ``info["not_a_lead"]``.

    ## Observation Space

    ``Box(-10, 10, float32)``: ``AFTIR-ArmFTL-v0``'s ``observation`` with ``guide=True`` and the
    route's sections from the floor (the arm, the tip's pose, clearances, the way to the
    target; that env has no lead, so for a lead other than 0 these columns describe the same
    sections started on the floor); then 25 slots of 4 columns: at the first step, lead ``j``
    in slot ``j`` (whether any first section from it is clear, the least distance-to-go
    through free space from such a section's end (cm/100; 10 where none), whether choosing
    it closes the route, the share of first sections clear from it); after it, move ``a`` in
    slot ``a`` (whether it is clear, the distance-to-go from its end, whether the route would
    then close and the share of moves clear after it:
    :func:`~aftir_rl.planning.ftl.route.route_moves` with ``ahead``); then whether the lead
    is still to choose, the lead (cm/100) and the target from the route's true end (3, cm/100).

    ## Episode End

    Terminated in success when the route closes onto the target and its motion keeps the
    margin (python-fcl, :meth:`motion`), on a closed action (in contact when a move is not
    clear), at a dead end when no move is clear from the route's end (``info["dead_end"]``;
    the arm's sections used up included). Never truncated.

    ## Rewards

    ``+1`` on success, ``-1`` on a closed action or at a dead end, 0 otherwise.

    ## Arguments

    ``settings`` (:data:`ROUTE_SETTINGS`): the route search's knobs (moves, margin, slack;
    the motion keeps ``settings.margin``); ``max_change`` (None: ``settings.max_change``, 1.0
    rad): the largest move, the moves' changes being a third, two thirds and all of it;
    ``leads`` (:data:`ROUTE_LEADS`, at most 25): the first decision's choices, ``(0.0,)`` for
    none; ``render_mode`` (``"rgb_array"``: the tank,
    the arm along the route, the target); every other keyword argument goes to the inner
    ``AFTIR-ArmFTL-v0`` (``tank``, ``bay``, ``target``...). ``tank`` may be any one tank, a pool
    ``"wing:BAYS:FIRST-LAST"`` (a wing drawn per episode, ``reset(options={"tank": k})``) or a
    stream ``"wing:BAYS:FIRST+"``: every wing of ``BAYS`` bays from seed ``FIRST`` on (or
    ``"round:BAYS:FIRST+"``, the round-holed family, or ``"mix:FIRST+"``, both families with 2
    to 5 bays: :class:`~aftir_rl.envs.ftl.pool.TankStream`), each
    built when the episode after ``tank_episodes`` (:data:`STREAM_TANK_EPISODES`) ones in the
    last begins, so the same calls meet the same wings whatever the reset seeds. ``reset``'s
    ``info["tank"]`` names the episode's tank; the observation has the same columns in every
    tank (the guide's way through that tank among them).

    ## Version History

    - v1: leads of -40 and -30 cm as well, moves up to 1.0 rad (v0: 0.75); the same
      observation and action spaces. ``AFTIR-ArmRoute-v0`` is this class with v0's leads
      and moves (:func:`route_env` makes either).
    - v0: initial version.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(
        self,
        settings: RouteSettings = ROUTE_SETTINGS,
        leads: Sequence[float] = ROUTE_LEADS,
        render_mode: str | None = None,
        tank_episodes: int | None = None,
        max_change: float | None = None,
        **kwargs: Any,
    ) -> None:
        self.render_mode = render_mode
        self._renderer: Any = None
        #: The stream ``tank="FAMILY:BAYS:FIRST+"`` or ``"mix:FIRST+"``, or None.
        self.stream = stream_spec(kwargs.get("tank"))
        if tank_episodes is not None and not (
            self.stream is not None and isinstance(tank_episodes, int) and tank_episodes >= 1
        ):
            raise ConfigError(
                "tank_episodes is a stream's (tank='wing:BAYS:FIRST+' or 'mix:FIRST+'): a count "
                f"of at least 1, got {tank_episodes!r}"
            )
        #: Episodes in each of a stream's wings before the next reset takes the next wing.
        self.tank_episodes = tank_episodes or STREAM_TANK_EPISODES
        #: Wings of the stream met so far, and episodes begun in the last one.
        self.tanks_met, self._episodes = 0, 0
        self._kwargs = kwargs
        self._inner_kwargs = {**kwargs, "guide": True, "steer": "target"}
        if self.stream is not None:
            self._inner_kwargs["tank"] = self.stream.spec_at(0)
            self.tanks_met = 1
        self.inner = ArmFTLEnv(**self._inner_kwargs)
        self.tank, self.arm = self.inner.tank, self.inner.tank.arm
        if max_change is not None:
            if (
                isinstance(max_change, bool)
                or not isinstance(max_change, (int, float))
                or not (0 < max_change <= np.pi)
            ):
                raise ConfigError(f"max_change must be in (0, pi] rad, got {max_change!r}")
            settings = replace(settings, max_change=float(max_change))
        self.settings = settings
        self.moves = move_set(settings)
        n_moves = len(self.moves)
        self.leads = tuple(float(v) for v in leads)
        if not 1 <= len(self.leads) <= n_moves or not np.all(np.isfinite(self.leads)):
            raise ConfigError(f"leads must be 1 to {n_moves} finite numbers, got {leads!r}")
        inner_space = cast(gym.spaces.Dict, self.inner.observation_space)["observation"]
        n_obs = int(np.prod(inner_space.shape or (0,))) + 4 * n_moves + 5
        self.n_obs, self.n_actions = n_obs, n_moves
        self.action_space = gym.spaces.Discrete(n_moves)
        self.observation_space = gym.spaces.Box(-10.0, 10.0, (n_obs,), np.float32)
        self.route = self._empty(self.leads[0])
        self.choosing = len(self.leads) > 1
        self.closed: tuple[Route, float] | None = None
        self._plan: MotionPlan | None = None
        self._mask = np.zeros(n_moves, dtype=bool)
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
        if self.stream is not None and self._episodes >= self.tank_episodes:
            self._next_wing()
        self._episodes += 1
        _, info = self.inner.reset(seed=seed, options=options)
        if self.inner.tank is not self.tank:  # a pool's episode in another tank
            self.tank, self.arm, self._renderer = self.inner.tank, self.inner.tank.arm, None
        self.choosing = len(self.leads) > 1
        self._set(self._empty(self.leads[0]))
        return self._obs.copy(), {"target": info["target"], "tank": info["tank"]}

    def _next_wing(self) -> None:
        """Move a stream on to its next wing (built now; the last one is let go)."""
        assert self.stream is not None
        spec = self.stream.spec_at(self.tanks_met)
        self.inner.close()
        self.inner = ArmFTLEnv(**{**self._inner_kwargs, "tank": spec})
        self.tanks_met += 1
        self._episodes = 0

    def in_tank(self, tank: object) -> ArmRouteEnv:
        """The same env (settings, leads, bay...) in another ``tank``: a wing revisited."""
        return ArmRouteEnv(self.settings, self.leads, **{**self._kwargs, "tank": tank})

    def action_masks(self) -> NDArray[np.bool_]:
        """Which actions are open from here (sb3-contrib's ``MaskablePPO`` reads it)."""
        return self._mask.copy()

    def step(
        self, action: int | np.integer[Any]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        """Choose the lead, or add the section of move ``action``; close the route if it can."""
        a = int(action)
        if not 0 <= a < len(self.moves):
            raise InvalidActionError(f"action must be a move 0 to {len(self.moves) - 1}, got {a}")
        info: dict[str, Any] = {"is_success": False, "contact": False}
        if self.choosing:
            if a >= len(self.leads):  # closed, as a move that would touch is
                info["not_a_lead"] = True
                return self._obs.copy(), -1.0, True, False, info
            self.choosing = False
            self._set(self._empty(self.leads[a]))
        elif self.closed is not None:  # closable before any move (a target near the panel)
            info["is_success"] = True
            return self._obs.copy(), 1.0, True, False, info
        elif not self._moves.ok[a]:
            info["contact"] = True
            return self._obs.copy(), -1.0, True, False, info
        else:
            kappa = np.vstack([self.route.kappa, self._moves.kappa[a][None]])
            self._set(Route(self.route.lead, kappa, self.arm.section_length))
        if self.closed is not None:
            info["is_success"] = True
            return self._obs.copy(), 1.0, True, False, info
        if not self._moves.ok.any():  # the arm used up, or no clear move from here
            info["dead_end"] = True
            return self._obs.copy(), -1.0, True, False, info
        return self._obs.copy(), 0.0, False, False, info

    def moves_kappa(self) -> NDArray[np.float64]:
        """The next section's ``κ`` ``(25, 2)`` [rad] per move from here (0 where not clear)."""
        return self._moves.kappa.copy()

    def observation(self) -> NDArray[np.float32]:
        """The observation of the route as it is (what the last reset or step returned)."""
        return self._obs.copy()

    def restore(self, route: Route, choosing: bool = False) -> None:
        """Put the episode back at ``route`` (a route it passed through): for search over moves.

        ``choosing``: back before the lead was chosen (``route`` is then empty).
        """
        self.choosing = choosing and len(self.leads) > 1
        self._set(route)

    def final_route(self) -> Route | None:
        """The closed route (the tip on the target), or None before success."""
        return None if self.closed is None else self.closed[0]

    def motion(self) -> MotionPlan | None:
        """The closed route's motion, checked along its whole length, or None before success."""
        return self._plan if self.closed is not None else None

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]
        """The tank, the arm along the route (the closed one after success), the target."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        if self._renderer is None:
            from aftir_rl.viz.plotting import PathRenderer

            self._renderer = PathRenderer(self.tank, title="AFTIR-ArmRoute")
        route, l = self.final_route() or self.route, self.arm.section_length
        posture = route.final_posture(max(self.arm.max_sections, route.min_sections()))
        body = body_points(posture.dis, posture.theta, posture.phi, l, 10)
        ends = forward_kinematics(route.lead, *kappa_to_angles(route.kappa), l)[:, :3, 3]
        return self._renderer.render(ends, self.target, arms=[body])

    def _empty(self, lead: float) -> Route:
        return Route(lead, np.zeros((0, 2)), self.arm.section_length)

    def _close(self, route: Route) -> tuple[Route, float] | None:
        """``route`` closed onto the target with a motion that keeps the margin, or None."""
        closed = close_route(self.tank, route, self.target, self.settings)
        if closed is None:
            return None
        plan = deploy_route(self.tank, self.target, closed[0], self.settings.margin)
        if not plan.complete:
            return None
        self._plan = plan
        return closed

    def _set(self, route: Route) -> None:
        """Make ``route`` the episode's: its closing, moves, mask and observation."""
        self.route = route
        n_moves = len(self.moves)
        slots = np.zeros((4, n_moves))
        slots[1] = _FAR / 100.0
        if self.choosing:
            self.closed = None
            for j, lead in enumerate(self.leads):
                moves = route_moves(self.tank, self._empty(lead), self.target, self.settings)
                togo = float(np.min(moves.togo[moves.ok], initial=_FAR))
                closes = self._close(self._empty(lead)) is not None
                slots[:, j] = moves.ok.any(), min(togo, _FAR) / 100.0, closes, moves.ok.mean()
            self._mask = np.arange(n_moves) < len(self.leads)
            self._moves = route_moves(self.tank, route, self.target, self.settings)
        else:
            self.closed = self._close(route)
            moves = route_moves(self.tank, route, self.target, self.settings, ahead=True)
            far = np.where(moves.ok, np.minimum(moves.togo, _FAR), _FAR) / 100.0
            slots[:] = moves.ok, far, moves.closes, moves.onward
            self._moves, self._mask = moves, moves.ok.copy()
        b, k = self.inner.batch, route.n_route_sections
        n = b.kappa.shape[1]
        b.kappa[0] = 0.0
        b.kappa[0, :k] = route.kappa[:n]
        if k < n:
            b.kappa[0, k] = route.kappa[-1] if k else 0.0
        b.k[0], b.s[0] = min(k, n - 1), k * self.arm.section_length
        b.refresh()
        end = (self.target - route.tip()) / 100.0
        tail = [float(self.choosing), route.lead / 100.0, *end]
        parts = [b.observation()[0], slots.reshape(-1), tail]
        self._obs = np.clip(np.concatenate(parts), -10.0, 10.0).astype(np.float32)


def route_env(env_id: str = ROUTE, **kwargs: Any) -> ArmRouteEnv:
    """The route env registered as ``env_id`` (any of :data:`ROUTE_IDS`), unwrapped.

    ``kwargs`` (``tank``, ``bay``...) go to :class:`ArmRouteEnv` after the id's registered
    ones (v0's leads and moves): the env a policy of that version was taught in.

    Raises:
        ConfigError: ``env_id`` is not a version of the route env.

    """
    if env_id not in ROUTE_IDS:
        raise ConfigError(f"env_id must be one of {', '.join(ROUTE_IDS)}, got {env_id!r}")
    return ArmRouteEnv(**{**REGISTRATIONS[env_id].get("kwargs", {}), **kwargs})
