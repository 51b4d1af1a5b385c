"""Training command line: ``python -m aftir_rl.train q_table|ppo|sac|td3``.

One run directory per target (Q-learning) or per run (SB3) under ``--logdir``, named
``{algo}__{env}__{target}__{seed}__{time}`` and built under a hidden ``.partial`` name until it is
complete; its files (``q_table.npz``, ``path.json``, ``trajectory.json``, ``config.json``,
``summary.json``, ``model.zip``...) are described in docs/design.md §9, its TensorBoard tags in
§10. User errors (a bad target, a malformed config, a corrupt checkpoint) print one line and exit
with status 2.

This module is the command line only: the runs are :mod:`aftir_rl.rl`'s, the replay and
the measures :mod:`aftir_rl.experiments.runs`'s.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from aftir_rl.cli.args import (
    MAX_ENVS,
    MAX_EPISODES,
    MAX_TIMESTEPS,
    OneLineParser,
    add_int_option,
    add_key_values_option,
    add_margin_option,
    add_motion_option,
    add_run_dir_options,
    add_seconds_option,
    add_seed_option,
    add_tank_option,
    add_target_option,
    check_margin,
    check_tank,
)
from aftir_rl.cli.guard import cli, exit_with
from aftir_rl.core import interrupts
from aftir_rl.core.config import CONFIG_DIR, DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN
from aftir_rl.core.errors import AftirError, ConfigError
from aftir_rl.experiments.runs import load_q_table_config
from aftir_rl.rl.common import DEFAULT_SB3_ENV_ID

if TYPE_CHECKING:
    from aftir_rl.rl.sb3.config import TrainConfig
    from aftir_rl.rl.tabular.learning import QLearningConfig

# The trainers (torch, numba) are imported when a command runs: Ctrl-C is honoured from then.
__all__ = ["build_parser", "main", "load_q_table_config"]

ALGOS = ("q_table", "ppo", "sac", "td3")


def _print_summary(s: dict[str, Any]) -> None:
    verdict = "optimal" if s["optimal"] else ("reached, not optimal" if s["success"] else "")
    if not verdict:  # the greedy path missed; the motion may still reach it (said below)
        reached = s.get("motion", {}).get("complete")
        verdict = "missed; the motion below reaches the target" if reached else "missed"
    target = ", ".join(f"{v:g}" for v in s["target"])
    print(
        f"target ({target}) cm -> cell {tuple(s['target_cell'])}: {s['episodes']} episodes in "
        f"{s['seconds']:.2f} s; greedy path {s['length_steps']} steps, BFS optimum "
        f"{s['bfs_optimal_steps']} ({verdict}); {s['path_length_cm']:.0f} cm"
    )
    print("  cells: " + " ".join("(" + ",".join(map(str, c)) + ")" for c in s["cells"]))
    if "motion" in s:
        m = s["motion"]
        if m["complete"]:
            dev = m["ftl_deviation_cm"]
            print(
                f"  motion: follow-the-leader, {m['n_sections']} sections, {m['entries']} entries "
                f"in {m['seconds']:.2f} s; clearance {m['min_clearance_cm']:.2f} cm, FTL deviation "
                f"max {dev[0]:.2f} / mean {dev[1]:.2f} cm, tip error {m['tip_error_cm']:.1e} cm"
            )
            if m["route_departure_cm"] is not None:
                far, mean = m["route_departure_cm"]
                print(
                    f"  the tip passes {mean:.1f} cm from the cell centres on average "
                    f"({far:.1f} max)"
                )
        else:
            print(f"  motion: none in {m['seconds']:.2f} s: {m['reason']}")
    if "trajectory" in s:
        t = s["trajectory"]
        print(
            f"  postures: {t['postures']}/{t['waypoints']} waypoints; {t['blocked_moves']} of "
            f"{t['moves']} moves collide ({t['bridged_moves']} bridged by RRT-Connect); "
            f"largest joint step {t['max_joint_step_deg']:.0f} deg"
        )
        for failure in t["failures"]:
            print(f"  no posture at {failure}")
    print(f"  run dir: {s['run_dir']}")


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m aftir_rl.train``: one subcommand per algorithm."""
    parser: argparse.ArgumentParser = OneLineParser(
        prog="aftir train",
        description="Train an agent on an aftir_rl environment and log the run to TensorBoard.",
    )
    sub = parser.add_subparsers(dest="algo", required=True, metavar="ALGO")
    _add_q_table_parser(sub)
    for algo in ("ppo", "sac", "td3"):
        _add_sb3_parser(sub, algo)
    return parser


