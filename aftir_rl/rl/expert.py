"""The follow-the-leader planner as a teacher of ``AFTIR-ArmFTL-v0``: its motions as env actions.

The env's arm traces a route of constant-curvature sections that start at the floor (a
:class:`~aftir_rl.planning.ftl.model.Route` with ``lead = 0``), each bent by the steered ``κ``
while the tip is in it. :func:`route_actions` turns such a route into the env's actions: pull
back to the floor, then for each route section steer at its start, where none of it is part of
the body yet, and push through it. :class:`FTLExpert` plans the route
(:func:`~aftir_rl.planning.ftl.route.plan_route`, lead 0, the main search variants of
:func:`~aftir_rl.planning.ftl.plan.plan_motion`) and replays the actions in a copy of the env:
between stages the env's body interpolates its sections, which can graze what the planned route
clears, so the route's slack is raised until the env itself ends the episode in success and
python-fcl finds the margin kept at every step. Only such replayed motions are returned.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.errors import ConfigError, PlanningError
from aftir_rl.envs.ftl.env import ArmFTLEnv
from aftir_rl.envs.ftl.spec import TRAINING_ONLY_KWARGS
from aftir_rl.planning.ftl.plan import MAIN_VARIANTS, warm_up
from aftir_rl.planning.ftl.route import plan_route

__all__ = ["ExpertPlan", "FTLExpert", "SLACKS", "route_actions"]

#: Extra route clearances [cm] tried in turn, for the env's deviation between stages.
SLACKS = (5.0, 8.0, 3.0, 1.5)
#: Env keyword arguments that change only the observation or the reward: the replay drops them.
_SIM_DROPS = ("guide", "near_goal", "shaping", "step_cost", "render_mode", "bay", "target")


def route_actions(
    kappa: ArrayLike,
    env: ArmFTLEnv,
    s0: float | None = None,
    steered: ArrayLike | None = None,
) -> NDArray[np.float32]:
    """The actions ``(T, 3)`` that deploy the lead-0 route ``kappa`` ``(M, 2)`` in ``env``.

    From the tip's arc length ``s0`` and the steered ``κ`` ``steered`` (default: ``env``'s
    now): retract to the floor, then per route section bend the steered ``κ`` to the section's
    at its start (no push: the body does not change) and push through it. With
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
    while s > 1e-9:
        acts.append([hold[0], hold[1], -1.0])
        s = max(0.0, s - push)
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

    """

    target: NDArray[np.float64]
    actions: NDArray[np.float32]
    route_kappa: NDArray[np.float64]
    slack: float
    min_clearance_cm: float
    seconds: float
    tries: int


class FTLExpert:
    """Plans follow-the-leader motions that ``AFTIR-ArmFTL-v0`` replays to success.

    Args:
        max_seconds: planning budget per target [s].
        max_steps: the most actions a motion may take (the env truncates at 300).
        env_kwargs: the env's keyword arguments (those of the task: tank, steps, margin,
            steer...; the observation's and the reward's are ignored).

    """

    def __init__(self, max_seconds: float = 30.0, max_steps: int = 300, **env_kwargs: Any):
        sim_kwargs = {
            k: v
            for k, v in env_kwargs.items()
            if k not in _SIM_DROPS and k not in TRAINING_ONLY_KWARGS
        }
        self.sim = ArmFTLEnv(**sim_kwargs)
        self.max_seconds = float(max_seconds)
        self.max_steps = int(max_steps)
        self.scene = CollisionScene(self.sim.tank)

    def replay(
        self, target: ArrayLike, actions: NDArray[np.float32], state: ArmFTLEnv | None = None
    ) -> tuple[bool, int, float]:
        """Replay ``actions`` from the start (or from ``state``'s arm): success, steps, clearance.

        Success: the env's (the tip within tolerance, no contact) with python-fcl's surface
        clearance at least the margin after every step; the clearance returned is fcl's least.
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
        tank = self.sim.tank
        warm_up(tank)
        start = time.perf_counter()
        target = np.asarray(target, dtype=np.float64)
        tries = 0
        # each setting once whatever its slack (the slacks below replace it); not the last
        # resorts: their deep leads are not the env's, and their wide beams cost a miss minutes
        for settings in dict.fromkeys(replace(v, slack=0.0) for v in MAIN_VARIANTS):
            for slack in SLACKS:  # more slack while the env's deployment grazes
                left = self.max_seconds - (time.perf_counter() - start)
                if left <= 0:
                    return None
                knobs = replace(settings, leads=(0.0,), slack=slack, max_seconds=min(left, 8.0))
                try:
                    found = plan_route(tank, target, None, knobs, tank.arm)
                except PlanningError:  # the search changes with the slack: the next may find one
                    continue
                if abs(found.route.lead) > 1e-9:  # a near closing moved it: not the env's
                    continue
                tries += 1
                origin = state if state is not None else self._start()
                actions = route_actions(found.route.kappa, origin)
                ok, steps, least = self.replay(target, actions, state)
                if ok:
                    return ExpertPlan(
                        target=target,
                        actions=actions[:steps],
                        route_kappa=found.route.kappa,
                        slack=slack,
                        min_clearance_cm=least,
                        seconds=time.perf_counter() - start,
                        tries=tries,
                    )
        return None

    def _start(self) -> ArmFTLEnv:
        """The sim at the start of an episode (its arm as every episode starts)."""
        self.sim.batch.reset_rows(np.array([0]), self.sim.batch.target[:1])
        return self.sim
