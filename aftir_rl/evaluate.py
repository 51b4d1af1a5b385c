"""``python -m aftir_rl.evaluate RUN_DIR [RUN_DIR ...]``: compare trained agents in one table.

Each run directory is loaded and measured by :func:`aftir_rl.run.evaluate_run`. A Q-learning run
(``q_table.npz``) is evaluated on the target it was trained for: its greedy cell
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
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path

import numpy as np

from aftir_rl.cli_args import add_margin_option, add_ray_options, add_target_option, check_margin
from aftir_rl.config import DEFAULT_MARGIN
from aftir_rl.errors import AftirError
from aftir_rl.run import evaluate_run
from aftir_rl.safety import check_writable_dir, cli

__all__ = ["main", "evaluate_run"]


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.evaluate``."""
    parser = argparse.ArgumentParser(
        prog="python -m aftir_rl.evaluate",
        description="Evaluate trained runs (Q-table or SB3) and print one comparison table.",
    )
    parser.add_argument("runs", nargs="+", metavar="RUN_DIR", help="run directories")
    add_target_option(parser, "evaluation target for SB3 runs (repeatable)")
    parser.add_argument("--logdir", default="runs", help="where the evaluate__<time> logs go")
    parser.add_argument(
        "--motion",
        choices=("ftl", "progressive"),
        default="ftl",
        help="a Q-table run's motion: follow-the-leader (default) or the papers' postures per cell",
    )
    add_margin_option(parser, f"clearance the arm keeps ({DEFAULT_MARGIN:g} cm)")
    add_ray_options(parser, "evaluate the runs")
    args = parser.parse_args(argv)
    targets = [np.array(t) for t in args.target] if args.target else None
    try:
        check_margin(args.margin)
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