_SEED_HELP = "random seed (default 0; to 2**32-1)"


def _add_q_table_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``q_table`` subcommand to the subparsers ``sub``."""
    q = sub.add_parser(
        "q_table",
        help="tabular Q-learning on AFTIR-Tank-v0 (filomat2018)",
        description="Tabular Q-learning on the rasterised tank, one run directory per target.",
    )
    q.add_argument(
        "--config",
        help="YAML of QLearningConfig fields (default: configs/q_table.yaml, or with --resume "
        "the resumed run's own)",
    )
    q.add_argument(
        "--tank",
        help="tank name, YAML path or generator spec such as wing:3:7 (overrides the config's)",
    )
    add_target_option(
        q, "target point in cm; repeat for several (default: the tank's reference targets)"
    )
    add_int_option(
        q,
        "--episodes",
        (1, MAX_EPISODES),
        f"training episodes per target, 1 to {MAX_EPISODES:,} (overrides config)",
    )
    q.add_argument(
        "--all-targets",
        action="store_true",
        help="one goal-conditioned run (AFTIR-TankGoal-v0) that learns every reachable cell",
    )
    add_seed_option(q, _SEED_HELP)
    add_run_dir_options(
        q, "parent of the run directories (default runs/)", "q_table.npz (q_table_goal.npz)"
    )
    q.add_argument(
        "--no-postures",
        action="store_true",
        help="skip turning the greedy path into arm postures (trajectory.json)",
    )
    add_motion_option(
        q,
        "ftl: follow-the-leader motion along a route from the learned cells (default); "
        "progressive: the papers' posture per cell, continued and bridged",
    )
    add_margin_option(
        q, f"clearance of the arm's surface along the motion (default {DEFAULT_MARGIN:g} cm)"
    )
    add_seconds_option(
        q,
        "--bridge-seconds",
        DEFAULT_BRIDGE_SECONDS,
        "RRT-Connect's budget for each colliding "
        f"move of the postures, 0 for none (default {DEFAULT_BRIDGE_SECONDS:g})",
    )


def _add_sb3_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser], algo: str) -> None:
    """Add the subcommand of the SB3 algorithm ``algo`` to the subparsers ``sub``."""
    p = sub.add_parser(
        algo,
        help=f"{algo.upper()} (Stable-Baselines3) on an arm env",
        description=f"{algo.upper()} on a continuous AFTIR arm env, one run directory.",
    )
    p.add_argument(
        "--config",
        help="YAML of SB3Config fields over the env's hyperparameters, or a stage file: a path or "
        "a shipped name (aftir configs lists them); default: the entry of --env in "
        f"configs/hyperparams/{algo}.yml",
    )
    p.add_argument(
        "--env",
        help="environment id, e.g. AFTIR-ArmFTL-v0: without --config, its entry in "
        f"configs/hyperparams/{algo}.yml (default {DEFAULT_SB3_ENV_ID}); with --config, overrides "
        "its env_id",
    )
    add_tank_option(p, "AFTIR-ArmFTL-v0's tank (a config names none)")
    add_int_option(
        p,
        "--total-timesteps",
        (0, MAX_TIMESTEPS),
        f"training steps, 0 to {MAX_TIMESTEPS:,} (overrides config; 0: evaluate only)",
        metavar="T",
    )
    add_int_option(
        p,
        "--n-envs",
        (1, MAX_ENVS),
        "parallel envs (overrides config): up to 64 subprocesses, "
        f"or up to {MAX_ENVS:,} rows of a batched env",
    )
    add_seed_option(p, _SEED_HELP)
    add_key_values_option(
        p,
        "--env-kwargs",
        "env keyword arguments over the config's, RL Zoo's spelling (e.g. "
        "bay:1 guide:true; values read as YAML)",
    )
    add_key_values_option(
        p,
        "--hyperparams",
        f"{algo.upper()} hyperparameters over the config's (e.g. learning_rate:1e-4 n_epochs:5)",
    )
    _add_run_numbers(p)
    add_run_dir_options(p, "parent of the run directory", "model.zip")
    if algo in ("ppo", "sac"):
        _add_rllib_options(p, algo)


def _add_rllib_options(p: argparse.ArgumentParser, algo: str) -> None:
    """``--rllib``, ``--ray ADDRESS`` and ``--env-runners N``: the same config with RLlib."""
    group = p.add_argument_group(
        "RLlib", f"the same config trained by RLlib's {algo.upper()}, here or on a Ray cluster"
    )
    group.add_argument(
        "--rllib",
        action="store_true",
        help="train with RLlib instead of SB3 (needs aftir_rl[rllib]); --resume takes an RLlib run",
    )
    group.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="with --rllib: local (default, a Ray on this machine), auto or HOST:PORT (a "
        "cluster's head node, started with ray start --head)",
    )
    add_int_option(
        group,
        "--env-runners",
        (0, 256),
        "with --rllib: env runner processes sharing --n-envs, each a Ray actor with one CPU "
        "anywhere on the cluster; 0: the trainer samples itself (default 1)",
    )


def _add_run_numbers(p: argparse.ArgumentParser) -> None:
    """Add RL Zoo's ``--eval-freq``, ``--eval-episodes``, ``--save-freq``, and ``--demos``."""
    steps = (1, MAX_TIMESTEPS)
    add_int_option(
        p,
        "--eval-freq",
        steps,
        "steps between evaluations (overrides config; default: every 5%% of the run)",
        metavar="T",
    )
    add_int_option(
        p,
        "--eval-episodes",
        (1, 1000),
        "fixed evaluation targets, up to 1,000 (overrides config's eval_targets)",
    )
    add_int_option(
        p,
        "--save-freq",
        steps,
        "steps between checkpoints (overrides config; default: every 10%% of the run)",
        metavar="T",
    )
    p.add_argument(
        "--demos",
        metavar="DATASET",
        help="behaviour-clone this Minari dataset (aftir dataset) into the new PPO policy first",
    )
    add_int_option(p, "--bc-epochs", (1, 1000), "passes over the demonstrations (default 20)", 20)


