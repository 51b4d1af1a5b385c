"""``python -m aftir_rl.evaluate RUN_DIR [RUN_DIR ...]``: compare trained agents in one table.

A Q-learning run (``q_table.npz``) is evaluated on the target it was trained for: its greedy cell
path is replayed in ``AFTIR-Tank-v0`` and turned into arm postures
(:func:`aftir_rl.posture.trajectory.plan_trajectory`); success means every waypoint got a posture,
the last reaches the target and every move between them is collision-free. An SB3 run
(``model.zip``) is evaluated on its env's fixed evaluation targets (or ``--target``), one
deterministic episode each. For both the table gives
success rate, tip error, tip path length, the smallest clearance to the tank along the motion
(for a Q-learning run: its postures and about 50 sampled along the motion, an upper bound) and
seconds per target; the same numbers go to TensorBoard under ``compare/<run>/...`` in a new
``evaluate__<time>`` directory of ``--logdir``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from aftir_rl.config import DEFAULT_MARGIN
from aftir_rl.errors import AftirError, CheckpointError, ConfigError
from aftir_rl.safety import check_writable_dir, cli

if TYPE_CHECKING:
    from aftir_rl.envs.tank_grid import TankGridEnv

__all__ = ["main", "evaluate_run"]


def _q_table_run(
    run_dir: Path, motion: str = "ftl", margin: float = DEFAULT_MARGIN
) -> dict[str, Any]:
    import gymnasium as gym

    from aftir_rl.agents.q_table import QLearning, greedy_rollout
    from aftir_rl.posture import Planner
    from aftir_rl.posture.trajectory import plan_trajectory

    _, meta = QLearning.read_checkpoint(run_dir / "q_table.npz")
    target = meta.get("target")
    if target is None:
        raise CheckpointError(f"{run_dir}: the Q-table has no target in its metadata")
    env = gym.make(
        meta.get("env_id", "AFTIR-Tank-v0"),
        tank=meta.get("tank", "b737_center"),
        target=tuple(target),
    )
    agent = QLearning.load(run_dir / "q_table.npz", env)
    start = time.perf_counter()
    states, reached = greedy_rollout(agent, env)
    grid = cast("TankGridEnv", env.unwrapped)
    raster = grid.raster
    points = [raster.cell_center(raster.cell(s)) for s in states]
    if motion == "ftl":
        from aftir_rl.motion.plan import plan_motion

        cells = [raster.cell(s) for s in states]
        plan = plan_motion(grid.tank, target, cells, margin=margin)
        nan = float("nan")
        return {
            "agent": "q_table + FTL motion",
            "targets": 1,
            "success_rate": float(reached and plan.complete),
            "tip_error_cm": plan.tip_error_cm if plan.complete else nan,
            "path_length_cm": plan.tip_path_length_cm if plan.complete else nan,
            "min_clearance_cm": plan.min_clearance_cm if plan.complete else nan,
            "seconds_per_target": time.perf_counter() - start,
            "note": "" if plan.complete else (plan.reason or "")[:80],
        }
    planner = Planner(grid.tank)
    trajectory = plan_trajectory(planner, points, target)
    seconds = time.perf_counter() - start
    m = trajectory.measures(planner.scene)
    return {
        "agent": "q_table + TGA/TSM",
        "targets": 1,
        "success_rate": float(reached and trajectory.complete),
        "tip_error_cm": m["tip_error_cm"],
        "path_length_cm": m["path_cm"],
        "min_clearance_cm": m["min_clearance_cm"],
        "seconds_per_target": seconds,
        "note": trajectory.note,
    }


def _sb3_run(run_dir: Path, targets: list[np.ndarray] | None) -> dict[str, Any]:
    from aftir_rl.agents.sb3 import evaluate_policy_on_targets, evaluation_targets, load_run

    # config.json checked key by key, the model loaded without unpickling (agents.sb3.load_run)
    algo, config, env_id, model = load_run(run_dir)
    targets = targets or evaluation_targets(env_id, config.eval_targets)
    metrics, _ = evaluate_policy_on_targets(model, env_id, targets, clearance=True)
    note = f"{metrics['collision_rate']:.0%} collided" if metrics["collision_rate"] else ""
    return {"agent": f"{algo} ({config.env_id})", "targets": len(targets), **metrics, "note": note}


def evaluate_run(
    run_dir: str | Path,
    targets: list[np.ndarray] | None = None,
    motion: str = "ftl",
    margin: float = DEFAULT_MARGIN,
) -> dict[str, Any]:
    """Evaluate one run directory (Q-table or SB3).

    A Q-table run's greedy path becomes a follow-the-leader motion keeping ``margin`` [cm]
    (``motion="ftl"``) or the papers' postures per cell (``"progressive"``).

    Raises:
        CheckpointError: not a run directory this knows, or unreadable files.

    """
    run_dir = Path(run_dir)
    if (run_dir / "q_table.npz").exists():
        return _q_table_run(run_dir, motion, margin)
    if (run_dir / "model.zip").exists() and (run_dir / "config.json").exists():
        return _sb3_run(run_dir, targets)
    raise CheckpointError(
        f"{run_dir}: not a run directory (no q_table.npz, nor model.zip with config.json)"
    )


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.evaluate``."""
    parser = argparse.ArgumentParser(
        prog="python -m aftir_rl.evaluate",
        description="Evaluate trained runs (Q-table or SB3) and print one comparison table.",
    )
    parser.add_argument("runs", nargs="+", metavar="RUN_DIR", help="run directories")
    parser.add_argument(
        "--target",
        nargs=3,
        type=float,
        action="append",
        metavar=("X", "Y", "Z"),
        help="evaluation target for SB3 runs (repeatable)",
    )
    parser.add_argument("--logdir", default="runs", help="where the evaluate__<time> logs go")
    parser.add_argument(
        "--motion",
        choices=("ftl", "progressive"),
        default="ftl",
        help="a Q-table run's motion: follow-the-leader (default) or the papers' postures per cell",
    )
    parser.add_argument(
        "--margin",
        type=float,
        default=DEFAULT_MARGIN,
        metavar="CM",
        help=f"clearance the arm keeps ({DEFAULT_MARGIN:g} cm)",
    )
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="evaluate the runs as Ray tasks: local (a Ray on this machine), auto or HOST:PORT (a "
        "cluster started with ray start); needs aftir_rl[ray]",
    )
    parser.add_argument(
        "--workers", type=int, metavar="N", help="CPUs of --ray local (default: every core)"
    )
    args = parser.parse_args(argv)
    targets = [np.array(t) for t in args.target] if args.target else None
    try:
        if not 0 <= args.margin <= 20:
            raise ConfigError(f"--margin must be between 0 and 20 cm, got {args.margin}")
        check_writable_dir(args.logdir)
        if args.ray is not None or args.workers is not None:
            from aftir_rl.distributed import check_ray_options, evaluate_on_ray, ray_session

            check_ray_options(args.ray, args.workers)
            with ray_session(args.ray, args.workers):
                rows = evaluate_on_ray(args.runs, targets, args.motion, args.margin)
            results = {Path(r).name: row for r, row in zip(args.runs, rows)}
        else:
            results = {
                Path(r).name: evaluate_run(r, targets, args.motion, args.margin) for r in args.runs
            }
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(
        "| run | agent | targets | success | tip error (cm) | path (cm) | min clearance (cm) | "
        "s / target | note |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---|")
    for name, r in results.items():
        head = f"| {name} | {r['agent']} | {r['targets']} | {r['success_rate']:.0%} | "
        body = f"{r['tip_error_cm']:.3g} | {r['path_length_cm']:.0f} | "
        tail = f"{r['min_clearance_cm']:.2f} | {r['seconds_per_target']:.2f} | {r['note']} |"
        print(head + body + tail)
    from stable_baselines3.common.logger import configure

    out = Path(args.logdir) / f"evaluate__{datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
    logger = configure(str(out), ["tensorboard", "csv"])
    for name, r in results.items():
        for key in (
            "success_rate",
            "tip_error_cm",
            "path_length_cm",
            "min_clearance_cm",
            "seconds_per_target",
        ):
            logger.record(f"compare/{name}/{key}", float(r[key]))
    logger.dump(0)
    logger.close()
    print(f"logged to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
