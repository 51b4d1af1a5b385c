"""The papers' posture chain (``q_table+postures``): compiled against numpy tip Jacobians, one run.

    python benchmarks/bench_chain.py [--sets bay1 bay2 filomat2018] [--n-random N] [--seed S]

The chain of :func:`aftir_rl.planning.posture.trajectory.plan_trajectory` moves each posture to
the next waypoint by damped least squares and repairs colliding postures in the null space of the
tip's Jacobian. That Jacobian is now :func:`aftir_rl.core.kernel.sections.joint_tip_jacobian`
(one compiled loop); before, numpy's :func:`aftir_rl.core.robot.tip_jacobian`. On the benchmark's
target sets (``python -m aftir_rl.bench``: the same seed and count), each target is planned by
both, one after the other, after Q-learning's greedy cells (learned once per target, not timed).
Bridges (RRT-Connect for moves that still collide) are off: they spend a fixed budget. Printed
per set: the chain's median and total seconds per target for both, the ratio, and whether every
outcome (completion, colliding moves, tip error, clearance, path length) agrees: the
counts exactly, the lengths to 1e-6 of their size.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from aftir_rl.core.config import CONFIG_DIR
from aftir_rl.core.errors import AftirError
from aftir_rl.core.robot import tip_jacobian
from aftir_rl.experiments.bench import machine_facts, target_sets
from aftir_rl.experiments.outcomes import Planners
from aftir_rl.experiments.runs import load_q_table_config
from aftir_rl.planning.posture import continuation
from aftir_rl.planning.posture.trajectory import plan_trajectory
from aftir_rl.rl.tabular.paths import learn_cells

COMPILED = continuation._tip_jacobian


def numpy_tip_jacobian(x: np.ndarray, n: int, l: float) -> tuple[np.ndarray, np.ndarray]:
    """The chain's Jacobian as it was: numpy's, sections still in the guide frozen."""
    tip, jac = tip_jacobian(x, l)
    ends = x[0] + l * np.arange(1, n + 1)
    jac[:, np.concatenate([[False], ends <= 0.0, ends <= 0.0])] = 0.0
    return tip, jac


def chain(planner, cells: list, target: np.ndarray, jacobian) -> tuple[float, tuple]:  # noqa: ANN001
    """Seconds and outcome of one chain with ``jacobian`` in place."""
    continuation._tip_jacobian = jacobian
    try:
        points = [planner.tank.raster.cell_center(c) for c in cells]
        start = time.perf_counter()
        trajectory = plan_trajectory(planner, points, target, bridge_seconds=0)
        seconds = time.perf_counter() - start
    finally:
        continuation._tip_jacobian = COMPILED
    m = trajectory.measures(planner.scene)
    outcome = (trajectory.complete, len(trajectory.blocked_moves), m["tip_error_cm"],
               m["min_clearance_cm"], m["path_cm"])  # fmt: skip
    return seconds, outcome


def same(a: tuple, b: tuple) -> bool:
    """Outcomes equal: the counts exactly, the measures to 1e-6 of their size (nan to nan)."""
    return a[:2] == b[:2] and all(
        (np.isnan(x) and np.isnan(y)) or math.isclose(x, y, rel_tol=1e-6, abs_tol=1e-6)
        for x, y in zip(a[2:], b[2:])
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", default=["filomat2018", "bay1", "bay2"])
    parser.add_argument("--n-random", type=int, default=10, help="random targets per bay")
    parser.add_argument("--seed", type=int, default=7, help="seed of the random targets")
    args = parser.parse_args()
    sets, planners = target_sets(args.n_random, args.seed), Planners()
    config = load_q_table_config(CONFIG_DIR / "q_table.yaml")
    rows = []
    for name in args.sets:
        times: dict[str, list[float]] = {"numpy": [], "compiled": []}
        agree = 0
        for tank, target in sets[name]:
            planner = planners(tank)
            try:
                cells, reached = learn_cells(planner.tank, target, config, 0)
            except AftirError:  # a target Q-learning cannot take (as the bench skips it)
                continue
            if not reached:
                continue
            chain(planner, cells, target, COMPILED)  # warm: kernels compiled, fields built
            t_numpy, out_numpy = chain(planner, cells, target, numpy_tip_jacobian)
            t_compiled, out_compiled = chain(planner, cells, target, COMPILED)
            times["numpy"].append(t_numpy)
            times["compiled"].append(t_compiled)
            agree += same(out_numpy, out_compiled)
        n = len(times["numpy"])
        med = {k: float(np.median(v)) for k, v in times.items()}
        tot = {k: float(np.sum(v)) for k, v in times.items()}
        rows.append(
            f"| {name} | {n} | {med['numpy']:.2f} | {med['compiled']:.2f} | "
            f"{tot['numpy']:.1f} | {tot['compiled']:.1f} | {tot['numpy'] / tot['compiled']:.2f}x "
            f"| {agree}/{n} |"
        )
    print("| set | targets | median s, numpy | median s, compiled | total s, numpy | "
          "total s, compiled | ratio | same outcome |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    print(machine_facts())


if __name__ == "__main__":
    main()
