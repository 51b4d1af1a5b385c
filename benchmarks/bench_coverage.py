"""Coverage tours of a bay: the share of its surface the tip camera sees, measured apart.

Run: ``python benchmarks/bench_coverage.py --goal 0.9 --bay 2 --seeds 1 2 3 --json OUT.json``.
For each seed, :func:`aftir_rl.planning.ftl.coverage.plan_coverage` picks viewpoints on a
lattice shifted by the seed and tours them (as ``aftir tour --coverage``); the tour is measured
by :func:`aftir_rl.experiments.coverage.measure_coverage` (ray casting on the tank's mesh, its
own surface samples) and re-checked by :func:`check_motion` (python-fcl, limits, time). Printed
per seed: viewpoints and candidates, the planner's estimate, the measured share, the tour's
duration, planning and measuring seconds, the least clearance and the check; then the machine.
"""

from __future__ import annotations

import argparse

from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.bench import write_results
from aftir_rl.experiments.coverage import measure_coverage
from aftir_rl.experiments.execution import check_tour
from aftir_rl.planning.ftl.coverage import plan_coverage


def main() -> None:
    """Plan, measure and check one coverage tour per seed; print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--goal", type=float, default=0.9, help="share of the surface to see")
    parser.add_argument("--bay", type=int, default=2, help="the bay, counted between baffles")
    parser.add_argument("--tank", default="b737_center", help="tank name or YAML")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="seeds")
    parser.add_argument("--json", help="write the rows here")
    args = parser.parse_args()
    tank = load_tank(args.tank)
    box = tank.bay(args.bay)
    print("| seed | viewpoints | candidates | estimate | measured | tour [s] | planned [s] | "
          "measured in [s] | clearance [cm] | check |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for seed in args.seeds:
        plan = plan_coverage(tank, box, args.goal, seed=seed)
        tour = plan.tour
        measured = measure_coverage(tank, tour.motion, box)
        problems = check_tour(tank, tour)
        row = {
            "seed": seed,
            **plan.report_json(),
            "measured": measured.to_json(),
            "duration_s": tour.duration,
            "min_clearance_cm": tour.min_clearance_cm,
            "check": problems[0] if problems else "ok",
        }
        rows.append(row)
        cells = [len(tour.order), f"{plan.planned}/{len(plan.candidates)}",
                 f"{100 * plan.estimate:.1f}%", f"{100 * measured.fraction:.1f}%",
                 f"{tour.duration:.0f}", f"{plan.seconds:.1f}", f"{measured.seconds:.1f}",
                 f"{tour.min_clearance_cm:.2f}", row["check"]]  # fmt: skip
        print(f"| {seed} | " + " | ".join(map(str, cells)) + " |", flush=True)
    write_results(args.json, args, rows)


if __name__ == "__main__":
    main()
