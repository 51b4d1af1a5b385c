"""Tabular Q-learning (filomat2018 eq. 1) for any Gymnasium env with Discrete spaces.

The update is ``Q(s,a) ← Q(s,a) + α [r + γ max_a' Q(s',a') − Q(s,a)]``; with ``α = 1`` it is the
paper's rule ``Q(s,a) = r + γ max_a' Q(s',a')``. Exploration is ε-greedy with ε decaying
geometrically per episode from ``exploration_initial_eps`` to a floor. Truncated episodes bootstrap
from the next state; terminated ones do not. Why the optimistic defaults of
``configs/q_table.yaml`` (``initial_q = 100``, α = 1, ε decaying to 0, ties broken by the lowest
index) converge to a shortest path in the tank: docs/design.md §8.

Checkpoints are ``.npz`` files holding the table and a JSON metadata record (hyperparameters,
episodes trained, the random generator's state), written to a temporary file and renamed, so a
crash never leaves half a file (:mod:`aftir_rl.rl.tabular.checkpoint`). Loading checks the file and
raises :class:`~aftir_rl.core.errors.CheckpointError` with a message saying what is wrong.
"""

from __future__ import annotations

import os
import random
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from aftir_rl.core import interrupts
from aftir_rl.core.errors import CheckpointError
from aftir_rl.rl.tabular.checkpoint import (
    Q_TABLE_FORMAT,
    random_state_from_json,
    random_state_to_json,
    read_q_table,
)
from aftir_rl.rl.tabular.greedy import greedy_rollout
from aftir_rl.rl.tabular.learning import QLearningConfig, TabularAgent, episode_bar

__all__ = ["QLearningConfig", "QLearning", "greedy_rollout"]


def _discrete_sizes(env: gym.Env[Any, Any]) -> tuple[int, int]:
    if not isinstance(env.observation_space, spaces.Discrete) or not isinstance(
        env.action_space, spaces.Discrete
    ):
        raise TypeError(
            "tabular Q-learning needs Discrete observation and action spaces, got "
            f"{env.observation_space} and {env.action_space}"
        )
    return int(env.observation_space.n), int(env.action_space.n)


