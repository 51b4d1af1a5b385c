"""The card of a route policy folder (``aftir route train`` wrote it): held-out success, measured.

``python benchmarks/route_card.py aftir_rl/rl/policies/route-bay2 --name route-bay2 --targets 500
--seed 4000000`` evaluates the folder's policy on ``--targets`` targets of its bay (reset seeds
``--seed``.., which no training, validation or journal evaluation used), greedily and best first
within ``--budget`` env steps, and the four reference corners (bay 2); every success is a
closed route whose motion keeps 1 cm along its whole length (python-fcl). Writes
``card.json`` beside the policy (``--dry-run``: prints it only).

A policy trained on generated wings (its config names a pool or a stream) is tested in tanks
none of its training used: ``--wings`` generated 3-bay wings from seed ``--wing-seed`` with
``--targets`` targets in all (each wing its share, reset seeds ``--seed``..), as many of the
round family (the same seeds), and ``--targets`` targets anywhere in the reference 737 tank.
"""

from __future__ import annotations

import argparse
import json
import time
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aftir_rl.cli.route import POLICY_FILE
from aftir_rl.core.files import read_json, write_json
from aftir_rl.envs.ftl.route_env import ArmRouteEnv, route_env
from aftir_rl.experiments.bench import machine_facts
from aftir_rl.rl.route_policy import RoutePolicy, load_route_policy, route_search

CORNERS = ((230.0, 140.0, 90.0), (-50.0, 140.0, 10.0), (-50.0, 72.0, 90.0), (230.0, 72.0, 10.0))


def measure(
    envs: list[ArmRouteEnv], policy: RoutePolicy, seeds: range, budget: int
) -> dict[str, Any]:
    """Success, steps, least clearance and time on the targets of ``seeds``.

    Target ``i`` is drawn in ``envs[i * len(envs) // len(seeds)]`` (one env: all of them).
    """
    start, hits, steps, least = time.perf_counter(), 0, [], np.inf
    for i, seed in enumerate(seeds):
        env = envs[i * len(envs) // len(seeds)]
        result = route_search(env, policy, seed, budget)
        hits += result.success
        steps.append(result.steps)
        plan = env.motion()
        if result.success and plan is not None and plan.min_clearance_cm is not None:
            least = min(least, plan.min_clearance_cm)
    return {
        "budget": budget,
        "success_rate": round(hits / len(seeds), 4),
        "steps_mean": round(float(np.mean(steps)), 2),
        "steps_max": int(np.max(steps)),
        "min_clearance_cm": round(float(least), 3),
        "seconds": round(time.perf_counter() - start, 1),
    }


def main() -> None:
    """Measure the folder's policy and write its card."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("folder")
    parser.add_argument("--name", required=True)
    parser.add_argument("--targets", type=int, default=500)
    parser.add_argument("--seed", type=int, default=4_000_000)
    parser.add_argument("--budget", type=int, default=100)
    parser.add_argument("--wings", type=int, default=20, help="held-out wings (wing policies)")
    parser.add_argument("--wing-seed", type=int, default=950_000, help="the first one's seed")
    parser.add_argument("--recipe", default="")
    parser.add_argument("--dry-run", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    folder = Path(args.folder)
    config = read_json(folder / "config.json", "route policy config")
    kwargs = config["env_kwargs"]
    make = partial(route_env, config["env_id"])  # the env of the policy's version
    policy = load_route_policy(folder / POLICY_FILE)
    seeds = range(args.seed, args.seed + args.targets)
    wings = "tank" in kwargs
    if wings:  # tested in unseen tanks: held-out wings, and the 737 tank it never met
        tests = {
            family: [make(tank=f"{kind}:3:{args.wing_seed + w}") for w in range(args.wings)]
            for family, kind in (("wings", "wing"), ("round_wings", "round"))
        }
        tests["b737"] = [make()]
    else:
        tests = {"bay": [make(bay=kwargs["bay"])]}
    card = {
        "name": args.name,
        "env_id": config["env_id"],
        "env_kwargs": config["env_kwargs"],
        "recipe": args.recipe,
        "seed": config["seed"],
        "training": {
            "routes": config["routes"],
            "rounds": config["rounds"],
            "states": config["rows"][-1]["states"],
            "teacher": config["rows"][-1]["teacher"],
            "minutes": config["minutes"],
        },
        "machine": machine_facts(),
    }
    for name, envs in tests.items():
        test: dict[str, Any] = {"targets": args.targets, "seed": args.seed}
        if name in ("wings", "round_wings"):
            kind = "wing" if name == "wings" else "round"
            test["tanks"] = f"{kind}:3:{args.wing_seed}-{args.wing_seed + args.wings - 1}"
        test["greedy"] = measure(envs, policy, seeds, 0)
        test["search"] = measure(envs, policy, seeds, args.budget)
        card["test" if name == "bay" else f"test_{name}"] = test
    env = tests["b737" if wings else "bay"][0]
    if kwargs.get("bay") == 2 or wings:
        card["corners"] = {
            str(c): route_search(env, policy, None, args.budget, np.array(c)).success
            for c in CORNERS
        }
    print(json.dumps(card, indent=1))
    if not args.dry_run:
        write_json(folder / "card.json", card)


if __name__ == "__main__":
    main()
