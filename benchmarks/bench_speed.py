"""Follow-the-leader planning speed, side by side with a previous implementation, in one run.

    python benchmarks/bench_speed.py [--n N] [--seed S] [--baseline REV] [--batch B] [--out FILE]

The same targets (N random free targets per bay of the reference tank, at least 10 cm from
every surface, and the four reference targets) are planned by
:func:`aftir_rl.planning.ftl.plan.plan_motion` of this tree and of the git revision ``REV``
(checked out in a temporary worktree and run in a subprocess, one after the other, each after
one warm-up target so that compiling is not counted). Printed per set: completion, median, p90
and max seconds per target and their ratios, the median with the motion's time-optimal schedule
(which newer trees compute on demand), the smallest clearance, the largest tip error and the
FTL deviation of both. Then :func:`aftir_rl.planning.ftl.batch.plan_motions` over every
target (or ``B`` random bay-2 targets of seed ``S + 1``) with one process per core.
``--baseline none`` skips the comparison. ``--tsm REV`` adds TSM (the three-segment posture
method, 1 cm margin) on the reference targets and the bay-2 ones, best of three runs per target,
side by side with revision ``REV``. ``--learned N`` plans N random bay-2 targets (seed ``S + 2``)
and N drawn within 30 cm behind the baffle (seed ``S + 3``) along goal-conditioned Q-learning's
greedy cells, as ``q_table+ftl`` does, and prints how many are complete.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Run in a tree (this one or the baseline's) with the targets' JSON on stdin: prints one JSON
#: row per target.
WORKER = r"""
import json, sys, time
import numpy as np
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.plan import plan_motion
sets = json.load(sys.stdin)
tank = load_tank("b737_center")
plan_motion(tank, tank.targets[0]).timing  # compiles the kernels, imports toppra
out = {}
for name, targets in sets["sets"].items():
    rows = []
    for t in targets:
        start = time.perf_counter()
        p = plan_motion(tank, np.array(t))
        planned = time.perf_counter() - start
        p.timing  # the schedule: computed on demand in newer trees, already there in older ones
        rows.append({"seconds": planned, "timed": time.perf_counter() - start,
                     "complete": p.complete,
                     "clearance": p.min_clearance_cm, "tip_error": p.tip_error_cm,
                     "deviation": p.ftl_deviation_cm[0] if p.ftl_deviation_cm else None})
    out[name] = rows
print(json.dumps(out))
"""

#: :data:`WORKER` for TSM: the posture method, best of ``repeats`` runs per target.
TSM_WORKER = r"""
import json, sys, time
import numpy as np
from aftir_rl.core.errors import PlanningError
from aftir_rl.planning.posture.planner import Planner
sets = json.load(sys.stdin)
planner = Planner("b737_center")
planner.plan(np.array(sets["sets"]["reference"][0]), method="tsm")
out = {}
for name, targets in sets["sets"].items():
    rows = []
    for t in targets:
        best, r = float("inf"), None
        for _ in range(sets["repeats"]):
            start = time.perf_counter()
            try:
                r = planner.plan(np.array(t), method="tsm")
            except PlanningError:
                r = None
            best = min(best, time.perf_counter() - start)
        rows.append({"seconds": best, "complete": r is not None, "deviation": 0.0,
                     "clearance": r.clearance_cm if r else None,
                     "tip_error": r.error_cm if r else None})
    out[name] = rows
print(json.dumps(out))
"""


def _targets(n: int, seed: int) -> dict[str, list[list[float]]]:
    """The benchmark's target sets: the reference targets and ``n`` per bay."""
    from aftir_rl.core.tank import load_tank
    from aftir_rl.planning.posture.planner import Planner, random_free_targets

    tank = load_tank("b737_center")
    drawn = random_free_targets(Planner(tank), n, seed=seed, clearance=10.0)
    return {
        "reference": [list(map(float, t)) for t in tank.targets],
        "bay1": [list(map(float, t)) for t in drawn["bay1"]],
        "bay2": [list(map(float, t)) for t in drawn["bay2"]],
    }


