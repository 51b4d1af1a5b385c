"""``aftir tour``: one deployment that visits many targets, timed and checked, in a run directory.

A thin command line over :func:`aftir_rl.planning.ftl.tour.plan_tour`. Writes ``DIR/
trajectory.json`` (the tour's motion with its timing: ``aftir view DIR`` plays it, ``aftir check
DIR`` re-checks it), ``DIR/tour.json`` (order, legs, durations) and ``DIR/summary.json`` (the
tank), and prints the tour's duration as a share of one deployment per target.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aftir_rl.cli.args import (
    OneLineParser,
    add_int_option,
    add_margin_option,
    add_seconds_option,
    add_seed_option,
    check_margin,
)
from aftir_rl.cli.guard import cli
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.shipped import DEFAULT_TANK

if TYPE_CHECKING:
    from aftir_rl.core.tank import Tank

__all__ = ["MAX_TOUR_TARGETS", "build_parser", "main"]

#: The most targets of one tour.
MAX_TOUR_TARGETS = 100


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir tour``."""
    parser = OneLineParser(
        prog="aftir tour",
        description="Plan one follow-the-leader deployment that visits every target (the order "
        "by OR-Tools over the legs' durations), timed under the arm's limits; needs "
        'pip install "aftir_rl[robot]".',
    )
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="the run directory")
    parser.add_argument(
        "--targets", metavar="FILE", help="a YAML file with 'targets: [[x, y, z], ...]' in cm"
    )
    add_int_option(
        parser, "--random", (1, MAX_TOUR_TARGETS), "N random targets at least 10 cm from every "
        "surface, instead of --targets"
    )  # fmt: skip
    parser.add_argument(
        "--coverage", type=float, metavar="SHARE", help="instead of targets: viewpoints whose "
        "routes let the tip camera (the arm's 'camera') see this share of --bay's surface, e.g. 0.9"
    )  # fmt: skip
    add_int_option(parser, "--bay", (1, 64), "--random's or --coverage's bay, counted between "
                   "baffles (2)", 2)  # fmt: skip
    parser.add_argument("--spacing", type=float, default=30.0, metavar="CM",
                        help="--coverage: spacing of the candidate viewpoints (30)")  # fmt: skip
    add_int_option(parser, "--samples", (100, 50_000), "--coverage: surface samples (3000)", 3000)
    add_seed_option(parser, "seed of --random (default 0)")
    parser.add_argument("--tank", default=DEFAULT_TANK, help=f"tank name or YAML ({DEFAULT_TANK})")
    add_margin_option(parser, f"clearance the arm keeps (default {DEFAULT_MARGIN:g} cm)")
    add_seconds_option(parser, "--solver-seconds", 2.0, "OR-Tools' time for the order (2)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return parser


def _targets(args: argparse.Namespace, tank: Tank) -> np.ndarray:
    """The tour's targets: from ``--targets`` or drawn by ``--random``."""
    from aftir_rl.core.config import read_yaml, to_float
    from aftir_rl.core.tank.loading import MAX_COORD
    from aftir_rl.planning.posture.context import random_free_targets
    from aftir_rl.planning.posture.planner import Planner

    if (args.targets is None) == (args.random is None):
        raise ConfigError("give --targets FILE, --random N or --coverage SHARE (one of them)")
    if args.random is not None and tank.baffle is not None and args.bay in (1, 2):
        drawn = random_free_targets(Planner(tank), args.random, args.seed, clearance=10.0)
        return np.array(drawn[f"bay{args.bay}"])
    if args.random is not None:  # any other tank: between its baffles
        from aftir_rl.experiments.suite import suite_targets

        return suite_targets(tank, args.random, args.seed, tank.bay(args.bay))
    points = read_yaml(args.targets).get("targets")
    if not isinstance(points, list) or not 0 < len(points) <= MAX_TOUR_TARGETS:
        raise ConfigError(f"{args.targets}: targets: expected a list of 1 to 100 [x, y, z]")
    out = []
    for i, point in enumerate(points):
        if not isinstance(point, list) or len(point) != 3:
            raise ConfigError(f"{args.targets}: targets[{i}]: expected [x, y, z] in cm")
        out.append([to_float(v, f"{args.targets}: targets[{i}]", MAX_COORD) for v in point])
    return np.array(out)


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir tour``."""
    import sys

    from aftir_rl.core.tank import load_tank
    from aftir_rl.planning.ftl.tour import plan_tour

    args = build_parser().parse_args(argv)
    check_margin(args.margin)
    if not 0 < args.solver_seconds <= 600:
        raise ConfigError("--solver-seconds must be in (0, 600]")
    tank = load_tank(args.tank)
    say = None if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    if args.coverage is not None:
        return _coverage(args, tank, say)
    targets = _targets(args, tank)
    tour = plan_tour(tank, targets, args.margin, args.solver_seconds, say)
    _write(Path(args.output), args.tank, tour)
    reached = len(tour.order)
    print(
        f"tour of {reached} targets ({len(tour.failures)} unreachable, "
        f"{len(tour.side_trips)} by side trips): {tour.duration:.1f} s, "
        f"{100 * tour.duration / tour.separate_s:.0f}% of {tour.separate_s:.1f} s for one "
        f"deployment each; planned in {tour.seconds:.1f} s; {args.output}"
    )
    return 0


def _write(out: Path, tank_name: str, tour: Any, extra: dict[str, Any] | None = None) -> None:
    """The run directory of a tour (``extra``: more files, name to JSON)."""
    from aftir_rl.core.files import write_json
    from aftir_rl.core.tank import keep_run_tank

    out.mkdir(parents=True, exist_ok=True)
    name = keep_run_tank(tank_name, out)
    write_json(out / "trajectory.json", tour.trajectory_json(), compact=True)
    write_json(out / "tour.json", {"tank": name, **tour.report_json()})
    for file, data in (extra or {}).items():
        write_json(out / file, data)
    write_json(out / "summary.json", {"tank": name, "method": "ftl-tour"})


def _coverage(args: argparse.Namespace, tank: Tank, say: Callable[[str], None] | None) -> int:
    """``--coverage``: plan the viewpoints' tour, measure what it sees, write the run."""
    import sys

    from aftir_rl.experiments.coverage import measure_coverage
    from aftir_rl.planning.ftl.coverage import plan_coverage

    if args.targets is not None or args.random is not None:
        raise ConfigError("give --targets FILE, --random N or --coverage SHARE (one of them)")
    if not 0 < args.coverage <= 1:
        raise ConfigError(f"--coverage must be a share in (0, 1], got {args.coverage:g}")
    if not 5 <= args.spacing <= 1000:
        raise ConfigError(f"--spacing must be in [5, 1000] cm, got {args.spacing:g}")
    box = tank.bay(args.bay)
    plan = plan_coverage(tank, box, args.coverage, args.spacing, args.samples, args.seed,
                         args.margin, args.solver_seconds, say)  # fmt: skip
    measured = measure_coverage(tank, plan.tour.motion, box)
    report = {**plan.report_json(), "bay": args.bay, "camera": tank.arm.camera.to_json(),
              "measured": measured.to_json()}  # fmt: skip
    _write(Path(args.output), args.tank, plan.tour, {"coverage.json": report})
    tour = plan.tour
    if measured.fraction < args.coverage:
        print(f"below the goal: the candidates' routes see {100 * plan.estimate:.1f}% by the "
              "planner's estimate (try a smaller --spacing)", file=sys.stderr)  # fmt: skip
    print(
        f"coverage tour of {len(tour.order)} viewpoints: {tour.duration:.1f} s; bay {args.bay}'s "
        f"surface seen: {100 * measured.fraction:.1f}% measured by ray casting (planner's estimate "
        f"{100 * plan.estimate:.1f}%, goal {100 * args.coverage:g}%); planned in "
        f"{plan.seconds:.1f} s; {args.output}"
    )
    return 0
