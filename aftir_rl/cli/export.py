"""``aftir export RUN -o FILE``: a timed motion as ROS ``JointTrajectory`` JSON or CSV.

Several runs go to a folder (``-o DIR``), one file per run named after it.

A thin command line over :func:`aftir_rl.experiments.execution.export_motion`: the run's
``trajectory.json`` with its timing, in joints (``dis`` and the bending vectors) or in cables
(``dis`` and each cable's length change), written atomically. The motion is first checked as
``aftir check`` checks it (``--margin``, default 1 cm); one that fails is not written unless
``--unchecked`` is given, and the file then says it was not checked.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from aftir_rl.cli.args import OneLineParser, add_margin_option, check_margin
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import AftirError
from aftir_rl.experiments.execution import FORMATS, SPACES

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir export``."""
    parser = OneLineParser(
        prog="aftir export",
        description="Write a run's timed motion (trajectory.json) as a JSON with ROS "
        "trajectory_msgs/JointTrajectory field names, or as CSV.",
    )
    parser.add_argument(
        "run", nargs="+", metavar="RUN", help="run directories (or their trajectory.json)"
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE|DIR",
        help="the file to write; with several runs, a folder: one RUN_NAME.json (.csv) per run",
    )
    parser.add_argument(
        "--format",
        choices=FORMATS,
        default="jointtrajectory-json",
        help="jointtrajectory-json (default) or csv",
    )
    parser.add_argument(
        "--space",
        choices=SPACES,
        default="joints",
        help="joints: dis [cm] and each section's bending vector kx, ky [rad] (default); "
        "cables: dis and each cable's length change [cm]",
    )
    parser.add_argument(
        "--tank", help="tank name or YAML to check in (default: the tank the run names)"
    )
    add_margin_option(parser, "the clearance [cm] the motion must keep to be written (default 1)")
    parser.add_argument(
        "--unchecked",
        action="store_true",
        help="write the motion without checking it (the file says so)",
    )
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir export``."""
    from aftir_rl.core.files import check_outputs, check_writable_dir

    args = build_parser().parse_args(argv)
    check_margin(args.margin)
    runs = [Path(r).parent if Path(r).is_file() else Path(r) for r in args.run]
    if len(runs) == 1:
        check_outputs([args.output], runs)
        return _export(args, args.run[0], Path(args.output))
    # several runs: -o is a folder, one file per run named after it
    folder = check_writable_dir(args.output, "-o")
    suffix = ".csv" if args.format == "csv" else ".json"
    outputs = [folder / f"{run.resolve().name}{suffix}" for run in runs]
    check_outputs(outputs, runs)
    worst = 0
    for given, out in zip(args.run, outputs):
        try:
            worst = max(worst, _export(args, given, out))
        except AftirError as exc:
            print(f"error: {exc}", file=sys.stderr)
            worst = 2
    return worst


def _export(args: argparse.Namespace, given: str, output: Path) -> int:
    """Check and write one run's motion; 0 if written, 1 if its check failed."""
    from aftir_rl.core.files import atomic_open
    from aftir_rl.experiments.execution import check_motion, export_motion, timed_run_tank

    run, tank = timed_run_tank(given, args.tank)
    if not args.unchecked:
        problems = check_motion(run, tank, args.margin)
        if problems:
            print(f"error: {given}: {problems[0]}; not written (--unchecked writes it)",
                  file=sys.stderr)  # fmt: skip
            return 1
    text = export_motion(run, args.format, args.space, None if args.unchecked else args.margin)
    with atomic_open(output) as out:
        out.write(text)
    now = ", timed now: the run saved no timing" if run.timed_now else ""
    print(f"wrote {output} ({len(run.dis)} points, {run.timing.duration:.2f} s, {args.space}{now})")
    return 0
