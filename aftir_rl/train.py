"""Training command line: ``python -m aftir_rl.train q_table``.

One run directory per target under ``--logdir``, named
``{algo}__{env}__{target}__{seed}__{time}`` (design.md §8), holding:

- ``q_table.npz``: the table and its metadata (resume with ``--resume``);
- ``trajectory.json``: a checked arm posture for every cell of that path and the exact target
  (:mod:`aftir_rl.posture.trajectory`), unless ``--no-postures``;
- ``path.json``: the greedy tip path, ``{"target", "target_cell", "cells", "points_cm", ...}``,
  start cell first, target cell last;
- ``progress.csv`` and a TensorBoard event file with ``rollout/ep_rew_mean``,
  ``rollout/ep_len_mean``, ``eval/success_rate``, ``eval/tip_error_cm``, ``eval/path_length_cm``,
  the picture ``paths/<target>`` and the hyperparameters as text.

The directory is built under a hidden ``.partial`` name and renamed when the run is complete, so a
failed or interrupted run leaves no directory that looks finished. User errors (a bad target, a
malformed config, a corrupt checkpoint) print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shutil
import sys
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from aftir_rl.atomic import write_json
from aftir_rl.config import (
    CONFIG_DIR,
    DEFAULT_BRIDGE_SECONDS,
    DEFAULT_MARGIN,
    brief,
    from_mapping,
    read_yaml,
)
from aftir_rl.errors import AftirError, CheckpointError, ConfigError
from aftir_rl.safety import cli

if TYPE_CHECKING:
    from aftir_rl.envs.tank_grid import TankGridEnv

__all__ = ["main", "train_q_table", "load_q_table_config"]

ALGOS = ("q_table", "ppo", "sac", "td3")


def load_q_table_config(path: str | Path) -> Any:
    """Read ``configs/q_table.yaml`` (or another file) into a ``QLearningConfig``."""
    from aftir_rl.agents.q_table import QLearningConfig

    return from_mapping(QLearningConfig, read_yaml(path), str(path))


def _target_tag(target: Sequence[float]) -> str:
    return "_".join(f"{float(v):g}" for v in target)


def _run_name(algo: str, env_id: str, target: Sequence[float] | str, seed: int) -> str:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    tag = target if isinstance(target, str) else _target_tag(target)
    return f"{algo}__{env_id}__{tag}__{seed}__{stamp}"


def _check_env_id(env_id: str, allowed: Sequence[str], algo: str) -> str:
    """The bare id of ``env_id`` (``ID`` or ``aftir_rl:ID``); any other module is never imported."""
    bare = env_id[len("aftir_rl:") :] if env_id.startswith("aftir_rl:") else env_id
    if bare not in allowed:
        raise ConfigError(
            f"{algo} cannot train on {brief(env_id)}; use one of {', '.join(allowed)} "
            "(--env or env_id)"
        )
    return bare


def _hyperparameter_text(params: dict[str, Any]) -> str:
    rows = "\n".join(f"|{k}|{v}|" for k, v in params.items())
    return "|param|value|\n|-|-|\n" + rows


def _greedy_path_summary(
    agent: Any, env: Any, target: Sequence[float], max_steps: int
) -> dict[str, Any]:
    """The greedy path of a trained agent as ``path.json`` holds it, with its BFS optimum."""
    from aftir_rl.agents.q_table import greedy_rollout

    base = env.unwrapped
    states, success = greedy_rollout(agent, env, max_steps=max_steps)
    cells = [base.raster.cell(s) for s in states]
    points = np.array([base.raster.cell_center(c) for c in cells])
    optimum = int(base.tank.reachable[base.target_cell])
    return {
        "target": [float(v) for v in target],
        "target_cell": list(base.target_cell),
        "cells": [list(c) for c in cells],
        "points_cm": points.tolist(),
        "success": success,
        "length_steps": len(cells) - 1,
        "bfs_optimal_steps": optimum,
        "optimal": success and len(cells) - 1 == optimum,
        "tip_error_cm": float(np.linalg.norm(points[-1] - base.target_point)),
        "path_length_cm": float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))),
        "episodes": agent.episodes_done,
    }


def train_q_table(
    config: Any,
    targets: Sequence[Sequence[float]],
    seed: int = 0,
    logdir: str | Path = "runs",
    resume: str | Path | None = None,
    progress_bar: bool = True,
    postures: bool = True,
    bridge_seconds: float = DEFAULT_BRIDGE_SECONDS,
    motion: str = "ftl",
    margin: float = DEFAULT_MARGIN,
) -> list[dict[str, Any]]:
    """Train one Q-table per target and write a run directory for each.

    Args:
        config: a ``QLearningConfig``.
        targets: target points [cm].
        seed: seed of exploration and of the env.
        logdir: parent of the run directories.
        resume: a ``q_table.npz`` (or a run directory holding one) to continue training from;
            only with a single target, which must be the checkpoint's.
        progress_bar: show a tqdm bar per target.
        postures: turn the greedy path into joint variables (``trajectory.json``, a picture of
            the arm under ``paths/<target>_arm``).
        bridge_seconds: RRT-Connect's budget for each move of that trajectory that collides
            (0: none; see :func:`aftir_rl.posture.motion.bridge`); ``progressive`` only.
        motion: ``"ftl"`` (default): a follow-the-leader motion along a route planned from the
            learned cells (:func:`aftir_rl.motion.plan.plan_motion`); ``"progressive"``: the
            papers' way, a posture per cell continued from the previous one.
        margin: clearance [cm] the arm's surface keeps along the motion (``ftl``).

    Returns:
        One summary dict per target (what ``path.json`` holds, plus ``run_dir`` and ``seconds``).

    Raises:
        TargetError: a target outside the box, in an obstructed cell or unreachable; checked for
            every target before any training starts.
        CheckpointError: ``resume`` is unreadable or was trained for another env or target.

    """
    import gymnasium as gym
    from stable_baselines3.common.logger import Image, configure

    from aftir_rl.agents.q_table import QLearning
    from aftir_rl.plotting import render_path

    _check_env_id(config.env_id, ("AFTIR-Tank-v0",), "q_table")
    # Make (and so validate) every env before training anything.
    envs = [
        gym.make(
            config.env_id,
            tank=config.tank,
            target=tuple(float(v) for v in t),
            step_penalty=config.step_penalty,
            max_episode_steps=config.max_episode_steps,
        )
        for t in targets
    ]
    checkpoint = None
    if resume is not None:
        checkpoint = Path(resume)
        if checkpoint.is_dir():
            checkpoint = checkpoint / "q_table.npz"
        if len(envs) != 1:
            raise CheckpointError("--resume continues one run: give at most one --target")
    summaries = []
    for target, env in zip(targets, envs):
        base = cast("TankGridEnv", env.unwrapped)  # config.env_id is AFTIR-Tank-v0 (checked above)
        if checkpoint is not None:
            agent = QLearning.load(checkpoint, env)
            meta = agent.metadata
            if meta.get("target_cell") not in (None, list(base.target_cell)):
                raise CheckpointError(
                    f"{checkpoint}: trained for target cell {meta['target_cell']}, not "
                    f"{list(base.target_cell)}; resume with the same --target"
                )
            if meta.get("tank_fingerprint", base.tank.fingerprint) != base.tank.fingerprint:
                raise CheckpointError(
                    f"{checkpoint}: trained in another tank ({brief(meta.get('tank'))}) than "
                    f"{config.tank!r}; resume with the tank it was trained in"
                )
        else:
            agent = QLearning.from_config(env, config, seed=seed)
        name = _run_name("q_table", config.env_id, target, seed)
        logdir = Path(logdir)
        partial = logdir / f".{name}.partial"
        partial.mkdir(parents=True, exist_ok=False)
        try:
            logger = configure(str(partial), ["csv", "tensorboard"])
            params = {**dataclasses.asdict(config), "seed": seed, "target": list(target)}
            logger.record("hyperparameters", _hyperparameter_text(params), exclude=("csv",))
            logger.dump(step=agent.num_timesteps)
            start = time.perf_counter()
            agent.learn(
                config.episodes,
                progress_bar=progress_bar,
                logger=logger,
                log_interval=config.log_interval,
            )
            seconds = time.perf_counter() - start
            summary = _greedy_path_summary(agent, env, target, config.max_episode_steps)
            summary["seconds"] = seconds
            success, optimum = summary["success"], summary["bfs_optimal_steps"]
            tip_error, length_cm = summary["tip_error_cm"], summary["path_length_cm"]
            points, steps = np.array(summary["points_cm"]), summary["length_steps"]
            logger.record("eval/path_length_steps", steps)
            logger.record("eval/bfs_optimal_steps", optimum)
            picture = render_path(
                base.tank,
                points,
                base.target_point,
                title=f"Q-learning greedy path to {_target_tag(target)} "
                f"({steps} steps, BFS {optimum})",
            )
            logger.record(
                f"paths/{_target_tag(target)}",
                Image(picture, "HWC"),
                exclude=("stdout", "log", "json", "csv"),
            )
            trajectory = None
            if postures and motion == "ftl":
                trajectory = _log_motion(logger, base, summary, target, margin)
            elif postures:
                trajectory = _log_trajectory(
                    logger, base, points, target, summary, bridge_seconds, seed
                )
                logger.record("eval/success_rate", float(success))
                logger.record("eval/tip_error_cm", tip_error)
                logger.record("eval/path_length_cm", length_cm)
            else:
                logger.record("eval/success_rate", float(success))
            if trajectory is None or getattr(trajectory, "motion", None) is None:
                # one picture card in every run: the cell path where there is no FTL motion
                logger.record(
                    "paths/eval", Image(picture, "HWC"), exclude=("stdout", "log", "json", "csv")
                )
            logger.dump(step=agent.num_timesteps)
            logger.close()
            agent.save(
                partial / "q_table.npz",
                extra={
                    "env_id": config.env_id,
                    "tank": config.tank,
                    "tank_fingerprint": base.tank.fingerprint,
                    "target": [float(v) for v in target],
                    "target_cell": list(base.target_cell),
                    "config": dataclasses.asdict(config),
                },
            )
            write_json(partial / "path.json", summary)
            if trajectory is not None:
                write_json(partial / "trajectory.json", trajectory.to_json())
            run_dir = logdir / name
            partial.rename(run_dir)
        except BaseException:
            shutil.rmtree(partial, ignore_errors=True)
            raise
        summary["run_dir"] = str(run_dir)
        summaries.append(summary)
    return summaries


def train_q_table_all_targets(
    config: Any, seed: int = 0, logdir: str | Path = "runs", progress_bar: bool = True
) -> dict[str, Any]:
    """One goal-conditioned Q-learning run for every reachable cell of the tank.

    Writes ``runs/q_table_goal__AFTIR-TankGoal-v0__all__{seed}__{time}/`` with
    ``q_table_goal.npz``, ``summary.json``, ``progress.csv`` and TensorBoard events
    (``eval/success_rate``: the share of goals whose greedy path reaches them).
    """
    from stable_baselines3.common.logger import configure

    from aftir_rl.agents.q_table_goal import train_all_targets

    name = _run_name("q_table_goal", "AFTIR-TankGoal-v0", "all", seed)
    partial = Path(logdir) / f".{name}.partial"
    partial.mkdir(parents=True, exist_ok=False)
    try:
        logger = configure(str(partial), ["csv", "tensorboard"])
        params = {**dataclasses.asdict(config), "seed": seed, "target": "all"}
        logger.record("hyperparameters", _hyperparameter_text(params), exclude=("csv",))
        agent, summary = train_all_targets(
            config=config, seed=seed, logger=logger, progress_bar=progress_bar
        )
        logger.record("eval/success_rate", summary["n_reached"] / summary["n_goals"])
        logger.record("eval/bfs_optimal_rate", summary["n_optimal"] / summary["n_goals"])
        logger.dump(step=agent.num_timesteps)
        logger.close()
        agent.save(partial / "q_table_goal.npz", extra={"config": dataclasses.asdict(config)})
        write_json(partial / "summary.json", summary)
        run_dir = Path(logdir) / name
        partial.rename(run_dir)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    summary["run_dir"] = str(run_dir)
    return summary


def _log_motion(
    logger: Any, env: Any, summary: dict[str, Any], target: Sequence[float], margin: float
) -> Any:
    """A follow-the-leader motion along the learned cells: logged, pictured, summarised."""
    from stable_baselines3.common.logger import Image

    from aftir_rl.motion.plan import plan_motion
    from aftir_rl.plotting import render_path

    plan = plan_motion(env.tank, target, summary["cells"], margin=margin)
    summary["motion"] = {
        "complete": plan.complete,
        "seconds": plan.seconds,
        "reason": plan.reason,
        "entries": len(plan.motion) if plan.motion is not None else 0,
        "n_sections": plan.motion.n_sections if plan.motion is not None else None,
        "min_clearance_cm": plan.min_clearance_cm,
        "ftl_deviation_cm": plan.ftl_deviation_cm,
        "tip_error_cm": plan.tip_error_cm,
        "route_departure_cm": plan.route_departure_cm,
    }
    # The same tags, with the same meaning, as every other algorithm (the arm's tip).
    logger.record("eval/success_rate", float(plan.complete))
    logger.record("eval/collision_rate", 0.0 if plan.complete else 1.0)
    if plan.motion is not None:
        logger.record("eval/tip_error_cm", plan.tip_error_cm)
        logger.record("eval/path_length_cm", plan.tip_path_length_cm)
        logger.record("eval/min_clearance_cm", plan.min_clearance_cm)
        assert plan.ftl_deviation_cm is not None  # measured with every motion
        logger.record("eval/ftl_deviation_max_cm", plan.ftl_deviation_cm[0])
        m = plan.motion
        shown = sorted(set(np.linspace(0, len(m) - 1, 7).astype(int)))
        arms = [m.posture(i).points(m.route.section_length, 10) for i in shown]
        picture = render_path(
            env.tank,
            m.tips(),
            env.target_point,
            arms=arms,
            title=f"follow-the-leader motion to {_target_tag(target)} "
            f"({len(m)} entries, clearance {plan.min_clearance_cm:.1f} cm)",
        )
        logger.record("paths/eval", Image(picture, "HWC"), exclude=("stdout", "log", "json", "csv"))
    return plan


def _log_trajectory(
    logger: Any,
    env: Any,
    points: np.ndarray,
    target: Sequence[float],
    summary: dict[str, Any],
    bridge_seconds: float,
    seed: int,
) -> Any:
    """Postures along the greedy path: logged, pictured and summarised into ``summary``."""
    from stable_baselines3.common.logger import Image

    from aftir_rl.plotting import render_path
    from aftir_rl.posture import Planner
    from aftir_rl.posture.trajectory import plan_trajectory

    trajectory = plan_trajectory(
        Planner(env.tank), points, target, bridge_seconds=bridge_seconds, seed=seed
    )
    found = [p for p in trajectory.postures if p is not None]
    summary["trajectory"] = {
        "postures": len(found),
        "waypoints": len(trajectory.waypoints),
        "failures": [f"waypoint {i} {pt}: {why}" for i, pt, why in trajectory.failures],
        "moves": len(trajectory.moves),
        "blocked_moves": len(trajectory.blocked_moves),
        "bridged_moves": len(trajectory.bridged),
        "max_joint_step_deg": trajectory.max_joint_step_deg,
    }
    logger.record("eval/postures_found", len(found) / len(trajectory.waypoints))
    logger.record("eval/blocked_moves", len(trajectory.blocked_moves))
    if found:
        last = found[-1]
        logger.record("eval/posture_tip_error_cm", last.error_cm)
        logger.record("eval/clearance_cm", min(p.clearance_cm for p in found))
        shown = found[:: max(1, len(found) // 5)] + [last]
        arms = [p.posture.points(p.section_length, 10) for p in shown]
        picture = render_path(
            env.tank,
            points,
            env.target_point,
            arms=arms,
            title=f"arm postures along the path to {_target_tag(target)}",
        )
        logger.record(
            f"paths/{_target_tag(target)}_arm",
            Image(picture, "HWC"),
            exclude=("stdout", "log", "json", "csv"),
        )
    return trajectory


def train_sb3(
    algo: str,
    config: Any,
    seed: int = 0,
    logdir: str | Path = "runs",
    resume: str | Path | None = None,
    progress_bar: bool = True,
    on_evaluation: Any = None,
) -> dict[str, Any]:
    """Train PPO, SAC or TD3 on an arm env; one run directory with the model and its logs.

    The run directory holds ``model.zip`` (atomic), ``checkpoints/``, ``config.json``,
    ``summary.json``, ``progress.csv`` and the TensorBoard events (``rollout/*``, ``train/*``,
    ``eval/*``, ``paths/eval``, the hyperparameters as text). It is built under a hidden
    ``.<name>.partial`` name and renamed once ``model.zip`` is written, so an interrupted run never
    looks finished. On Ctrl-C the model is saved to ``checkpoints/model_<steps>.zip`` of the
    partial directory, which ``--resume`` continues from. ``on_evaluation(model, metrics)``, if
    given, is called after each evaluation is logged (``aftir tune`` reports to Ray Tune there).

    Raises:
        ConfigError: the config, ``logdir`` or the hyperparameters are refused (before any
            training).
        CheckpointError: ``resume`` is unreadable, or does not fit this config.
        KeyboardInterrupt: Ctrl-C, once the model is saved; its message says where.

    """
    import signal
    import threading

    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from aftir_rl.agents.sb3 import (
        ArmEvalCallback,
        AtomicCheckpoint,
        build_model,
        check_sb3_config,
        evaluation_targets,
        load_model,
        newest_model,
        save_model,
    )
    from aftir_rl.agents.sb3_config import SB3_ENV_IDS
    from aftir_rl.agents.vec_adapter import make_batched_vec_env
    from aftir_rl.safety import check_writable_dir

    bare = _check_env_id(config.env_id, SB3_ENV_IDS, algo)
    check_sb3_config(config, algo, "config")
    env_id = f"aftir_rl:{bare}"
    logdir = check_writable_dir(logdir)
    resume_path = newest_model(resume) if resume is not None else None
    targets = evaluation_targets(env_id, config.eval_targets, env_kwargs=config.env_kwargs)
    vec_cls = SubprocVecEnv if config.n_envs > 1 else DummyVecEnv
    # Workers ignore Ctrl-C: the main process stops them once the model is saved. Only the main
    # thread may set handlers (a Ray Tune trial runs in another one).
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
    try:
        # a batched env (one numpy pass for all rows) when the env has one, else copies
        venv = make_batched_vec_env(env_id, config.n_envs, seed, config.env_kwargs)
        if venv is None:
            venv = make_vec_env(
                env_id,
                n_envs=config.n_envs,
                seed=seed,
                vec_env_cls=vec_cls,
                env_kwargs=config.env_kwargs,
            )
    finally:
        if main_thread:
            signal.signal(signal.SIGINT, previous)
    partial = None
    try:
        if resume_path is not None:
            model = load_model(algo, resume_path, env=venv, config=config, evaluation=False)
        else:
            model = build_model(algo, config, venv, seed=seed)
        name = _run_name(algo, bare, "random", seed)
        run_dir = logdir / name
        partial = logdir / f".{name}.partial"
        partial.mkdir(parents=True, exist_ok=False)
        logger = configure(str(partial), ["csv", "tensorboard"])
        model.set_logger(logger)
        params = {
            **dataclasses.asdict(config),
            "algo": algo,
            "seed": seed,
            "resume": str(resume_path) if resume_path else None,
        }
        write_json(partial / "config.json", params)
        logger.record("hyperparameters", _hyperparameter_text(params), exclude=("csv",))
        evaluator = ArmEvalCallback(
            env_id, targets, config.eval_freq, config.env_kwargs, on_evaluate=on_evaluation
        )
        callbacks = [evaluator, AtomicCheckpoint(partial / "checkpoints", config.checkpoint_freq)]
        start = time.perf_counter()
        try:
            model.learn(
                config.total_timesteps,
                callback=callbacks,
                progress_bar=progress_bar,
                reset_num_timesteps=resume_path is None,
            )
        except KeyboardInterrupt:
            steps = int(model.num_timesteps)
            save_model(model, partial / "checkpoints" / f"model_{steps}.zip")
            logger.close()
            raise KeyboardInterrupt(
                f"the model at step {steps} is saved in {partial}/checkpoints; continue with "
                f"--resume {partial}"
            ) from None
        seconds = time.perf_counter() - start
        save_model(model, partial / "model.zip")
        logger.close()
        summary = {
            "algo": algo,
            "env_id": config.env_id,
            "timesteps": int(model.num_timesteps),
            "seconds": seconds,
            "run_dir": str(run_dir),
            **evaluator.last_metrics,
        }
        write_json(partial / "summary.json", summary)
        partial.rename(run_dir)
    except BaseException:
        # Keep a partial run that holds a checkpoint (resumable); remove any other.
        if partial is not None and not any((partial / "checkpoints").glob("model_*.zip")):
            shutil.rmtree(partial, ignore_errors=True)
        raise
    finally:
        try:
            venv.close()
        except (OSError, EOFError):
            pass
    return summary


def _print_summary(s: dict[str, Any]) -> None:
    verdict = "optimal" if s["optimal"] else ("reached, not optimal" if s["success"] else "FAILED")
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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m aftir_rl.train",
        description="Train an agent on an aftir_rl environment and log the run to TensorBoard.",
    )
    sub = parser.add_subparsers(dest="algo", required=True, metavar="ALGO")
    q = sub.add_parser(
        "q_table",
        help="tabular Q-learning on AFTIR-Tank-v0 (filomat2018)",
        description="Tabular Q-learning on the rasterised tank, one run directory per target.",
    )
    q.add_argument(
        "--config",
        default=str(CONFIG_DIR / "q_table.yaml"),
        help="YAML of QLearningConfig fields (default: configs/q_table.yaml)",
    )
    q.add_argument(
        "--target",
        nargs=3,
        type=float,
        action="append",
        metavar=("X", "Y", "Z"),
        help="target point in cm; repeat for several (default: the tank's reference targets)",
    )
    q.add_argument("--episodes", type=int, help="training episodes per target (overrides config)")
    q.add_argument(
        "--all-targets",
        action="store_true",
        help="one goal-conditioned run (AFTIR-TankGoal-v0) that learns every reachable cell",
    )
    q.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    q.add_argument("--logdir", default="runs", help="parent of the run directories (default runs/)")
    q.add_argument("--resume", help="q_table.npz or run directory to continue training from")
    q.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    q.add_argument(
        "--no-postures",
        action="store_true",
        help="skip turning the greedy path into arm postures (trajectory.json)",
    )
    q.add_argument(
        "--motion",
        choices=("ftl", "progressive"),
        default="ftl",
        help="ftl: follow-the-leader motion along a route from the learned cells (default); "
        "progressive: the papers' posture per cell, continued and bridged",
    )
    q.add_argument(
        "--margin",
        type=float,
        default=DEFAULT_MARGIN,
        metavar="CM",
        help=f"clearance of the arm's surface along the motion (default {DEFAULT_MARGIN:g} cm)",
    )
    q.add_argument(
        "--bridge-seconds",
        type=float,
        default=DEFAULT_BRIDGE_SECONDS,
        metavar="S",
        help="RRT-Connect's budget for each colliding move of the postures, 0 for none "
        f"(default {DEFAULT_BRIDGE_SECONDS:g})",
    )
    for algo in ("ppo", "sac", "td3"):
        p = sub.add_parser(
            algo,
            help=f"{algo.upper()} (Stable-Baselines3) on an arm env",
            description=f"{algo.upper()} on a continuous AFTIR arm env, one run directory.",
        )
        p.add_argument(
            "--config",
            default=str(CONFIG_DIR / f"{algo}.yaml"),
            help=f"YAML of SB3Config fields (default: configs/{algo}.yaml)",
        )
        p.add_argument("--env", help="environment id (overrides config), e.g. AFTIR-ArmReach-v0")
        p.add_argument("--total-timesteps", type=int, help="training steps (overrides config)")
        p.add_argument("--n-envs", type=int, help="parallel subprocess envs (overrides config)")
        p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
        p.add_argument("--logdir", default="runs", help="parent of the run directory")
        p.add_argument("--resume", help="model.zip or run directory to continue training from")
        p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


def _main_sb3(args: argparse.Namespace) -> int:
    from aftir_rl.agents.sb3 import load_sb3_config

    config = load_sb3_config(args.config, args.algo)
    overrides = {"env_id": args.env, "total_timesteps": args.total_timesteps, "n_envs": args.n_envs}
    for key, value in overrides.items():
        if value is not None:
            if isinstance(value, int) and value < 1:
                raise ConfigError(f"--{key.replace('_', '-')} must be at least 1, got {value}")
            config = dataclasses.replace(config, **{key: value})
    s = train_sb3(
        args.algo,
        config,
        seed=args.seed,
        logdir=args.logdir,
        resume=args.resume,
        progress_bar=not args.no_progress,
    )
    print(
        f"{args.algo.upper()} on {s['env_id']}: {s['timesteps']} steps in {s['seconds']:.0f} s; "
        f"evaluation: success {s['success_rate']:.0%}, tip error {s['tip_error_cm']:.1f} cm, "
        f"path {s['path_length_cm']:.0f} cm, collisions {s['collision_rate']:.0%}"
    )
    print(f"  run dir: {s['run_dir']}")
    return 0


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.train``."""
    args = _parser().parse_args(argv)
    if not 0 <= args.seed < 2**32:
        print(f"error: --seed must be from 0 to 2**32 - 1, got {args.seed}", file=sys.stderr)
        return 2
    if args.algo != "q_table":
        try:
            return _main_sb3(args)
        except AftirError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    try:
        config = load_q_table_config(args.config)
        if args.episodes is not None:
            if args.episodes < 1:
                raise ConfigError(f"--episodes must be at least 1, got {args.episodes}")
            config = dataclasses.replace(config, episodes=args.episodes)
        if not 0 <= args.margin <= 20:
            raise ConfigError(f"--margin must be between 0 and 20 cm, got {args.margin}")
        if not 0 <= args.bridge_seconds < math.inf:
            raise ConfigError(
                f"--bridge-seconds must be a finite 0 or more, got {args.bridge_seconds}"
            )
        if args.all_targets:
            if args.target or args.resume:
                raise ConfigError("--all-targets learns every cell: drop --target and --resume")
            s = train_q_table_all_targets(
                config, seed=args.seed, logdir=args.logdir, progress_bar=not args.no_progress
            )
            print(
                f"every target of {s['tank']}: {s['n_goals']} goals, {s['episodes']} episodes "
                f"each in {s['seconds']:.1f} s; greedy paths reach {s['n_reached']} and are "
                f"BFS-optimal for {s['n_optimal']}"
            )
            print(f"  run dir: {s['run_dir']}")
            return 0
        targets = args.target
        if targets is None:
            from aftir_rl.tank import load_tank

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
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for s in summaries:
        _print_summary(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
