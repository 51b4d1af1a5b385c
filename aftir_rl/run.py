"""A run directory of any kind: load it, replay its greedy policy, measure what it does.

The kinds (:func:`run_kind`), as ``python -m aftir_rl.train`` writes them:

- ``q_table``: ``q_table.npz``, one target (:func:`load_q_table_run`);
- ``q_table_goal``: ``q_table_goal.npz``, every reachable cell (``--all-targets``,
  :func:`load_goal_run`);
- ``sb3``: ``model.zip`` with ``config.json`` (``ppo | sac | td3``, :func:`load_sb3_run`:
  ``config.json`` checked key by key, the model loaded without unpickling).

The workflow shared by ``train``, ``evaluate`` and ``bench``: a tabular agent's greedy cells
(:func:`greedy_cells`, :func:`learn_cells`) become a follow-the-leader motion
(:func:`aftir_rl.motion.plan.plan_motion`, summarised by :func:`motion_summary`) or the papers'
postures per cell (:func:`aftir_rl.posture.trajectory.plan_trajectory`); :func:`evaluate_run`
gives the measures of one run directory. Environment ids read from a file or a config are
checked before anything is made (:func:`check_env_id`,
:func:`aftir_rl.safety.registered_env_id`): no other module is imported.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.config import DEFAULT_MARGIN, brief, from_mapping, read_yaml
from aftir_rl.errors import CheckpointError, ConfigError
from aftir_rl.safety import registered_env_id

if TYPE_CHECKING:
    from aftir_rl.envs.tank_grid import TankGridEnv

__all__ = [
    "QTableRun",
    "GoalRun",
    "SB3Run",
    "check_env_id",
    "load_q_table_config",
    "run_kind",
    "load_run",
    "load_q_table_run",
    "load_goal_run",
    "load_sb3_run",
    "greedy_cells",
    "learn_cells",
    "path_summary",
    "motion_summary",
    "evaluate_run",
]

#: The file that marks each kind of run directory.
RUN_FILES = {"q_table": "q_table.npz", "q_table_goal": "q_table_goal.npz", "sb3": "model.zip"}


def check_env_id(env_id: Any, allowed: Sequence[str], algo: str) -> str:
    """The bare id of ``env_id`` (``ID`` or ``aftir_rl:ID``); any other module is never imported.

    Raises:
        ConfigError: ``env_id`` is not one of ``allowed`` (``algo`` cannot train on it).

    """
    try:
        return registered_env_id(env_id, algo, allowed)
    except ConfigError:
        raise ConfigError(
            f"{algo} cannot train on {brief(env_id)}; use one of {', '.join(allowed)} "
            "(--env or env_id)"
        ) from None


def load_q_table_config(path: str | Path) -> Any:
    """Read ``configs/q_table.yaml`` (or another file) into a ``QLearningConfig``."""
    from aftir_rl.agents.q_table import QLearningConfig

    return from_mapping(QLearningConfig, read_yaml(path), str(path))


# ---------------------------------------------------------------- loading


@dataclass
class QTableRun:
    """A ``q_table`` run: the agent in the env of the target it was trained for."""

    run_dir: Path
    agent: Any
    env: Any
    target: list[float]


@dataclass
class GoalRun:
    """A ``q_table_goal`` run: one goal-conditioned agent for every reachable cell."""

    run_dir: Path
    agent: Any
    env: Any


@dataclass
class SB3Run:
    """An ``sb3`` run: its algorithm, checked config, ``aftir_rl:``-prefixed env id and model."""

    run_dir: Path
    algo: str
    config: Any
    env_id: str
    model: Any


def run_kind(run_dir: str | Path) -> str | None:
    """``"q_table"``, ``"sb3"``, ``"q_table_goal"`` or None (not a run directory)."""
    run = Path(run_dir)
    if (run / RUN_FILES["q_table"]).exists():
        return "q_table"
    if (run / RUN_FILES["sb3"]).exists() and (run / "config.json").exists():
        return "sb3"
    if (run / RUN_FILES["q_table_goal"]).exists():
        return "q_table_goal"
    return None


def load_run(
    run_dir: str | Path, kinds: Sequence[str] = ("q_table", "sb3", "q_table_goal")
) -> QTableRun | GoalRun | SB3Run:
    """Load a run directory of one of ``kinds``.

    Raises:
        CheckpointError: not a run directory of those kinds, or unreadable files.

    """
    run = Path(run_dir)
    kind = run_kind(run)
    if kind is None or kind not in kinds:
        files = " nor ".join(
            "model.zip with config.json" if k == "sb3" else RUN_FILES[k] for k in kinds
        )
        raise CheckpointError(f"{run}: not a run directory (no {files})")
    loaders: dict[str, Callable[[Path], QTableRun | GoalRun | SB3Run]]
    loaders = {"q_table": load_q_table_run, "sb3": load_sb3_run, "q_table_goal": load_goal_run}
    return loaders[kind](run)


def load_q_table_run(run_dir: str | Path) -> QTableRun:
    """The Q-table of a run and the env of its target (its metadata's env id, tank, target)."""
    import gymnasium as gym

    from aftir_rl.agents.q_table import QLearning

    path = Path(run_dir) / RUN_FILES["q_table"]
    _, meta = QLearning.read_checkpoint(path)  # the env id checked (agents.checkpoint)
    target = meta.get("target")
    if target is None:
        raise CheckpointError(f"{run_dir}: the Q-table has no target in its metadata")
    env = gym.make(
        meta.get("env_id", "AFTIR-Tank-v0"),
        tank=meta.get("tank", "b737_center"),
        target=tuple(target),
    )
    return QTableRun(Path(run_dir), QLearning.load(path, env), env, list(target))


def load_goal_run(run_dir: str | Path) -> GoalRun:
    """The goal-conditioned Q-table of an ``--all-targets`` run, in an env of its tank."""
    import gymnasium as gym

    from aftir_rl.agents.q_table_goal import GoalQLearning

    path = Path(run_dir) / RUN_FILES["q_table_goal"]
    _, _, meta = GoalQLearning.read_checkpoint(path)
    config = meta.get("config")
    tank = meta.get("tank") or (config.get("tank") if isinstance(config, dict) else None)
    env = gym.make("AFTIR-TankGoal-v0", tank=tank or "b737_center")
    return GoalRun(Path(run_dir), GoalQLearning.load(path, env), env)


def load_sb3_run(run_dir: str | Path) -> SB3Run:
    """An SB3 run (``config.json`` checked key by key, the model loaded without unpickling)."""
    from aftir_rl.agents.sb3 import load_run as load_sb3

    algo, config, env_id, model = load_sb3(run_dir)
    return SB3Run(Path(run_dir), algo, config, env_id, model)


# ---------------------------------------------------------------- replaying


def greedy_cells(agent: Any, env: Any, max_steps: int = 1000) -> tuple[list[Any], bool]:
    """The raster cells of a Q-table's greedy path (start first), and whether it reaches."""
    from aftir_rl.agents.q_table import greedy_rollout

    states, reached = greedy_rollout(agent, env, max_steps=max_steps)
    raster = cast("TankGridEnv", env.unwrapped).raster
    return [raster.cell(s) for s in states], reached


def learn_cells(tank: Any, target: ArrayLike, config: Any, seed: int = 0) -> tuple[list[Any], bool]:
    """Q-learning on ``target`` in ``tank`` with ``config``; its greedy cells and success.

    Raises:
        AftirError: the target cannot be learned (outside, obstructed, unreachable).

    """
    import gymnasium as gym

    from aftir_rl.agents.q_table import QLearning

    env = gym.make("AFTIR-Tank-v0", tank=tank, target=tuple(np.asarray(target, dtype=float)))
    agent = QLearning.from_config(env, config, seed=seed)
    agent.learn(config.episodes)
    return greedy_cells(agent, env)


def path_summary(agent: Any, env: Any, target: Sequence[float], max_steps: int) -> dict[str, Any]:
    """The greedy path of a trained agent as ``path.json`` holds it, with its BFS optimum."""
    base = env.unwrapped
    cells, success = greedy_cells(agent, env, max_steps=max_steps)
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


def motion_summary(plan: Any) -> dict[str, Any]:
    """What ``path.json`` says of a :class:`~aftir_rl.motion.plan.MotionPlan`."""
    return {
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


# ---------------------------------------------------------------- measuring


def _evaluate_q_table(run: QTableRun, motion: str, margin: float) -> dict[str, Any]:
    from aftir_rl.posture import Planner
    from aftir_rl.posture.trajectory import plan_trajectory

    start = time.perf_counter()
    cells, reached = greedy_cells(run.agent, run.env)
    grid = cast("TankGridEnv", run.env.unwrapped)
    if motion == "ftl":
        from aftir_rl.motion.plan import plan_motion

        plan = plan_motion(grid.tank, run.target, cells, margin=margin)
        nan = float("nan")
        return {
            "agent": "q_table + FTL motion",
            "targets": 1,
            "success_rate": float(reached and plan.complete),
            "tip_error_cm": plan.tip_error_cm if plan.complete else nan,
            "path_length_cm": plan.tip_path_length_cm if plan.complete else nan,
            "min_clearance_cm": plan.min_clearance_cm if plan.complete else nan,
            "seconds_per_target": time.perf_counter() - start,
            "note": "" if plan.complete else (plan.reason or "")[:80],
        }
    points = [grid.raster.cell_center(c) for c in cells]
    planner = Planner(grid.tank)
    trajectory = plan_trajectory(planner, points, run.target)
    seconds = time.perf_counter() - start
    m = trajectory.measures(planner.scene)
    return {
        "agent": "q_table + TGA/TSM",
        "targets": 1,
        "success_rate": float(reached and trajectory.complete),
        "tip_error_cm": m["tip_error_cm"],
        "path_length_cm": m["path_cm"],
        "min_clearance_cm": m["min_clearance_cm"],
        "seconds_per_target": seconds,
        "note": trajectory.note,
    }


def _evaluate_sb3(
    run: SB3Run, targets: list[np.ndarray] | None, draw: tuple[int, int] | None = None
) -> dict[str, Any]:
    from aftir_rl.agents.sb3 import EVAL_SEED, evaluate_policy_on_targets, evaluation_targets

    kwargs = dict(run.config.env_kwargs or {})  # the env the model was trained on (spaces)
    if not targets:
        count, seed = draw or (run.config.eval_targets, EVAL_SEED)
        targets = evaluation_targets(run.env_id, count, seed=seed, env_kwargs=kwargs)
    metrics, _ = evaluate_policy_on_targets(
        run.model, run.env_id, targets, clearance=True, env_kwargs=kwargs
    )
    note = f"{metrics['collision_rate']:.1%} collided" if metrics["collision_rate"] else ""
    agent = f"{run.algo} ({run.config.env_id})"
    return {"agent": agent, "targets": len(targets), **metrics, "note": note}


def evaluate_run(
    run_dir: str | Path,
    targets: list[np.ndarray] | None = None,
    motion: str = "ftl",
    margin: float = DEFAULT_MARGIN,
    draw: tuple[int, int] | None = None,
) -> dict[str, Any]:
    """Evaluate one run directory (Q-table or SB3): one row of ``python -m aftir_rl.evaluate``.

    A Q-table run is evaluated on the target it was trained for: its greedy path becomes a
    follow-the-leader motion keeping ``margin`` [cm] (``motion="ftl"``) or the papers' postures
    per cell (``"progressive"``). An SB3 run on ``targets``, else on ``draw = (count, seed)``
    targets drawn by its env (seeds ``seed .. seed + count − 1``), else on the fixed evaluation
    targets its training measured it on; one deterministic episode each.

    Raises:
        CheckpointError: not a run directory this knows, or unreadable files.

    """
    run = load_run(run_dir, ("q_table", "sb3"))
    if isinstance(run, QTableRun):
        return _evaluate_q_table(run, motion, margin)
    return _evaluate_sb3(cast(SB3Run, run), targets, draw)
