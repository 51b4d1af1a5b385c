"""``aftir export RUN -o FILE``: a timed motion as ROS ``JointTrajectory`` JSON or CSV.

A thin command line over :func:`aftir_rl.experiments.execution.export_motion`: the run's
``trajectory.json`` with its timing, in joints (``dis`` and the bending vectors) or in cables
(``dis`` and each cable's length change), written atomically.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser
from aftir_rl.cli.guard import cli
from aftir_rl.experiments.execution import FORMATS, SPACES

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir export``."""
    parser = OneLineParser(
        prog="aftir export",
        description="Write a run's timed motion (trajectory.json) as a JSON with ROS "
        "trajectory_msgs/JointTrajectory field names, or as CSV.",
    )
    parser.add_argument("run", metavar="RUN", help="a run directory or its trajectory.json")
    parser.add_argument("-o", "--output", required=True, metavar="FILE", help="the file to write")
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
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir export``."""
    from aftir_rl.core.files import atomic_open
    from aftir_rl.experiments.execution import export_motion, read_timed

    args = build_parser().parse_args(argv)
    run = read_timed(args.run)
    text = export_motion(run, args.format, args.space)
    with atomic_open(args.output) as out:
        out.write(text)
    print(f"wrote {args.output} ({len(run.dis)} points, {run.timing.duration:.2f} s, {args.space})")
    return 0
