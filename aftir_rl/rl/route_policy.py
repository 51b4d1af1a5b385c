"""Route policies for ``AFTIR-ArmRoute-v1``: taught by the planner, searched at inference.

The route env puts the learner where the route planner decides (the lead, then one route
section at a time, the planner's closing placing the tip). Here:

- :class:`RouteTeacher`, the planner as an online teacher for any route the env is at: the lead
  from which its moves reach the target (each lead tried by following it), and after the lead
  the clear move nearest the next section of the planner's continuation of the route
  (:func:`~aftir_rl.planning.ftl.route.plan_route` with the route as prefix, its lead and
  sections kept);
- :class:`RoutePolicy`, logits over the 25 actions from the env's observation, the closed ones
  masked;
- :func:`train_route_policy`: cloning from the teacher's own episodes, then DAgger rounds
  (the policy's episodes, each state it visits labelled by the teacher);
- :func:`route_search`: the policy at inference, greedily or best first over the cumulative
  log-probability of its choices within a budget of env steps (work, not time: the same
  routes under any load); :func:`route_success` its success over many targets.

Weights are kept as tensors only (:mod:`aftir_rl.rl.tensors`): :func:`save_route_policy`,
:func:`load_route_policy`.
"""

from __future__ import annotations

import heapq
import itertools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import CheckpointError, ConfigError, PlanningError
from aftir_rl.planning.ftl.route import RouteSettings, plan_route
from aftir_rl.planning.ftl.search import MAIN_VARIANTS
from aftir_rl.rl.level_replay import LevelReplay
from aftir_rl.rl.tensors import load_tensors, save_tensors

if TYPE_CHECKING:
    import torch

    from aftir_rl.envs.ftl.route_env import ArmRouteEnv

__all__ = [
    "TEACHER_SETTINGS",
    "RoutePolicy",
    "RouteTeacher",
    "SearchResult",
    "load_route_policy",
    "route_search",
    "route_success",
    "save_route_policy",
    "train_route_policy",
    "REPLAY_FIT_EVERY",
]

#: The planner's search settings the teacher tries after the env's own, in turn, from the
#: route as it is; each searches with the env's moves (its ``max_change``), so that the
#: section it plans next is one of them.
TEACHER_SETTINGS = MAIN_VARIANTS[1:4]


def _teacher_settings(env: ArmRouteEnv, leads: tuple[float, ...]) -> list[RouteSettings]:
    """The env's settings, then :data:`TEACHER_SETTINGS`, with the env's moves and ``leads``."""
    change = env.settings.max_change
    return [replace(v, max_change=change, leads=leads) for v in (env.settings, *TEACHER_SETTINGS)]


#: Width of the policy's two hidden layers.
HIDDEN = 256
#: The longest observation (and most actions) a saved policy may declare (the bay-2 env's: 192).
MAX_OBS = 4096


@dataclass
class RouteTeacher:
    """The planner's action for the route an env is at; counts its queries and their time."""

    queries: int = 0
    answered: int = 0
    seconds: float = 0.0

    def __call__(self, env: ArmRouteEnv) -> int | None:
        """The action that continues ``env``'s route to its target, or None where none does.

        Before the lead is chosen: the first lead (the planner's own choice first, then
        ``env.leads`` in order) from which the teacher's moves, followed in ``env``, reach the
        target. After it: the clear move nearest the next section of the planner's
        continuation of the route.
        """
        if env.choosing:
            return self._lead(env)
        start = time.perf_counter()
        self.queries += 1
        k, ok = env.route.n_route_sections, env.action_masks()
        label = None
        for settings in _teacher_settings(env, (env.route.lead,)) if ok.any() else []:
            try:
                prefix = env.route if k else None
                route = plan_route(env.tank, env.target, None, settings, env.arm, prefix).route
            except PlanningError:
                continue
            if route.n_route_sections > k:
                far = np.abs(env.moves_kappa() - route.kappa[k]).sum(axis=1)
                label = int(np.argmin(np.where(ok, far, np.inf)))
                self.answered += 1
                break
        self.seconds += time.perf_counter() - start
        return label

    def finishes(self, env: ArmRouteEnv) -> bool:
        """Whether the teacher's actions, followed from ``env``'s route, reach the target.

        The env is put back at its route after.
        """
        route, choosing = env.route, env.choosing
        success = False
        while True:
            action = self(env)
            if action is None:
                break
            _, _, terminated, _, info = env.step(action)
            if terminated:
                success = bool(info["is_success"])
                break
        env.restore(route, choosing)
        return success

    def _lead(self, env: ArmRouteEnv) -> int | None:
        start, first = time.perf_counter(), None
        self.queries += 1
        for settings in _teacher_settings(env, env.leads):
            try:
                found = plan_route(env.tank, env.target, None, settings)
            except PlanningError:
                continue
            first = int(np.argmin(np.abs(np.array(env.leads) - found.route.lead)))
            break
        self.seconds += time.perf_counter() - start
        order = ([first] if first is not None else []) + list(range(len(env.leads)))
        label, empty = None, env.route
        for j in dict.fromkeys(order):
            env.restore(empty, choosing=True)
            _, _, terminated, _, info = env.step(j)
            if info["is_success"] or (not terminated and self.finishes(env)):
                label = j
                break
        env.restore(empty, choosing=True)
        self.answered += label is not None
        return label if label is not None else first


