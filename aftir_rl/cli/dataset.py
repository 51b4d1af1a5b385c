"""``aftir dataset``: expert episodes of ``AFTIR-ArmFTL-v0`` as a Minari dataset.

A thin command line over :func:`aftir_rl.rl.demos.write_dataset`: the env's keyword arguments
come from a PPO config (default ``ppo_ftl_demos``, the recipe that learns from the dataset) and
``--env-kwargs``; the dataset goes to ``-o ROOT/<id>`` (``ROOT`` is what ``MINARI_DATASETS_PATH``
names for ``minari.load_dataset``). Run again with a larger ``--episodes`` to add to it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence

from aftir_rl.cli.args import (
    OneLineParser,
    add_int_option,
    add_key_values_option,
    add_seconds_option,
    add_seed_option,
    bounded_int,
)
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import ConfigError
from aftir_rl.envs.registration import ARM_FTL, bare_env_id

__all__ = ["build_parser", "main"]

#: The most episodes one dataset may hold.
MAX_EPISODES = 100_000


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir dataset``."""
    p = OneLineParser(
        prog="aftir dataset",
        description="Write expert episodes of AFTIR-ArmFTL-v0 (the follow-the-leader planner's "
        "motions, replayed in the env) as a Minari dataset.",
    )
    p.add_argument(
        "--episodes",
        type=bounded_int(1, MAX_EPISODES),
        required=True,
        metavar="N",
        help=f"episodes the dataset should hold, 1 to {MAX_EPISODES:,}",
    )
    p.add_argument("-o", "--output", required=True, metavar="ROOT", help="the datasets root")
    p.add_argument(
        "--config",
        default="ppo_ftl_demos",
        help="the PPO config whose env_kwargs the episodes use (default ppo_ftl_demos)",
    )
    add_key_values_option(p, "--env-kwargs", "env keyword arguments over the config's (e.g. bay:1)")
    add_seed_option(
        p, "reset seed of the first target (default 0); target j is drawn with seed + j"
    )
    p.add_argument("--id", default="aftir/armftl-expert-v0", help="Minari's dataset id")
    add_int_option(p, "--workers", (1, 64), "processes that plan (default 1)", 1, "W")
    add_seconds_option(
        p,
        "--max-seconds",
        30.0,
        "the expert's planning budget per target (default 30 s); a target it misses is skipped",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir dataset``."""
    args = build_parser().parse_args(argv)
    if not 0 < args.max_seconds <= 3600:
        raise ConfigError(f"--max-seconds must be in (0, 3600], got {args.max_seconds:g}")
    from tqdm import tqdm

    from aftir_rl.rl.demos import check_dataset_id, write_dataset
    from aftir_rl.rl.sb3.hyperparams import load_sb3_config, with_overrides

    check_dataset_id(args.id)
    config = with_overrides(load_sb3_config(args.config, "ppo"), "ppo", args.env_kwargs)
    if bare_env_id(config.env_id) != ARM_FTL:
        raise ConfigError(f"--config: the expert plays {ARM_FTL}, not {config.env_id}")
    start = time.perf_counter()
    bars: list[tqdm] = []  # made at the first episode, once every argument has been checked

    def progress(done: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(total=total, unit="ep", disable=args.no_progress))
        bars[0].n = done
        bars[0].refresh()

    try:
        out = write_dataset(
            args.output,
            args.episodes,
            args.seed,
            config.env_kwargs,
            args.id,
            args.workers,
            args.max_seconds,
            progress,
        )
    finally:
        for bar in bars:
            bar.close()
    out["seconds"] = round(time.perf_counter() - start, 1)
    if out["before"] >= args.episodes:
        print(
            f"{out['path']} already holds {out['before']} episodes ({args.episodes} asked): "
            "nothing added; a larger --episodes completes it, another --id starts a new one",
            file=sys.stderr,
        )
    print(json.dumps(out))
    return 0
