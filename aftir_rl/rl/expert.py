"""The follow-the-leader planner as a teacher of ``AFTIR-ArmFTL-v0``: its motions as env actions.

The env's arm traces a route of constant-curvature sections that start at the floor (a
:class:`~aftir_rl.planning.ftl.model.Route` with ``lead = 0``), each bent by the steered ``κ``
while the tip is in it. :func:`route_actions` turns such a route into the env's actions: pull
back to the floor, then for each route section steer at its start, where none of it is part of
the body yet, and push through it. :class:`FTLExpert` plans the route
(:func:`~aftir_rl.planning.ftl.route.plan_route`, lead 0, the search settings of
:func:`~aftir_rl.planning.ftl.plan.plan_motion`) and replays the actions in a copy of the env:
between stages the env's body interpolates its sections, which can graze what the planned route
clears, so the route's slack is raised until the env itself ends the episode in success and
python-fcl finds the margin kept at every step. Only such replayed motions are returned. A
route whose closing moved its start off the floor by up to ``max_lead`` is replayed as if it
started there (the motion is shifted along the panel's axis by that much; the replay judges it).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import ConfigError, PlanningError
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.envs.ftl.spec import MOTION_FREE_KWARGS
from aftir_rl.planning.ftl.model import Route
from aftir_rl.planning.ftl.plan import SEARCH_VARIANTS, warm_up
from aftir_rl.planning.ftl.route import RouteSettings, plan_route

__all__ = [
    "EXPERT_SETTINGS",
    "ExpertPlan",
    "ExpertPolicy",
    "FTLExpert",
    "MAX_LEAD",
    "SLACKS",
    "arm_state",
    "route_actions",
]

#: Extra route clearances [cm] tried in turn, for the env's deviation between stages.
SLACKS = (5.0, 8.0, 3.0, 1.5)
#: The largest start off the floor [cm] (a route's ``lead``) replayed from the floor.
MAX_LEAD = 1.0
#: The route searches tried in turn, each with every slack of :data:`SLACKS`: those of
#: :func:`~aftir_rl.planning.ftl.plan.plan_motion` (its slacks replaced), all starting on the
#: floor, where the env's arm starts.
EXPERT_SETTINGS: tuple[RouteSettings, ...] = tuple(
    dict.fromkeys(replace(v, slack=0.0, leads=(0.0,)) for v in SEARCH_VARIANTS)
)


#: What the env's arm is: the traced route's ``κ`` ``(k + 1, 2)``, the steered section ``k`` and
#: the tip's arc length ``s`` [cm].
ArmState = tuple[NDArray[np.float64], int, float]


def arm_state(env: ArmFTLEnv) -> ArmState:
    """The arm of a single ``AFTIR-ArmFTL-v0`` env (:data:`ArmState`), a copy."""
    return env.route_kappa, int(env.batch.k[0]), env.insertion


def _same_arm(a: ArmState, b: ArmState) -> bool:
    """Whether two arms are the same to 1e-9 (κ [rad], s [cm])."""
    return (
        a[1] == b[1]
        and abs(a[2] - b[2]) <= 1e-9
        and a[0].shape == b[0].shape
        and bool(np.allclose(a[0], b[0], rtol=0.0, atol=1e-9))
    )


def route_actions(
    kappa: ArrayLike,
    env: ArmFTLEnv,
    s0: float | None = None,
    steered: ArrayLike | None = None,
    back_to: float = 0.0,
) -> NDArray[np.float32]:
    """The actions ``(T, 3)`` that deploy the lead-0 route ``kappa`` ``(M, 2)`` in ``env``.

    From the tip's arc length ``s0`` and the steered ``κ`` ``steered`` (default: ``env``'s
    now): retract to the arc length ``back_to`` (the floor; or the end of the whole sections
    a continuation keeps, ``kappa`` then being the sections after them), then per route section
    bend the steered ``κ`` to the section's at its start (no push: the body does not change)
    and push through it. With
    ``steer="target"`` the steering actions name the section's bend, with ``"increment"`` they
    are the changes of ``κ`` (at most ``kappa_step`` per step and component, either way).
    """
    b = env.batch
    tmax, kstep, push, l = float(env.arm.theta_max), b.kappa_step, b.push_step, b.l
    s = float(b.s[0] if s0 is None else s0)
    cur = np.array(b.kappa[0, b.k[0]] if steered is None else steered, dtype=np.float64)
    by_target = b.steer == "target"
    acts: list[list[float]] = []
    hold = cur / tmax if by_target else np.zeros(2)
    while s > back_to + 1e-9:
        acts.append([hold[0], hold[1], -min(1.0, (s - back_to) / push)])
        s = max(back_to, s - push)
    pushes = round(l / push)
    if abs(pushes * push - l) > 1e-9:
        raise ConfigError(f"push_step must divide the section length {l:g} cm, got {push:g}")
    for kj in np.asarray(kappa, dtype=np.float64).reshape(-1, 2):
        while np.max(np.abs(kj - cur)) > 1e-9:
            delta = np.clip(kj - cur, -kstep, kstep)
            cur = cur + delta
            a = kj / tmax if by_target else delta / kstep
            acts.append([a[0], a[1], 0.0])
        a = kj / tmax if by_target else np.zeros(2)
        acts += [[a[0], a[1], 1.0]] * pushes
    return np.clip(np.array(acts, dtype=np.float32).reshape(-1, 3), -1.0, 1.0)


@dataclass
class ExpertPlan:
    """A motion the expert replayed to success: its actions and how they were found.

    Attributes:
        target: the target [cm].
        actions: ``(T, 3)``; the replay ends in success at the last one.
        route_kappa: the route's ``κ`` ``(M, 2)`` [rad].
        slack: the route's extra clearance [cm].
        min_clearance_cm: the least surface clearance of the replay [cm].
        seconds: planning and replay time [s].
        tries: routes planned and replayed.
        arms: the env's arm after each action of the replay (:func:`arm_state`).

    """

    target: NDArray[np.float64]
    actions: NDArray[np.float32]
    route_kappa: NDArray[np.float64]
    slack: float
    min_clearance_cm: float
    seconds: float
    tries: int
    arms: list[ArmState]


class FTLExpert:
    """Plans follow-the-leader motions that ``AFTIR-ArmFTL-v0`` replays to success.

    Args:
        max_seconds: planning budget per target [s].
        max_steps: the most actions a motion may take (the env truncates at 300).
        max_lead: routes that start up to this far off the floor [cm] are replayed from it
            (0: only routes that start on it).
        settings: the route searches tried in turn (default :data:`EXPERT_SETTINGS`).
        env_kwargs: the env's keyword arguments (those of the task: tank, steps, margin,
            steer...; the observation's and the reward's are ignored).

    """

    def __init__(
        self,
        max_seconds: float = 30.0,
        max_steps: int = 300,
        max_lead: float = MAX_LEAD,
        settings: tuple[RouteSettings, ...] = EXPERT_SETTINGS,
        **env_kwargs: Any,
    ):
        # what the policy sees or aims at and the reward do not move the arm: the replay drops them
        drop = (*MOTION_FREE_KWARGS, "render_mode")
        sim_kwargs = {k: v for k, v in env_kwargs.items() if k not in drop}
        self.sim = ArmFTLEnv(**sim_kwargs)
        self.max_seconds = float(max_seconds)
        self.max_steps = int(max_steps)
        if not 0.0 <= max_lead < math.inf:
            raise ConfigError(f"max_lead must be a length of 0 cm or more, got {max_lead!r}")
        self.max_lead = float(max_lead)
        self.settings = tuple(settings)
        self.scene = CollisionScene(self.sim.tank)

    def replay(
        self,
        target: ArrayLike,
        actions: NDArray[np.float32],
        state: ArmFTLEnv | None = None,
        arms: list[ArmState] | None = None,
    ) -> tuple[bool, int, float]:
        """Replay ``actions`` from the start (or from ``state``'s arm): success, steps, clearance.

        Success: the env's (the tip within tolerance, no contact) with python-fcl's surface
        clearance at least the margin after every step; the clearance returned is fcl's least.
        ``arms``, when given, gets the arm after each step (:func:`arm_state`).
        """
        sim, b = self.sim, self.sim.batch
        sim.reset(options={"target": np.asarray(target, dtype=np.float64)})
        if state is not None:
            src = state.batch
            b.kappa[0], b.k[0], b.s[0] = src.kappa[0], src.k[0], src.s[0]
            b.refresh()
        least = math.inf
        for t, a in enumerate(actions[: self.max_steps]):
            _, _, done, _, info = sim.step(a)
            if arms is not None:
                arms.append(arm_state(sim))
            least = min(least, self.scene.clearance(sim.posture))
            if least < b.margin:
                return False, t + 1, least
            if done:
                return bool(info["is_success"]), t + 1, least
        return False, min(len(actions), self.max_steps), least

    def plan(self, target: ArrayLike, state: ArmFTLEnv | None = None) -> ExpertPlan | None:
        """A motion to ``target`` that the env replays to success, or None within the budget.

        ``state``: an env whose arm the motion starts from (default: the start of an episode).
        The budget starts once the planner's kernels are compiled (:func:`warm_up`).
        """
        return self._search(target, state, 0)

    def continue_plan(self, target: ArrayLike, state: ArmFTLEnv) -> ExpertPlan | None:
        """A motion to ``target`` that keeps ``state``'s whole sections, or None.

        The online teacher: the arm of ``state`` has traced ``k`` whole route sections and is
        ``s − k·l`` into the next (:func:`arm_state`). The route search continues those ``k``
        sections (:func:`~aftir_rl.planning.ftl.route.plan_route` with them as its prefix, a
        search from one state instead of the whole tree), and the motion pulls back to the end
        of section ``k``, bends the steered section to the first new one and pushes on; it is
        replayed from ``state`` and kept only if that replay succeeds with the margin kept
        (python-fcl), as :meth:`plan`'s. With no whole section yet it is :meth:`plan`.
        """
        return self._search(target, state, arm_state(state)[1])

    def _search(self, target: ArrayLike, state: ArmFTLEnv | None, k: int) -> ExpertPlan | None:
        """The first motion the env replays to success, each setting and slack in turn.

        A route that keeps the first ``k`` sections of ``state``'s arm, deployed from the end
        of them (from the floor when ``k`` is 0) and replayed from ``state``.
        """
        tank, l = self.sim.tank, self.sim.batch.l
        warm_up(tank)
        start = time.perf_counter()
        target = np.asarray(target, dtype=np.float64)
        prefix = None if k == 0 or state is None else Route(0.0, arm_state(state)[0][:k], l)
        tries = 0
        for settings in self.settings:
            for slack in SLACKS:  # more slack while the env's deployment grazes
                left = self.max_seconds - (time.perf_counter() - start)
                if left <= 0:
                    return None
                knobs = replace(settings, slack=slack, max_seconds=min(left, 8.0))
                try:
                    found = plan_route(tank, target, None, knobs, tank.arm, prefix)
                except PlanningError:  # the search changes with the slack: the next may find one
                    continue
                if abs(found.route.lead) > self.max_lead + 1e-9:  # closing moved it too far
                    continue
                tries += 1
                origin = state if state is not None else self._start()
                actions = route_actions(found.route.kappa[k:], origin, back_to=k * l)
                arms: list[ArmState] = []
                ok, steps, least = self.replay(target, actions, state, arms)
                if ok:
                    return ExpertPlan(
                        target=target,
                        actions=actions[:steps],
                        route_kappa=found.route.kappa,
                        slack=slack,
                        min_clearance_cm=least,
                        seconds=time.perf_counter() - start,
                        tries=tries,
                        arms=arms,
                    )
        return None

    def _start(self) -> ArmFTLEnv:
        """The sim at the start of an episode (its arm as every episode starts)."""
        self.sim.batch.reset_rows(np.array([0]), self.sim.batch.target[:1])
        return self.sim


class ExpertPolicy:
    """The expert as the policy of one ``AFTIR-ArmFTL-v0`` env: plans, follows, recovers.

    It reads the target and the arm from ``env`` (a ``gym.make`` env or an :class:`ArmFTLEnv`).
    At an episode's first call (a new target) it plans from the arm as it is and plays the
    plan's actions, checking before each that the env's arm is where the plan's replay put it.
    When not (another action was taken, as a learner's in DAgger), it replans from the arm as it
    is: a route that keeps the arm's whole sections (:meth:`FTLExpert.continue_plan`), else one
    from the floor (pull back, deploy a new route: :meth:`FTLExpert.plan` with ``state``).
    When that finds nothing within the budget it falls back: it pulls the arm back to the floor
    and plans once more from there; when that fails too it holds the arm still. Call
    :meth:`reset` (or ``predict`` with ``episode_start``) when an episode starts.

    Args:
        env: the env the policy acts in.
        expert: the planner, made with the env's keyword arguments (default: one made from
            those ``gym.make`` recorded in ``env.spec``, with ``max_seconds``).
        max_seconds: planning budget per (re)plan [s], for the default expert.

    Raises:
        ConfigError: a pool of tanks, no ``expert`` for an env not made by ``gym.make``, or an
            expert whose tank, steering or steps are not the env's.

    """

    def __init__(
        self, env: gym.Env[Any, Any], expert: FTLExpert | None = None, max_seconds: float = 10.0
    ):
        if not isinstance(env.unwrapped, ArmFTLEnv):
            raise ConfigError(
                f"ExpertPolicy plays AFTIR-ArmFTL-v0, not {type(env.unwrapped).__name__}"
            )
        self.env: ArmFTLEnv = env.unwrapped
        if self.env.pool is not None:
            raise ConfigError("ExpertPolicy plays in one tank, not in a pool of tanks")
        if expert is None:
            if self.env.spec is None:
                raise ConfigError("ExpertPolicy: pass expert=FTLExpert(**the env's kwargs)")
            expert = FTLExpert(max_seconds=max_seconds, **self.env.spec.kwargs)
        mine, its = self.env.batch, expert.sim.batch
        same = (mine.steer, mine.kappa_step, mine.push_step, mine.l) == (
            its.steer,
            its.kappa_step,
            its.push_step,
            its.l,
        )
        if not same or expert.sim.tank != self.env.tank:
            raise ConfigError(
                "ExpertPolicy: the expert's tank, steering or steps are not the env's"
            )
        self.expert = expert
        #: Plans made after the first of an episode (the state had left the plan).
        self.replans = 0
        #: Calls that fell back to pulling the arm back (no plan from where the arm was).
        self.fallbacks = 0
        self._target: NDArray[np.float64] | None = None
        self._actions: NDArray[np.float32] = np.zeros((0, 3), np.float32)
        self._arms: list[ArmState] = []
        self._next = 0
        self._retreat = False
        self.reset()

    def predict(
        self,
        observation: Any = None,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[NDArray[np.float32], None]:
        """The next action, SB3's ``predict`` signature (the env is read, not ``observation``)."""
        if episode_start is not None and np.any(episode_start):
            self.reset()
        return self(), None

    def reset(self) -> None:
        """Forget the plan: the next call plans from the env's arm."""
        self._target, self._retreat = None, False
        self._actions, self._arms, self._next = np.zeros((0, 3), np.float32), [], 0

    def __call__(self) -> NDArray[np.float32]:
        """The next action for the env as it is now."""
        target, arm = self.env.target, arm_state(self.env)
        if self._target is None or not np.array_equal(target, self._target):
            self._target, self._retreat = target, False
            self._plan(target)
        elif not self._on_plan(arm):
            self.replans += 1
            self._plan(target)
        if self._next < len(self._actions):
            self._next += 1
            return self._actions[self._next - 1]
        if self._retreat and self.env.insertion <= 1e-9:  # back on the floor: one more plan
            self._retreat = False
            self._plan(target)
            if len(self._actions):
                self._next = 1
                return self._actions[0]
        if not self._retreat and self.env.insertion > 1e-9 and not len(self._actions):
            self.fallbacks += 1
            self._retreat = True
        return self._hold(-1.0 if self._retreat else 0.0)

    def _on_plan(self, arm: ArmState) -> bool:
        """Whether the arm is where the plan put it after the actions played so far."""
        return self._next == 0 or _same_arm(arm, self._arms[self._next - 1])

    def _plan(self, target: NDArray[np.float64]) -> None:
        """Plan from the env's arm; keep the actions and the arm the replay had after each.

        First as a continuation of the arm's whole sections (:meth:`FTLExpert.continue_plan`,
        tens of milliseconds), else from the floor (:meth:`FTLExpert.plan`).
        """
        self._actions, self._arms, self._next = np.zeros((0, 3), np.float32), [], 0
        plan = self.expert.continue_plan(target, self.env)
        if plan is None and arm_state(self.env)[1] > 0:
            plan = self.expert.plan(target, state=self.env)
        if plan is not None:
            self._actions, self._arms = plan.actions, plan.arms

    def _hold(self, push: float) -> NDArray[np.float32]:
        """Keep the steered bend, pushing ``push`` (-1: pull back a step, 0: hold)."""
        b = self.env.batch
        bend = b.kappa[0, b.k[0]] / float(self.env.arm.theta_max)
        steer = bend if b.steer == "target" else np.zeros(2)
        return np.clip(np.array([steer[0], steer[1], push], np.float32), -1.0, 1.0)