class QLearning(TabularAgent):
    """Tabular Q-learning agent.

    Args:
        env: environment with ``Discrete`` observation and action spaces.
        learning_rate: α in (0, 1].
        gamma: discount factor.
        exploration_initial_eps: ε at the start of training.
        exploration_final_eps: floor of ε.
        exploration_decay: multiplicative decay of ε per episode.
        initial_q: value every entry of the table starts from. An optimistic value (the largest
            return there is, 100 for the tank) makes the greedy policy try every untried action,
            which finds a distant target in a few hundred episodes where zeros wander.
        seed: seed of the exploration generator and of the first ``env.reset``.

    """

    FORMAT = Q_TABLE_FORMAT

    def _setup(self, env: gym.Env[Any, Any]) -> None:
        n_states, n_actions = _discrete_sizes(env)
        self.q_table: NDArray[np.float64] = np.full((n_states, n_actions), self.initial_q)
        self._rng = random.Random(self.seed)
        self._seeded_env = False

    # ------------------------------------------------------------------ training
    def learn(
        self,
        episodes: int,
        callback: Callable[[QLearning], bool] | None = None,
        progress_bar: bool = False,
        logger: Any | None = None,
        log_interval: int = 50,
        reset_options: dict[str, Any] | None = None,
    ) -> QLearning:
        """Train for ``episodes`` episodes.

        Args:
            episodes: number of episodes to run.
            callback: called with the agent every ``log_interval`` episodes (its ``q_table``
                current); returning False stops training.
            progress_bar: show a tqdm bar over episodes.
            logger: an SB3 logger; gets ``rollout/ep_rew_mean``, ``rollout/ep_len_mean``,
                ``rollout/exploration_rate`` and ``time/*`` every ``log_interval`` episodes.
            log_interval: episodes between two logger dumps and callback calls.
            reset_options: passed to every ``env.reset``.

        Returns:
            self, trained further (``episodes_done`` and ``num_timesteps`` advance). A stop
            request (Ctrl-C under the command lines, :mod:`aftir_rl.core.interrupts`) ends
            training after the current episode.

        """
        env, rng = self.env, self._rng
        q = self.q_table.tolist()  # lists index and max() far faster than numpy rows
        alpha, gamma = self.learning_rate, self.gamma
        returns: deque[float] = deque(maxlen=100)
        lengths: deque[int] = deque(maxlen=100)
        start = time.perf_counter()
        bar = episode_bar(progress_bar, episodes, "Q-learning")
        try:
            for _ in range(episodes):
                ep_return, ep_len = self._run_episode(env, rng, q, alpha, gamma, reset_options)
                self.episodes_done += 1
                self.num_timesteps += ep_len
                returns.append(ep_return)
                lengths.append(ep_len)
                if bar is not None:
                    bar.update(1)
                if self.episodes_done % log_interval == 0:
                    if logger is not None:
                        elapsed = time.perf_counter() - start
                        self._log(logger, returns, lengths, self.episodes_done, elapsed)
                    if callback is not None:
                        self.q_table = np.array(q)
                        if callback(self) is False:
                            break
                if interrupts.requested():
                    break
        finally:
            if bar is not None:
                bar.close()
            self.q_table = np.array(q)
        return self

    def _run_episode(
        self,
        env: gym.Env[Any, Any],
        rng: random.Random,
        q: list[list[float]],
        alpha: float,
        gamma: float,
        reset_options: dict[str, Any] | None,
    ) -> tuple[float, int]:
        """Run one epsilon-greedy episode, updating the Q-table rows ``q`` in place.

        Args:
            env: the environment to run in.
            rng: the exploration generator.
            q: the Q-table as lists of rows (updated in place).
            alpha: the learning rate.
            gamma: the discount factor.
            reset_options: passed to ``env.reset``.

        Returns:
            The episode's return and length.

        """
        n_actions = len(q[0])
        eps = self.exploration_rate
        seed = None if self._seeded_env else self.seed
        self._seeded_env = True
        s, _ = env.reset(seed=seed, options=reset_options)
        s = int(s)
        ep_return, ep_len = 0.0, 0
        while True:
            row = q[s]
            if rng.random() < eps:
                a = rng.randrange(n_actions)
            else:
                a = row.index(max(row))
            s2, r, terminated, truncated, _ = env.step(a)
            s2, r = int(s2), float(r)
            target = r if terminated else r + gamma * max(q[s2])
            row[a] += alpha * (target - row[a])
            ep_return += r
            ep_len += 1
            s = s2
            if terminated or truncated:
                break
        return ep_return, ep_len

    # ------------------------------------------------------------------ acting
    def predict(self, observation: int, deterministic: bool = True) -> tuple[int, None]:
        """Action for ``observation`` (SB3's signature); greedy unless ``deterministic=False``."""
        if not deterministic and self._rng.random() < self.exploration_rate:
            return self._rng.randrange(self.q_table.shape[1]), None
        return int(np.argmax(self.q_table[int(observation)])), None

    # ------------------------------------------------------------------ persistence
    def _arrays(self) -> dict[str, NDArray[Any]]:
        return {"q_table": self.q_table}

    def _rng_state(self) -> list[Any]:
        return random_state_to_json(self._rng.getstate())

    def _set_rng_state(self, state: list[Any]) -> None:
        self._rng.setstate(random_state_from_json(state))

    @staticmethod
    def read_checkpoint(path: str | os.PathLike[str]) -> tuple[NDArray[np.float64], dict[str, Any]]:
        """Read ``(q_table, metadata)`` from a checkpoint.

        Raises:
            CheckpointError: missing, corrupt or not a Q-table checkpoint.

        """
        return read_q_table(path)

    def _restore(self, path: str | os.PathLike[str], checkpoint: tuple[Any, ...]) -> None:
        q_table, _ = checkpoint
        if q_table.shape != self.q_table.shape:
            raise CheckpointError(
                f"{path}: the Q-table has shape {q_table.shape} but the env needs "
                f"{self.q_table.shape}; load it with the env it was trained on"
            )
        self.q_table = q_table
        self._seeded_env = True
