"""The goal-conditioned Q-learning sweep, compiled (numba): every goal's episodes in one call.

The goals' tables are independent, so :func:`goal_episodes` runs each goal's episodes one after
the other on a contiguous copy of its table (the goals spread over the cores), the update of
filomat2018 eq. 1 per transition.
Used by :class:`~aftir_rl.rl.tabular.q_table_goal.GoalQLearning`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

__all__ = ["goal_episodes"]


@njit(cache=True, inline="always")
def _episode(
    local: NDArray[np.float64],
    model: tuple[NDArray[np.int64], NDArray[np.bool_], int, int],
    eps: float,
    update: tuple[float, float, int],
    rewards: NDArray[np.float64],
) -> tuple[float, int]:
    """One ε-greedy episode on one goal's table ``local (S, A)``: its return and steps.

    ``model``: ``next_state`` and ``hit`` flat by ``s·A + a``, the goal and the start state;
    ``update``: α, γ and the step limit.
    """
    next_state, hit, goal, start = model
    alpha, gamma, max_steps = update
    n_actions = local.shape[1]
    s, t, ret = start, 0, 0.0
    while True:
        a = 0  # greedy, lowest index on ties
        for b in range(1, n_actions):
            if local[s, b] > local[s, a]:
                a = b
        if np.random.random() < eps:
            a = np.random.randint(0, n_actions)
        sa = s * n_actions + a
        s2, h = next_state[sa], hit[sa]
        reached = s2 == goal  # a hit stays in s, never the goal during an episode
        r = rewards[int(h) + 2 * int(reached)]
        boot = 0.0
        if not (h or reached):
            boot = local[s2, 0]
            for b in range(1, n_actions):
                boot = max(boot, local[s2, b])
        local[s, a] += alpha * (r + gamma * boot - local[s, a])
        t += 1
        ret += r
        if h or reached or t >= max_steps:
            return ret, t
        s = s2


@njit(cache=True, parallel=True)
def goal_episodes(
    q: NDArray[np.float64],
    model: tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.int64], int],
    seeds: NDArray[np.int64],
    episodes: int,
    done_before: int,
    schedule: tuple[float, float, float, float, float, int],
    rewards: NDArray[np.float64],
    returns: NDArray[np.float64],
    lengths: NDArray[np.int64],
) -> int:
    """``episodes`` ε-greedy Q-learning episodes of every goal, in place on ``q (A, S, G)``.

    Args:
        q: the table, actions first.
        model: ``next_state`` and ``hit`` flat by ``s·A + a``, the goal states ``(G,)`` and
            the start state.
        seeds: per goal, the seed of its exploration draws.
        episodes: episodes per goal.
        done_before: episodes every goal has run before (for ε).
        schedule: ε's initial value, decay per episode and floor; α, γ; the step limit.
        rewards: the step reward by ``hit + 2·reached``.
        returns: ``(G, episodes)``, filled with each episode's return.
        lengths: ``(G, episodes)``, filled with each episode's steps.

    Returns:
        The transitions made.

    """
    next_state, hit, goals, start = model
    eps0, decay, eps_min, alpha, gamma, max_steps = schedule
    n_actions, n_cells = q.shape[0], q.shape[1]
    steps = 0
    for g in prange(goals.shape[0]):  # the goals' tables are independent: one thread each
        local = np.empty((n_cells, n_actions))
        np.random.seed(seeds[g])  # (numba's generator is per thread: seeded per goal)
        for s in range(n_cells):
            for a in range(n_actions):
                local[s, a] = q[a, s, g]
        for e in range(episodes):
            eps = max(eps_min, eps0 * decay ** (done_before + e))
            returns[g, e], lengths[g, e] = _episode(
                local, (next_state, hit, goals[g], start), eps, (alpha, gamma, max_steps), rewards
            )
        steps += int(lengths[g].sum())
        for s in range(n_cells):
            for a in range(n_actions):
                q[a, s, g] = local[s, a]
    return steps
