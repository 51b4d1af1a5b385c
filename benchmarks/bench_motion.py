"""Follow-the-leader motions along learned paths: completeness, time, clearance, FTL deviation.

    python benchmarks/bench_motion.py [--n N] [--seed S] [--margin CM]

Targets: the four reference targets and N random free targets per bay at least 10 cm from every
surface (targets in obstructed raster cells are skipped: the grid world cannot learn them). The
learned paths come from one goal-conditioned Q-learning run (every greedy path BFS-optimal).
Each motion is planned by :func:`aftir_rl.planning.ftl.plan.plan_motion` and re-checked here with
python-fcl capsules on every 4th entry and every stage.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder
from tqdm import tqdm

from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.plan import plan_motion
from aftir_rl.planning.posture.planner import Planner, random_free_targets
from aftir_rl.rl.tabular.q_table_goal import train_all_targets

QUICK = {"n": 3}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=20, help="random targets per bay (default 20)")
    parser.add_argument("--seed", type=int, default=21, help="seed of the random targets")
    parser.add_argument("--margin", type=float, default=1.0, help="clearance [cm] (default 1)")
    args = parse_args(parser, QUICK)
    tank = load_tank("b737_center")
    start = time.perf_counter()
    agent, _ = train_all_targets(tank=tank.name, seed=0)
    drawn = random_free_targets(Planner(tank), args.n, seed=args.seed, clearance=10.0)
    sets = {
        "reference": [np.array(t, float) for t in tank.targets],
        "bay1": drawn["bay1"],
        "bay2": drawn["bay2"],
    }
    scene = CollisionScene(tank)
    print_header(args, QUICK)
    print(
        f"machine: {platform.machine()}, Python {platform.python_version()}; seed {args.seed}, "
        f"margin {args.margin:g} cm\n"
    )
    print(
        "| set | targets | complete | median s | max s | min clearance, ours / fcl (cm) | "
        "FTL deviation max: worst / median (cm) | deviation mean, worst (cm) | tip error max (cm) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    misses = []
    for name, targets in sets.items():
        rows, skipped = [], 0
        for target in tqdm(targets, desc=name, leave=False):
            cell = tank.raster.point_to_cell(target)
            if tank.raster.obstructed[cell]:
                skipped += 1
                continue
            cells, _ = agent.greedy_path(cell)
            plan = plan_motion(tank, target, cells, margin=args.margin)
            fcl = np.nan
            if plan.complete:
                m = plan.motion
                picks = sorted(set(range(0, len(m), 4)) | set(m.stage_index) | {len(m) - 1})
                fcl = min(scene.clearance(m.posture(i)) for i in picks)
            else:
                misses.append((name, target.round(1).tolist(), plan.reason))
            rows.append((plan, fcl))
        ok = [(p, f) for p, f in rows if p.complete]
        secs = [p.seconds for p, _ in rows]
        dev = [p.ftl_deviation_cm for p, _ in ok]
        label = f"{len(rows)}" + (f" (+{skipped} in obstructed cells)" if skipped else "")
        print(
            f"| {name} | {label} | {len(ok)}/{len(rows)} | {np.median(secs):.2f} | "
            f"{max(secs):.2f} | {min(p.min_clearance_cm for p, _ in ok):.2f} / "
            f"{min(f for _, f in ok):.2f} | {max(d[0] for d in dev):.2f} / "
            f"{np.median([d[0] for d in dev]):.2f} | {max(d[1] for d in dev):.2f} | "
            f"{max(p.tip_error_cm for p, _ in ok):.1e} |"
        )
    print(f"\n{time.perf_counter() - start:.0f} s in all")
    for name, target, reason in misses:
        print(f"not complete ({name}) {target}: {reason}")


if __name__ == "__main__":
    main()