def _train_config(args: argparse.Namespace) -> TrainConfig:
    """The run ``args`` asks for, resolved and checked once (:func:`train_config`).

    The numbers of the command line, ``--env-kwargs``, ``--hyperparams`` and ``--tank`` apply to
    every stage (a short try of a whole curriculum); ``--env`` alone trains the env's entry in the
    hyperparameter file (or in ``--config``'s, if it is one), with a named config it replaces the
    config's env. ``--resume`` without ``--config`` trains the resumed run's own config.
    """
    from aftir_rl.rl.sb3.hyperparams import train_config

    if args.tank is not None:
        check_tank(args.tank)
    numbers = {
        "n_envs": args.n_envs,
        "total_timesteps": args.total_timesteps,
        "eval_freq": args.eval_freq,
        "eval_targets": args.eval_episodes,
        "checkpoint_freq": args.save_freq,
    }
    return train_config(
        args.algo,
        args.config,
        env=args.env,
        resume=args.resume,
        tank=args.tank,
        env_kwargs=args.env_kwargs,
        hyperparams=args.hyperparams,
        numbers=numbers,
        seed=args.seed,
        logdir=args.logdir,
        progress_bar=not args.no_progress,
        demos=args.demos,
        bc_epochs=args.bc_epochs,
    )


def _main_rllib(args: argparse.Namespace) -> int:
    """``ppo|sac --rllib``: the config resolved as SB3's, trained by RLlib (one stage)."""
    run = _train_config(args)
    if len(run.stages) > 1 or run.demos is not None:
        raise ConfigError("--rllib trains one config: no stage file and no --demos")
    with interrupts.held():  # torch and Ray: Ctrl-C is taken once they are imported
        from aftir_rl.experiments.distributed import ray_session
        from aftir_rl.rl.rllib.train import check_rllib_run, train_rllib

    (config,) = run.stages
    runners = 1 if args.env_runners is None else args.env_runners
    check_rllib_run(config, runners, run.algo)  # before Ray starts
    address = args.ray or "local"  # local: a Ray of one CPU per env runner
    with ray_session(address, max(runners, 1) if address == "local" else None):
        s = train_rllib(
            config,
            algo=run.algo,
            seed=run.seed,
            logdir=run.logdir,
            resume=run.resume,
            env_runners=runners,
            progress_bar=run.progress_bar,
        )
    _print_run(f"{run.algo.upper()} (RLlib, {runners} env runner{'s' * (runners != 1)})", s)
    return 0


def _print_run(what: str, s: dict[str, Any]) -> None:
    """A trained run's line (steps, time, last evaluation) and its run directory."""
    print(
        f"{what} on {s['env_id']}: {s['timesteps']} steps in {s['seconds']:.0f} s; evaluation: "
        f"success {s['success_rate']:.0%}, tip error {s['tip_error_cm']:.1f} cm, path "
        f"{s['path_length_cm']:.0f} cm, collisions {s['collision_rate']:.0%}"
    )
    print(f"  run dir: {s['run_dir']}")


