"""What the two tabular Q-learning agents share: config, hyperparameters, ε, log, checkpoints.

:class:`~aftir_rl.rl.tabular.q_table.QLearning` (one target, any env with Discrete spaces) and
:class:`~aftir_rl.rl.tabular.q_table_goal.GoalQLearning` (every target of the tank in one table) are
:class:`TabularAgent` subclasses: each makes its own table and runs its own training loop, and
this class keeps what is the same idea in both, the hyperparameters and counters, the ε schedule
(decaying geometrically per episode from ``exploration_initial_eps`` to a floor), the training log
and the ``.npz`` checkpoint (:mod:`aftir_rl.rl.tabular.checkpoint`).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.rl.tabular.checkpoint import HYPERPARAMETER_BOUNDS, npz_path, write_npz

if TYPE_CHECKING:
    import gymnasium as gym

__all__ = ["QLearningConfig", "TabularAgent", "episode_bar"]

A = TypeVar("A", bound="TabularAgent")


@dataclass(frozen=True)
class QLearningConfig:
    """Hyperparameters of a Q-learning run (``configs/q_table.yaml``).

    Attributes:
        env_id: Gymnasium id of the environment.
        tank: tank name or YAML path (AFTIR envs only).
        episodes: training episodes per target.
        learning_rate: α; 1.0 is the paper's update.
        gamma: discount factor γ.
        exploration_initial_eps: ε at the first episode.
        exploration_final_eps: floor of ε.
        exploration_decay: factor applied to ε after each episode.
        initial_q: starting value of every table entry (optimistic: see
            :mod:`aftir_rl.rl.tabular.q_table`).
        max_episode_steps: truncation limit of an episode.
        step_penalty: reward subtracted per free move (AFTIR envs only).
        log_interval: episodes between two logger dumps.

    """

    env_id: str = "AFTIR-Tank-v0"
    tank: str = DEFAULT_TANK
    episodes: int = 2000
    learning_rate: float = 1.0
    gamma: float = 0.95
    exploration_initial_eps: float = 1.0
    exploration_final_eps: float = 0.0
    exploration_decay: float = 0.98
    initial_q: float = 100.0
    max_episode_steps: int = 500
    step_penalty: float = 0.0
    log_interval: int = 50

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"episodes must be at least 1, got {self.episodes}")
        if not 0 < self.learning_rate <= 1:
            raise ValueError(f"learning_rate must be in (0, 1], got {self.learning_rate}")
        if not 0 <= self.gamma <= 1:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        for name in ("exploration_initial_eps", "exploration_final_eps", "exploration_decay"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        if self.max_episode_steps < 1 or self.log_interval < 1:
            raise ValueError("max_episode_steps and log_interval must be at least 1")


def episode_bar(enabled: bool, total: int, desc: str) -> Any:
    """A tqdm bar over ``total`` episodes, or None when not ``enabled``."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="ep", leave=False)


