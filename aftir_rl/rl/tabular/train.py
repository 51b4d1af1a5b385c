"""Tabular Q-learning runs: one run directory per target, or one for every target.

:func:`train_q_table` learns each target (``AFTIR-Tank-v0``), replays the greedy cell path
(:func:`aftir_rl.rl.tabular.paths.path_summary`) and turns it into a follow-the-leader motion or
the papers' postures per cell; :func:`train_q_table_all_targets` runs goal-conditioned Q-learning on
``AFTIR-TankGoal-v0``. The run directory's files are described in :mod:`aftir_rl.cli.train`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from aftir_rl.core.config import DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN, brief
from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.files import staged_dir, write_json
from aftir_rl.planning.ftl.plan import motion_summary
from aftir_rl.rl.common import check_env_id, hyperparameter_text, run_name, target_tag
from aftir_rl.rl.tabular.paths import path_summary

if TYPE_CHECKING:
    from aftir_rl.envs.tank_grid import TankGridEnv
    from aftir_rl.rl.tabular.q_table import QLearning

__all__ = ["train_q_table", "train_q_table_all_targets"]


@dataclasses.dataclass(frozen=True)
class _MotionOptions:
    """How :func:`train_q_table` turns a greedy cell path into arm motion (its arguments)."""

    postures: bool
    bridge_seconds: float
    motion: str
    margin: float


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
            (0: none; see :func:`aftir_rl.planning.jointspace.bridge`); ``progressive`` only.
        motion: ``"ftl"`` (default): a follow-the-leader motion along a route planned from the
            learned cells (:func:`aftir_rl.planning.ftl.plan.plan_motion`); ``"progressive"``: the
            papers' way, a posture per cell continued from the previous one.
        margin: clearance [cm] the arm's surface keeps along the motion (``ftl``).

    Returns:
        One summary dict per target (what ``path.json`` holds, plus ``run_dir`` and ``seconds``).

    Raises:
        TargetError: a target outside the box, in an obstructed cell or unreachable; checked for
            every target before any training starts.
        CheckpointError: ``resume`` is unreadable or was trained for another env or target.

    """
    check_env_id(config.env_id, ("AFTIR-Tank-v0",), "q_table")
    # Make (and so validate) every env before training anything.
    envs = _make_target_envs(config, targets)
    checkpoint = _checkpoint_path(resume, len(envs))
    options = _MotionOptions(postures, bridge_seconds, motion, margin)
    summaries = []
    for target, env in zip(targets, envs):
        agent = _make_agent(config, env, checkpoint, seed)
        summary = _train_target_run(
            agent, env, config, target, seed, Path(logdir), progress_bar, options
        )
        summaries.append(summary)
    return summaries


def _make_target_envs(config: Any, targets: Sequence[Sequence[float]]) -> list[Any]:
    """Make one ``AFTIR-Tank-v0`` env per target (which validates every target)."""
    import gymnasium as gym

    return [
        gym.make(
            config.env_id,
            tank=config.tank,
            target=tuple(float(v) for v in t),
            step_penalty=config.step_penalty,
            max_episode_steps=config.max_episode_steps,
        )
        for t in targets
    ]


def _checkpoint_path(resume: str | Path | None, n_targets: int) -> Path | None:
    """The ``q_table.npz`` to resume from (``None``: train from scratch).

    Raises:
        CheckpointError: a checkpoint is given with more than one target.

    """
    if resume is None:
        return None
    checkpoint = Path(resume)
    if checkpoint.is_dir():
        checkpoint = checkpoint / "q_table.npz"
    if n_targets != 1:
        raise CheckpointError("--resume continues one run: give at most one --target")
    return checkpoint


def _make_agent(config: Any, env: Any, checkpoint: Path | None, seed: int) -> QLearning:
    """A fresh agent, or the checkpoint's after checking it was trained for this target and tank.

    Raises:
        CheckpointError: the checkpoint was trained for another target cell or tank.

    """
    from aftir_rl.rl.tabular.q_table import QLearning

    if checkpoint is None:
        return QLearning.from_config(env, config, seed=seed)
    base = cast("TankGridEnv", env.unwrapped)  # config.env_id is AFTIR-Tank-v0 (checked)
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
    return agent


def _train_target_run(
    agent: QLearning,
    env: Any,
    config: Any,
    target: Sequence[float],
    seed: int,
    logdir: Path,
    progress_bar: bool,
    options: _MotionOptions,
) -> dict[str, Any]:
    """Train ``agent`` on one target and write its run directory (nothing left if it fails).

    Returns:
        The target's summary (what ``path.json`` holds, plus ``run_dir`` and ``seconds``).

    """
    from stable_baselines3.common.logger import configure

    name = run_name("q_table", config.env_id, target, seed)
    run_dir = logdir / name
    with staged_dir(run_dir) as partial:
        logger = configure(str(partial), ["csv", "tensorboard"])
        params = {**dataclasses.asdict(config), "seed": seed, "target": list(target)}
        logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))
        logger.dump(step=agent.num_timesteps)
        start = time.perf_counter()
        agent.learn(
            config.episodes,
            progress_bar=progress_bar,
            logger=logger,
            log_interval=config.log_interval,
        )
        seconds = time.perf_counter() - start
        summary = path_summary(agent, env, target, config.max_episode_steps)
        summary["seconds"] = seconds
        trajectory = _log_greedy_path(logger, env, summary, target, seed, options)
        logger.dump(step=agent.num_timesteps)
        logger.close()
        _save_target_run(partial, agent, env, config, target, summary, trajectory)
    summary["run_dir"] = str(run_dir)
    return summary


