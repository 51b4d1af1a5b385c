"""Tabular goal-conditioned Q-learning: every reachable target of the tank learned in one run.

The table is ``Q[s, g, a]`` of shape ``(n_cells, n_goals, 6)``: for every goal ``g`` of
:attr:`~aftir_rl.envs.tank_goal.TankGoalEnv.goal_cells` (the reachable free cells but the start,
586 in the reference tank) a Q-table of the grid world with that cell as target. The update is
seed 002 eq. 1, ``Q(s,g,a) ← Q(s,g,a) + α [r + γ max_a' Q(s',g,a') − Q(s,g,a)]`` (no bootstrap
on termination), with the step reward of ``AFTIR-TankGoal-v0`` (+100 entering ``g``, −100 on a
hit, ``-step_penalty`` otherwise).

**Why every goal's episode is stepped in parallel.** Training one
:class:`~aftir_rl.agents.q_table.QLearning` per target costs one Python-level step per transition
(about 21 s for the 586 targets of the reference tank). Here each goal has its own behaviour
episode, ε-greedy on its own slice ``Q[:, g, :]`` with its own ε schedule, and all G episodes
advance together: one vectorised numpy step moves every unfinished episode by one transition
(``next_state``/``hit`` read from the env's goal-independent model,
:meth:`~aftir_rl.envs.tank_goal.TankGoalEnv.dynamics`) and applies eq. 1 to the one
``(s, g, a)`` entry each episode experienced. Episodes end and restart per goal (on reaching the
goal, a hit, or ``max_episode_steps``), and a goal leaves the batch after ``episodes`` episodes.
Because episode ``g`` only ever writes ``Q[:, g, :]``, the run is exactly G independent
Q-learning runs of the paper's algorithm (only the random stream is shared), so the convergence
argument of :mod:`aftir_rl.agents.q_table` holds goal by goal: with an optimistic table
(``initial_q = 100``), α = 1, ε decaying to 0 and greedy ties broken by the lowest action index,
the greedy path to every goal becomes a BFS shortest path. It is model-free learning from
experienced transitions, not value iteration: an entry changes only when its goal's episode takes
that action in that state, and the model is used only as the simulator (it is the env's step
table, so this is the env's ``step`` without the Python overhead). The alternative, sweeping every
``(s, a)`` through the model for every goal with α = 1, is value iteration under another name;
relabelling each experienced transition for all goals (Kaelbling's all-goals updating) would be
legitimate too, but costs O(G) per transition for each of G episodes.

Measured (``benchmarks/bench_goal.py``, 2,000 episodes per target, 2 shared cores): 586 goals,
18.5 M transitions in 8.3 s, every greedy path BFS-optimal, against 41.8 s for 586 separate
``QLearning`` tables in the same run (5.1x). The table is stored actions first,
``(6, n_cells, n_goals)``, because gathering ``(6, n)`` blocks and reducing over the first axis
is several times faster in numpy than over a trailing axis of 6; :attr:`GoalQLearning.q_table`
is a ``(n_cells, n_goals, 6)`` view of it.

Resuming (``learn`` again, or :meth:`GoalQLearning.load` then ``learn``) continues each goal's ε
schedule and the random generator, and starts every goal on a fresh episode; because the goals'
episodes interleave differently, ``learn(a); learn(b)`` is not bit-identical to ``learn(a + b)``.

Checkpoints are ``.npz`` files (table + JSON metadata: hyperparameters, goal cells, episodes,
random generator state), written atomically with :func:`aftir_rl.atomic.atomic_open` like
:meth:`QLearning.save <aftir_rl.agents.q_table.QLearning.save>`; loading raises
:class:`~aftir_rl.errors.CheckpointError` for a missing, corrupt or mismatched file.
"""

from __future__ import annotations

import json
import os
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from aftir_rl.agents.q_table import QLearningConfig, check_hyperparameters, read_npz_checkpoint
from aftir_rl.atomic import atomic_open
from aftir_rl.envs.tank_goal import TankGoalEnv
from aftir_rl.envs.tank_grid import OBSTACLE_REWARD, TARGET_REWARD
from aftir_rl.errors import CheckpointError, TargetError
from aftir_rl.tank import Tank

__all__ = ["GoalQLearning", "train_all_targets"]

FORMAT = "aftir_rl.q_table_goal/1"


