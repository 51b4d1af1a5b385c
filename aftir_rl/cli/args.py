"""Options shared by the command lines (``train``, ``evaluate``, ``bench``, ``plan``).

Each adds one option to an ``argparse`` parser with the same flag, type, metavar and checks in
every command that has it; the help text is the command's own.
"""

from __future__ import annotations

import argparse

from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import ConfigError

__all__ = ["add_target_option", "add_margin_option", "add_ray_options", "check_margin"]


def add_target_option(parser: argparse.ArgumentParser, help: str, required: bool = False) -> None:
    """``--target X Y Z`` in cm, repeatable (one ``--target`` with ``required``)."""
    parser.add_argument(
        "--target",
        nargs=3,
        type=float,
        required=required,
        action="store" if required else "append",
        metavar=("X", "Y", "Z"),
        help=help,
    )


def add_margin_option(parser: argparse.ArgumentParser, help: str) -> None:
    """``--margin CM``, the clearance the arm keeps (default :data:`DEFAULT_MARGIN`)."""
    parser.add_argument("--margin", type=float, default=DEFAULT_MARGIN, metavar="CM", help=help)


def check_margin(margin: float) -> None:
    """Refuse a ``--margin`` outside 0 to 20 cm (a :class:`ConfigError`)."""
    if not 0 <= margin <= 20:
        raise ConfigError(f"--margin must be between 0 and 20 cm, got {margin}")


def add_ray_options(parser: argparse.ArgumentParser, what: str) -> None:
    """``--ray ADDRESS`` and ``--workers N``: ``what`` (e.g. "evaluate the runs") on Ray."""
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        help=f"{what} as Ray tasks: local (a Ray on this machine), auto or HOST:PORT (a "
        "cluster started with ray start); needs aftir_rl[ray]",
    )
    parser.add_argument(
        "--workers", type=int, metavar="N", help="CPUs of --ray local (default: every core)"
    )
