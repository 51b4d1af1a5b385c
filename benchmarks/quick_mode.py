"""The scripts' ``--quick`` mode: the same tables on smaller sets and shorter budgets.

``make bench`` runs every script with ``--quick`` (a few minutes on 2 cores), ``make bench-full``
without it: the full tables, the numbers of docs/benchmarks.md. Each script names its quick
values; ``--quick`` takes them for the options left at their defaults, and the script prints
:func:`print_header` above its tables, so that a quick table says what it was measured on.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping


def _flags(values: Mapping[str, object]) -> str:
    return " ".join(f"--{name.replace('_', '-')} {value}" for name, value in values.items())


def parse_args(parser: argparse.ArgumentParser, quick: Mapping[str, object]) -> argparse.Namespace:
    """Add ``--quick`` to ``parser``, parse, and apply ``quick`` to the options left at default."""
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"the quick set of make bench: {_flags(quick)} (options given keep their value)",
    )
    args = parser.parse_args()
    if args.quick:
        for name, value in quick.items():
            if getattr(args, name) == parser.get_default(name):
                setattr(args, name, value)
    return args


def print_header(args: argparse.Namespace, quick: Mapping[str, object]) -> None:
    """Print, for a quick run, the line above its tables that says so (nothing for a full run)."""
    if args.quick:
        used = {name: getattr(args, name) for name in quick}
        print(
            f"Quick set (make bench): {_flags(used)}; the full tables: make bench-full "
            "(docs/benchmarks.md)\n"
        )
