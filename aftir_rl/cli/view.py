"""``python -m aftir_rl.cli.view RUN_DIR... -o view.html``: an interactive 3D page of runs.

A thin command line over :func:`aftir_rl.viz.page.write_view`: the tank, each run's cell path, tip
route and, where ``trajectory.json`` has a motion, the arm moving along it (slider and play
button). The page embeds plotly.js and opens with no network. A run directory that cannot be read
prints "error: <why>" and exits with status 2. Imports neither torch nor stable-baselines3.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser, bounded_int
from aftir_rl.cli.guard import cli, exit_with
from aftir_rl.core.errors import AftirError

__all__ = ["build_parser", "main"]

#: The most animation frames of a page (``--max-frames``): each repeats the arm's traces.
MAX_FRAMES = 1000


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir view``."""
    from aftir_rl.viz.page import DEFAULT_MAX_FRAMES

    parser = OneLineParser(
        prog="aftir view",
        description="Write one self-contained HTML page showing runs in 3D: the tank, each run's "
        "cell path and tip route, and the arm moving along its motion (trajectory.json).",
    )
    parser.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run directories to overlay")
    parser.add_argument("-o", "--output", default="view.html", help="HTML file (default view.html)")
    parser.add_argument(
        "--tank",
        default=None,
        help="tank name or YAML path (default: the one a run names, else b737_center)",
    )
    parser.add_argument(
        "--max-frames",
        type=bounded_int(2, MAX_FRAMES),
        default=DEFAULT_MAX_FRAMES,
        metavar="N",
        help=f"most animation frames per page, 2 to {MAX_FRAMES:,} (default {DEFAULT_MAX_FRAMES})",
    )
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.cli.view`` (and ``aftir view``)."""
    from aftir_rl.core.files import check_outputs
    from aftir_rl.core.tank import tank_files
    from aftir_rl.viz.page import write_view

    args = build_parser().parse_args(argv)
    try:
        tank_inputs = tank_files(args.tank) if args.tank else []
        check_outputs([args.output], [*args.run_dirs, *tank_inputs])
        out = write_view(args.run_dirs, args.output, tank=args.tank, max_frames=args.max_frames)
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: cannot write {args.output}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB): open it in a browser")
    return 0


if __name__ == "__main__":
    exit_with(main())
