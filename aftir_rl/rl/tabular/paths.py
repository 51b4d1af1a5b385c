"""A tabular agent's greedy path: its raster cells, a learned path for a target, its summary."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    import gymnasium as gym

    from aftir_rl.core.tank import Tank
    from aftir_rl.envs.tank_grid import TankGridEnv
    from aftir_rl.rl.tabular.learning import QLearningConfig
    from aftir_rl.rl.tabular.q_table import QLearning

__all__ = ["greedy_cells", "learn_cells", "path_summary"]


def greedy_cells(
    agent: QLearning, env: gym.Env[Any, Any], max_steps: int = 1000
) -> tuple[list[Any], bool]:
    """The raster cells of a Q-table's greedy path (start first), and whether it reaches."""
    from aftir_rl.rl.tabular.q_table import greedy_rollout

    states, reached = greedy_rollout(agent, env, max_steps=max_steps)
    raster = cast("TankGridEnv", env.unwrapped).raster
    return [raster.cell(s) for s in states], reached


def learn_cells(
    tank: Tank, target: ArrayLike, config: QLearningConfig, seed: int = 0
) -> tuple[list[Any], bool]:
    """Q-learning on ``target`` in ``tank`` with ``config``; its greedy cells and success.

    Raises:
        AftirError: the target cannot be learned (outside, obstructed, unreachable).

    """
    import gymnasium as gym

    from aftir_rl.rl.tabular.q_table import QLearning

    env = gym.make("AFTIR-Tank-v0", tank=tank, target=tuple(np.asarray(target, dtype=float)))
    agent = QLearning.from_config(env, config, seed=seed)
    agent.learn(config.episodes)
    return greedy_cells(agent, env)


def path_summary(
    agent: QLearning, env: gym.Env[Any, Any], target: Sequence[float], max_steps: int
) -> dict[str, Any]:
    """The greedy path of a trained agent as ``path.json`` holds it, with its BFS optimum."""
    base = cast("TankGridEnv", env.unwrapped)
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
