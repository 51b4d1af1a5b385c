"""``aftir simulate RUN...``: re-run timed motions on a Cosserat rod under gravity; exit 0 or 1.

A thin command line over :func:`aftir_rl.experiments.physics.simulate_motion`: each run's timed
motion is simulated on a Cosserat rod of the arm (PyElastica, the ``physics`` extra) with the
body's properties from the tank's ``arm.rod``; ``physics.json`` is written beside its
``trajectory.json``, and one line says whether the simulated body kept ``--margin`` (default
1 cm; never a margin a file states). ``--replan DIR`` plans a motion that failed again with the
margin its body lacked and writes the new run there. Exit 0 if every body kept the margin, 1 if
one did not, 2 if a run cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from aftir_rl.cli.args import OneLineParser, add_margin_option, bounded_float, check_margin
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import AftirError, ConfigError
from aftir_rl.core.extras import require

if TYPE_CHECKING:
    from aftir_rl.experiments.physics import PhysicsReport

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir simulate``."""
    parser = OneLineParser(
        prog="aftir simulate",
        description="Re-run a run's timed motion on a Cosserat rod of the arm under gravity "
        "(PyElastica) and check the clearance of the simulated body; writes physics.json beside "
        "trajectory.json. Exit 0 if every body keeps the margin, 1 otherwise.",
    )
    parser.add_argument(
        "runs", nargs="+", metavar="RUN", help="run directories (or their trajectory.json)"
    )
    parser.add_argument(
        "--tank",
        help="tank name or YAML (default: the tank the run names, else b737_center); the "
        "body's mass and stiffnesses are this tank's arm.rod, else the defaults (never a run's "
        "own files)",
    )
    add_margin_option(
        parser, "the clearance [cm] the simulated body must keep (default 1; a file's is not used)"
    )
    parser.add_argument(
        "--every",
        type=bounded_float(0.1, 1000.0),
        default=1.0,
        metavar="S",
        help="seconds of the motion between two simulated instants (default 1)",
    )
    parser.add_argument(
        "--stiffness",
        type=bounded_float(0.01, 1000.0),
        default=1.0,
        metavar="X",
        help="multiply every stiffness of the body by X (default 1): how stiff it must be",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    parser.add_argument(
        "--replan",
        metavar="DIR",
        help="(one run) if the body does not keep the margin, plan the run's target again with "
        "the margin it lacked added, simulate that, and write the new run to DIR",
    )
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir simulate``."""
    args = build_parser().parse_args(argv)
    check_margin(args.margin)
    require("elastica", "physics")  # before any run is read: the one thing missing, said first
    if args.replan is not None and len(args.runs) != 1:
        raise ConfigError("--replan takes one run")
    if len(args.runs) == 1:  # one run: an unreadable one is the command's one-line error
        return _simulate(args.runs[0], args)
    worst = 0
    for run in args.runs:
        try:
            code = _simulate(run, args)
        except AftirError as exc:
            print(f"error: {exc}", file=sys.stderr)
            code = 2
        worst = max(worst, code)
    return worst


def _simulate(path: str, args: argparse.Namespace) -> int:
    """Simulate one run, write its physics.json, print its line; 0 if the margin held."""
    from aftir_rl.core.files import check_outputs, check_writable_dir, write_json
    from aftir_rl.core.rod import RodProperties
    from aftir_rl.core.shipped import DEFAULT_TANK
    from aftir_rl.core.tank import keep_run_tank, resolve_run_tank
    from aftir_rl.experiments.execution import timed_run_tank
    from aftir_rl.experiments.physics import PHYSICS_FILE, replan_for_physics, simulate_motion

    run, tank = timed_run_tank(path, args.tank)
    folder = Path(path).parent if Path(path).name == "trajectory.json" else Path(path)
    replan = Path(args.replan or ".")
    new = [replan / name for name in ("trajectory.json", PHYSICS_FILE, "summary.json")]
    if args.replan is not None:
        check_outputs(new, [folder])
    # the body's properties: the user's tank, never the run's own files (a check trusts only
    # what it is given)
    rod = (tank.arm.rod if args.tank else RodProperties()).scaled(args.stiffness)
    report = simulate_motion(run, tank, args.margin, args.every, rod, progress=not args.no_progress)
    write_json(folder / PHYSICS_FILE, report.to_json(), compact=True)
    print(f"{path}: {_line(report)}")
    if report.held or args.replan is None:
        return 0 if report.held else 1
    target = run.target
    if target is None:
        raise ConfigError(f"{path}: trajectory.json names no target to plan again")
    out = check_writable_dir(args.replan, "--replan")
    plan, report, margin = replan_for_physics(
        tank, target.tolist(), report, args.margin, args.every, rod, progress=not args.no_progress
    )
    tank_ref = args.tank or (resolve_run_tank(run.tank, folder) if run.tank else DEFAULT_TANK)
    write_json(new[0], plan.to_json())
    write_json(new[1], report.to_json(), compact=True)
    write_json(new[2], {"tank": keep_run_tank(tank_ref, out), "planned_margin_cm": margin})
    print(f"{out}: planned with a {margin:g} cm margin: {_line(report)}")
    return 0 if report.held else 1


def _line(report: PhysicsReport) -> str:
    """The one-line verdict of a physics report."""
    s = report.summary()
    verdict = "margin held" if s["margin_held"] else "MARGIN LOST"
    return (
        f"{verdict}: the simulated body keeps {s['least_clearance_cm']:.2f} cm "
        f"(kinematic {s['kinematic_least_clearance_cm']:.2f} cm, margin {s['margin_cm']:g} cm), "
        f"sags up to {s['deviation_max_cm']:.2f} cm (tip {s['tip_error_final_cm']:.2f} cm at "
        f"the end); {s['snapshots']} instants, {report.seconds:.0f} s"
    )
