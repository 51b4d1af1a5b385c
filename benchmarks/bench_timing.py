"""Timed motions on the benchmark's target sets: does every planned motion pass ``aftir check``?

Run: ``python benchmarks/bench_timing.py --n-random 10 --seed 7 --json OUT.json``. The targets are
the benchmark's (``python -m aftir_rl.bench --sets bay1 bay2 filomat2018``: random targets 5 cm
from every surface on each side of the baffle, and the paper's four reference corners). Each is
planned by :func:`plan_motion` (timed with the default actuator limits) and re-checked by
:func:`check_motion` (time, limits, density, python-fcl clearance and the panel rule). Printed
per set: motions, checks passed, the motions' durations (median, max), the timing's share of the
planning time, and the machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.bench import target_sets, write_results
from aftir_rl.experiments.execution import TimedRun, check_motion
from aftir_rl.planning.ftl.plan import plan_motion


def main() -> None:
    """Plan, time and check every target; print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--n-random", type=int, default=10, help="random targets per bay")
    parser.add_argument("--seed", type=int, default=7, help="seed of the random targets")
    parser.add_argument("--json", help="where the rows go")
    args = parser.parse_args()
    tank = load_tank("b737_center")
    sets = target_sets(args.n_random, args.seed)
    rows = []
    print("| set | motions | check ok | duration median [s] | max [s] | timing [ms] median |")
    print("|---|---|---|---|---|---|")
    for name in ("filomat2018", "bay1", "bay2"):
        done = []
        for _, target in sets[name]:
            start = time.perf_counter()
            plan = plan_motion(tank, target)
            row = {"set": name, "target": target.tolist(), "complete": plan.complete}
            row["seconds"] = time.perf_counter() - start
            if plan.complete and plan.timing is not None and plan.motion is not None:
                m, timing = plan.motion, plan.timing
                run = TimedRun(m.dis, m.theta, m.phi, timing, plan.section_length, plan.margin_cm)
                problems = check_motion(run, tank)
                row.update(duration_s=timing.duration, timing_ms=timing.seconds * 1e3,
                           check=problems[0] if problems else "ok")  # fmt: skip
                done.append(row)
            rows.append(row)
        durations = [r["duration_s"] for r in done]
        ok = sum(r["check"] == "ok" for r in done)
        print(f"| {name} | {len(done)}/{len(sets[name])} | {ok}/{len(done)} | "
              f"{np.median(durations):.1f} | {max(durations):.1f} | "
              f"{np.median([r['timing_ms'] for r in done]):.0f} |", flush=True)  # fmt: skip
    write_results(args.json, args, rows)


if __name__ == "__main__":
    main()
