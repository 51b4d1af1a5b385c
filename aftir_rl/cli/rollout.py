"""``aftir rollout RUN_DIR --target X Y Z -o DIR``: a policy's motions, drawn like the planner's.

A thin command line over :func:`aftir_rl.experiments.rollout.rollout`: for each target, the policy
of an SB3 run (loaded without unpickling; its mean actions, or sampled with ``--stochastic``) runs
once and ``DIR/<target>/trajectory.json`` (the planner's contract) and ``summary.json`` (tank, env,
result) are written, so ``aftir view DIR/<target>`` shows the arm moving, beside a planner's run if
given too. ``--random N`` draws N targets with the run's env instead (seeds from ``--seed``).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym

from aftir_rl.cli.args import (
    OneLineParser,
    add_stochastic_option,
    add_tank_option,
    add_target_option,
    bounded_int,
    check_tank,
)
from aftir_rl.cli.guard import cli
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.files import check_writable_dir, write_json
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank.loading import keep_run_tank
from aftir_rl.envs.registration import bare_env_id

__all__ = [
    "build_parser",
    "main",
    "policy_env_kwargs",
    "policy_parser",
    "policy_run",
    "policy_seed",
    "policy_targets",
]

#: The most targets one command rolls out.
MAX_TARGETS = 1000


def policy_parser(prog: str, what: str) -> argparse.ArgumentParser:
    """The options ``rollout`` and ``record`` share: the run, and ``--target`` or ``--random``."""
    parser = OneLineParser(prog=prog, description=what)
    parser.add_argument(
        "run", nargs="?", metavar="RUN_DIR", help="an SB3 or RLlib run directory (or its best/)"
    )
    parser.add_argument(
        "--pretrained",
        metavar="NAME",
        help="a policy shipped with the package instead of RUN_DIR (aftir pretrained lists them)",
    )
    add_target_option(parser, "a target [cm] (repeatable)")
    parser.add_argument(
        "--random",
        type=bounded_int(1, MAX_TARGETS),
        metavar="N",
        help=f"N targets drawn by the run's env (1..{MAX_TARGETS}) instead of --target",
    )
    parser.add_argument(
        "--seed", type=bounded_int(0, 2**31), default=0, metavar="S", help="first seed of --random"
    )
    add_tank_option(parser, "AFTIR-ArmFTL-v0 runs: roll out in this tank, not the run's own")
    add_stochastic_option(parser, "each episode")
    return parser


def policy_seed(args: argparse.Namespace, i: int) -> int | None:
    """The sampling seed of target ``i``'s episode: ``--stochastic SEED`` + ``i``, or None."""
    return None if args.stochastic is None else args.stochastic + i


def policy_env_kwargs(args: argparse.Namespace, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The run's env kwargs, in ``--tank`` if given; a motion is in one tank, not a pool.

    Raises:
        ConfigError: the tank is a pool or stream (the run's, without ``--tank``), or does not
            load.

    """
    from aftir_rl.envs.ftl.pool import evaluation_tank, pool_specs

    kwargs = dict(env_kwargs)
    if args.tank is not None:
        check_tank(args.tank)
        kwargs["tank"] = args.tank
    specs = pool_specs(evaluation_tank(kwargs.get("tank")))
    if specs is not None:
        what = "pool" if pool_specs(kwargs["tank"]) else "stream of tanks"
        raise ConfigError(
            f"the run trained on the {what} {kwargs['tank']}; a motion is in one tank: give "
            f"--tank ({specs[0]}, another of the {what}, or a tank it never saw)"
        )
    return kwargs


def policy_run(args: argparse.Namespace) -> Path:
    """The run directory of ``RUN_DIR`` or ``--pretrained NAME`` (one of them, not both)."""
    from aftir_rl.rl.pretrained import policy_dir

    if (args.run is None) == (args.pretrained is None):
        raise ConfigError("give RUN_DIR or --pretrained NAME (aftir pretrained lists them)")
    return Path(args.run) if args.pretrained is None else policy_dir(args.pretrained)


def policy_targets(args: argparse.Namespace, env_id: str, env_kwargs: dict[str, Any]) -> list[Any]:
    """The targets of ``--target`` or ``--random`` (one of them, not both)."""
    from aftir_rl.rl.sb3 import evaluation_targets

    if bool(args.target) == bool(args.random):
        raise ConfigError("give --target X Y Z (repeatable) or --random N")
    if args.random:
        return evaluation_targets(env_id, args.random, args.seed, env_kwargs)
    return [tuple(t) for t in args.target]


def _name(target: Any) -> str:
    return "target_" + "_".join(f"{v:.1f}" for v in target)


def build_parser() -> argparse.ArgumentParser:
    """The options of ``aftir rollout``."""
    parser = policy_parser(
        "aftir rollout",
        "Roll out an SB3 or RLlib run's policy to targets; write each "
        "motion as trajectory.json for aftir view.",
    )
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    return parser


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``aftir rollout``."""
    from aftir_rl.experiments.rollout import rollout
    from aftir_rl.experiments.runs import load_policy_run

    args = build_parser().parse_args(argv)
    run = policy_run(args)
    loaded = load_policy_run(run)
    algo, config, env_id, model = loaded.algo, loaded.config, loaded.env_id, loaded.model
    env_kwargs = policy_env_kwargs(args, config.env_kwargs)
    targets = policy_targets(args, env_id, env_kwargs)
    out = check_writable_dir(args.output, "--output")
    tank = env_kwargs.get("tank") or gym.spec(bare_env_id(env_id)).kwargs.get("tank", DEFAULT_TANK)
    reached = 0
    for i, target in enumerate(targets):
        folder = out / _name(target)
        folder.mkdir(exist_ok=True)
        result = rollout(model, env_id, env_kwargs, target, policy_seed(args, i))
        write_json(folder / "trajectory.json", result)
        summary = {k: v for k, v in result.items() if k != "motion"}
        summary.update(
            tank=keep_run_tank(tank, folder),
            algo=algo,
            env_id=config.env_id,
            run=args.pretrained or str(run.resolve()),
            policy_seed=policy_seed(args, i),
        )
        write_json(folder / "summary.json", summary)
        reached += result["complete"]
        print(
            f"{folder.name}: {'reached' if result['complete'] else 'missed'}, tip error "
            f"{result['tip_error_cm']:.2f} cm, clearance {result['min_clearance_cm']:.2f} cm, "
            f"{result['steps']} steps"
        )
    print(f"{reached}/{len(targets)} reached; aftir view {out}/<target> -o view.html shows one")
    return 0
