"""``python -m aftir_rl.plan``: one posture for one target, as a table or as JSON.

Imports neither torch nor stable-baselines3, so it starts in well under a second. A target that
cannot be reached prints "error: Cannot reach the target: <why>" and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser, add_margin_option, add_target_option, check_margin
from aftir_rl.cli.guard import cli, exit_with
from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import AftirError, PlanningError
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.planning.posture.context import PlannedPosture
from aftir_rl.planning.posture.planner import Planner
from aftir_rl.planning.posture.registry import AUTO, METHOD_NAMES, REGISTRY

__all__ = ["build_parser", "main", "format_table"]


def format_table(result: PlannedPosture) -> str:
    """A readable table of a planned posture (angles in degrees, lengths in cm)."""
    p = result.posture
    lines = [
        f"method {result.method}: {p.n_sections} sections of {result.section_length:g} cm, "
        f"planned in {result.seconds * 1e3:.1f} ms",
        f"dis (linear module) {p.dis:9.3f} cm",
        "",
        " section   theta [deg]   phi [deg]",
    ]
    for i, (t, f) in enumerate(zip(p.theta, p.phi), start=1):
        lines.append(f" {i:7d}   {math.degrees(t):11.3f}   {math.degrees(f):9.3f}")
    tip = ", ".join(f"{v:.3f}" for v in result.tip)
    target = ", ".join(f"{v:g}" for v in result.target)
    lines += [
        "",
        f"target  ({target}) cm",
        f"tip     ({tip}) cm, error {result.error_cm:.2e} cm",
        f"smallest clearance to the tank {result.clearance_cm:.2f} cm",
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir plan``."""
    methods = "; ".join(f"{m.name}: {m.summary} ({m.paper})" for m in REGISTRY.values())
    parser = OneLineParser(
        prog="aftir plan",
        description="Plan a collision-free posture (dis, theta, phi) of the arm reaching a target.",
    )
    add_target_option(
        parser, "target point in cm (frame S: origin at the access panel)", required=True
    )
    parser.add_argument("--tank", default=DEFAULT_TANK, help="tank name or YAML path")
    parser.add_argument(
        "--method",
        default=AUTO,
        choices=METHOD_NAMES,
        help=f"auto: TSM beyond the baffle, TGA otherwise (default); {methods}",
    )
    parser.add_argument("--json", action="store_true", help="print the posture JSON")
    add_margin_option(
        parser, f"clearance the arm's surface keeps from the tank (default {DEFAULT_MARGIN:g} cm)"
    )
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.plan``."""
    args = build_parser().parse_args(argv)
    try:
        check_margin(args.margin)
        result = Planner(args.tank).plan(args.target, method=args.method)
        if result.clearance_cm < args.margin:
            raise PlanningError(
                f"Cannot reach the target with a margin of {args.margin:g} cm: the "
                f"{result.method} posture keeps only {result.clearance_cm:.2f} cm from the tank "
                "(a smaller --margin accepts it)"
            )
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        print(format_table(result))
    return 0


if __name__ == "__main__":
    exit_with(main())
