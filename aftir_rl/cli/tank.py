"""``aftir tank [show|generate|export] ...``: see a tank, generate a wing tank, export a mesh.

A thin command line over :mod:`aftir_rl.core.tank`:

- ``aftir tank [show] [--tank NAME|PATH|SPEC] [--json]`` prints
  :meth:`Tank.ascii() <aftir_rl.core.tank.geometry.Tank.ascii>` (z-slices of the raster) or the
  scene export (docs/design.md §5);
- ``aftir tank generate --kind wing --bays N --seed S -o wing.yaml`` writes a generated wing
  tank (:func:`~aftir_rl.core.tank.generate.generated_tank`: ``--kind`` wing or round);
- ``aftir tank export [--tank TANK] -o tank.stl [--walls walls.stl] [--yaml OUT.yaml]`` writes the
  tank's solids as one triangle mesh (needs ``aftir_rl[mesh]``), with ``--walls`` its inside
  (the box, narrowed by its taper) as a walls mesh, and with ``--yaml`` a tank file that reads
  them back.

A tank that cannot be read or written prints "error: <why>" and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

import yaml

from aftir_rl.cli.args import OneLineParser, add_int_option
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import AftirError
from aftir_rl.core.files import atomic_open
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank.generate import FAMILIES, MAX_BAYS, MAX_SEED, generated_tank
from aftir_rl.core.tank.loading import load_tank, tank_files, tank_from_mapping

__all__ = ["build_parser", "main"]

_TANK_HELP = "tank name in configs/tanks, a YAML path, or a generator spec wing:BAYS:SEED"


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir tank`` and its subcommands."""
    parser = OneLineParser(
        prog="aftir tank",
        description="Show a tank's raster or scene, generate a wing tank, or export a mesh "
        "(units cm). Without a subcommand: show.",
    )
    sub = parser.add_subparsers(dest="command", metavar="{show,generate,export}")
    show = sub.add_parser("show", help="the raster as z-slices, or the scene as JSON")
    _add_show_options(show)
    gen = sub.add_parser("generate", help="a generated wing tank as YAML")
    gen.add_argument(
        "--kind",
        choices=tuple(FAMILIES),
        default="wing",
        help="the generator's family: wing, or round (ribs with only round and oval holes)",
    )
    add_int_option(gen, "--bays", (1, MAX_BAYS), f"number of bays, 1 to {MAX_BAYS} (3)", 3)
    add_int_option(gen, "--seed", (0, MAX_SEED), "random seed (0)", 0)
    gen.add_argument("-o", "--output", required=True, help="the YAML file to write")
    export = sub.add_parser("export", help="the tank's solids as a triangle mesh (STL, OBJ, PLY)")
    export.add_argument("--tank", default=DEFAULT_TANK, help=_TANK_HELP)
    export.add_argument("-o", "--output", required=True, help="mesh file: .stl, .obj or .ply")
    export.add_argument("--walls", help="also write the tank's inside as a walls mesh")
    export.add_argument("--yaml", help="also write a tank YAML that reads the mesh files back")
    return parser


def _add_show_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tank", default=DEFAULT_TANK, help=_TANK_HELP)
    parser.add_argument("--json", action="store_true", help="print the scene export as JSON")


def _generate(args: argparse.Namespace) -> None:
    data = generated_tank(args.kind, args.bays, args.seed)
    tank_from_mapping(data, args.output)  # what is written reads back
    with atomic_open(args.output, "w") as fh:
        fh.write(f"# {data['description']}. Units: cm.\n")
        yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None, width=100)
    print(f"wrote {args.output}: {data['description']}")


def _export(args: argparse.Namespace) -> None:
    from aftir_rl.core.files import check_outputs
    from aftir_rl.core.tank.meshes import export_tank_mesh

    check_outputs([args.output, args.walls, args.yaml], tank_files(args.tank))
    tank = load_tank(args.tank)
    triangles = export_tank_mesh(tank, args.output, args.yaml, args.walls)
    also = [name for name in (args.walls, args.yaml) if name]
    print(f"wrote {args.output}: {triangles:,} triangles" + "".join(f", and {a}" for a in also))


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir tank`` (and ``python -m aftir_rl.tank``)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("show", "generate", "export", "-h", "--help"):
        argv = ["show", *argv]
    args = build_parser().parse_args(argv)
    try:
        if args.command == "generate":
            _generate(args)
        elif args.command == "export":
            _export(args)
        else:
            tank = load_tank(args.tank)
            print(json.dumps(tank.scene_dict()) if args.json else tank.ascii())
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
