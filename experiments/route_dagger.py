"""DAgger at the route planner's decision level: ``ArmRouteEnv`` taught by the planner.

Run from a checkout: ``python experiments/route_dagger.py --seed 0 --json OUT.json`` (about 5
minutes on 2 cores with the defaults). A policy (a 2 x 256 MLP over the env's observation,
logits over the 25 moves, the unclear ones masked) is cloned from the planner's routes to
``--routes`` training targets, then ``--rounds`` DAgger rounds each roll it out to ``--routes``
new targets, label every state it visits with the planner's continuation of its route
(:func:`~aftir_rl.planning.ftl.route.plan_route` with the route as prefix; the label is the
clear move nearest the continuation's next section) and fit it again on everything so far.
After each round it is evaluated on ``--eval`` held-out bay-2 targets (the reset seeds
3,000,000.. that ``aftir evaluate --random N --seed 3000000`` uses), greedily and with
``--backtrack`` extra env steps of depth-first search over its own move order. The last
evaluation also deploys each closed route (:func:`~aftir_rl.planning.ftl.plan.deploy_route`)
and counts the motions that keep 1 cm along their whole length. Seeds: training targets
10,000,000 + 100,000·seed.., torch and the batch order from ``--seed``.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from aftir_rl.core.errors import PlanningError
from aftir_rl.envs.ftl.route_env import ROUTE_SETTINGS, ArmRouteEnv
from aftir_rl.experiments.bench import machine_facts
from aftir_rl.planning.ftl.route import plan_route
from aftir_rl.planning.ftl.search import MAIN_VARIANTS

#: The teacher's search settings, tried in turn from the route as it is.
TEACHERS = (ROUTE_SETTINGS, *MAIN_VARIANTS[1:4])


class Teacher:
    """The planner's next move from an env's route; counts queries and their time."""

    def __init__(self) -> None:
        self.queries, self.answered, self.seconds = 0, 0, 0.0

    def __call__(self, env: ArmRouteEnv) -> int | None:
        """The action the planner's continuation of ``env``'s route begins with, or None.

        Before the lead is chosen: the first lead (the planner's own first, then ``env.leads``
        in order) from which the teacher's moves, followed in ``env``, reach the target; after
        it, the clear move nearest the next section of the route continued from ``env``'s
        (its lead and sections kept).
        """
        if env.choosing:
            return self.lead(env)
        start = time.perf_counter()
        self.queries += 1
        k, ok = env.route.n_route_sections, env.action_masks()
        label = None
        for settings in TEACHERS if ok.any() else ():
            try:
                prefix = env.route if k else None
                settings = replace(settings, leads=(env.route.lead,))
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

    def lead(self, env: ArmRouteEnv) -> int | None:
        """The lead to choose: each tried by following the teacher from it (``env`` restored)."""
        start, first = time.perf_counter(), None
        self.queries += 1
        for settings in TEACHERS:
            try:
                route = plan_route(env.tank, env.target, None, replace(settings, leads=env.leads))
            except PlanningError:
                continue
            first = int(np.argmin(np.abs(np.array(env.leads) - route.route.lead)))
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

    def finishes(self, env: ArmRouteEnv) -> bool:
        """Whether the teacher's moves, followed from ``env``'s route, reach the target.

        The env is put back at its route after.
        """
        route, choosing = env.route, env.choosing
        success = False
        while True:
            move = self(env)
            if move is None:
                break
            _, _, terminated, _, info = env.step(move)
            if terminated:
                success = info["is_success"]
                break
        env.restore(route, choosing)
        return success


class Policy(nn.Module):
    """Logits over the moves from the observation; moves that are not clear masked out."""

    def __init__(self, n_in: int, n_out: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(n_in, 256), nn.Tanh(), nn.Linear(256, 256), nn.Tanh(), nn.Linear(256, n_out)
        )

    def forward(self, obs: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """The masked logits."""
        return self.net(obs).masked_fill(~mask, -1e9)

    def order(self, obs: np.ndarray, mask: np.ndarray) -> list[int]:
        """The clear moves, most likely first."""
        with torch.no_grad():
            z = self(torch.as_tensor(obs[None]), torch.as_tensor(mask[None]))[0].numpy()
        return [int(a) for a in np.argsort(-z, kind="stable") if mask[a]]


def collect(env: ArmRouteEnv, seed: int, teacher: Teacher, policy: Policy | None) -> list[Any]:
    """One episode's labelled states; the teacher's moves (no policy) or the policy's."""
    obs, _ = env.reset(seed=seed)
    rows = []
    while True:
        mask = env.action_masks()
        label = teacher(env)
        if label is not None:
            rows.append((obs, mask, label))
        move = label if policy is None else (policy.order(obs, mask) or [0])[0]
        if move is None:
            return rows
        obs, _, terminated, truncated, _ = env.step(move)
        if terminated or truncated:
            return rows


