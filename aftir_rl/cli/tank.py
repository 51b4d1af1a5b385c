"""``python -m aftir_rl.tank [--tank NAME|PATH] [--json]``: a tank's raster, or its scene as JSON.

A thin command line over :func:`~aftir_rl.core.tank.loading.load_tank`: it prints
:meth:`Tank.ascii() <aftir_rl.core.tank.geometry.Tank.ascii>` (z-slices of the raster), or with
``--json`` :meth:`Tank.scene_dict() <aftir_rl.core.tank.geometry.Tank.scene_dict>` (the scene
export, docs/design.md §5). A tank that cannot be read prints "error: <why>" and exits with
status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import AftirError
from aftir_rl.core.tank.loading import load_tank

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir tank``."""
    parser = OneLineParser(
        prog="python -m aftir_rl.tank",
        description="Show a tank's raster as z-slices, or export its scene as JSON (units cm).",
    )
    parser.add_argument(
        "--tank", default="b737_center", help="tank name in configs/tanks or a YAML path"
    )
    parser.add_argument("--json", action="store_true", help="print the scene export as JSON")
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.tank`` (and ``aftir tank``)."""
    args = build_parser().parse_args(argv)
    try:
        tank = load_tank(args.tank)
        print(json.dumps(tank.scene_dict()) if args.json else tank.ascii())
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