def _run(
    tree: Path, sets: dict[str, list[list[float]]], worker: str = WORKER
) -> dict[str, list[dict]]:
    """Plan every target with the package of ``tree`` in a fresh single-threaded process."""
    env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1")
    payload = json.dumps({"sets": sets, "repeats": 3})
    done = subprocess.run(
        [sys.executable, "-c", worker], input=payload, capture_output=True, text=True,
        env=env, cwd=tree, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def _baseline(
    rev: str, sets: dict[str, list[list[float]]], worker: str = WORKER
) -> dict[str, list[dict]]:
    """:func:`_run` in a temporary worktree of ``rev``."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "baseline"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), rev],
            check=True, capture_output=True,
        )  # fmt: skip
        try:
            return _run(tree, sets, worker)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                check=False, capture_output=True,
            )  # fmt: skip


def _stats(rows: list[dict]) -> dict[str, float]:
    """Completion, time percentiles and the worst outcomes of one set."""
    secs = np.array([r["seconds"] for r in rows])
    ok = [r for r in rows if r["complete"]]
    return {
        "complete": len(ok),
        "n": len(rows),
        "median": float(np.median(secs)),
        "p90": float(np.percentile(secs, 90)),
        "max": float(secs.max()),
        "timed_median": float(np.median([r.get("timed", r["seconds"]) for r in rows])),
        "clearance": min((r["clearance"] for r in ok), default=float("nan")),
        "tip_error": max((r["tip_error"] for r in ok), default=float("nan")),
        "deviation": float(np.median([r["deviation"] for r in ok])) if ok else float("nan"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=20, help="random targets per bay (default 20)")
    parser.add_argument("--seed", type=int, default=21, help="seed of the random targets")
    parser.add_argument("--baseline", default="e156ea7", help="git revision to compare, or none")
    parser.add_argument(
        "--batch", type=int, default=0,
        help="plan_motions over this many random bay-2 targets (default: the sets' targets)",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, help="write the rows and the table's numbers here")
    parser.add_argument("--tsm", metavar="REV", help="also TSM's time, against revision REV")
    parser.add_argument(
        "--learned", type=int, default=0, metavar="N",
        help="also N bay-2 targets and N behind the baffle along Q-learning's cells",
    )  # fmt: skip
    args = parser.parse_args()
    sets = _targets(args.n, args.seed)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}; seed {args.seed}, {args.n} targets per bay, margin 1 cm\n"
    )
    runs = {"this tree": _run(ROOT, sets)}
    if args.baseline != "none":
        runs[args.baseline] = _baseline(args.baseline, sets)
    print(
        "| set | tree | complete | median s | p90 s | max s | median s with the schedule | "
        "min clearance (cm) | tip error max (cm) | FTL deviation max, median (cm) |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    table: dict[str, dict[str, dict[str, float]]] = {}
    for name in sets:
        for tree, rows in runs.items():
            s = table.setdefault(name, {})[tree] = _stats(rows[name])
            print(
                f"| {name} | {tree} | {s['complete']}/{s['n']} | {s['median']:.3f} | "
                f"{s['p90']:.3f} | {s['max']:.2f} | {s['timed_median']:.3f} | "
                f"{s['clearance']:.2f} | {s['tip_error']:.1e} | {s['deviation']:.2f} |"
            )
        if len(runs) == 2:
            new, old = (table[name][t] for t in runs)
            print(
                f"| {name} | ratio (old / new) | | {old['median'] / new['median']:.1f}× | "
                f"{old['p90'] / new['p90']:.1f}× | {old['max'] / new['max']:.1f}× | "
                f"{old['timed_median'] / new['timed_median']:.1f}× | | | |"
            )
    batch = _batch(sets, args.batch, args.seed)
    print(
        f"\nplan_motions, {os.cpu_count()} processes: {batch['n']} targets in "
        f"{batch['seconds']:.1f} s ({batch['per_minute']:.0f} a minute), "
        f"{batch['complete']} complete"
    )
    out = {"runs": runs, "table": table, "batch": batch}
    if args.tsm:
        out["tsm"] = _tsm(sets, args.tsm)
    if args.learned:
        out["learned"] = _learned(args.learned, args.seed)
    if args.out:
        args.out.write_text(json.dumps(out, indent=1))


def _tsm(sets: dict[str, list[list[float]]], rev: str) -> dict[str, dict[str, dict[str, float]]]:
    """TSM on the reference and bay-2 targets in this tree and ``rev``; print their table."""
    sets = {k: sets[k] for k in ("reference", "bay2")}
    runs = {"this tree": _run(ROOT, sets, TSM_WORKER), rev: _baseline(rev, sets, TSM_WORKER)}
    print("\nTSM (best of 3 runs per target, 1 cm margin):\n")
    print(
        "| set | tree | complete | median ms | max ms | min clearance (cm) | tip error max (cm) |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    table: dict[str, dict[str, dict[str, float]]] = {}
    for name in sets:
        for tree, rows in runs.items():
            t = table.setdefault(name, {})[tree] = _stats(rows[name])
            print(
                f"| {name} | {tree} | {t['complete']}/{t['n']} | {t['median'] * 1e3:.1f} | "
                f"{t['max'] * 1e3:.1f} | {t['clearance']:.2f} | {t['tip_error']:.1e} |"
            )
        new, old = (table[name][t] for t in runs)
        print(
            f"| {name} | ratio (old / new) | | {old['median'] / new['median']:.1f}× | "
            f"{old['max'] / new['max']:.1f}× | | |"
        )
    return table


def _learned(n: int, seed: int) -> dict[str, dict[str, float]]:
    """Motions along goal-conditioned Q-learning's greedy cells: bay 2 and behind the baffle."""
    from aftir_rl.core.errors import TargetError
    from aftir_rl.core.tank import load_tank
    from aftir_rl.experiments.suite import suite_targets
    from aftir_rl.planning.ftl.plan import plan_motion
    from aftir_rl.rl.tabular.q_table_goal import train_all_targets

    tank = load_tank("b737_center")
    agent, summary = train_all_targets(tank, seed=0)
    baffle = tank.baffle
    assert baffle is not None
    lo, hi = np.array(tank.box_min, dtype=float), np.array(tank.box_max, dtype=float)
    lo[baffle.index], hi[baffle.index] = baffle.position, baffle.position + 30.0
    drawn = {
        "bay2": np.array(_targets(n, seed + 2)["bay2"]),
        "behind the baffle": suite_targets(tank, n, seed=seed + 3, region=(lo, hi)),
    }
    print(f"\nAlong Q-learning's greedy cells ({summary['n_optimal']}/{summary['n_goals']} goals "
          "BFS-optimal):\n")  # fmt: skip
    print("| set | complete | with cells | whole-tank corridor | median s | p90 s | max s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    out = {}
    for name, targets in drawn.items():
        secs, done, with_cells, whole = [], 0, 0, 0
        for t in targets:
            try:  # an obstructed raster cell is no goal: planned without cells
                cells, reached = agent.greedy_path(agent.raster.point_to_cell(t))
            except TargetError:
                cells, reached = [], False
            plan = plan_motion(tank, t, cells if reached else None)
            secs.append(plan.seconds)
            done += plan.complete
            with_cells += reached
            whole += reached and plan.complete and plan.corridor != "learned path"
            if not plan.complete:
                print(f"  {name}: no motion to {np.round(t, 2).tolist()}: {plan.reason}")
        row = {"n": len(targets), "complete": done, "with_cells": with_cells, "whole": whole}
        row |= {k: float(f(secs)) for k, f in _PERCENTILES.items()}
        out[name] = row
        print(f"| {name} | {done}/{len(targets)} | {with_cells} | {whole} | {row['median']:.3f} "
              f"| {row['p90']:.3f} | {row['max']:.2f} |")  # fmt: skip
    return out


_PERCENTILES = {"median": np.median, "p90": lambda x: np.percentile(x, 90), "max": np.max}


def _batch(sets: dict[str, list[list[float]]], n: int, seed: int) -> dict[str, float]:
    """The sets' targets, or ``n`` random bay-2 ones, through :func:`plan_motions` (all cores)."""
    from aftir_rl.core.tank import load_tank
    from aftir_rl.planning.ftl.batch import plan_motions

    targets = np.array([t for rows in sets.values() for t in rows])
    if n:
        targets = np.array(_targets(n, seed + 1)["bay2"])
    start = time.perf_counter()
    plans = plan_motions(load_tank("b737_center"), targets, workers=0)
    seconds = time.perf_counter() - start
    return {
        "n": len(targets),
        "seconds": seconds,
        "per_minute": 60.0 * len(targets) / seconds,
        "complete": sum(p.complete for p in plans),
    }


if __name__ == "__main__":
    main()
