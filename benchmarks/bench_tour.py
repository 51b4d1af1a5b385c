"""Inspection tours of random bay-2 targets: the tour's duration against one deployment each.

Run: ``python benchmarks/bench_tour.py --targets 20 --seeds 1 2 3 --json OUT.json``. For each
seed, ``--targets`` random bay-2 targets at least 10 cm from every surface (as ``aftir tour
--random N --bay 2 --seed S`` draws them) are toured by :func:`aftir_rl.planning.ftl.tour.plan_tour`
with the default actuator limits; the tour is re-checked by :func:`check_motion` (python-fcl,
limits, time). Printed per seed: targets reached, routes of their own, targets visited by side
trips, the tour's duration, that of one deployment and retraction per target (the same routes),
their ratio, planning seconds, the least clearance and the check; then the machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.bench import write_results
from aftir_rl.experiments.execution import check_tour
from aftir_rl.planning.ftl.tour import plan_tour
from aftir_rl.planning.posture.context import random_free_targets
from aftir_rl.planning.posture.planner import Planner


def main() -> None:
    """Plan, check and measure one tour per seed; print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--targets", type=int, default=20, help="targets per tour")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="seeds")
    parser.add_argument("--json", help="where the rows go")
    args = parser.parse_args()
    tank = load_tank("b737_center")
    rows = []
    print("| seed | reached | own routes | side trips | tour [s] | separate [s] | ratio | "
          "planned [s] | clearance [cm] | check |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for seed in args.seeds:
        targets = random_free_targets(Planner(tank), args.targets, seed, clearance=10.0)["bay2"]
        start = time.perf_counter()
        tour = plan_tour(tank, np.array(targets))
        seconds = time.perf_counter() - start
        problems = check_tour(tank, tour)
        row = {
            "seed": seed,
            "reached": len(tour.order),
            "own_routes": sum(i is None for i, _ in tour.branches.values()),
            "side_trips": len(tour.side_trips),
            "duration_s": tour.duration,
            "separate_s": tour.separate_s,
            "ratio": tour.duration / tour.separate_s,
            "seconds": seconds,
            "min_clearance_cm": tour.min_clearance_cm,
            "entries": len(tour.timing.t),
            "check": problems[0] if problems else "ok",
            "failures": [{"target": i, "reason": r} for i, r in tour.failures],
        }
        rows.append(row)
        cells = [f"{row['reached']}/{args.targets}", row["own_routes"], row["side_trips"],
                 f"{tour.duration:.0f}",
                 f"{tour.separate_s:.0f}", f"{row['ratio']:.2f}", f"{seconds:.1f}",
                 f"{tour.min_clearance_cm:.2f}", row["check"]]  # fmt: skip
        print(f"| {seed} | " + " | ".join(map(str, cells)) + " |", flush=True)
    write_results(args.json, args, rows)


if __name__ == "__main__":
    main()
