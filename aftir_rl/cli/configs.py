"""``aftir configs [FOLDER]``: the configs shipped with the package, by the name ``--config`` takes.

A thin command line over :func:`~aftir_rl.core.shipped.shipped_configs`: one row per config, its
name and the first line of its leading comment.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from aftir_rl.cli.args import OneLineParser
from aftir_rl.cli.guard import cli
from aftir_rl.core.config import CONFIG_DIR, MAX_YAML_BYTES, one_line, read_limited
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.shipped import find_config, shipped_configs

__all__ = ["build_parser", "main"]


_ABBREVIATIONS = (" eq", " e.g", " i.e", " cf", " vs")


def _summary(name: str) -> str:
    """The first sentence of a shipped config's leading comment (its purpose), or ``""``."""
    raw = read_limited(find_config(name), MAX_YAML_BYTES, ConfigError)
    words: list[str] = []
    for line in raw.decode("utf-8", "replace").splitlines():
        if not line.startswith("#"):
            break
        words += line.lstrip("#").split()
    text, depth = " ".join(words), 0
    for i, char in enumerate(text):  # the first sentence: up to ". X" or ": " outside brackets
        depth += (char in "([") - (char in ")]")
        rest = text[i + 1 : i + 3]
        period = char == "." and not text[:i].endswith(_ABBREVIATIONS) and not rest[1:].islower()
        if depth == 0 and rest[:1] == " " and (char == ":" or period):
            return one_line(text[: i + 1])
    return one_line(text)


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir configs``."""
    parser = OneLineParser(
        prog="aftir configs",
        description="List the configs shipped with the package: give a name to --config "
        "(e.g. aftir train ppo --config ppo_ftl) or to --tank (tanks/NAME without tanks/).",
    )
    parser.add_argument(
        "folder",
        nargs="?",
        default="",
        choices=["", "hyperparams", "tanks", "search_spaces"],
        help="only the hyperparameter files, the tanks or the search spaces (default: everything)",
    )
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir configs``."""
    args = build_parser().parse_args(argv)
    names = shipped_configs(args.folder)
    width = max(map(len, names), default=0)
    for name in names:
        print(f"{name:<{width}}  {_summary(f'{args.folder}/{name}' if args.folder else name)}")
    print(f"({len(names)} in {CONFIG_DIR / args.folder})")
    if args.folder in ("", "tanks"):
        print("--tank also takes a YAML path, or wing:BAYS:SEED for a generated wing tank")
    return 0
