"""Tabular goal-conditioned Q-learning: every reachable target of the tank learned in one run.

The table is ``Q[s, g, a]`` of shape ``(n_cells, n_goals, 6)``: for every goal ``g`` of
:attr:`~aftir_rl.envs.tank_goal.TankGoalEnv.goal_cells` (the reachable free cells but the start,
586 in the reference tank) a Q-table of the grid world with that cell as target. The update is
filomat2018 eq. 1, ``Q(s,g,a) ← Q(s,g,a) + α [r + γ max_a' Q(s',g,a') − Q(s,g,a)]`` (no bootstrap
on termination), with the step reward of ``AFTIR-TankGoal-v0`` (+100 entering ``g``, −100 on a
hit, ``-step_penalty`` otherwise).

Every goal's ε-greedy episode is stepped in parallel: one vectorised numpy step moves every
unfinished episode by one transition through the env's goal-independent model
(:meth:`~aftir_rl.envs.tank_goal.TankGoalEnv.dynamics`) and updates the one ``(s, g, a)`` entry
each experienced: G independent Q-learning runs of the paper's algorithm. Table, greedy policy
and checkpoints: :class:`~aftir_rl.rl.tabular.goal_table.GoalTable`. Why this is learning, not
value iteration, and how resuming behaves: docs/design.md §8; its speed: docs/benchmarks.md.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.tank import Tank
from aftir_rl.envs.tank_goal import TankGoalEnv
from aftir_rl.envs.tank_grid import OBSTACLE_REWARD, TARGET_REWARD
from aftir_rl.rl.tabular.goal_table import GoalTable
from aftir_rl.rl.tabular.learning import QLearningConfig, episode_bar

__all__ = ["GoalQLearning", "train_all_targets"]


@dataclass
class _GoalRun:
    """What one :meth:`GoalQLearning.learn` call works on.

    The tables and hyperparameters, read once at the start, and the state of every goal's
    unfinished episode (one lane per goal, dropped when the goal has run all its episodes).
    """

    q: NDArray[np.float64]  # actions first: (n_actions, n_cells * n_goals), a view of the table
    q_flat: NDArray[np.float64]
    next_state: NDArray[np.int64]  # flat, indexed by s * n_actions + a
    hit: NDArray[np.bool_]
    rng: np.random.Generator
    alpha: float
    gamma: float
    start: int
    max_steps: int
    n_goals: int
    rewards: NDArray[np.float64]
    lanes: NDArray[np.int64]  # goal index of each unfinished episode
    goal: NDArray[np.int64]
    s: NDArray[np.int64]
    t: NDArray[np.int64]
    ret: NDArray[np.float64]
    ep: NDArray[np.int64]  # episodes finished in this call, per lane
    eps: NDArray[np.float64]
    returns: deque[float]
    lengths: deque[int]
    ar: NDArray[np.int64]  # 0, 1, ..., n_lanes - 1
    next_log: int
    begin: float
    total_eps: int = 0
    steps: int = 0


def _step_lanes(run: _GoalRun) -> NDArray[np.bool_] | None:
    """One epsilon-greedy step and Q update of every unfinished episode.

    Returns:
        Which lanes' episodes ended (``None`` when none did).

    """
    n = len(run.lanes)
    if len(run.ar) != n:
        run.ar = run.ar[:n]
    q, s, lanes, n_goals, rng = run.q, run.s, run.lanes, run.n_goals, run.rng
    n_actions, size = q.shape
    idx = s * n_goals + lanes  # flat (s, g)
    a = q.take(idx, axis=1).argmax(axis=0)  # greedy, lowest index on ties
    explore = np.flatnonzero(rng.random(n) < run.eps)
    if len(explore):
        a[explore] = rng.integers(0, n_actions, len(explore))
    sa = s * n_actions + a
    s2 = run.next_state[sa]
    hit = run.hit[sa]
    reached = s2 == run.goal  # a hit stays in s, never the goal during an episode
    term = hit | reached
    r = run.rewards[hit + 2 * reached]
    nxt_rows = q.take(s2 * n_goals + lanes, axis=1)
    boot = nxt_rows[nxt_rows.argmax(axis=0), run.ar]
    boot[term] = 0.0
    flat = a * size + idx
    old = run.q_flat[flat]
    run.q_flat[flat] = old + run.alpha * (r + run.gamma * boot - old)
    run.steps += n
    run.t += 1
    run.ret += r
    end = term | (run.t >= run.max_steps)
    if not end.any():
        run.s = s2
        return None
    run.s = np.where(end, run.start, s2)
    return end


class GoalQLearning(GoalTable):
    """Tabular Q-learning over ``(cell, goal)`` for :class:`~aftir_rl.envs.tank_goal.TankGoalEnv`.

    The constructor, table, greedy policy and checkpoints are
    :class:`~aftir_rl.rl.tabular.goal_table.GoalTable`'s (its docstring has the arguments);
    :meth:`learn` trains every goal's episodes in parallel.
    """

    def learn(
        self,
        episodes: int,
        callback: Callable[[GoalQLearning], bool] | None = None,
        progress_bar: bool = False,
        logger: Any | None = None,
        log_interval: int = 50,
    ) -> GoalQLearning:
        """Train ``episodes`` more episodes for every goal, all goals' episodes in parallel.

        Args:
            episodes: episodes per goal.
            callback: called with the agent every ``log_interval`` episodes per goal (counted
                over all goals) and at the end; returning False stops training. Stopping early
                leaves goals with different episode counts; ``episodes_done`` then counts the
                goals' mean, rounded down.
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
        run = self._start_run(log_interval)
        bar = episode_bar(progress_bar, episodes * run.n_goals, "goal Q-learning")
        stopped = False
        try:
            stopped = self._run_lanes(run, episodes, callback, logger, log_interval, bar)
        finally:
            if bar is not None:
                bar.close()
            self.num_timesteps += run.steps
            self.episodes_done += run.total_eps // run.n_goals
        if logger is not None:
            self._log_goals(
                logger, run.returns, run.lengths, len(run.lanes), run.begin, run.total_eps
            )
        if callback is not None and not stopped:
            callback(self)
        return self

    def _start_run(self, log_interval: int) -> _GoalRun:
        """The tables and the lanes of one :meth:`learn` call, every goal's episode at its start."""
        # Actions first: Q[a] is a flat (n_cells * n_goals) vector, so gathering the 6 values of
        # n episodes gives a (6, n) block whose argmax over axis 0 is fast (numpy reduces short
        # trailing axes several times slower).
        q = self._q.reshape(self._q.shape[0], -1)
        n_goals = self.n_goals
        return _GoalRun(
            q=q,
            q_flat=q.reshape(-1),
            next_state=self.next_state.ravel(),
            hit=self.hit.ravel(),
            rng=self._rng,
            alpha=self.learning_rate,
            gamma=self.gamma,
            start=self.start_state,
            max_steps=self.max_episode_steps,
            n_goals=n_goals,
            # by hit + 2 * reached
            rewards=np.array([-self.step_penalty, OBSTACLE_REWARD, TARGET_REWARD]),
            lanes=np.arange(n_goals),
            goal=self.goal_states.copy(),
            s=np.full(n_goals, self.start_state, dtype=np.int64),
            t=np.zeros(n_goals, dtype=np.int64),
            ret=np.zeros(n_goals),
            ep=np.zeros(n_goals, dtype=np.int64),
            eps=self._eps(np.full(n_goals, self.episodes_done, dtype=np.float64)),
            ar=np.arange(n_goals),
            returns=deque(maxlen=100 * n_goals),
            lengths=deque(maxlen=100 * n_goals),
            next_log=log_interval * n_goals,
            begin=time.perf_counter(),
        )

    def _run_lanes(
        self,
        run: _GoalRun,
        episodes: int,
        callback: Callable[[GoalQLearning], bool] | None,
        logger: Any | None,
        log_interval: int,
        bar: Any,
    ) -> bool:
        """Step every goal's episodes until each goal has run ``episodes`` of them.

        Returns:
            True when the callback stopped training.

        """
        while len(run.lanes):
            end = _step_lanes(run)
            if end is None:
                continue
            self._end_episodes(run, end, episodes, logger is not None, bar)
            if run.total_eps >= run.next_log and len(run.lanes):
                run.next_log += log_interval * run.n_goals
                self.num_timesteps += run.steps
                run.steps = 0
                if logger is not None:
                    self._log_goals(
                        logger, run.returns, run.lengths, len(run.lanes), run.begin, run.total_eps
                    )
                if callback is not None and callback(self) is False:
                    return True
        return False

    def _end_episodes(
        self, run: _GoalRun, end: NDArray[np.bool_], episodes: int, logged: bool, bar: Any
    ) -> None:
        """Count the episodes that ended, restart them and drop the goals that are done."""
        ended = np.flatnonzero(end)
        if logged:
            run.returns.extend(run.ret[ended].tolist())
            run.lengths.extend(run.t[ended].tolist())
        run.ep[ended] += 1
        run.t[ended] = 0
        run.ret[ended] = 0.0
        run.eps[ended] = self._eps(self.episodes_done + run.ep[ended])
        run.total_eps += len(ended)
        if bar is not None:
            bar.update(len(ended))
        keep = run.ep < episodes
        if not keep.all():
            run.lanes, run.goal, run.s = run.lanes[keep], run.goal[keep], run.s[keep]
            run.t, run.ret, run.ep, run.eps = (
                run.t[keep],
                run.ret[keep],
                run.ep[keep],
                run.eps[keep],
            )

    def _log_goals(
        self,
        logger: Any,
        returns: deque[float],
        lengths: deque[int],
        goals_left: int,
        begin: float,
        total_eps: int,
    ) -> None:
        done = self.episodes_done + total_eps // self.n_goals
        elapsed = time.perf_counter() - begin
        self._log(logger, returns, lengths, done, elapsed, goals_left=goals_left)


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

    Returns:
        The trained agent and a summary: ``tank``, ``seed``, ``episodes`` (per goal),
        ``num_timesteps``, ``seconds`` (training wall time), and :meth:`GoalQLearning.evaluate`'s
        ``n_goals``, ``n_reached``, ``n_optimal``, ``all_optimal``, ``mean_path_steps``,
        ``max_path_steps``, ``not_optimal``.

    """
    config = config or QLearningConfig()
    tank = config.tank if tank is None else tank
    episodes = config.episodes if episodes is None else int(episodes)
    env = TankGoalEnv(tank=tank, step_penalty=config.step_penalty)
    agent = GoalQLearning.from_config(env, config, seed=seed)
    start = time.perf_counter()
    agent.learn(
        episodes,
        callback=callback,
        progress_bar=progress_bar,
        logger=logger,
        log_interval=config.log_interval if log_interval is None else log_interval,
    )
    seconds = time.perf_counter() - start
    summary = {
        "tank": env.tank.name,
        "seed": seed,
        "episodes": agent.episodes_done,
        "num_timesteps": agent.num_timesteps,
        "seconds": seconds,
        **agent.evaluate(),
    }
    return agent, summary
