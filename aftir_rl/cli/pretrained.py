"""``aftir pretrained [NAME]``: the policies shipped with the package, or one policy's card.

A thin command line over :mod:`aftir_rl.rl.pretrained`: one row per policy (its env, recipe and
measured success on held-out targets), or with ``NAME`` its card as a few lines (``--json``: the
whole card). Give a name to
``aftir evaluate|rollout|record --pretrained NAME`` or to ``aftir_rl.rl.pretrained.load``.
"""

from __future__ import annotations

import argparse
import json
import textwrap
from collections.abc import Sequence
from typing import Any

from aftir_rl.cli.args import OneLineParser
from aftir_rl.cli.guard import cli
from aftir_rl.rl.pretrained import POLICY_DIR, card, names

__all__ = ["build_parser", "card_text", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir pretrained``."""
    parser = OneLineParser(
        prog="aftir pretrained",
        description="List the trained policies shipped with the package, or show one's card.",
    )
    parser.add_argument("name", nargs="?", help="a policy's name: print its card")
    parser.add_argument("--json", action="store_true", help="print the whole card as JSON")
    return parser


def _measured(m: dict[str, Any]) -> str:
    return (
        f"{m['success_rate']:.1%} success, {m['collision_rate']:.1%} contacts, tip error "
        f"{m['tip_error_cm']:.2f} cm, least clearance {m['min_clearance_cm']:.2f} cm on "
        f"{m['targets']} held-out targets (seed {m['seed']}..)"
    )


def card_text(c: dict[str, Any]) -> str:
    """A policy's card as a few lines a person reads: what it is, how it was made, what it did."""
    kwargs = ", ".join(f"{k}={v}" for k, v in c.get("env_kwargs", {}).items())
    machine = c.get("machine", {})
    lines = [
        f"{c['name']}: {c['algo'].upper()} on {c['env_id']}" + (f" ({kwargs})" if kwargs else ""),
        textwrap.fill(
            c["recipe"],
            100,
            initial_indent="  recipe:  ",
            subsequent_indent=" " * 11,
            break_long_words=False,
            break_on_hyphens=False,
        ),
        f"  trained: {c['training']['timesteps']:,} steps, {c['training']['minutes']:.1f} min, "
        f"seed {c['seed']}, on {machine.get('cpu', '?')} ({machine.get('cores', '?')} cores)",
        f"  test:    {_measured(c['test'])}",
    ]
    if "chosen" in c:
        lines.append(f"  chosen:  {c['chosen']['from']}, by {c['chosen']['by']}")
    return "\n".join(lines)


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir pretrained``."""
    args = build_parser().parse_args(argv)
    if args.name is not None:
        c = card(args.name)
        print(json.dumps(c, indent=2) if args.json else card_text(c))
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
