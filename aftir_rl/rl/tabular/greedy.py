"""Greedy paths of a learned policy: rolled out in an env, or walked on a tank's model.

:func:`greedy_rollout` follows any agent's ``predict`` through an env;
:func:`greedy_walk` and :func:`greedy_lengths` follow a goal-conditioned Q-table through the
goal-independent model of :meth:`~aftir_rl.envs.tank_goal.TankGoalEnv.dynamics` (one goal, or all
at once), and :func:`optimality` compares the lengths with the BFS optimum.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from aftir_rl.rl.common import Predictor

__all__ = ["greedy_rollout", "greedy_walk", "greedy_lengths", "optimality"]


#: A deterministic model: ``next_state[s, a]`` and ``hit[s, a]``.
Dynamics = tuple[NDArray[np.int64], NDArray[np.bool_]]


def greedy_rollout(
    agent: Predictor,
    env: gym.Env[Any, Any],
    max_steps: int = 1000,
    options: dict[str, Any] | None = None,
    stop_on_cycle: bool = True,
) -> tuple[list[int], bool]:
    """Follow the greedy policy from ``env.reset`` until the episode ends.

    Args:
        agent: anything with SB3's ``predict(obs, deterministic=True)``.
        env: the environment (its current target is used unless ``options`` change it).
        max_steps: the most steps taken.
        options: passed to ``env.reset``.
        stop_on_cycle: stop when a (state, action) pair repeats, which in a deterministic env
            means the greedy policy cycles forever; turn off for stochastic envs.

    Returns:
        The visited states (start first, repeats of a state in place dropped) and whether the
        episode terminated with ``info["is_success"]`` (or, without that key, a positive reward).

    """
    s, _ = env.reset(options=options)
    states = [int(s)]
    seen: set[tuple[int, int]] = set()
    for _ in range(max_steps):
        action, _ = agent.predict(s, deterministic=True)
        if stop_on_cycle:
            if (int(s), int(action)) in seen:
                break
            seen.add((int(s), int(action)))
        s, reward, terminated, truncated, info = env.step(action)
        if int(s) != states[-1]:
            states.append(int(s))
        if terminated:
            return states, bool(info.get("is_success", float(reward) > 0))
        if truncated:
            break
    return states, False


def greedy_walk(
    q: NDArray[np.float64], dynamics: Dynamics, start: int, goal: int
) -> tuple[list[int], bool]:
    """Follow the greedy actions of ``q[s]`` (shape ``(n_cells, n_actions)``) from ``start``.

    ``dynamics`` is the model ``(next_state, hit)``, each of shape ``(n_cells, n_actions)``.

    Returns:
        The visited states, start first, and whether ``goal`` was reached. The walk stops on a
        hit or when a state repeats (a deterministic greedy policy then cycles forever).

    """
    next_state, hit = dynamics
    s, states, seen = start, [start], {start}
    while True:
        a = int(np.argmax(q[s]))
        if hit[s, a]:
            return states, False
        s = int(next_state[s, a])
        if s in seen:
            return states, False
        states.append(s)
        seen.add(s)
        if s == goal:
            return states, True


def greedy_lengths(
    q_table: NDArray[np.float64], dynamics: Dynamics, start: int, goals: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Greedy path length (moves) from ``start`` to every goal, −1 where it fails.

    ``q_table[s, g]`` holds goal ``g``'s action values in state ``s``; all goals are walked at
    once through ``dynamics`` (as :func:`greedy_walk`). A walk fails on a hit, or when it has not
    arrived after as many moves as there are states (it then cycles).
    """
    next_state, hit = dynamics
    n = len(goals)
    lanes = np.arange(n)
    s = np.full(n, start, dtype=np.int64)
    length = np.full(n, -1, dtype=np.int64)
    alive = np.ones(n, dtype=bool)
    for step in range(1, len(next_state) + 1):
        a = q_table[s, lanes].argmax(axis=1)
        alive &= ~hit[s, a]
        s = next_state[s, a]
        arrived = alive & (s == goals)
        length[arrived] = step
        alive &= ~arrived
        if not alive.any():
            break
    return length


def optimality(
    length: NDArray[np.int64], optimum: NDArray[np.int64], goal_cells: NDArray[np.int64]
) -> dict[str, Any]:
    """Greedy path lengths (:func:`greedy_lengths`) against the BFS optimum of each goal.

    Returns:
        ``n_goals``, ``n_reached``, ``n_optimal``, ``all_optimal``, ``mean_path_steps`` and
        ``max_path_steps`` (over reached goals), and ``not_optimal``: up to 10 goal cells
        whose greedy path is missing or longer than the BFS optimum.

    """
    optimal = length == optimum
    reached = length >= 0
    return {
        "n_goals": len(length),
        "n_reached": int(reached.sum()),
        "n_optimal": int(optimal.sum()),
        "all_optimal": bool(optimal.all()),
        "mean_path_steps": float(length[reached].mean()) if reached.any() else None,
        "max_path_steps": int(length[reached].max()) if reached.any() else None,
        "not_optimal": [[int(c) for c in goal_cells[i]] for i in np.flatnonzero(~optimal)[:10]],
    }
