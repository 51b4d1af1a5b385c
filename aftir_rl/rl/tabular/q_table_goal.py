"""Tabular goal-conditioned Q-learning: every reachable target of the tank learned in one run.

The table is ``Q[s, g, a]`` of shape ``(n_cells, n_goals, 6)``: for every goal ``g`` of
:attr:`~aftir_rl.envs.tank_goal.TankGoalEnv.goal_cells` (the reachable free cells but the start,
586 in the reference tank) a Q-table of the grid world with that cell as target. The update is
filomat2018 eq. 1, ``Q(s,g,a) ← Q(s,g,a) + α [r + γ max_a' Q(s',g,a') − Q(s,g,a)]`` (no bootstrap
on termination), with the step reward of ``AFTIR-TankGoal-v0`` (+100 entering ``g``, −100 on a
hit, ``-step_penalty`` otherwise).

The goals' tables are independent: a compiled sweep (:mod:`~aftir_rl.rl.tabular.goal_kernel`)
runs every goal's ε-greedy episodes through the env's goal-independent model, G independent
Q-learning runs of the paper's algorithm, ``log_interval`` episodes per goal between two logs.
Table, greedy policy and checkpoints: :class:`~aftir_rl.rl.tabular.goal_table.GoalTable`. Why
this is learning, not value iteration, and how resuming behaves: docs/design.md §8; its speed:
docs/benchmarks.md.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.tank import Tank
from aftir_rl.envs.tank_goal import TankGoalEnv
from aftir_rl.envs.tank_grid import OBSTACLE_REWARD, TARGET_REWARD
from aftir_rl.rl.tabular.goal_kernel import goal_episodes
from aftir_rl.rl.tabular.goal_table import GoalTable
from aftir_rl.rl.tabular.learning import QLearningConfig, episode_bar

__all__ = ["GoalQLearning", "train_all_targets"]


class GoalQLearning(GoalTable):
    """Tabular Q-learning over ``(cell, goal)`` for :class:`~aftir_rl.envs.tank_goal.TankGoalEnv`.

    The constructor, table, greedy policy and checkpoints are
    :class:`~aftir_rl.rl.tabular.goal_table.GoalTable`'s (its docstring has the arguments);
    :meth:`learn` trains every goal's episodes.
    """

    def learn(
        self,
        episodes: int,
        callback: Callable[[GoalQLearning], bool] | None = None,
        progress_bar: bool = False,
        logger: Any | None = None,
        log_interval: int = 50,
    ) -> GoalQLearning:
        """Train ``episodes`` more episodes for every goal, in compiled sweeps over the goals.

        Args:
            episodes: episodes per goal.
            callback: called with the agent every ``log_interval`` episodes per goal and at
                the end; returning False stops training (every goal has then run the same
                number of episodes, ``episodes_done``).
            progress_bar: show a tqdm bar over all goals' episodes.
            logger: an SB3 logger; gets ``rollout/ep_rew_mean``, ``rollout/ep_len_mean`` (the
                last 100 episodes per goal), ``rollout/exploration_rate``, ``rollout/goals_left``
                and ``time/*`` every ``log_interval`` episodes per goal.
            log_interval: episodes per goal between two logger dumps and callback calls.

        Returns:
            self, trained further.

        """
        if episodes < 1:
            raise ValueError(f"episodes must be at least 1, got {episodes}")
        n_goals, begin = self.n_goals, time.perf_counter()
        bar = episode_bar(progress_bar, episodes * n_goals, "goal Q-learning")
        returns: deque[float] = deque(maxlen=100 * n_goals)
        lengths: deque[int] = deque(maxlen=100 * n_goals)
        left, stopped = episodes, False
        try:
            while left > 0 and not stopped:
                chunk = min(log_interval, left)
                ret, steps = self._sweep(chunk)
                left -= chunk
                self.episodes_done += chunk
                self.num_timesteps += steps
                returns.extend(ret[0].ravel().tolist())
                lengths.extend(ret[1].ravel().tolist())
                if bar is not None:
                    bar.update(chunk * n_goals)
                if logger is not None and left > 0:
                    elapsed = time.perf_counter() - begin
                    self._log(
                        logger, returns, lengths, self.episodes_done, elapsed, goals_left=n_goals
                    )
                if left > 0 and callback is not None and callback(self) is False:
                    stopped = True
        finally:
            if bar is not None:
                bar.close()
        if logger is not None:
            elapsed = time.perf_counter() - begin
            self._log(logger, returns, lengths, self.episodes_done, elapsed, goals_left=0)
        if callback is not None and not stopped:
            callback(self)
        return self

    def _sweep(self, episodes: int) -> tuple[tuple[NDArray[np.float64], NDArray[np.int64]], int]:
        """``episodes`` more episodes of every goal (compiled): their returns and lengths, steps."""
        n_goals = self.n_goals
        returns = np.empty((n_goals, episodes))
        lengths = np.empty((n_goals, episodes), dtype=np.int64)
        seeds = self._rng.integers(0, 2**32 - 1, n_goals, dtype=np.int64)
        model = (
            np.ascontiguousarray(self.next_state.ravel(), dtype=np.int64),
            np.ascontiguousarray(self.hit.ravel()),
            np.asarray(self.goal_states, dtype=np.int64),
            int(self.start_state),
        )
        schedule = (
            float(self.exploration_initial_eps),
            float(self.exploration_decay),
            float(self.exploration_final_eps),
            float(self.learning_rate),
            float(self.gamma),
            int(self.max_episode_steps),
        )
        rewards = np.array([-self.step_penalty, OBSTACLE_REWARD, TARGET_REWARD], dtype=np.float64)
        steps = goal_episodes(
            self._q, model, seeds, episodes, int(self.episodes_done), schedule, rewards,
            returns, lengths,
        )  # fmt: skip
        return (returns, lengths), int(steps)


def train_all_targets(
    tank: str | Path | Tank | None = None,
    episodes: int | None = None,
    seed: int | None = 0,
    *,
    config: QLearningConfig | None = None,
    logger: Any | None = None,
    log_interval: int | None = None,
    progress_bar: bool = False,
    callback: Callable[[GoalQLearning], bool] | None = None,
    agent: GoalQLearning | None = None,
) -> tuple[GoalQLearning, dict[str, Any]]:
    """Learn a greedy path to every reachable free cell of a tank in one goal-conditioned run.

    Args:
        tank: tank name or YAML path; default ``config.tank``.
        episodes: episodes per goal; default ``config.episodes``.
        seed: seed of the exploration generator.
        config: hyperparameters (``configs/q_table.yaml``); default ``QLearningConfig()``. Its
            ``env_id`` is ignored (the goal env is used), ``step_penalty`` and
            ``max_episode_steps`` apply.
        logger: an SB3 logger (see :meth:`GoalQLearning.learn`).
        log_interval: episodes per goal between logger dumps; default ``config.log_interval``.
        progress_bar: show a tqdm bar.
        callback: see :meth:`GoalQLearning.learn`.
        agent: an agent to train further (a checkpoint's, loaded with its env) instead of a new
            one; ``tank`` and ``seed`` are then its own.

    Returns:
        The trained agent and a summary: ``tank``, ``seed``, ``episodes`` (per goal),
        ``num_timesteps``, ``seconds`` (training wall time), and :meth:`GoalQLearning.evaluate`'s
        ``n_goals``, ``n_reached``, ``n_optimal``, ``all_optimal``, ``mean_path_steps``,
        ``max_path_steps``, ``not_optimal``.

    """
    config = config or QLearningConfig()
    tank = config.tank if tank is None else tank
    episodes = config.episodes if episodes is None else int(episodes)
    if agent is None:
        env = TankGoalEnv(tank=tank, step_penalty=config.step_penalty)
        agent = GoalQLearning.from_config(env, config, seed=seed)
    start = time.perf_counter()
    if episodes > 0:  # 0: a resumed run that had trained them all
        agent.learn(
            episodes,
            callback=callback,
            progress_bar=progress_bar,
            logger=logger,
            log_interval=config.log_interval if log_interval is None else log_interval,
        )
    seconds = time.perf_counter() - start
    summary = {
        "tank": agent.tank.name,
        "seed": agent.seed,
        "episodes": agent.episodes_done,
        "num_timesteps": agent.num_timesteps,
        "seconds": seconds,
        **agent.evaluate(),
    }
    return agent, summary