class GoalQLearning:
    """Tabular Q-learning over ``(cell, goal)`` for :class:`~aftir_rl.envs.tank_goal.TankGoalEnv`.

    Args:
        env: a ``TankGoalEnv`` (wrapped or not); its tank, goal cells, start cell, step penalty and
            goal-independent model are used, the env itself is never stepped.
        learning_rate: α in (0, 1]; 1 is the paper's update.
        gamma: discount factor.
        exploration_initial_eps: ε at each goal's first episode.
        exploration_final_eps: floor of ε.
        exploration_decay: multiplicative decay of ε per episode of a goal.
        initial_q: starting value of every entry; optimistic (100) by default, see the module
            docstring of :mod:`aftir_rl.agents.q_table`.
        max_episode_steps: truncation limit of each goal's episodes.
        seed: seed of the exploration generator.

    Attributes:
        q_table: ``Q[s, g, a]``, shape ``(n_cells, n_goals, 6)``.
        goal_cells: the goals, shape ``(n_goals, 3)``, the env's ``goal_cells``.
        episodes_done: episodes trained per goal.
        num_timesteps: transitions experienced, all goals together.

    """

    def __init__(
        self,
        env: TankGoalEnv | gym.Env,
        learning_rate: float = 1.0,
        gamma: float = 0.95,
        exploration_initial_eps: float = 1.0,
        exploration_final_eps: float = 0.0,
        exploration_decay: float = 0.98,
        initial_q: float = 100.0,
        max_episode_steps: int = 500,
        seed: int | None = None,
    ) -> None:
        base = env.unwrapped
        if not isinstance(base, TankGoalEnv):
            raise TypeError(
                "GoalQLearning needs an AFTIR-TankGoal-v0 env (aftir_rl.envs.TankGoalEnv), "
                f"got {type(base).__name__}"
            )
        if not 0 < learning_rate <= 1:
            raise ValueError(f"learning_rate must be in (0, 1], got {learning_rate}")
        if max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be at least 1, got {max_episode_steps}")
        self.env = env
        self.learning_rate = float(learning_rate)
        self.gamma = float(gamma)
        self.exploration_initial_eps = float(exploration_initial_eps)
        self.exploration_final_eps = float(exploration_final_eps)
        self.exploration_decay = float(exploration_decay)
        self.initial_q = float(initial_q)
        self.max_episode_steps = int(max_episode_steps)
        self.seed = seed
        self.raster = base.raster
        self.tank: Tank = base.tank
        self.step_penalty = float(base.step_penalty)
        self.start_state = int(base.start_state)
        self.goal_cells: NDArray[np.int64] = base.goal_cells
        self.goal_states: NDArray[np.int64] = base.goal_states
        self.next_state, self.hit = base.dynamics()
        n_cells = self.raster.n_cells
        self._goal_index = np.full(n_cells, -1, dtype=np.int64)
        self._goal_index[self.goal_states] = np.arange(len(self.goal_states))
        # Stored actions first, (6, n_cells, n_goals), for fast vectorised updates.
        self._q = np.full((self.next_state.shape[1], n_cells, len(self.goal_states)), initial_q)
        self.episodes_done = 0
        self.num_timesteps = 0
        self._rng = np.random.default_rng(seed)
        #: Metadata of the checkpoint this agent was loaded from (empty for a new agent).
        self.metadata: dict[str, Any] = {}

    @classmethod
    def from_config(
        cls, env: TankGoalEnv | gym.Env, config: QLearningConfig, seed: int | None = None
    ) -> GoalQLearning:
        """An untrained agent with the hyperparameters of a ``QLearningConfig``."""
        return cls(
            env,
            learning_rate=config.learning_rate,
            gamma=config.gamma,
            exploration_initial_eps=config.exploration_initial_eps,
            exploration_final_eps=config.exploration_final_eps,
            exploration_decay=config.exploration_decay,
            initial_q=config.initial_q,
            max_episode_steps=config.max_episode_steps,
            seed=seed,
        )

    @property
    def q_table(self) -> NDArray[np.float64]:
        """``Q[s, g, a]``, shape ``(n_cells, n_goals, 6)`` (a view of the stored table)."""
        return np.moveaxis(self._q, 0, -1)

    @q_table.setter
    def q_table(self, value: NDArray[np.float64]) -> None:
        value = np.asarray(value, dtype=np.float64)
        if value.shape != self.q_table.shape:
            raise ValueError(f"q_table must have shape {self.q_table.shape}, got {value.shape}")
        self._q = np.ascontiguousarray(np.moveaxis(value, -1, 0))

    @property
    def n_goals(self) -> int:
        """Number of goals (targets) in the table."""
        return len(self.goal_states)

    @property
    def exploration_rate(self) -> float:
        """Current ε (every goal has trained the same number of episodes between calls)."""
        return float(self._eps(self.episodes_done))

    def _eps(self, episodes: Any) -> Any:
        eps = self.exploration_initial_eps * self.exploration_decay**episodes
        return np.maximum(self.exploration_final_eps, eps)

    def hyperparameters(self) -> dict[str, Any]:
        """The agent's hyperparameters as a plain dict (the constructor's keywords)."""
        return {
            "learning_rate": self.learning_rate,
            "gamma": self.gamma,
            "exploration_initial_eps": self.exploration_initial_eps,
            "exploration_final_eps": self.exploration_final_eps,
            "exploration_decay": self.exploration_decay,
            "initial_q": self.initial_q,
            "max_episode_steps": self.max_episode_steps,
            "seed": self.seed,
        }

    # ------------------------------------------------------------------ training
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
        # Actions first: Q[a] is a flat (n_cells * n_goals) vector, so gathering the 6 values of
        # n episodes gives a (6, n) block whose argmax over axis 0 is fast (numpy reduces short
        # trailing axes several times slower).
        q = self._q.reshape(self._q.shape[0], -1)
        q_flat = q.reshape(-1)
        n_actions, size = q.shape
        nxt_t, hit_t, rng = self.next_state.ravel(), self.hit.ravel(), self._rng
        alpha, gamma = self.learning_rate, self.gamma
        pen, start, max_steps = -self.step_penalty, self.start_state, self.max_episode_steps
        n_goals = self.n_goals
        rewards = np.array([pen, OBSTACLE_REWARD, TARGET_REWARD])  # by hit + 2 * reached
        lanes = np.arange(n_goals)  # goal index of each unfinished episode
        goal = self.goal_states.copy()
        s = np.full(n_goals, start, dtype=np.int64)
        t = np.zeros(n_goals, dtype=np.int64)
        ret = np.zeros(n_goals)
        ep = np.zeros(n_goals, dtype=np.int64)  # episodes finished in this call, per lane
        eps = self._eps(np.full(n_goals, self.episodes_done, dtype=np.float64))
        returns: deque[float] = deque(maxlen=100 * n_goals)
        lengths: deque[int] = deque(maxlen=100 * n_goals)
        total_eps, next_log, steps = 0, log_interval * n_goals, 0
        begin = time.perf_counter()
        bar = None
        if progress_bar:
            from tqdm.auto import tqdm

            bar = tqdm(total=episodes * n_goals, desc="goal Q-learning", unit="ep", leave=False)
        stopped = False
        try:
            ar = np.arange(n_goals)
            while len(lanes):
                n = len(lanes)
                if len(ar) != n:
                    ar = ar[:n]
                idx = s * n_goals + lanes  # flat (s, g)
                a = q.take(idx, axis=1).argmax(axis=0)  # greedy, lowest index on ties
                explore = np.flatnonzero(rng.random(n) < eps)
                if len(explore):
                    a[explore] = rng.integers(0, n_actions, len(explore))
                sa = s * n_actions + a
                s2 = nxt_t[sa]
                hit = hit_t[sa]
                reached = s2 == goal  # a hit stays in s, never the goal during an episode
                term = hit | reached
                r = rewards[hit + 2 * reached]
                nxt_rows = q.take(s2 * n_goals + lanes, axis=1)
                boot = nxt_rows[nxt_rows.argmax(axis=0), ar]
                boot[term] = 0.0
                flat = a * size + idx
                old = q_flat[flat]
                q_flat[flat] = old + alpha * (r + gamma * boot - old)
                steps += n
                t += 1
                ret += r
                end = term | (t >= max_steps)
                if not end.any():
                    s = s2
                    continue
                s = np.where(end, start, s2)
                ended = np.flatnonzero(end)
                if logger is not None:
                    returns.extend(ret[ended].tolist())
                    lengths.extend(t[ended].tolist())
                ep[ended] += 1
                t[ended] = 0
                ret[ended] = 0.0
                eps[ended] = self._eps(self.episodes_done + ep[ended])
                total_eps += len(ended)
                if bar is not None:
                    bar.update(len(ended))
                keep = ep < episodes
                if not keep.all():
                    lanes, goal, s, t = lanes[keep], goal[keep], s[keep], t[keep]
                    ret, ep, eps = ret[keep], ep[keep], eps[keep]
                if total_eps >= next_log and len(lanes):
                    next_log += log_interval * n_goals
                    self.num_timesteps += steps
                    steps = 0
                    if logger is not None:
                        self._log(logger, returns, lengths, len(lanes), begin, total_eps)
                    if callback is not None and callback(self) is False:
                        stopped = True
                        break
        finally:
            if bar is not None:
                bar.close()
            self.num_timesteps += steps
            self.episodes_done += total_eps // n_goals
        if logger is not None:
            self._log(logger, returns, lengths, len(lanes), begin, total_eps)
        if callback is not None and not stopped:
            callback(self)
        return self

    def _log(
        self,
        logger: Any,
        returns: deque[float],
        lengths: deque[int],
        goals_left: int,
        begin: float,
        total_eps: int,
    ) -> None:
        done = self.episodes_done + total_eps // self.n_goals
        logger.record("rollout/ep_rew_mean", float(np.mean(returns)) if returns else 0.0)
        logger.record("rollout/ep_len_mean", float(np.mean(lengths)) if lengths else 0.0)
        logger.record("rollout/exploration_rate", float(self._eps(done)))
        logger.record("rollout/goals_left", goals_left)
        logger.record("time/episodes", done)
        logger.record("time/total_timesteps", self.num_timesteps)
        logger.record("time/time_elapsed", time.perf_counter() - begin)
        logger.dump(step=self.num_timesteps)

    # ------------------------------------------------------------------ acting
    def goal_index(self, goal: Sequence[int] | NDArray[np.integer]) -> int:
        """Index in :attr:`goal_cells` of a goal cell ``(a, b, c)``.

        Raises:
            TargetError: the cell is not one of the goals (obstructed, unreachable, the start).

        """
        cell = tuple(int(c) for c in np.asarray(goal).ravel())
        if len(cell) != 3 or not self.raster.in_bounds(cell):
            raise TargetError(f"goal {list(cell)} is not a cell of the raster {self.raster.shape}")
        g = int(self._goal_index[self.raster.index(cell)])
        if g < 0:
            raise TargetError(
                f"cell {list(cell)} is not a goal of this table: goals are the free cells "
                "reachable from the start cell, the start cell itself excluded"
            )
        return g

    def predict(self, observation: dict[str, Any], deterministic: bool = True) -> tuple[int, None]:
        """Action for a ``TankGoalEnv`` observation (SB3's signature).

        Greedy on ``Q[tip, goal]``; with ``deterministic=False`` ε-greedy with the current ε.
        """
        g = self.goal_index(observation["desired_goal"])
        s = self.raster.index(np.asarray(observation["observation"]).ravel())
        if not deterministic and self._rng.random() < self.exploration_rate:
            return int(self._rng.integers(self.q_table.shape[2])), None
        return int(np.argmax(self.q_table[s, g])), None

    def greedy_path(
        self, goal: Sequence[int] | NDArray[np.integer]
    ) -> tuple[list[tuple[int, int, int]], bool]:
        """Follow the greedy policy for goal cell ``goal`` from the start cell.

        Returns:
            The visited cells, start first, and whether the goal was reached. The walk stops on a
            hit or when a cell repeats (a deterministic greedy policy then cycles forever).

        """
        g = self.goal_index(goal)
        s, states, seen = self.start_state, [self.start_state], {self.start_state}
        while True:
            a = int(np.argmax(self.q_table[s, g]))
            if self.hit[s, a]:
                break
            s = int(self.next_state[s, a])
            if s in seen:
                break
            states.append(s)
            seen.add(s)
            if s == self.goal_states[g]:
                return [self.raster.cell(x) for x in states], True
        return [self.raster.cell(x) for x in states], False

    def greedy_path_lengths(self) -> NDArray[np.int64]:
        """Greedy path length (moves) from the start to every goal, −1 where it fails.

        All goals are walked at once; a walk fails on a hit, or when it has not arrived after
        ``n_cells`` moves (it then cycles).
        """
        n = self.n_goals
        lanes = np.arange(n)
        s = np.full(n, self.start_state, dtype=np.int64)
        length = np.full(n, -1, dtype=np.int64)
        alive = np.ones(n, dtype=bool)
        for step in range(1, self.raster.n_cells + 1):
            a = self.q_table[s, lanes].argmax(axis=1)
            alive &= ~self.hit[s, a]
            s = self.next_state[s, a]
            arrived = alive & (s == self.goal_states)
            length[arrived] = step
            alive &= ~arrived
            if not alive.any():
                break
        return length

    def evaluate(self) -> dict[str, Any]:
        """Greedy paths to all goals against the BFS optimum (``tank.reachable``).

        Returns:
            ``n_goals``, ``n_reached``, ``n_optimal``, ``all_optimal``, ``mean_path_steps`` and
            ``max_path_steps`` (over reached goals), and ``not_optimal``: up to 10 goal cells
            whose greedy path is missing or longer than the BFS optimum.

        """
        length = self.greedy_path_lengths()
        optimum = self.tank.reachable[tuple(self.goal_cells.T)]
        optimal = length == optimum
        reached = length >= 0
        return {
            "n_goals": self.n_goals,
            "n_reached": int(reached.sum()),
            "n_optimal": int(optimal.sum()),
            "all_optimal": bool(optimal.all()),
            "mean_path_steps": float(length[reached].mean()) if reached.any() else None,
            "max_path_steps": int(length[reached].max()) if reached.any() else None,
            "not_optimal": [
                [int(c) for c in self.goal_cells[i]] for i in np.flatnonzero(~optimal)[:10]
            ],
        }

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str], extra: dict[str, Any] | None = None) -> Path:
        """Write the table and metadata to ``path`` (``.npz``, compressed) atomically.

        Args:
            path: destination; ``.npz`` is appended if missing.
            extra: more JSON-serialisable metadata.

        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        meta = {
            "format": FORMAT,
            "tank": self.tank.name,
            "raster_shape": list(self.raster.shape),
            "step_penalty": self.step_penalty,
            "hyperparameters": self.hyperparameters(),
            "episodes_done": self.episodes_done,
            "num_timesteps": self.num_timesteps,
            "rng_state": self._rng.bit_generator.state,
            **(extra or {}),
        }
        with atomic_open(path, "wb") as fh:
            np.savez_compressed(
                fh,
                q_table=self.q_table,
                goal_cells=self.goal_cells,
                metadata=np.array(json.dumps(meta)),
            )
        return path

    @staticmethod
    def read_checkpoint(
        path: str | os.PathLike[str],
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], dict[str, Any]]:
        """Read ``(q_table, goal_cells, metadata)`` from a checkpoint.

        Raises:
            CheckpointError: missing, corrupt or not a goal-conditioned Q-table checkpoint.

        """
        path = Path(path)
        hint = "retrain with aftir_rl.agents.train_all_targets or pass the right file"
        arrays, meta = read_npz_checkpoint(
            path, ("q_table", "goal_cells"), FORMAT, "goal Q-table", hint
        )
        q_table = np.asarray(arrays["q_table"], dtype=np.float64)
        goal_cells = np.asarray(arrays["goal_cells"])
        if not np.issubdtype(goal_cells.dtype, np.integer):
            raise CheckpointError(f"{path}: goal_cells must be integers; {hint}")
        goal_cells = goal_cells.astype(np.int64)
        where = f"{path}: metadata"
        check_hyperparameters(meta, where, {"max_episode_steps": (1, 1_000_000)})
        if "rng_state" in meta:
            try:
                np.random.default_rng().bit_generator.state = meta["rng_state"]
            except (TypeError, ValueError, KeyError, OverflowError):
                raise CheckpointError(f"{where}: rng_state is not a generator's state") from None
        if (
            q_table.ndim != 3
            or goal_cells.shape != (q_table.shape[1], 3)
            or not np.all(np.isfinite(q_table))
        ):
            raise CheckpointError(
                f"{path}: the goal Q-table is malformed (shape {q_table.shape}, "
                f"{len(goal_cells)} goals); {hint}"
            )
        return q_table, goal_cells, meta

    @classmethod
    def load(cls, path: str | os.PathLike[str], env: TankGoalEnv | gym.Env) -> GoalQLearning:
        """Load a checkpoint for ``env``; training can then resume with :meth:`learn`.

        Raises:
            CheckpointError: unreadable file, or a table whose cells or goals do not fit ``env``.

        """
        q_table, goal_cells, meta = cls.read_checkpoint(path)
        agent = cls(env, **meta["hyperparameters"])
        if q_table.shape != agent.q_table.shape or not np.array_equal(goal_cells, agent.goal_cells):
            raise CheckpointError(
                f"{path}: the table has shape {q_table.shape} but this env's tank "
                f"({agent.tank.name}) needs {agent.q_table.shape} with its goal cells; load it "
                "with the tank it was trained on"
            )
        agent.q_table = q_table
        agent.episodes_done = int(meta.get("episodes_done", 0))
        agent.num_timesteps = int(meta.get("num_timesteps", 0))
        if "rng_state" in meta:
            agent._rng.bit_generator.state = meta["rng_state"]
        agent.metadata = meta
        return agent


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
