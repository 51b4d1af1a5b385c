"""A goal-conditioned Q-table of the tank: its goals, greedy policy and checkpoint.

:class:`GoalTable` is the table ``Q[s, g, a]`` of
:class:`~aftir_rl.rl.tabular.q_table_goal.GoalQLearning` (which adds the training) for the goals of
a :class:`~aftir_rl.envs.tank_goal.TankGoalEnv`: every reachable free cell but the start. It is
stored actions first, ``(6, n_cells, n_goals)``, because gathering ``(6, n)`` blocks and reducing
over the first axis is several times faster in numpy than over a trailing axis of 6;
:attr:`GoalTable.q_table` is a ``(n_cells, n_goals, 6)`` view of it.

Checkpoints are ``.npz`` files (table + JSON metadata: hyperparameters, goal cells, episodes,
random generator state), written and read like :class:`~aftir_rl.rl.tabular.q_table.QLearning`'s
(:class:`~aftir_rl.rl.tabular.learning.TabularAgent`); loading raises
:class:`~aftir_rl.core.errors.CheckpointError` for a missing, corrupt or mismatched file.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import CheckpointError, TargetError
from aftir_rl.core.tank import Tank
from aftir_rl.envs.tank_goal import TankGoalEnv
from aftir_rl.rl.tabular.checkpoint import (
    GOAL_INTEGER_HYPERPARAMETERS,
    GOAL_TABLE_FORMAT,
    read_goal_table,
)
from aftir_rl.rl.tabular.greedy import greedy_lengths, greedy_walk, optimality
from aftir_rl.rl.tabular.learning import QLearningConfig, TabularAgent

__all__ = ["GoalTable"]

#: Default hyperparameters: the converging ones of ``configs/q_table.yaml``.
_DEFAULT = QLearningConfig()


class GoalTable(TabularAgent):
    """A Q-table over ``(cell, goal)`` for :class:`~aftir_rl.envs.tank_goal.TankGoalEnv`, to act on.

    :class:`~aftir_rl.rl.tabular.q_table_goal.GoalQLearning` learns it; this class holds it, acts on
    it, evaluates its greedy paths and keeps it in a checkpoint.

    Args:
        env: a ``TankGoalEnv`` (wrapped or not); its tank, goal cells, start cell, step penalty and
            goal-independent model are used, the env itself is never stepped.
        learning_rate: α in (0, 1]; 1 is the paper's update.
        gamma: discount factor.
        exploration_initial_eps: ε at each goal's first episode.
        exploration_final_eps: floor of ε.
        exploration_decay: multiplicative decay of ε per episode of a goal.
        initial_q: starting value of every entry; optimistic (100) by default, see the module
            docstring of :mod:`aftir_rl.rl.tabular.q_table`.
        max_episode_steps: truncation limit of each goal's episodes.
        seed: seed of the exploration generator.

    Attributes:
        q_table: ``Q[s, g, a]``, shape ``(n_cells, n_goals, 6)``.
        goal_cells: the goals, shape ``(n_goals, 3)``, the env's ``goal_cells``.
        episodes_done: episodes trained per goal.
        num_timesteps: transitions experienced, all goals together.

    """

    FORMAT = GOAL_TABLE_FORMAT
    INTEGER_HYPERPARAMETERS = GOAL_INTEGER_HYPERPARAMETERS
    COMPRESSED = True

    def __init__(
        self,
        env: TankGoalEnv | gym.Env[Any, Any],
        learning_rate: float = _DEFAULT.learning_rate,
        gamma: float = _DEFAULT.gamma,
        exploration_initial_eps: float = _DEFAULT.exploration_initial_eps,
        exploration_final_eps: float = _DEFAULT.exploration_final_eps,
        exploration_decay: float = _DEFAULT.exploration_decay,
        initial_q: float = _DEFAULT.initial_q,
        max_episode_steps: int = _DEFAULT.max_episode_steps,
        seed: int | None = None,
    ) -> None:
        _goal_env(env)
        if not 0 < learning_rate <= 1:
            raise ValueError(f"learning_rate must be in (0, 1], got {learning_rate}")
        if max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be at least 1, got {max_episode_steps}")
        self.max_episode_steps = int(max_episode_steps)
        super().__init__(
            env,
            learning_rate,
            gamma,
            exploration_initial_eps,
            exploration_final_eps,
            exploration_decay,
            initial_q,
            seed,
        )

    def _setup(self, env: TankGoalEnv | gym.Env[Any, Any]) -> None:
        base = _goal_env(env)
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
        shape = (self.next_state.shape[1], n_cells, len(self.goal_states))
        self._q = np.full(shape, self.initial_q)
        self._rng = np.random.default_rng(self.seed)

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
        q, goal_state = self.q_table[:, g], int(self.goal_states[g])
        states, reached = greedy_walk(q, (self.next_state, self.hit), self.start_state, goal_state)
        return [self.raster.cell(x) for x in states], reached

    def greedy_path_lengths(self) -> NDArray[np.int64]:
        """Greedy path length (moves) from the start to every goal, −1 where it fails.

        All goals are walked at once; a walk fails on a hit, or when it has not arrived after
        ``n_cells`` moves (it then cycles).
        """
        dynamics = (self.next_state, self.hit)
        return greedy_lengths(self.q_table, dynamics, self.start_state, self.goal_states)

    def evaluate(self) -> dict[str, Any]:
        """Greedy paths to all goals against the BFS optimum (``tank.reachable``).

        Returns:
            ``n_goals``, ``n_reached``, ``n_optimal``, ``all_optimal``, ``mean_path_steps`` and
            ``max_path_steps`` (over reached goals), and ``not_optimal``: up to 10 goal cells
            whose greedy path is missing or longer than the BFS optimum.

        """
        optimum = self.tank.reachable[tuple(self.goal_cells.T)]
        return optimality(self.greedy_path_lengths(), optimum, self.goal_cells)

    # ------------------------------------------------------------------ persistence
    def _describe(self) -> dict[str, Any]:
        return {
            "tank": self.tank.name,
            "raster_shape": list(self.raster.shape),
            "step_penalty": self.step_penalty,
        }

    def _arrays(self) -> dict[str, NDArray[Any]]:
        return {"q_table": self.q_table, "goal_cells": self.goal_cells}

    def _rng_state(self) -> Mapping[str, Any]:
        return self._rng.bit_generator.state

    def _set_rng_state(self, state: dict[str, Any]) -> None:
        self._rng.bit_generator.state = state

    @staticmethod
    def read_checkpoint(
        path: str | os.PathLike[str],
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], dict[str, Any]]:
        """Read ``(q_table, goal_cells, metadata)`` from a checkpoint.

        Raises:
            CheckpointError: missing, corrupt or not a goal-conditioned Q-table checkpoint.

        """
        return read_goal_table(path)

    def _restore(self, path: str | os.PathLike[str], checkpoint: tuple[Any, ...]) -> None:
        q_table, goal_cells, _ = checkpoint
        if q_table.shape != self.q_table.shape or not np.array_equal(goal_cells, self.goal_cells):
            raise CheckpointError(
                f"{path}: the table has shape {q_table.shape} but this env's tank "
                f"({self.tank.name}) needs {self.q_table.shape} with its goal cells; load it "
                "with the tank it was trained on"
            )
        self.q_table = q_table


def _goal_env(env: TankGoalEnv | gym.Env[Any, Any]) -> TankGoalEnv:
    """The ``TankGoalEnv`` under ``env``'s wrappers; a TypeError if there is none."""
    base = env.unwrapped
    if not isinstance(base, TankGoalEnv):
        raise TypeError(
            "GoalQLearning needs an AFTIR-TankGoal-v0 env (aftir_rl.envs.TankGoalEnv), "
            f"got {type(base).__name__}"
        )
    return base
