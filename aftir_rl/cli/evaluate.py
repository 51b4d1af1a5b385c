"""``python -m aftir_rl.evaluate RUN_DIR [RUN_DIR ...]``: compare trained agents in one table.

Each run directory is loaded and measured by :func:`aftir_rl.experiments.runs.evaluate_run`: a
Q-learning run on the target it was trained for (its greedy cells made into a motion), an SB3 or
RLlib run on its env's evaluation targets, ``--target`` or ``--random N --seed S``. One row per run:
success rate, tip error, tip path length, least clearance and seconds per target, also logged to
TensorBoard as ``eval/<metric>``, one folder per run (and ``results.json``). What success and
each column mean: docs/reference.md, "Evaluating runs".
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from aftir_rl.cli.args import (
    OneLineParser,
    add_int_option,
    add_margin_option,
    add_motion_option,
    add_ray_options,
    add_seed_option,
    add_stochastic_option,
    add_tank_option,
    add_target_option,
    check_margin,
    check_tank,
)
from aftir_rl.cli.guard import cli, exit_with, preload
from aftir_rl.core.config import DEFAULT_MARGIN, EVAL_SEED
from aftir_rl.core.errors import AftirError, ConfigError
from aftir_rl.core.files import check_writable_dir, write_json
from aftir_rl.experiments.runs import evaluate_run
from aftir_rl.rl.pretrained import policy_dir

__all__ = ["build_parser", "main", "evaluate_run"]


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


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m aftir_rl.evaluate``."""
    parser = OneLineParser(
        prog="aftir evaluate",
        description="Evaluate trained runs (Q-table or SB3) and print one comparison table.",
    )
    parser.add_argument("runs", nargs="*", metavar="RUN_DIR", help="run directories")
    parser.add_argument(
        "--pretrained",
        action="append",
        default=[],
        metavar="NAME",
        help="a policy shipped with the package, evaluated like a run (repeatable; "
        "aftir pretrained lists them)",
    )
    add_target_option(parser, "evaluation target for SB3 runs (repeatable)")
    parser.add_argument("--logdir", default="runs", help="where the evaluate__<time> logs go")
    add_motion_option(
        parser,
        "a Q-table run's motion: follow-the-leader (default) or the papers' postures per cell",
    )
    add_int_option(
        parser,
        "--random",
        (1, MAX_RANDOM_TARGETS),
        f"SB3 runs: N targets drawn by the run's "
        f"env (1..{MAX_RANDOM_TARGETS}), not its fixed evaluation targets",
    )
    add_seed_option(
        parser,
        f"first seed of --random's targets, 0 to 2**32-1-N (default {RANDOM_SEED}, far "
        f"from training's {EVAL_SEED})",
        None,
    )
    add_margin_option(parser, f"clearance the arm keeps ({DEFAULT_MARGIN:g} cm)")
    add_stochastic_option(parser, "SB3 runs")
    add_tank_option(parser, "AFTIR-ArmFTL-v0 runs: evaluate here, not in the run's own tank")
    add_ray_options(parser, "evaluate the runs")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    return parser


#: :func:`evaluate_run`'s parameter -> the flag that gives it.
FLAGS = {"tank": "--tank", "policy_seed": "--stochastic"}


def _evaluate_runs(
    args: argparse.Namespace, targets: list[np.ndarray] | None, draw: tuple[int, int] | None
) -> dict[str, dict[str, Any]]:
    """Each run's row by its name in the table, on Ray with ``--ray``/``--workers``.

    Raises:
        AftirError: a run or the Ray options are refused.

    """
    if args.ray is not None or args.workers is not None:
        from aftir_rl.experiments.distributed import (
            check_ray_options,
            evaluate_on_ray,
            ray_session,
        )

        check_ray_options(args.ray, args.workers)
        with ray_session(args.ray, args.workers):
            rows = evaluate_on_ray(
                args.runs,
                targets,
                args.motion,
                args.margin,
                draw=draw,
                tank=args.tank,
                policy_seed=args.stochastic,
            )
        return {_row_name(r): row for r, row in zip(args.runs, rows)}
    try:
        table: dict[str, dict[str, Any]] = {}
        for r in args.runs:
            with _bar(r, args.no_progress) as progress:
                table[_row_name(r)] = evaluate_run(
                    r, targets, args.motion, args.margin, draw, args.tank, args.stochastic,
                    progress,
                )  # fmt: skip
        return table
    except ConfigError as exc:  # a value the run refuses: say which flag gave it
        if exc.param not in FLAGS:
            raise
        raise ConfigError(f"{FLAGS[exc.param]}: {exc}") from None


@contextmanager
def _bar(run: str, hidden: bool) -> Iterator[Callable[[int, int], None]]:
    """``progress(done, total)`` drawing a bar of one run's episodes on stderr (when it has any)."""
    from tqdm import tqdm

    bars: list[Any] = []

    def progress(done: int, total: int) -> None:
        if not bars:
            name = Path(run).name
            bars.append(tqdm(total=total, unit="ep", desc=name[:40], disable=hidden, leave=False))
        bars[0].update(done - bars[0].n)

    try:
        yield progress
    finally:
        for bar in bars:
            bar.close()


def _print_table(results: dict[str, dict[str, Any]]) -> None:
    """Print the comparison table, one row per run."""
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


#: The metrics each evaluated run logs, as ``eval/<metric>`` (the tags training logs too).
LOGGED = (
    "success_rate",
    "tip_error_cm",
    "path_length_cm",
    "min_clearance_cm",
    "seconds_per_target",
)


def _log_results(logdir: str, results: dict[str, dict[str, Any]]) -> Path:
    """Log each run's metrics to ``logdir/evaluate__<time>/<run>/`` as ``eval/<metric>``.

    One folder per run, the same tags for all, so TensorBoard draws every run on one card per
    metric; ``results.json`` holds the table's rows.

    Returns:
        The folder logged to.

    """
    from stable_baselines3.common.logger import configure

    out = Path(logdir) / f"evaluate__{datetime.now().strftime('%Y%m%d-%H%M%S-%f')}"
    for name, r in results.items():
        logger = configure(str(out / name), ["tensorboard", "csv"])
        for key in LOGGED:
            logger.record(f"eval/{key}", float(r[key]))
        logger.dump(0)
        logger.close()
    rows = {
        name: {k: v if isinstance(v, (str, int, float)) else str(v) for k, v in r.items()}
        for name, r in results.items()
    }
    write_json(out / "results.json", rows)
    return out


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.evaluate``."""
    args = build_parser().parse_args(argv)
    preload("aftir_rl.rl.sb3")  # torch: SB3 runs and the TensorBoard log need it
    targets = [np.array(t) for t in args.target] if args.target else None
    try:
        draw = _check_draw(args.random, args.seed, targets)
        check_margin(args.margin)
        if args.tank is not None:
            check_tank(args.tank)
        check_writable_dir(args.logdir)
        args.runs = [*args.runs, *map(str, map(policy_dir, args.pretrained))]
        if not args.runs:
            raise ConfigError("give RUN_DIR... or --pretrained NAME")
        results = _evaluate_runs(args, targets, draw)
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    _print_table(results)
    out = _log_results(args.logdir, results)
    print(f"logged to {out}")
    return 0


if __name__ == "__main__":
    exit_with(main())