def fit(policy: Policy, data: list[Any], updates: int, seed: int) -> float:
    """Cross-entropy on every labelled state so far, ``updates`` batches of 256; the accuracy."""
    obs, mask, label = (torch.as_tensor(np.array(col)) for col in zip(*data))
    opt = torch.optim.Adam(policy.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    for _ in range(max(1, updates * 256 // len(label))):
        perm = torch.randperm(len(label), generator=gen)
        for i in range(0, len(label), 256):
            j = perm[i : i + 256]
            loss = nn.functional.cross_entropy(policy(obs[j], mask[j]), label[j])
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        return float((policy(obs, mask).argmax(1) == label).float().mean())


def episode(env: ArmRouteEnv, policy: Policy, seed: int, backtrack: int) -> tuple[bool, int]:
    """The policy's route to a target: greedy, then depth-first over its move order."""
    env.reset(seed=seed)
    steps = 0

    def dfs() -> bool:
        nonlocal steps
        route, choosing = env.route, env.choosing
        obs, mask = env.observation(), env.action_masks()
        for move in policy.order(obs, mask):
            if steps >= env.arm.max_sections + 1 + backtrack:
                return False
            env.restore(route, choosing)
            _, _, terminated, truncated, info = env.step(move)
            steps += 1
            if info["is_success"]:
                return True
            if not (terminated or truncated) and dfs():
                return True
            if backtrack == 0:
                return False
        return False

    return dfs(), steps


def diagnose(env: ArmRouteEnv, policy: Policy, teacher: Teacher, seeds: list[int]) -> dict:
    """Where the greedy policy's failures go wrong, counted by decision.

    The first of its decisions after which the teacher, followed from there, no longer reaches
    the target (``lead``, ``section 1``...; ``start`` where it cannot from the empty route
    either), or ``at the end`` where it still could from the last route the policy left.
    """
    where: dict[str, int] = {}
    names = ["start", *(["lead"] if len(env.leads) > 1 else [])]
    for seed in seeds:
        env.reset(seed=seed)
        wrong, k = "at the end", 0
        while True:
            if not teacher.finishes(env):
                wrong = names[k] if k < len(names) else f"section {k - len(names) + 1}"
                break
            move = policy.order(env.observation(), env.action_masks())
            if not move:
                break
            _, _, terminated, _, _ = env.step(move[0])
            k += 1
            if terminated:
                break
        where[wrong] = where.get(wrong, 0) + 1
    return dict(sorted(where.items()))


def evaluate(env: ArmRouteEnv, policy: Policy, n: int, backtrack: int, deploy: bool) -> dict:
    """Success on the held-out targets; with ``deploy``, motions that keep 1 cm too."""
    reached, kept, steps, failed = 0, 0, [], []
    for i in range(n):
        ok, used = episode(env, policy, 3_000_000 + i, backtrack)
        reached += ok
        steps.append(used)
        failed += [] if ok else [3_000_000 + i]
        if ok and deploy:
            plan = env.motion()
            assert plan is not None and plan.min_clearance_cm is not None
            kept += plan.complete and plan.min_clearance_cm >= 1.0
    out = {"success": reached / n, "steps_mean": float(np.mean(steps)), "failed": failed}
    return out | ({"motions_keeping_1cm": kept / n} if deploy else {})


def main() -> None:
    """Clone, run the DAgger rounds, evaluate each; print a JSON line per round."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--routes", type=int, default=150, help="training targets per round")
    parser.add_argument("--rounds", type=int, default=2, help="DAgger rounds after cloning")
    parser.add_argument("--updates", type=int, default=3000, help="batches per fit")
    parser.add_argument("--eval", type=int, default=200, help="held-out targets")
    parser.add_argument("--backtrack", type=int, default=20, help="extra steps of search")
    parser.add_argument("--json", help="where the rounds go")
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    env, teacher = ArmRouteEnv(bay=2), Teacher()
    policy = Policy(env.observation_space.shape[0], int(env.action_space.n))
    start, data, rounds = time.perf_counter(), [], []
    first = 10_000_000 + 100_000 * args.seed
    for r in range(args.rounds + 1):
        learner = policy if r else None  # round 0: the teacher's own routes
        for i in range(args.routes):
            data += collect(env, first + r * args.routes + i, teacher, learner)
        accuracy = fit(policy, data, args.updates, args.seed + r)
        trained = time.perf_counter() - start
        last = r == args.rounds
        row = {
            "round": r,
            "states": len(data),
            "train_accuracy": round(accuracy, 3),
            "minutes": round(trained / 60, 2),
            "teacher": {
                "queries": teacher.queries,
                "answered": teacher.answered,
                "seconds": round(teacher.seconds, 1),
            },  # fmt: skip
            "greedy": evaluate(env, policy, args.eval, 0, last),
        }
        if last:
            row["backtrack"] = evaluate(env, policy, args.eval, args.backtrack, True)
            row["greedy_failures_go_wrong_at"] = diagnose(
                env, policy, Teacher(), row["greedy"]["failed"]
            )
        rounds.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "failed"}), flush=True)
    if args.json:
        out = {"machine": machine_facts(), "options": vars(args), "rounds": rounds}
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
