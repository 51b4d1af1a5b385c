"""One route policy for any tank: taught by the planner on a stream of generated wings.

Run from a checkout: ``python experiments/route_anytank.py --seeds 0 1 --json OUT.json``.
:func:`~aftir_rl.rl.route_policy.train_route_policy` clones a policy on ``AFTIR-ArmRoute-v1``
(``--env-id`` another version) with ``tank="wing:BAYS:FIRST+"`` (``--family round``:
``round:BAYS:FIRST+``; ``mix``: ``mix:FIRST+``, both families with 2 to 5 bays): a stream of
generated wings, ``--tank-episodes`` routes in each (targets anywhere in the wing), ``--tanks``
visits in all, with ``--replay P`` level replay
(:class:`~aftir_rl.rl.level_replay.LevelReplay`); the stream of seed ``s`` starts at wing
``10,000 + 100,000·s``. ``--policy`` evaluates a policy trained already (its weights, or the
folder ``aftir route train`` wrote: its config names the env's version). The policy is then
evaluated, greedily and best first within each of ``--budgets`` env steps
(:func:`~aftir_rl.rl.route_policy.route_success`), on tanks no training used:

- ``held_out_wings``: ``--wings`` generated 3-bay wings (seeds 900,000..), ``--wing-targets``
  targets each (reset seeds 3,000,000 + n·w..; 20 x 10 = 200 by default);
- ``held_out_round_wings``: ``--round-wings`` 3-bay wings of the round family (the same seeds
  and targets' seeds; 10 x 10 by default);
- ``b737``: the reference 737 tank, ``--eval`` targets anywhere in it and per bay (reset seeds
  3,000,000..): no 737-like tank is in the stream;
- ``suite``: every scene of ``aftir bench --suite`` with its own targets
  (:func:`~aftir_rl.experiments.suite.suite_targets`, ``--suite-targets`` per scene).

A success is a closed route whose motion keeps 1 cm along its whole length (python-fcl).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from functools import partial
from pathlib import Path
from typing import Any

import torch

from aftir_rl.envs.ftl.route_env import STREAM_TANK_EPISODES, route_env
from aftir_rl.envs.registration import ROUTE, ROUTE_IDS
from aftir_rl.experiments.bench import env_steps_per_second, machine_facts
from aftir_rl.experiments.suite import SCENES, scene_tanks, suite_targets
from aftir_rl.rl.level_replay import LevelReplay
from aftir_rl.rl.route_policy import (
    RoutePolicy,
    load_route_policy,
    route_success,
    save_route_policy,
    train_route_policy,
)

#: Held-out generated wings: seeds from here, none in any training stream.
HELD_OUT_WINGS = 900_000


def pooled(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Rows of equal weight per target, summed into one."""
    n = sum(r["targets"] for r in rows)
    least = [r["least_clearance_cm"] for r in rows if r["least_clearance_cm"] is not None]
    out: dict[str, Any] = {"targets": n}
    for key in rows[0]:
        if key == "greedy" or key.startswith("search_"):
            out[key] = round(sum(r[key] * r["targets"] for r in rows) / n, 4)
    out["least_clearance_cm"] = min(least) if least else None
    return out


def evaluate(policy: RoutePolicy, args: argparse.Namespace) -> dict[str, Any]:
    """The policy on the held-out wings, the 737 tank and the suite's scenes."""
    start = time.perf_counter()
    out: dict[str, Any] = {}
    rows = []
    n = args.wing_targets
    make = partial(route_env, args.env_id)  # the env of the policy's version

    for w in range(args.wings):
        env = make(tank=f"wing:3:{HELD_OUT_WINGS + w}")
        seeds = list(range(3_000_000 + n * w, 3_000_000 + n * (w + 1)))
        rows.append(route_success([env], policy, seeds, args.budgets))
    out["held_out_wings"] = pooled(rows)
    rows = []
    for w in range(args.round_wings):  # the round family: every way through a rib round
        env = make(tank=f"round:3:{HELD_OUT_WINGS + w}")
        seeds = list(range(3_000_000 + n * w, 3_000_000 + n * (w + 1)))
        rows.append(route_success([env], policy, seeds, args.budgets))
    if rows:
        out["held_out_round_wings"] = pooled(rows)
    seeds = list(range(3_000_000, 3_000_000 + args.eval))
    out["b737"] = route_success([make()], policy, seeds, args.budgets)
    for bay in (1, 2):
        out[f"b737_bay{bay}"] = route_success([make(bay=bay)], policy, seeds, args.budgets)
    with tempfile.TemporaryDirectory() as folder:
        for s, (name, tank) in enumerate(scene_tanks(Path(folder)).items()):
            spec = SCENES[name] if isinstance(SCENES[name], str) else tank.source
            targets = list(suite_targets(tank, args.suite_targets, seed=s))
            env = make(tank=str(spec))
            out[f"suite_{name}"] = route_success([env], policy, targets, args.budgets)
    out["seconds"] = round(time.perf_counter() - start, 1)
    return out


