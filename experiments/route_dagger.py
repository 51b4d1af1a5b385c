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
from aftir_rl.planning.ftl.plan import deploy_route
from aftir_rl.planning.ftl.route import plan_route
from aftir_rl.planning.ftl.search import MAIN_VARIANTS

#: The teacher's search settings, tried in turn from the route as it is (lead 0, as the env).
TEACHERS = (ROUTE_SETTINGS, *(replace(v, leads=(0.0,)) for v in MAIN_VARIANTS[1:4]))


class Teacher:
    """The planner's next move from an env's route; counts queries and their time."""

    def __init__(self) -> None:
        self.queries, self.answered, self.seconds = 0, 0, 0.0

    def __call__(self, env: ArmRouteEnv) -> int | None:
        """The move of ``env``'s route that the planner's continuation begins with, or None."""
        start = time.perf_counter()
        self.queries += 1
        k, ok = env.route.n_route_sections, env.action_masks()
        label = None
        for settings in TEACHERS if ok.any() else ():
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
        route, obs, mask = env.route, env.observation(), env.action_masks()
        for move in policy.order(obs, mask):
            if steps >= env.arm.max_sections + backtrack:
                return False
            env.restore(route)
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


def evaluate(env: ArmRouteEnv, policy: Policy, n: int, backtrack: int, deploy: bool) -> dict:
    """Success on the held-out targets; with ``deploy``, motions that keep 1 cm too."""
    reached, kept, steps = 0, 0, []
    for i in range(n):
        ok, used = episode(env, policy, 3_000_000 + i, backtrack)
        reached += ok
        steps.append(used)
        if ok and deploy:
            route = env.final_route()
            assert route is not None
            plan = deploy_route(env.tank, env.target, route)
            kept += plan.complete and plan.min_clearance_cm >= 1.0
    out = {"success": reached / n, "steps_mean": float(np.mean(steps))}
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
        rounds.append(row)
        print(json.dumps(row), flush=True)
    if args.json:
        out = {"machine": machine_facts(), "options": vars(args), "rounds": rounds}
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
