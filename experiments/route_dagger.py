"""A route policy at the planner's decision level: cloned, DAgger, searched at inference.

Run from a checkout: ``python experiments/route_dagger.py --seeds 0 1 2 --json OUT.json`` (about 6.5
minutes per seed in bay 2 on 2 cores with the defaults, 4.5 in bay 1).
:func:`~aftir_rl.rl.route_policy.train_route_policy` clones a policy (a 2 x 256 MLP over
``AFTIR-ArmRoute-v1``'s observation, ``--env-id`` another version; logits over its 25 actions, the
closed ones masked) from the planner's routes to ``--routes`` training targets, then runs
``--rounds`` DAgger rounds (each the policy's episodes to ``--routes`` new targets, every state
labelled by the planner's continuation). After each round the policy is evaluated on ``--eval``
held-out targets of the bay (reset seeds ``--eval-seed``.., the ones ``aftir evaluate --random N
--seed 3000000`` draws), greedily and best first within ``--budget`` env steps
(:func:`~aftir_rl.rl.route_policy.route_search`); a success is a closed route whose motion keeps 1
cm along its whole length (python-fcl). The last round also evaluates the four reference corners
(bay 2) and says where the greedy failures go wrong: the first decision after which the teacher,
followed from there, no longer reaches the target. Seeds: training targets 10,000,000 +
100,000·seed.., torch and the batch order from the seed.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aftir_rl.envs.ftl.route_env import ArmRouteEnv, route_env
from aftir_rl.envs.registration import ROUTE, ROUTE_IDS
from aftir_rl.experiments.bench import env_steps_per_second, machine_facts
from aftir_rl.rl.route_policy import (
    RoutePolicy,
    RouteTeacher,
    route_search,
    save_route_policy,
    train_route_policy,
)

#: The four reference targets, 10 cm inside the corners of bay 2 [cm].
CORNERS = ((230.0, 140.0, 90.0), (-50.0, 140.0, 10.0), (-50.0, 72.0, 90.0), (230.0, 72.0, 10.0))


def evaluate(env: ArmRouteEnv, policy: RoutePolicy, seeds: range, budget: int) -> dict[str, Any]:
    """Success on the targets of ``seeds``; the motions' least clearance; the failures."""
    start, reached, steps, clearance, failed = time.perf_counter(), 0, [], [], []
    for seed in seeds:
        result = route_search(env, policy, seed, budget)
        reached += result.success
        steps.append(result.steps)
        if result.success:
            plan = env.motion()
            assert plan is not None and plan.complete and plan.min_clearance_cm is not None
            clearance.append(plan.min_clearance_cm)
        else:
            failed.append(seed)
    return {
        "success": reached / len(seeds),
        "steps_mean": round(float(np.mean(steps)), 2),
        "steps_max": int(np.max(steps)),
        "least_clearance_cm": round(min(clearance), 3) if clearance else None,
        "seconds": round(time.perf_counter() - start, 1),
        "failed": failed,
    }


def diagnose(env: ArmRouteEnv, policy: RoutePolicy, seeds: list[int]) -> dict[str, int]:
    """Where the greedy policy's failures go wrong, counted by decision.

    The first of its decisions after which the teacher, followed from there, no longer reaches
    the target (``lead``, ``section 1``...; ``start`` where it cannot from the empty route
    either), or ``at the end`` where it still could from the last route the policy left.
    """
    teacher, where = RouteTeacher(), dict[str, int]()
    names = ["start", *(["lead"] if len(env.leads) > 1 else [])]
    for seed in seeds:
        env.reset(seed=seed)
        wrong, k = "at the end", 0
        while True:
            if not teacher.finishes(env):
                wrong = names[k] if k < len(names) else f"section {k - len(names) + 1}"
                break
            order = policy.order(env.observation(), env.action_masks())
            if not order:
                break
            _, _, terminated, _, _ = env.step(order[0])
            k += 1
            if terminated:
                break
        where[wrong] = where.get(wrong, 0) + 1
    return dict(sorted(where.items()))


def run_seed(args: argparse.Namespace, seed: int) -> dict[str, Any]:
    """Train one seed, evaluating each round; its rows."""
    env, rows = route_env(args.env_id, bay=args.bay), []
    held_out = range(args.eval_seed, args.eval_seed + args.eval)

    def after_round(r: int, policy: RoutePolicy, row: dict[str, Any]) -> None:
        row["greedy"] = evaluate(env, policy, held_out, 0)
        row["search"] = evaluate(env, policy, held_out, args.budget)
        if r == args.rounds:
            if args.bay == 2:
                row["corners"] = [
                    route_search(env, policy, None, args.budget, np.array(c)).success
                    for c in CORNERS
                ]
            row["greedy_failures_go_wrong_at"] = diagnose(env, policy, row["greedy"]["failed"])
            if args.save:
                save_route_policy(policy, f"{args.save}.seed{seed}.pt")
        rows.append(row)
        brief = {k: v for k, v in row.items() if k not in ("greedy", "search")}
        for k in ("greedy", "search"):
            brief[k] = {key: v for key, v in row[k].items() if key != "failed"}
        print(json.dumps({"seed": seed, **brief}), flush=True)

    train_route_policy(
        env,
        routes=args.routes,
        rounds=args.rounds,
        updates=args.updates,
        seed=seed,
        first_target_seed=10_000_000 + 100_000 * seed,
        after_round=after_round,
    )
    return {"seed": seed, "minutes": rows[-1]["minutes"], "rounds": rows}


def main() -> None:
    """Train each seed, evaluate each round; print a JSON line per round."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--env-id", choices=ROUTE_IDS, default=ROUTE, help="the route env")
    parser.add_argument("--bay", type=int, default=2, choices=(1, 2))
    parser.add_argument("--routes", type=int, default=600, help="training targets per round")
    parser.add_argument("--rounds", type=int, default=0, help="DAgger rounds after cloning")
    parser.add_argument("--updates", type=int, default=3000, help="batches per fit")
    parser.add_argument("--eval", type=int, default=500, help="held-out targets")
    parser.add_argument("--eval-seed", type=int, default=3_000_000, help="their first reset seed")
    parser.add_argument("--budget", type=int, default=100, help="env steps of the search")
    parser.add_argument("--json", help="where the runs go")
    parser.add_argument("--save", help="the policies' weights go to SAVE.seedN.pt")
    args = parser.parse_args()
    torch.set_num_threads(1)
    lake = env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8", is_slippery=False)
    runs = [run_seed(args, seed) for seed in args.seeds]
    if args.json:
        out = {
            "recipe": f"route policy, {args.routes} routes cloned, {args.rounds} DAgger rounds",
            "env_id": args.env_id,
            "bay": args.bay,
            "eval": {"targets": args.eval, "seed": args.eval_seed, "budget": args.budget},
            "machine": machine_facts(),
            "frozenlake_8x8_steps_per_s": lake,
            "options": vars(args),
            "runs": runs,
        }
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
