"""``aftir pretrained [NAME]``: the policies shipped with the package, or one policy's card.

A thin command line over :mod:`aftir_rl.rl.pretrained`: one row per policy (its env, recipe and
measured success on held-out targets), or with ``NAME`` its whole card as JSON. Give a name to
``aftir evaluate|rollout|record --pretrained NAME`` or to ``aftir_rl.rl.pretrained.load``.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser
from aftir_rl.cli.guard import cli
from aftir_rl.rl.pretrained import POLICY_DIR, card, names

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir pretrained``."""
    parser = OneLineParser(
        prog="aftir pretrained",
        description="List the trained policies shipped with the package, or show one's card.",
    )
    parser.add_argument("name", nargs="?", help="a policy's name: print its card as JSON")
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir pretrained``."""
    args = build_parser().parse_args(argv)
    if args.name is not None:
        print(json.dumps(card(args.name), indent=2))
        return 0
    shipped = names()
    for name in shipped:
        c = card(name)
        test = c["test"]
        kwargs = ", ".join(f"{k}={v}" for k, v in c.get("env_kwargs", {}).items())
        print(
            f"{name}: {c['algo'].upper()} on {c['env_id']}{f' ({kwargs})' if kwargs else ''}, "
            f"{c['training']['timesteps']:,} steps; {test['success_rate']:.1%} success, "
            f"{test['collision_rate']:.1%} contacts on {test['targets']} held-out targets "
            f"(seed {test['seed']}..)"
        )
    print(f"({len(shipped)} in {POLICY_DIR})")
    return 0
