"""``aftir tune ALGO``: a hyperparameter sweep of PPO, SAC or TD3 on Ray Tune.

The sweep itself is :func:`aftir_rl.experiments.tune.run_sweep`; this module parses the command
line, builds the base config and prints the trials' table.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aftir_rl.cli.args import (
    MAX_ENVS,
    MAX_TIMESTEPS,
    OneLineParser,
    add_int_option,
    add_ray_options,
    add_seed_option,
)
from aftir_rl.cli.guard import cli, exit_with, preload
from aftir_rl.core.config import CONFIG_DIR
from aftir_rl.core.errors import ConfigError
from aftir_rl.experiments.search_space import load_search_space
from aftir_rl.experiments.tune import ALGOS, MAX_EVALUATIONS, MAX_TRIALS, run_sweep

if TYPE_CHECKING:
    from aftir_rl.rl.sb3.config import SB3Config

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir tune``."""
    parser = OneLineParser(
        prog="aftir tune",
        description="Hyperparameter sweep of an SB3 algorithm on Ray Tune: Optuna samples the "
        "search space, ASHA stops the trials that trail on eval/success_rate, every trial is a "
        "run directory, and the best config is written as a YAML for `aftir train`. Needs "
        'pip install "aftir_rl[ray]".',
    )
    parser.add_argument("algo", choices=ALGOS, metavar="ALGO", help="ppo, sac or td3")
    parser.add_argument(
        "--env",
        help="environment id, e.g. AFTIR-ArmReach-v0: without --config, the base is its entry in "
        "configs/hyperparams/ALGO.yml (default AFTIR-ArmReach-v0); with --config, replaces the "
        "config's",
    )
    add_int_option(
        parser, "--trials", (1, MAX_TRIALS), f"trials, 1 to {MAX_TRIALS:,} (default 8)", 8
    )
    add_ray_options(parser, "run the trials", default="local")
    parser.add_argument(
        "--logdir", default="runs", help="parent of the sweep folder (default runs/)"
    )
    per_trial = {
        "--total-timesteps": ((1, MAX_TIMESTEPS), None, "T", "training steps"),
        "--evaluations": ((1, MAX_EVALUATIONS), 4, "K", "evaluations (ASHA's rungs)"),
        "--n-envs": ((1, MAX_ENVS), None, "N", "envs (and CPUs): up to 64 subprocesses or rows"),
    }
    for flag, (bounds, default, metavar, what) in per_trial.items():
        told = "the config's" if default is None else default
        help = f"{what} of each trial, {bounds[0]} to {bounds[1]:,} (default {told})"
        add_int_option(parser, flag, bounds, help, default, metavar)
    parser.add_argument(
        "--config", help="base config: a named config or a path (default: the entry of --env)"
    )
    parser.add_argument("--space", help="search space (default: configs/search_spaces/ALGO.yaml)")
    add_seed_option(parser, "seed of every trial, 0 to 2**32-1 (default 0)")
    parser.add_argument("--quiet", action="store_true", help="no Ray Tune status tables")
    return parser


def _base_config(args: argparse.Namespace) -> SB3Config:
    """The config every trial starts from: ``--config`` or ``--env``'s entry, with overrides.

    Resolved and checked as ``aftir train`` resolves one (:func:`train_config`); its
    ``eval_freq`` makes ``--evaluations`` evaluations of each trial (ASHA's rungs).
    """
    from aftir_rl.rl.sb3 import train_config

    numbers = {"total_timesteps": args.total_timesteps, "n_envs": args.n_envs}
    run = train_config(args.algo, args.config, env=args.env, numbers=numbers)
    if len(run.stages) != 1:
        raise ConfigError(f"--config: {args.config} is a stage file; a sweep tunes one config")
    (config,) = run.stages
    # from 1 to total_timesteps: within eval_freq's bounds, as checked
    every = max(1, math.ceil(config.total_timesteps / args.evaluations))
    return dataclasses.replace(config, eval_freq=every)


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir tune``."""
    args = build_parser().parse_args(argv)
    from aftir_rl.experiments.distributed import check_ray_options

    check_ray_options(args.ray, args.workers)  # Ray installed, the address well formed
    preload("aftir_rl.rl.sb3", "ray.tune")  # torch, Ray
    base = _base_config(args)
    space_path = args.space or CONFIG_DIR / "search_spaces" / f"{args.algo}.yaml"
    space = load_search_space(space_path, args.algo, base)
    out = run_sweep(
        args.algo,
        base,
        space,
        args.trials,
        logdir=args.logdir,
        ray=args.ray,
        workers=args.workers,
        seed=args.seed,
        verbose=0 if args.quiet else 1,
    )
    _print_trials(out, [d.key for d in space], args.algo)
    return 0


def _print_trials(out: dict[str, Any], keys: list[str], algo: str) -> None:
    """Print the sweep's trials as a table, then where the sweep and its best config are."""
    print(f"| trial | {' | '.join(keys)} | success | tip error (cm) | steps | run |")
    print("|---:|" + "---:|" * len(keys) + "---:|---:|---:|---|")
    for i, r in enumerate(out["trials"]):
        values = " | ".join(f"{r[k]:.3g}" if isinstance(r[k], float) else str(r[k]) for k in keys)
        run = Path(r["run_dir"]).name if r["run_dir"] else "–"
        note = (
            f" (error: {r['error']})"
            if r["error"]
            else (" (stopped early)" if r["stopped_early"] else "")
        )
        print(
            f"| {i} | {values} | {r['success_rate']:.0%} | {r['tip_error_cm']:.2f} | "
            f"{r['timesteps']} | {run}{note} |"
        )
    print(f"sweep: {out['sweep_dir']}")
    print(f"best config: {out['best_yaml']} (aftir train {algo} --config {out['best_yaml']})")


if __name__ == "__main__":
    exit_with(main())
