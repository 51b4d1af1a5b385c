"""The card of a route policy folder (``aftir route train`` wrote it): held-out success, measured.

``python benchmarks/route_card.py aftir_rl/rl/policies/route-bay2 --name route-bay2 --targets 500
--seed 4000000`` evaluates the folder's policy on ``--targets`` targets of its bay (reset seeds
``--seed``.., which no training, validation or journal evaluation used), greedily and best first
within ``--budget`` env steps, and the four reference corners (bay 2); every success is a
closed route whose motion keeps 1 cm along its whole length (python-fcl). Writes
``card.json`` beside the policy (``--dry-run``: prints it only).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aftir_rl.cli.route import POLICY_FILE
from aftir_rl.core.files import read_json, write_json
from aftir_rl.envs.ftl.route_env import ArmRouteEnv
from aftir_rl.experiments.bench import machine_facts
from aftir_rl.rl.route_policy import RoutePolicy, load_route_policy, route_search

CORNERS = ((230.0, 140.0, 90.0), (-50.0, 140.0, 10.0), (-50.0, 72.0, 90.0), (230.0, 72.0, 10.0))


def measure(env: ArmRouteEnv, policy: RoutePolicy, seeds: range, budget: int) -> dict[str, Any]:
    """Success, steps, least clearance and time on the targets of ``seeds``."""
    start, hits, steps, least = time.perf_counter(), 0, [], np.inf
    for seed in seeds:
        result = route_search(env, policy, seed, budget)
        hits += result.success
        steps.append(result.steps)
        plan = env.motion()
        if result.success and plan is not None and plan.min_clearance_cm is not None:
            least = min(least, plan.min_clearance_cm)
    return {
        "budget": budget,
        "success_rate": hits / len(seeds),
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
    parser.add_argument("--recipe", default="")
    parser.add_argument("--dry-run", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    folder = Path(args.folder)
    config = read_json(folder / "config.json", "route policy config")
    bay = config["env_kwargs"]["bay"]
    env, policy = ArmRouteEnv(bay=bay), load_route_policy(folder / POLICY_FILE)
    seeds = range(args.seed, args.seed + args.targets)
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
        "test": {
            "targets": args.targets,
            "seed": args.seed,
            "greedy": measure(env, policy, seeds, 0),
            "search": measure(env, policy, seeds, args.budget),
        },
        "machine": machine_facts(),
    }
    if bay == 2:
        card["corners"] = {
            str(c): route_search(env, policy, None, args.budget, np.array(c)).success
            for c in CORNERS
        }
    print(json.dumps(card, indent=1))
    if not args.dry_run:
        write_json(folder / "card.json", card)


if __name__ == "__main__":
    main()