def _network(n_in: int, n_out: int) -> torch.nn.Module:
    from torch import nn

    return nn.Sequential(
        nn.Linear(n_in, HIDDEN), nn.Tanh(), nn.Linear(HIDDEN, HIDDEN), nn.Tanh(),
        nn.Linear(HIDDEN, n_out),
    )  # fmt: skip


class RoutePolicy:
    """Logits over the route env's actions from its observation (2 x 256 tanh MLP, torch).

    Args:
        n_obs: the observation's length.
        n_actions: the actions (25).

    """

    def __init__(self, n_obs: int, n_actions: int) -> None:
        self.n_obs, self.n_actions = int(n_obs), int(n_actions)
        self.net = _network(self.n_obs, self.n_actions)

    def logits(self, obs: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """The masked logits of a batch (closed actions at -1e9)."""
        return self.net(obs).masked_fill(~mask, -1e9)

    def log_probs(self, obs: NDArray[np.float32], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
        """The log-probabilities of one observation's actions (closed ones about -1e9)."""
        import torch

        with torch.no_grad():
            z = self.logits(torch.as_tensor(obs[None]), torch.as_tensor(mask[None]))[0]
            return torch.log_softmax(z.double(), 0).numpy()

    def order(self, obs: NDArray[np.float32], mask: NDArray[np.bool_]) -> list[int]:
        """The open actions, most likely first."""
        z = self.log_probs(obs, mask)
        return [int(a) for a in np.argsort(-z, kind="stable") if mask[a]]


def collect(
    env: ArmRouteEnv, seed: int, teacher: RouteTeacher, policy: RoutePolicy | None
) -> list[tuple[NDArray[np.float32], NDArray[np.bool_], int]]:
    """One episode's states labelled by ``teacher``, acting by the teacher (no policy) or not.

    Returns:
        ``(observation, mask, label)`` per state the teacher answered.

    """
    obs, _ = env.reset(seed=seed)
    rows = []
    while True:
        mask = env.action_masks()
        label = teacher(env)
        if label is not None:
            rows.append((obs, mask, label))
        order = policy.order(obs, mask) if policy is not None else []
        action = label if policy is None else (order[0] if order else None)
        if action is None:
            return rows
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            return rows


def fit(policy: RoutePolicy, data: list[Any], updates: int, seed: int) -> float:
    """Cross-entropy on the labelled states, about ``updates`` batches of 256; the accuracy."""
    import torch
    from torch import nn

    obs, mask, label = (torch.as_tensor(np.array(col)) for col in zip(*data, strict=True))
    opt = torch.optim.Adam(policy.net.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    for _ in range(max(1, updates * 256 // len(label))):
        perm = torch.randperm(len(label), generator=gen)
        for i in range(0, len(label), 256):
            j = perm[i : i + 256]
            loss = nn.functional.cross_entropy(policy.logits(obs[j], mask[j]), label[j])
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        return float((policy.logits(obs, mask).argmax(1) == label).float().mean())


@dataclass
class TrainStats:
    """What :func:`train_route_policy` did, round by round."""

    rounds: list[dict[str, Any]] = field(default_factory=list)
    teacher: RouteTeacher = field(default_factory=RouteTeacher)
    #: Visits that replayed a wing met before (level replay).
    replays: int = 0


def train_route_policy(
    env: ArmRouteEnv,
    *,
    routes: int = 600,
    rounds: int = 0,
    updates: int = 3000,
    seed: int = 0,
    first_target_seed: int = 10_000_000,
    after_round: Any = None,
    on_route: Any = None,
    level_replay: LevelReplay | None = None,
) -> tuple[RoutePolicy, TrainStats]:
    """A route policy cloned from the teacher, then ``rounds`` DAgger rounds.

    Round 0 labels the teacher's own episodes to ``routes`` targets (reset seeds
    ``first_target_seed``..), every later round the policy's episodes to ``routes`` new ones;
    after each round the policy is fitted again on every labelled state so far.
    ``after_round(r, policy, row)`` is called after each (for evaluations; its time is left out
    of the rows' ``minutes``), ``on_route()`` after each episode (for a progress bar). Seeds:
    torch and the batch order from ``seed``.

    ``level_replay`` (an env on a stream only): round 0 goes wing by wing, ``tank_episodes``
    routes a visit, each in a new wing of the stream or, as
    :class:`~aftir_rl.rl.level_replay.LevelReplay` chooses, in one met before (new targets
    there); the policy is fitted every :data:`REPLAY_FIT_EVERY` routes (``updates / 10``
    batches) so that each visit can be scored by it.
    """
    import torch

    if routes < 1 or rounds < 0 or updates < 1:
        raise ConfigError("routes and updates must be at least 1 and rounds at least 0")
    torch.manual_seed(seed)
    policy = RoutePolicy(env.n_obs, env.n_actions)
    stats, data, start, aside = TrainStats(), [], time.perf_counter(), 0.0
    for r in range(rounds + 1):
        learner = policy if r else None  # round 0: the teacher's own routes
        if r == 0 and level_replay is not None:
            data = _replayed(env, policy, routes, updates, seed, first_target_seed, stats,
                             level_replay, on_route)  # fmt: skip
        for i in range(0 if r == 0 and level_replay is not None else routes):
            data += collect(env, first_target_seed + r * routes + i, stats.teacher, learner)
            if on_route is not None:
                on_route()
        accuracy = fit(policy, data, updates, seed + r)
        row = {
            "round": r,
            "states": len(data),
            "train_accuracy": round(accuracy, 3),
            "minutes": round((time.perf_counter() - start - aside) / 60, 2),
            "teacher": {
                "queries": stats.teacher.queries,
                "answered": stats.teacher.answered,
                "seconds": round(stats.teacher.seconds, 1),
            },  # fmt: skip
        }
        if r == 0 and level_replay is not None:
            row["replayed_visits"] = stats.replays
        stats.rounds.append(row)
        if after_round is not None:
            begun = time.perf_counter()
            after_round(r, policy, row)
            aside += time.perf_counter() - begun
    return policy, stats


#: Routes between the fits that score a level-replay run's visits.
REPLAY_FIT_EVERY = 100


def _replayed(
    env: ArmRouteEnv,
    policy: RoutePolicy,
    routes: int,
    updates: int,
    seed: int,
    first_target_seed: int,
    stats: TrainStats,
    plr: LevelReplay,
    on_route: Any,
) -> list[Any]:
    """Round 0 of :func:`train_route_policy` with level replay: the labelled states."""
    import torch

    if env.stream is None:
        raise ConfigError("level replay needs a stream of tanks: wing:BAYS:FIRST+ or mix:FIRST+")
    rng = np.random.default_rng([seed, 7])
    data: list[Any] = []
    i = 0
    while i < routes:
        name = plr.choose(rng)
        where = env if name is None else env.in_tank(name)
        visit: list[Any] = []
        for _ in range(min(env.tank_episodes, routes - i)):
            visit += collect(where, first_target_seed + i, stats.teacher, None)
            i += 1
            if on_route is not None:
                on_route()
            if i % REPLAY_FIT_EVERY == 0:
                fit(policy, data + visit, max(1, updates // 10), seed + i)
        if visit:
            obs, mask, label = (torch.as_tensor(np.array(c)) for c in zip(*visit, strict=True))
            with torch.no_grad():
                wrong = (policy.logits(obs, mask).argmax(1) != label).float().mean()
            plr.update(str(where.tank.source if name is None else name), float(wrong))
        stats.replays += name is not None
        data += visit
    return data


@dataclass
class SearchResult:
    """One target's search: whether a route closed (its motion keeping the margin); env steps."""

    success: bool
    steps: int


def route_search(
    env: ArmRouteEnv,
    policy: RoutePolicy,
    seed: int | None,
    budget: int,
    target: NDArray[np.float64] | None = None,
) -> SearchResult:
    """The policy's route to the target of reset ``seed`` (or to ``target``): greedy, or best first.

    ``budget`` 0: the policy's most likely action at every step, one episode. Otherwise best
    first over the cumulative log-probability of the actions taken, at most ``budget`` env
    steps in all: where the most likely route ends without success, the next tried is the one
    whose choices the policy found likeliest, wherever along the route it branches. On
    success the env holds the closed route and its motion (:meth:`~ArmRouteEnv.motion`).
    """
    env.reset(seed=seed, options=None if target is None else {"target": target})
    if budget <= 0:
        steps = 0
        while True:
            order = policy.order(env.observation(), env.action_masks())
            if not order:
                return SearchResult(False, steps)
            _, _, terminated, _, info = env.step(order[0])
            steps += 1
            if terminated:
                return SearchResult(bool(info["is_success"]), steps)
    heap: list[tuple[float, int, Any, bool, int]] = []
    tie = itertools.count()  # equal scores: the earlier branch first

    def branch(score: float) -> None:
        mask = env.action_masks()
        z = policy.log_probs(env.observation(), mask)
        for a in np.flatnonzero(mask):
            heapq.heappush(heap, (-(score + z[a]), next(tie), env.route, env.choosing, int(a)))

    steps = 0
    branch(0.0)
    while heap and steps < budget:
        neg, _, route, choosing, action = heapq.heappop(heap)
        if env.route is not route or env.choosing != choosing:
            env.restore(route, choosing)
        _, _, terminated, _, info = env.step(int(action))
        steps += 1
        if info["is_success"]:
            return SearchResult(True, steps)
        if not terminated:
            branch(-neg)
    return SearchResult(False, steps)


def route_success(
    envs: Sequence[ArmRouteEnv],
    policy: RoutePolicy,
    jobs: Sequence[Any],
    budgets: Sequence[int],
    on_search: Any = None,
) -> dict[str, Any]:
    """Greedy success, and best first within each of ``budgets``, of the policy on ``jobs``.

    ``jobs``: reset seeds, or targets [cm]; job ``i`` is played in ``envs[i·len(envs)/len(jobs)]``
    (one env: all of them). A success is a closed route whose motion keeps the margin; the
    least clearance is that of the largest budget's successes. ``on_search()`` after each.
    """
    out: dict[str, Any] = {"targets": len(jobs)}
    clearance: list[float] = []
    for steps in [0, *budgets]:
        reached, clearance = 0, []
        for i, job in enumerate(jobs):
            env = envs[i * len(envs) // len(jobs)]
            seed, target = (job, None) if isinstance(job, int) else (None, np.asarray(job))
            result = route_search(env, policy, seed, steps, target)
            reached += result.success
            plan = env.motion()
            if result.success and plan is not None and plan.min_clearance_cm is not None:
                clearance.append(plan.min_clearance_cm)
            if on_search is not None:
                on_search()
        out["greedy" if steps == 0 else f"search_{steps}"] = reached / len(jobs)
    out["least_clearance_cm"] = round(min(clearance), 3) if clearance else None
    return out


def save_route_policy(policy: RoutePolicy, path: str | Path) -> Path:
    """Write the policy's weights and sizes (tensors only), atomically."""
    state = {"n_obs": policy.n_obs, "n_actions": policy.n_actions, "net": policy.net.state_dict()}
    return save_tensors(state, Path(path))


def load_route_policy(path: str | Path) -> RoutePolicy:
    """A policy :func:`save_route_policy` wrote.

    Raises:
        CheckpointError: not such a file (nothing but tensors is read; the size is bounded).

    """
    state = load_tensors(path, "route policy's weights")
    try:
        n_obs, n_actions = int(state["n_obs"]), int(state["n_actions"])
        if not (1 <= n_obs <= MAX_OBS and 1 <= n_actions <= MAX_OBS):
            raise ValueError(f"sizes {n_obs} x {n_actions} out of range")
        policy = RoutePolicy(n_obs, n_actions)
        policy.net.load_state_dict(state["net"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"{path}: not a route policy's weights ({exc})") from None
    return policy
