"""Planned motions on a Cosserat rod under gravity: the margin the body keeps, and what restores it.

Run: ``python benchmarks/bench_physics.py --n-random 20 --seed 7 --json OUT.json``. The targets
are the four reference corners of bay 2 and ``--n-random`` random bay-2 targets of the
benchmark's sets (5 cm from every surface, ``python -m aftir_rl.bench --sets bay2``). Each is
planned (1 cm margin), timed, and re-run by :func:`simulate_motion` with the default body
(``RodProperties()``, docs/robot.md "Physics"). Per motion: the body's largest and mean distance
from the kinematic body, the tip's at the end, the least clearance of the kinematic and of the
simulated body, whether 1 cm held; the least stiffness (a factor on every default stiffness, from
a grid of powers of two) at which the simulated body keeps 1 cm; for a motion that loses the
margin, the margin it is planned again with (:func:`replan_for_physics`) and whether the new
motion keeps 1 cm on the rod. Below the table: the simulation's cost per second of motion and
the machine, with the FrozenLake 8x8 yardstick measured in the same run.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder

from aftir_rl.core.rod import RodProperties
from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.bench import env_steps_per_second, target_sets, write_results
from aftir_rl.experiments.execution import TimedRun
from aftir_rl.experiments.physics import replan_for_physics, simulate_motion
from aftir_rl.planning.ftl.plan import plan_motion

#: Stiffness factors tried, in order from the default outwards.
FACTORS = (1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
MARGIN = 1.0
#: make bench's quick set: the four corners and one random target, an instant every 4 s.
QUICK = {"n_random": 1, "every": 4.0}


def _motion(job: tuple[str, list[float], float]) -> dict[str, Any]:
    """Plan, simulate, find the stiffness needed and (if lost) re-plan one target."""
    name, target, every = job
    tank = load_tank("b737_center")
    plan = plan_motion(tank, target, margin=MARGIN)
    row: dict[str, Any] = {"set": name, "target": target, "complete": plan.complete}
    if not plan.complete or plan.motion is None or plan.timing is None:
        return row
    m = plan.motion
    run = TimedRun(m.dis, m.theta, m.phi, plan.timing, plan.section_length, plan.margin_cm)
    report = simulate_motion(run, tank, MARGIN, every, RodProperties())
    s = report.summary()
    row.update(
        duration_s=round(plan.timing.duration, 2),
        sections=int(m.theta.shape[1]),
        kinematic_cm=s["kinematic_least_clearance_cm"],
        physical_cm=s["least_clearance_cm"],
        held=s["margin_held"],
        deviation_max_cm=s["deviation_max_cm"],
        deviation_mean_cm=s["deviation_mean_cm"],
        tip_final_cm=s["tip_error_final_cm"],
        nearest=s["nearest"],
        unsettled=s["unsettled_snapshots"],
        snapshots=s["snapshots"],
        sim_seconds=round(report.seconds, 2),
        steps=report.settings["steps"],
    )
    held = {1.0: report.held}
    i = FACTORS.index(1.0)
    step = -1 if report.held else 1
    while 0 <= i + step < len(FACTORS):  # walk until the verdict flips
        i += step
        factor = FACTORS[i]
        held[factor] = simulate_motion(
            run, tank, MARGIN, every, RodProperties().scaled(factor)
        ).held
        if held[factor] != report.held:
            break
    holding = [f for f, ok in held.items() if ok]
    row["least_stiffness"] = min(holding) if holding else None
    if not report.held:
        try:
            _, again, margin = replan_for_physics(tank, target, report, MARGIN, every)
            row.update(replan_margin_cm=margin, replan_physical_cm=again.summary()[
                "least_clearance_cm"], replan_held=again.held)  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - a row says why
            row.update(replan_error=str(exc)[:200])
    return row


def main() -> None:
    """Simulate every target's motion; print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--n-random", type=int, default=20, help="random bay-2 targets")
    parser.add_argument("--seed", type=int, default=7, help="seed of the random targets")
    parser.add_argument("--every", type=float, default=1.0, help="seconds between instants")
    parser.add_argument("--workers", type=int, default=2, help="processes")
    parser.add_argument("--json", help="where the rows go")
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    tank = load_tank("b737_center")
    sets = target_sets(args.n_random, args.seed)
    jobs = [("reference", [float(v) for v in t], args.every) for t in tank.targets]
    jobs += [("bay2", target.tolist(), args.every) for _, target in sets["bay2"]]
    start = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(_motion, jobs))
    wall = time.perf_counter() - start
    print(
        "| set | target [cm] | sections | duration [s] | sag max [cm] | tip [cm] | kinematic "
        "[cm] | on the rod [cm] | 1 cm held | least stiffness | planned again with |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "held" not in r:
            print(f"| {r['set']} | {r['target']} | not planned |")
            continue
        again = "—"
        if not r["held"]:
            again = (f"{r['replan_margin_cm']:g} cm: {r['replan_physical_cm']:.2f} cm, "
                     f"{'held' if r['replan_held'] else 'lost'}" if "replan_held" in r
                     else r.get("replan_error", "?"))  # fmt: skip
        target = ", ".join(f"{v:.0f}" for v in r["target"])
        least = r["least_stiffness"]
        least = "—" if least is None else f"{'≤ ' if least == FACTORS[0] else ''}×{least:g}"
        held = "yes" if r["held"] else "no"
        print(
            f"| {r['set']} | ({target}) | {r['sections']} | {r['duration_s']:.0f} | "
            f"{r['deviation_max_cm']:.2f} | {r['tip_final_cm']:.2f} | {r['kinematic_cm']:.2f} "
            f"| {r['physical_cm']:.2f} | {held} | {least} | {again} |"
        )
    done = [r for r in rows if "held" in r]
    cost = sum(r["sim_seconds"] for r in done) / sum(r["duration_s"] for r in done)
    print(
        f"\n{sum(r['held'] for r in done)}/{len(done)} keep 1 cm on the rod with the default "
        f"body; sag max median {np.median([r['deviation_max_cm'] for r in done]):.2f} cm; "
        f"simulation {cost:.3f} s per second of motion at --every {args.every:g} "
        f"(median {np.median([r['sim_seconds'] for r in done]):.1f} s per motion); "
        f"unsettled instants {sum(r['unsettled'] for r in done)}; {wall:.0f} s in all on "
        f"{args.workers} processes"
    )
    yardstick = env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8", is_slippery=False)
    print(f"yardstick: FrozenLake 8x8 {yardstick:,.0f} steps/s")
    for r in rows:
        r["frozenlake_steps_per_s"] = round(yardstick)
    write_results(args.json, args, rows)


if __name__ == "__main__":
    main()
