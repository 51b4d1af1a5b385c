"""``aftir check RUN...``: re-check a timed motion independently of the planner; exit 0 or 1.

A thin command line over :func:`aftir_rl.experiments.execution.check_motion`: time from 0 and
never back, every joint's and cable's speed and acceleration within the arm's limits, the cables
within their travel, the joint limits, entries dense enough, and python-fcl clearance of at
least ``--margin`` (default 1 cm; the margin the run's file states is only reported, never
trusted) with the panel rule at every entry. Prints ``ok`` or the first problem in one line
(exit 1); a file that cannot be read exits 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser, add_margin_option, check_margin
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import AftirError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir check``."""
    parser = OneLineParser(
        prog="aftir check",
        description="Re-check a run's timed motion: time, actuator limits, forward kinematics, "
        "clearance and the margin. Exit 0 if it holds, 1 with the first problem otherwise.",
    )
    parser.add_argument(
        "runs", nargs="+", metavar="RUN", help="run directories (or their trajectory.json)"
    )
    parser.add_argument(
        "--tank", help="tank name or YAML (default: the tank the run names, else b737_center)"
    )
    add_margin_option(
        parser, "the clearance [cm] every entry must keep (default 1; the file's is not used)"
    )
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir check``."""
    args = build_parser().parse_args(argv)
    check_margin(args.margin)
    if len(args.runs) == 1:  # one run: an unreadable one is the command's one-line error
        return _check(args.runs[0], args.tank, args.margin)
    worst = 0
    for run in args.runs:
        try:
            code = _check(run, args.tank, args.margin)
        except AftirError as exc:
            print(f"error: {exc}", file=sys.stderr)
            code = 2
        worst = max(worst, code)
    return worst


def _check(path: str, tank_name: str | None, margin: float) -> int:
    """Check one run, print its line; 0 if it holds, 1 if not."""
    from aftir_rl.experiments.execution import check_motion, timed_run_tank

    run, tank = timed_run_tank(path, tank_name)
    problems = check_motion(run, tank, margin)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        print(f"{path}: {problems[0]}{more}")
        return 1
    stated = "" if run.margin_cm == margin else f"; the file states {run.margin_cm:g} cm"
    stated += "; timed now: the run saved no timing" if run.timed_now else ""
    facts = f"{len(run.dis)} entries, {run.timing.duration:.2f} s, margin {margin:g} cm"
    print(f"{path}: ok ({facts}{stated})")
    return 0
