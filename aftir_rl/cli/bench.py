"""``python -m aftir_rl.bench`` / ``aftir bench``: every method on the same fixed target sets.

The sets and the methods are :mod:`aftir_rl.experiments.bench`'s; this module parses the
command line, checks the inputs and prints the table.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from aftir_rl.cli.args import (
    OneLineParser,
    add_int_option,
    add_margin_option,
    add_ray_options,
    add_seconds_option,
    add_seed_option,
)
from aftir_rl.cli.guard import cli, exit_with, preload
from aftir_rl.core.config import DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN
from aftir_rl.core.errors import AftirError
from aftir_rl.core.files import write_json
from aftir_rl.experiments.bench import (
    SETS,
    Row,
    format_table,
    machine_facts,
    run_benchmark,
    target_sets,
)

__all__ = ["build_parser", "main"]


#: The most random targets per bay (``--n-random``): each is run by every method.
MAX_N_RANDOM = 1000
#: ``--quick`` (``make bench``): every set and method on the first ``QUICK_TARGETS`` targets of
#: each set (as many random ones per bay), shorter budgets.
QUICK_TARGETS = 2
QUICK = {"n_random": QUICK_TARGETS, "rrt_seconds": 1.0, "bridge_seconds": 1.0}


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m aftir_rl.bench``."""
    parser = OneLineParser(
        prog="aftir bench",
        description="Measure every planner, Q-learning + postures, RRT-Connect and trained SB3 "
        "agents on the same fixed target sets; print one markdown table.",
    )
    parser.add_argument(
        "--sets",
        nargs="+",
        choices=SETS,
        default=list(SETS),
        help="target sets to run, named after the papers (aftir_rl.core.papers) and the two bays "
        "(default: all)",
    )
    add_int_option(
        parser,
        "--n-random",
        (1, MAX_N_RANDOM),
        f"random targets per bay, 1 to {MAX_N_RANDOM:,} (default 10)",
        10,
    )
    add_seed_option(parser, "seed of the random targets, 0 to 2**32-1 (default 7)", 7)
    add_seconds_option(
        parser, "--rrt-seconds", 10.0, "RRT-Connect's budget per target (default 10)"
    )
    add_seconds_option(
        parser,
        "--bridge-seconds",
        DEFAULT_BRIDGE_SECONDS,
        "RRT-Connect's budget per colliding "
        f"move of a q_table+postures trajectory, 0 for none (default {DEFAULT_BRIDGE_SECONDS:g})",
    )
    parser.add_argument(
        "--model",
        action="append",
        default=[],
        metavar="RUN_DIR",
        help="an SB3 run directory (python -m aftir_rl.train ppo|sac|td3)",
    )
    parser.add_argument("--json", metavar="PATH", help="also write every outcome as JSON")
    parser.add_argument(
        "--suite",
        metavar="DIR",
        help="instead: the scene suite (8 tanks, fixed targets, the follow-the-leader planner); "
        "writes suite.json, suite.csv and suite.db (OMPL's benchmark database) in DIR",
    )
    add_int_option(
        parser, "--suite-targets", (1, 100), "targets per scene of --suite, 1 to 100 (100)", 100
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"the quick table of make bench: the first {QUICK_TARGETS} targets of each set "
        f"({QUICK['n_random']} random ones per bay), {QUICK['rrt_seconds']:g} s for RRT-Connect "
        f"per target, {QUICK['bridge_seconds']:g} s per colliding move (options given keep their "
        "value)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    add_margin_option(
        parser, f"clearance the q_table+ftl motions keep (default {DEFAULT_MARGIN:g} cm)"
    )
    add_ray_options(parser, "run the items")
    return parser