class TabularAgent(ABC):
    """ε-greedy tabular Q-learning: hyperparameters, counters, ε schedule, log and checkpoints.

    The constructor is :class:`~aftir_rl.rl.tabular.q_table.QLearning`'s (its docstring has the
    arguments); a subclass makes its table in :meth:`_setup`, and says what its checkpoint holds
    (:attr:`FORMAT`, :meth:`_arrays`, :meth:`read_checkpoint`, :meth:`_restore`) and how its random
    generator's state is kept (:meth:`_rng_state`, :meth:`_set_rng_state`).

    Attributes:
        episodes_done: episodes trained (per goal, for a goal-conditioned table).
        num_timesteps: transitions experienced.
        metadata: metadata of the checkpoint this agent was loaded from (empty for a new agent).

    """

    #: ``format`` of the subclass's checkpoints.
    FORMAT: ClassVar[str] = ""
    #: Integer keywords of the subclass's constructor, with their bounds in a checkpoint.
    INTEGER_HYPERPARAMETERS: ClassVar[dict[str, tuple[int, int]]] = {}
    #: Whether the checkpoint's arrays are compressed.
    COMPRESSED: ClassVar[bool] = False

    def __init__(
        self,
        env: gym.Env[Any, Any],
        learning_rate: float = 1.0,
        gamma: float = 0.95,
        exploration_initial_eps: float = 1.0,
        exploration_final_eps: float = 0.05,
        exploration_decay: float = 0.99,
        initial_q: float = 0.0,
        seed: int | None = None,
    ) -> None:
        self.env = env
        self.learning_rate = float(learning_rate)
        self.gamma = float(gamma)
        self.exploration_initial_eps = float(exploration_initial_eps)
        self.exploration_final_eps = float(exploration_final_eps)
        self.exploration_decay = float(exploration_decay)
        self.initial_q = float(initial_q)
        self.seed = seed
        self.episodes_done = 0
        self.num_timesteps = 0
        self.metadata: dict[str, Any] = {}
        self._setup(env)

    @abstractmethod
    def _setup(self, env: gym.Env[Any, Any]) -> None:
        """Make the table (and the random generator) for ``env``."""

    @classmethod
    def _keywords(cls) -> list[str]:
        """The constructor's hyperparameter keywords but ``seed``."""
        return [*HYPERPARAMETER_BOUNDS, *cls.INTEGER_HYPERPARAMETERS]

    @classmethod
    def from_config(
        cls: type[A], env: gym.Env[Any, Any], config: QLearningConfig, seed: int | None = None
    ) -> A:
        """An untrained agent with the hyperparameters of a :class:`QLearningConfig`."""
        return cls(env, seed=seed, **{key: getattr(config, key) for key in cls._keywords()})

    def hyperparameters(self) -> dict[str, Any]:
        """The agent's hyperparameters as a plain dict (the constructor's keywords)."""
        return {**{key: getattr(self, key) for key in self._keywords()}, "seed": self.seed}

    # ------------------------------------------------------------------ ε schedule and log
    def _eps(self, episodes: Any) -> Any:
        """ε after ``episodes`` episodes (a number or an array of them)."""
        eps = self.exploration_initial_eps * self.exploration_decay**episodes
        return np.maximum(self.exploration_final_eps, eps)

    @property
    def exploration_rate(self) -> float:
        """Current ε."""
        return float(self._eps(self.episodes_done))

    def _log(
        self, logger: Any, returns: Any, lengths: Any, episodes: int, elapsed: float, **rollout: Any
    ) -> None:
        """Record the last episodes' means, ε, ``rollout/<key>`` and ``time/*``, then dump."""
        logger.record("rollout/ep_rew_mean", float(np.mean(returns)) if returns else 0.0)
        logger.record("rollout/ep_len_mean", float(np.mean(lengths)) if lengths else 0.0)
        logger.record("rollout/exploration_rate", float(self._eps(episodes)))
        for key, value in rollout.items():
            logger.record(f"rollout/{key}", value)
        logger.record("time/episodes", episodes)
        logger.record("time/total_timesteps", self.num_timesteps)
        logger.record("time/time_elapsed", elapsed)
        logger.dump(step=self.num_timesteps)

    # ------------------------------------------------------------------ persistence
    @abstractmethod
    def _arrays(self) -> dict[str, NDArray[Any]]:
        """The arrays a checkpoint holds (the table first)."""

    def _describe(self) -> dict[str, Any]:
        """Metadata a checkpoint holds before the hyperparameters (the env's, for instance)."""
        return {}

    @abstractmethod
    def _rng_state(self) -> Any:
        """The random generator's state, as JSON."""

    @abstractmethod
    def _set_rng_state(self, state: Any) -> None:
        """Restore the random generator from :meth:`_rng_state`'s value (checked on reading)."""

    def save(self, path: str | os.PathLike[str], extra: dict[str, Any] | None = None) -> Path:
        """Write the table and metadata to ``path`` (``.npz``) atomically.

        Args:
            path: destination; ``.npz`` is appended if missing.
            extra: more JSON-serialisable metadata (env id, target...).

        """
        meta = {
            "format": self.FORMAT,
            **self._describe(),
            "hyperparameters": self.hyperparameters(),
            "episodes_done": self.episodes_done,
            "num_timesteps": self.num_timesteps,
            "rng_state": self._rng_state(),
            **(extra or {}),
        }
        return write_npz(npz_path(path), self._arrays(), meta, compressed=self.COMPRESSED)

    @staticmethod
    @abstractmethod
    def read_checkpoint(path: str | os.PathLike[str]) -> tuple[Any, ...]:
        """The checked arrays of a checkpoint, then its metadata.

        Raises:
            CheckpointError: missing, corrupt or not this agent's checkpoint.

        """

    @abstractmethod
    def _restore(self, path: str | os.PathLike[str], checkpoint: tuple[Any, ...]) -> None:
        """Take the tables of :meth:`read_checkpoint`'s ``checkpoint`` read from ``path``.

        Raises:
            CheckpointError: they do not fit this agent's env.

        """

    @classmethod
    def load(cls: type[A], path: str | os.PathLike[str], env: gym.Env[Any, Any]) -> A:
        """Load a checkpoint for ``env``; training can then resume with ``learn``.

        Raises:
            CheckpointError: unreadable file, or a table that does not fit ``env``.

        """
        checkpoint = cls.read_checkpoint(path)
        meta = checkpoint[-1]
        agent = cls(env, **meta["hyperparameters"])  # keys and values checked on reading
        agent._restore(path, checkpoint)
        agent.episodes_done = int(meta.get("episodes_done", 0))
        agent.num_timesteps = int(meta.get("num_timesteps", 0))
        if "rng_state" in meta:
            agent._set_rng_state(meta["rng_state"])
        agent.metadata = meta
        return agent
