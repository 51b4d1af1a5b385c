"""``python -m aftir_rl.evaluate RUN_DIR [RUN_DIR ...]``: compare trained agents in one table.

Each run directory is loaded and measured by :func:`aftir_rl.experiments.runs.evaluate_run`. A
Q-learning run
(``q_table.npz``) is evaluated on the target it was trained for: its greedy cell
path is replayed in ``AFTIR-Tank-v0`` and turned into arm postures
(:func:`aftir_rl.planning.posture.trajectory.plan_trajectory`); success means every waypoint got a
posture,
the last reaches the target and every move between them is collision-free. An SB3 run
(``model.zip``) is evaluated on its env's fixed evaluation targets (or ``--target``, or
``--random N --seed S``: ``N`` targets its env draws with seeds ``S .. S + N − 1``, which its
training never measured it on unless they overlap its evaluation seeds
``12345 .. 12345 + eval_targets − 1``), one deterministic episode each. A training run's
``best/`` (the best model its evaluations saw) is itself a run directory. For both the table gives
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

from aftir_rl.cli.args import add_margin_option, add_ray_options, add_target_option, check_margin
from aftir_rl.cli.guard import cli
from aftir_rl.core.config import DEFAULT_MARGIN, EVAL_SEED
from aftir_rl.core.errors import AftirError, ConfigError
from aftir_rl.core.files import check_writable_dir
from aftir_rl.experiments.runs import evaluate_run

__all__ = ["main", "evaluate_run"]


#: Most targets ``--random`` may draw, and the first seed it draws them with by default.
MAX_RANDOM_TARGETS = 10_000
RANDOM_SEED = 1_000_000


def _check_draw(
    count: int | None, seed: int | None, targets: list[np.ndarray] | None
) -> tuple[int, int] | None:
    """``(count, seed)`` of ``--random``/``--seed``, or None without ``--random``.

    Raises:
        ConfigError: a count or seed out of range, ``--random`` beside ``--target``, or
            ``--seed`` without ``--random``.

    """
    if count is None:
        if seed is not None:
            raise ConfigError("--seed chooses --random's targets; give --random N too")
        return None
    seed = RANDOM_SEED if seed is None else seed
    if targets:
        raise ConfigError("give --target or --random, not both")
    if not 1 <= count <= MAX_RANDOM_TARGETS:
        raise ConfigError(f"--random must be in 1..{MAX_RANDOM_TARGETS}, got {count}")
    if not 0 <= seed <= 2**32 - 1 - count:
        raise ConfigError(f"--seed must be in 0..{2**32 - 1 - count}, got {seed}")
    return count, seed


def _row_name(run: str) -> str:
    """A run's name in the table: its directory, with its parent for a run's ``best/``."""
    path = Path(run)
    return f"{path.parent.name}/best" if path.name == "best" else path.name


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
    parser.add_argument(
        "--random",
        type=int,
        metavar="N",
        help=f"SB3 runs: N targets drawn by the run's env (1..{MAX_RANDOM_TARGETS}), not "
        "its fixed evaluation targets",
    )
    parser.add_argument(
        "--seed",
        type=int,
        metavar="S",
        help=f"first seed of --random's targets (default {RANDOM_SEED}, far from training's "
        f"{EVAL_SEED})",
    )
    add_margin_option(parser, f"clearance the arm keeps ({DEFAULT_MARGIN:g} cm)")
    add_ray_options(parser, "evaluate the runs")
    args = parser.parse_args(argv)
    targets = [np.array(t) for t in args.target] if args.target else None
    try:
        draw = _check_draw(args.random, args.seed, targets)
        check_margin(args.margin)
        check_writable_dir(args.logdir)
        if args.ray is not None or args.workers is not None:
            from aftir_rl.experiments.distributed import (
                check_ray_options,
                evaluate_on_ray,
                ray_session,
            )

            check_ray_options(args.ray, args.workers)
            with ray_session(args.ray, args.workers):
                rows = evaluate_on_ray(args.runs, targets, args.motion, args.margin, draw=draw)
            results = {_row_name(r): row for r, row in zip(args.runs, rows)}
        else:
            results = {
                _row_name(r): evaluate_run(r, targets, args.motion, args.margin, draw)
                for r in args.runs
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