def _check_numbers(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Exit through ``parser.error`` (status 2) when a number of the command line is refused."""
    if args.n_random < 1 or args.rrt_seconds <= 0:  # the seconds are bounded as parsed
        parser.error("--n-random must be at least 1 and --rrt-seconds positive")
    if not 0 <= args.margin <= 20:
        parser.error("--margin must be between 0 and 20 cm")


def _run_benchmark(args: argparse.Namespace) -> list[Row]:
    """The benchmark's rows for the chosen sets, models and options.

    Raises:
        AftirError: a target, model or Ray option is refused.

    """
    sets = {k: v for k, v in target_sets(args.n_random, args.seed).items() if k in args.sets}
    if args.quick:
        sets = {k: v[:QUICK_TARGETS] for k, v in sets.items()}
    progress = None if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    options = ("rrt_seconds", "bridge_seconds", "margin", "ray", "workers")
    chosen = {name: getattr(args, name) for name in options}
    return run_benchmark(sets, models=args.model, progress=progress, **chosen)


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.bench``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.quick:
        for name, value in QUICK.items():
            if getattr(args, name) == parser.get_default(name):
                setattr(args, name, value)
    _check_numbers(parser, args)
    if args.model:
        preload("aftir_rl.rl.sb3")  # torch
    problem = _check_inputs(args.model, args.json)
    if args.ray is not None or args.workers is not None:
        from aftir_rl.experiments.distributed import check_ray_options

        check_ray_options(args.ray, args.workers)  # one line and exit 2 (cli.guard)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    if args.suite:
        return _run_suite(args)
    start = time.perf_counter()
    try:
        rows = _run_benchmark(args)
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    seconds = time.perf_counter() - start
    facts = machine_facts()
    print(
        f"machine: {facts['cpu']}, {facts['system']}, {facts['cores']} cores, "
        f"Python {facts['python']}; {seconds:.0f} s in all"
    )
    print(
        (
            f"quick table (make bench; make bench-full for the full one): the first "
            f"{QUICK_TARGETS} targets of each set, "
            if args.quick
            else ""
        )
        + f"{args.n_random} random targets per bay (seed {args.seed}); RRT-Connect "
        f"{args.rrt_seconds:g} s per target and {args.bridge_seconds:g} s per colliding move"
    )
    print()
    print(format_table(rows))
    if args.json:
        rows_out = [{**r.summary(), "outcomes": [asdict(o) for o in r.outcomes]} for r in rows]
        options = {k: getattr(args, k) for k in ("sets", "n_random", "seed", "margin")}
        write_json(
            args.json, {"machine": facts, "seconds": seconds, "options": options, "rows": rows_out}
        )
    return 0


def _run_suite(args: argparse.Namespace) -> int:
    """``--suite DIR``: every scene's targets planned; a table of each scene's outcomes."""
    from aftir_rl.experiments.suite import run_suite

    progress = None if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    try:
        rows = run_suite(args.suite, args.suite_targets, progress=progress)
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print("scene | targets | complete | median s | max s | failures (reason)")
    for scene in dict.fromkeys(r.scene for r in rows):
        mine = [r for r in rows if r.scene == scene]
        times = [r.seconds for r in mine]
        fails = "; ".join(f"{list(r.target)}: {r.reason}" for r in mine if not r.complete)
        print(f"{scene} | {len(mine)} | {sum(r.complete for r in mine)} | "
              f"{np.median(times):.2f} | {max(times):.2f} | {fails or '-'}")  # fmt: skip
    print(f"wrote {args.suite}/suite.json, suite.csv, suite.db")
    return 0


def _check_inputs(models: Sequence[str], json_path: str | None) -> str:
    """What is wrong with the run directories or the JSON path ("" if nothing), before a run."""
    for run_dir in models:
        run = Path(run_dir)
        if not (run / "model.zip").exists():
            return f"{run_dir}: no model.zip; give a run directory of python -m aftir_rl.train"
        from aftir_rl.core.files import read_json
        from aftir_rl.experiments.runs import load_sb3_run
        from aftir_rl.rl.sb3 import sb3_config_from_run

        try:
            sb3_config_from_run(read_json(run / "config.json", "config.json"), str(run))
        except AftirError as exc:
            return f"{run_dir}: config.json is missing or not a training run's ({exc})"
        try:  # the model too, before any benchmark work (nothing in it is unpickled)
            load_sb3_run(run)
        except AftirError as exc:
            return str(exc)
    if json_path is not None:
        folder = Path(json_path).resolve().parent
        if not folder.is_dir() or not os.access(folder, os.W_OK):
            return f"--json {json_path}: cannot write in {folder}"
    return ""


if __name__ == "__main__":
    exit_with(main())