def _log_greedy_path(
    logger: Any,
    env: Any,
    summary: dict[str, Any],
    target: Sequence[float],
    seed: int,
    options: _MotionOptions,
) -> Any:
    """Log the greedy cell path, and the motion or postures along it, with their pictures.

    Returns:
        The FTL plan or posture trajectory (``None`` without ``postures``).

    """
    from stable_baselines3.common.logger import Image

    from aftir_rl.viz.plotting import render_path

    base = cast("TankGridEnv", env.unwrapped)
    success, optimum = summary["success"], summary["bfs_optimal_steps"]
    tip_error, length_cm = summary["tip_error_cm"], summary["path_length_cm"]
    points, steps = np.array(summary["points_cm"]), summary["length_steps"]
    logger.record("eval/path_length_steps", steps)
    logger.record("eval/bfs_optimal_steps", optimum)
    picture = render_path(
        base.tank,
        points,
        base.target_point,
        title=f"Q-learning greedy path to {target_tag(target)} ({steps} steps, BFS {optimum})",
    )
    logger.record(
        f"paths/{target_tag(target)}",
        Image(picture, "HWC"),
        exclude=("stdout", "log", "json", "csv"),
    )
    trajectory = None
    if options.postures and options.motion == "ftl":
        trajectory = _log_motion(logger, base, summary, target, options.margin)
    elif options.postures:
        trajectory = _log_trajectory(
            logger, base, points, target, summary, options.bridge_seconds, seed
        )
        logger.record("eval/success_rate", float(success))
        logger.record("eval/tip_error_cm", tip_error)
        logger.record("eval/path_length_cm", length_cm)
    else:
        logger.record("eval/success_rate", float(success))
    if trajectory is None or getattr(trajectory, "motion", None) is None:
        # one picture card in every run: the cell path where there is no FTL motion
        logger.record("paths/eval", Image(picture, "HWC"), exclude=("stdout", "log", "json", "csv"))
    return trajectory


def _save_target_run(
    partial: Path,
    agent: QLearning,
    env: Any,
    config: Any,
    target: Sequence[float],
    summary: dict[str, Any],
    trajectory: Any,
) -> None:
    """Write the Q-table, ``path.json`` and (if any) ``trajectory.json`` into ``partial``."""
    base = cast("TankGridEnv", env.unwrapped)
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


def train_q_table_all_targets(
    config: Any, seed: int = 0, logdir: str | Path = "runs", progress_bar: bool = True
) -> dict[str, Any]:
    """One goal-conditioned Q-learning run for every reachable cell of the tank.

    Writes ``runs/q_table_goal__AFTIR-TankGoal-v0__all__{seed}__{time}/`` with
    ``q_table_goal.npz``, ``summary.json``, ``progress.csv`` and TensorBoard events
    (``eval/success_rate``: the share of goals whose greedy path reaches them).
    """
    from stable_baselines3.common.logger import configure

    from aftir_rl.rl.tabular.q_table_goal import train_all_targets

    name = run_name("q_table_goal", "AFTIR-TankGoal-v0", "all", seed)
    run_dir = Path(logdir) / name
    with staged_dir(run_dir) as partial:
        logger = configure(str(partial), ["csv", "tensorboard"])
        params = {**dataclasses.asdict(config), "seed": seed, "target": "all"}
        logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))
        agent, summary = train_all_targets(
            config=config, seed=seed, logger=logger, progress_bar=progress_bar
        )
        logger.record("eval/success_rate", summary["n_reached"] / summary["n_goals"])
        logger.record("eval/bfs_optimal_rate", summary["n_optimal"] / summary["n_goals"])
        logger.dump(step=agent.num_timesteps)
        logger.close()
        agent.save(partial / "q_table_goal.npz", extra={"config": dataclasses.asdict(config)})
        write_json(partial / "summary.json", summary)
    summary["run_dir"] = str(run_dir)
    return summary


def _log_motion(
    logger: Any, env: Any, summary: dict[str, Any], target: Sequence[float], margin: float
) -> Any:
    """A follow-the-leader motion along the learned cells: logged, pictured, summarised."""
    from stable_baselines3.common.logger import Image

    from aftir_rl.planning.ftl.plan import plan_motion
    from aftir_rl.viz.plotting import render_path

    plan = plan_motion(env.tank, target, summary["cells"], margin=margin)
    summary["motion"] = motion_summary(plan)
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
            title=f"follow-the-leader motion to {target_tag(target)} "
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

    from aftir_rl.planning.posture import Planner
    from aftir_rl.planning.posture.trajectory import plan_trajectory
    from aftir_rl.viz.plotting import render_path

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
            title=f"arm postures along the path to {target_tag(target)}",
        )
        logger.record(
            f"paths/{target_tag(target)}_arm",
            Image(picture, "HWC"),
            exclude=("stdout", "log", "json", "csv"),
        )
    return trajectory