def _main_sb3(args: argparse.Namespace) -> int:
    if getattr(args, "rllib", False):
        return _main_rllib(args)
    for flag in ("ray", "env_runners"):
        if getattr(args, flag, None) is not None:
            raise ConfigError(f"--{flag.replace('_', '-')} is an RLlib option: add --rllib")
    with interrupts.held():  # torch: Ctrl-C is taken once it is imported
        from aftir_rl.rl.sb3.train import train_run

    from aftir_rl.rl.sb3.config import rollout_steps

    run = _train_config(args)
    for config in run.stages:  # the steps asked are not a whole number of rollouts: say so
        rollout, asked = rollout_steps(run.algo, config), config.total_timesteps
        if asked % rollout:
            print(
                f"note: {run.algo.upper()} collects {rollout:,} steps per update "
                f"({config.n_envs} envs), so {-(-asked // rollout) * rollout:,} steps are "
                f"trained for --total-timesteps {asked:,}"
            )
    pretrain = None
    if run.demos is not None:
        from aftir_rl.rl.imitation import pretrainer

        pretrain = pretrainer(run.demos, run.stages[0], run.bc_epochs, run.seed)
    if len(run.stages) > 1:
        print(f"{len(run.stages)} stages, each resumed from the one before: {run.logdir}/stage<k>/")
    summaries = train_run(run, pretrain)
    for k, s in enumerate(summaries):
        stage = f"stage {k}: " if len(summaries) > 1 else ""
        _print_run(f"{stage}{run.algo.upper()}", s)
    return 0


def _q_table_config(args: argparse.Namespace) -> QLearningConfig:
    """The ``QLearningConfig`` of ``--config`` with ``--episodes``; the other numbers checked.

    Without ``--config``: the config of the run ``--resume`` names, else ``configs/q_table.yaml``.

    Raises:
        AftirError: the config or a number of the command line is refused.

    """
    config = None
    if args.config is None and args.resume is not None:
        from aftir_rl.rl.tabular.train import resumed_config

        config = resumed_config(args.resume, args.all_targets)
    if config is None:
        config = load_q_table_config(args.config or CONFIG_DIR / "q_table.yaml")
    if args.tank is not None:
        from aftir_rl.core.tank import load_tank

        load_tank(args.tank)  # a bad tank is one line before anything runs
        config = dataclasses.replace(config, tank=args.tank)
    if args.episodes is not None:
        if args.episodes < 1:
            raise ConfigError(f"--episodes must be at least 1, got {args.episodes}")
        config = dataclasses.replace(config, episodes=args.episodes)
    check_margin(args.margin)
    return config


def _main_all_targets(args: argparse.Namespace, config: QLearningConfig) -> int:
    """``q_table --all-targets``: one goal-conditioned run; print its summary."""
    with interrupts.held():  # torch (the logger): Ctrl-C is taken once it is imported
        from aftir_rl.rl.tabular.train import train_q_table_all_targets

    if args.target:
        raise ConfigError("--all-targets learns every cell: drop --target")
    s = train_q_table_all_targets(
        config,
        seed=args.seed,
        logdir=args.logdir,
        progress_bar=not args.no_progress,
        resume=args.resume,
    )
    print(
        f"every target of {s['tank']}: {s['n_goals']} goals, {s['episodes']} episodes "
        f"each in {s['seconds']:.1f} s; greedy paths reach {s['n_reached']} and are "
        f"BFS-optimal for {s['n_optimal']}"
    )
    print(f"  run dir: {s['run_dir']}")
    return 0


def _main_q_table(args: argparse.Namespace) -> int:
    """``q_table``: one run per target (the tank's reference targets by default), summarised."""
    with interrupts.held():  # torch (the logger): Ctrl-C is taken once it is imported
        from aftir_rl.rl.tabular.train import resumed_target, train_q_table

    config = _q_table_config(args)
    if args.all_targets:
        return _main_all_targets(args, config)
    targets = args.target
    if targets is None and args.resume:  # the checkpoint's own target
        targets = [resumed_target(args.resume)]
    if targets is None:
        from aftir_rl.core.tank import load_tank

        targets = [list(t) for t in load_tank(config.tank).targets]
    summaries = train_q_table(
        config,
        targets,
        seed=args.seed,
        logdir=args.logdir,
        resume=args.resume,
        progress_bar=not args.no_progress,
        postures=not args.no_postures,
        bridge_seconds=args.bridge_seconds,
        motion=args.motion,
        margin=args.margin,
    )
    for s in summaries:
        _print_summary(s)
    return 0


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.train``."""
    args = build_parser().parse_args(argv)
    try:
        return _main_q_table(args) if args.algo == "q_table" else _main_sb3(args)
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    exit_with(main())