def run_seed(args: argparse.Namespace, seed: int) -> dict[str, Any]:
    """Train one seed on its stream (or load ``--policy``); its evaluation."""
    first = 10_000 + 100_000 * seed
    if args.policy:  # weights, or the folder aftir route train wrote (its config says how)
        folder = Path(args.policy)
        row = {"seed": seed, "policy": args.policy}
        if folder.is_dir():
            config = json.loads((folder / "config.json").read_text())
            args.env_id, kwargs = config["env_id"], config["env_kwargs"]
            episodes = kwargs.get("tank_episodes", STREAM_TANK_EPISODES)
            met = config.get("tanks_met") or -(-config["routes"] // episodes)
            row.update(stream=kwargs["tank"], wings_met=met, minutes=config["minutes"])
            row.update(config["rows"][-1])
            folder = folder / "route_policy.pt"
        row["eval"] = evaluate(load_route_policy(folder), args)
        print(json.dumps(row), flush=True)
        return row
    stream = f"mix:{first}+" if args.family == "mix" else f"{args.family}:{args.bays}:{first}+"
    env = route_env(args.env_id, tank=stream, tank_episodes=args.tank_episodes)
    start = time.perf_counter()
    policy, stats = train_route_policy(
        env,
        routes=args.tanks * args.tank_episodes,
        updates=args.updates,
        seed=seed,
        first_target_seed=10_000_000 + 100_000 * seed,
        level_replay=LevelReplay(replay=args.replay) if args.replay else None,
    )
    minutes = round((time.perf_counter() - start) / 60, 2)
    if args.save:
        save_route_policy(policy, f"{args.save}.seed{seed}.pt")
    row = {
        "seed": seed,
        "stream": stream,
        "wings_met": env.tanks_met,
        "minutes": minutes,
        **stats.rounds[-1],
    }
    row["eval"] = evaluate(policy, args)
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    """Train each seed on its stream, evaluate; print a JSON line per seed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--env-id", choices=ROUTE_IDS, default=ROUTE, help="the route env")
    parser.add_argument(
        "--family", choices=("wing", "round", "mix"), default="wing", help="the stream's wings"
    )
    parser.add_argument("--bays", type=int, default=3, help="bays of the stream's wings (not mix)")
    parser.add_argument(
        "--replay", type=float, default=0.0, help="level replay's probability (0: none)"
    )
    parser.add_argument("--tanks", type=int, default=400, help="wings met in training")
    parser.add_argument("--tank-episodes", type=int, default=5, help="routes in each wing")
    parser.add_argument("--updates", type=int, default=3000, help="batches of the fit")
    parser.add_argument("--wings", type=int, default=20, help="held-out wings")
    parser.add_argument("--wing-targets", type=int, default=10, help="targets per held-out wing")
    parser.add_argument(
        "--round-wings", type=int, default=10, help="held-out 3-bay wings of the round family"
    )
    parser.add_argument("--eval", type=int, default=200, help="targets in the 737 tank")
    parser.add_argument("--suite-targets", type=int, default=50, help="targets per scene")
    parser.add_argument(
        "--budgets", type=int, nargs="+", default=[100, 1000], help="env steps of the searches"
    )
    parser.add_argument("--json", help="where the runs go")
    parser.add_argument("--save", help="the policies' weights go to SAVE.seedN.pt")
    parser.add_argument(
        "--policy",
        help="evaluate these weights, or the folder aftir route train wrote, instead of "
        "training (one seed)",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    runs = []
    for seed in args.seeds:  # the yardstick beside each seed: they may run side by side
        lake = env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8", is_slippery=False)
        runs.append({**run_seed(args, seed), "frozenlake_8x8_steps_per_s": lake})
    if args.json:
        out = {
            "recipe": f"route policy cloned on {args.tanks} visits of {args.tank_episodes} routes "
            f"to streamed wings ({args.family}, {'2-5' if args.family == 'mix' else args.bays} "
            "bays)" + (f", level replay {args.replay}" if args.replay else ""),
            "env_id": args.env_id,
            "budgets": args.budgets,
            "machine": machine_facts(),
            "options": vars(args),
            "runs": runs,
        }
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
