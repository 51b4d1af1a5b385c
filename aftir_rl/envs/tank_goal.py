"""``AFTIR-TankGoal-v0``: the tank grid world as a goal-conditioned env (targets drawn per episode).

The dynamics, rewards and rendering are those of the grid world it holds
(:attr:`TankGoalEnv.grid`, a :class:`~aftir_rl.envs.tank_grid.TankGridEnv` whose model it points
at each episode's goal); the interface follows the goal-conditioned convention of
Gymnasium-Robotics that SB3's ``HerReplayBuffer`` relies on: a ``Dict`` observation
``{"observation", "achieved_goal", "desired_goal"}`` of ``MultiDiscrete`` cells, and vectorised
:meth:`TankGoalEnv.compute_reward`, :meth:`TankGoalEnv.compute_terminated` and
:meth:`TankGoalEnv.compute_truncated`. A hit is ``info["hit"]``, so it keeps its −100 under any
relabelled goal (pass ``replay_buffer_kwargs={"copy_info_dict": True}`` to HER). Goals are
drawn among :attr:`TankGoalEnv.goal_cells` or set by ``reset(options=...)``; registered with
``max_episode_steps=100``. Why each choice: docs/design.md §8.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import TargetError
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.envs.tank_grid import TankGridEnv, step_reward, target_options

__all__ = ["TankGoalEnv", "GoalObs"]

#: One observation of :class:`TankGoalEnv`.
GoalObs = dict[str, NDArray[np.int64]]


class TankGoalEnv(gym.Env[GoalObs, int]):
    """Goal-conditioned ``AFTIR-Tank-v0``: reach a target cell drawn per episode.

    ## Description

    The grid world of :class:`~aftir_rl.envs.tank_grid.TankGridEnv` (same tank, moves, rewards
    and terminations) with the target as part of the observation, for goal-conditioned agents
    (HER, tabular goal-conditioned Q-learning) that learn every target in one run.

    ## Action Space

    ``Discrete(6)``, :class:`~aftir_rl.envs.tank_grid.Action`: ±x, ±y, ±z, one cell each.

    ## Observation Space

    ``Dict`` of three ``MultiDiscrete(raster shape)`` (``int64``) cells: ``observation`` and
    ``achieved_goal`` the tip's cell ``(a, b, c)``, ``desired_goal`` the target cell.

    ## Starting State

    The tip in the start cell (the one holding ``(0, 0, 10)`` cm); the goal drawn uniformly among
    :attr:`goal_cells` with ``np_random`` unless fixed by keyword or ``reset`` options.

    ## Rewards

    +100 entering the goal cell, −100 entering an obstructed cell or leaving the box
    (``info["hit"]``), else ``-step_penalty``; :meth:`compute_reward` reproduces it in batches.

    ## Episode End

    Terminated when the goal is reached or on a hit (:meth:`compute_terminated`); truncated by
    ``max_episode_steps`` (100 at registration).

    ## Arguments

    - ``tank``: tank name in ``configs/tanks`` or a YAML path (default ``"b737_center"``).
    - ``target`` (cm) or ``target_cell``: a fixed goal for every episode; default random goals.
    - ``step_penalty``: reward subtracted on every move into a free cell (default 0).
    - ``render_mode``: ``"ansi"`` or ``"rgb_array"``, as the grid world.

    ## Version History

    - v0: initial version.
    """

    metadata = TankGridEnv.metadata

    def __init__(
        self,
        tank: str | Path | Tank = "b737_center",
        target: tuple[float, float, float] | None = None,
        target_cell: tuple[int, int, int] | None = None,
        step_penalty: float = 0.0,
        render_mode: str | None = None,
    ) -> None:
        loaded = load_tank(tank)
        reach = loaded.reachable
        #: Every goal a random episode can draw: reachable free cells but the start, shape (G, 3),
        #: in flat-index order.
        self.goal_cells: NDArray[np.int64] = np.argwhere(reach > 0).astype(np.int64)
        if len(self.goal_cells) == 0:
            raise TargetError(f"tank {loaded.name}: no free cell is reachable from the start")
        #: Flat state index of each of :attr:`goal_cells`.
        self.goal_states: NDArray[np.int64] = cast(  # numpy types it a scalar (a tuple of Any)
            NDArray[np.int64], np.ravel_multi_index(tuple(self.goal_cells.T), reach.shape)
        ).astype(np.int64)
        #: The constructor's goal ``(target, target_cell)``, or None: drawn per episode.
        self._fixed = None if target is None and target_cell is None else (target, target_cell)
        if self._fixed is None:
            a, b, c = (int(v) for v in self.goal_cells[0])
            target_cell = (a, b, c)  # replaced at every reset
        #: The grid world the tip moves in (dynamics, rewards, rendering), aimed at the goal.
        self.grid = TankGridEnv(loaded, target, target_cell, step_penalty, render_mode)
        self.tank, self.raster = self.grid.tank, self.grid.raster
        self.step_penalty, self.render_mode = self.grid.step_penalty, render_mode
        self.start_cell, self.start_state = self.grid.start_cell, self.grid.start_state
        self.action_space = self.grid.action_space
        cell_space = spaces.MultiDiscrete(np.array(self.raster.shape, dtype=np.int64), np.int64)
        # gymnasium types a Dict space's elements as dict[str, Space], not dict[str, element]
        self.observation_space = spaces.Dict(
            {
                "observation": cell_space,
                "achieved_goal": copy.deepcopy(cell_space),
                "desired_goal": copy.deepcopy(cell_space),
            }
        )
        self._dynamics: tuple[NDArray[np.int64], NDArray[np.bool_]] | None = None

    @property
    def target_cell(self) -> tuple[int, int, int]:
        """The episode's goal cell ``(a, b, c)``."""
        return self.grid.target_cell

    @property
    def target_point(self) -> NDArray[np.float64]:
        """The episode's goal [cm]: the point given, or the goal cell's centre."""
        return self.grid.target_point

    @property
    def target_state(self) -> int:
        """The flat state index of the goal cell."""
        return self.grid.target_state

    # ---------------------------------------------------------------- observations
    def _obs(self, state: int) -> GoalObs:
        tip = np.array(self.raster.cell(state), dtype=np.int64)
        return {
            "observation": tip,
            "achieved_goal": tip.copy(),
            "desired_goal": np.array(self.target_cell, dtype=np.int64),
        }

    # ---------------------------------------------------------------- Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[GoalObs, dict[str, Any]]:
        """Put the tip in the start cell and choose the episode's goal.

        Args:
            seed: seeds ``np_random``, which draws the goals.
            options: ``{"target": (x, y, z)}`` (cm) or ``{"target_cell": (a, b, c)}`` sets this
                episode's goal; otherwise the fixed goal of the constructor, or a random one of
                :attr:`goal_cells`.

        Returns:
            The observation and ``{"prob": 1.0, "target_cell": (a, b, c)}``.

        Raises:
            TargetError: the given goal is outside the tank, obstructed or unreachable.
            ValueError: an unknown option.

        """
        super().reset(seed=seed)  # seeds np_random, which draws the goals
        state, info = self.grid.reset()  # the tip to the start cell
        target, target_cell = target_options(options)
        if target is not None or target_cell is not None:
            self.grid.set_target(target, target_cell)
        elif self._fixed is not None:
            self.grid.set_target(*self._fixed)
        else:
            i = int(self.np_random.integers(len(self.goal_cells)))
            self.grid.set_target(None, tuple(int(c) for c in self.goal_cells[i]))
        info["target_cell"] = self.target_cell
        return self._obs(int(state)), info

    def step(self, action: int) -> tuple[GoalObs, SupportsFloat, bool, bool, dict[str, Any]]:
        """Move the tip one cell (the grid world's step); ``info`` adds ``"hit"``."""
        state, reward, terminated, truncated, info = self.grid.step(action)
        info["hit"] = bool(terminated and not info["is_success"])
        return self._obs(int(state)), reward, terminated, truncated, info

    def render(self) -> str | NDArray[np.uint8] | None:  # type: ignore[override]
        """The tank and the tip's path so far, as the grid world renders them."""
        return self.grid.render()

    def path_cells(self) -> list[tuple[int, int, int]]:
        """Cells visited by the tip in this episode, start first."""
        return self.grid.path_cells()

    # ---------------------------------------------------------------- goal-conditioned API
    def compute_reward(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> float | NDArray[np.float64]:
        """The step reward for any (relabelled) goal, vectorised over leading axes.

        Args:
            achieved_goal: tip cells, shape ``(..., 3)`` (the step's next ``achieved_goal``).
            desired_goal: goal cells, shape ``(..., 3)``.
            info: the step's info dict, a list / object array of them (one per batch entry), or
                ``None``; only ``"hit"`` is read (missing means no hit).

        Returns:
            −100 where hit, else +100 where the cells are equal, else ``-step_penalty``; a float
            for single cells, an array of the batch shape otherwise.

        """
        reached, hit = self._reached_and_hit(achieved_goal, desired_goal, info)
        reward = step_reward(hit, reached, self.step_penalty)
        return float(reward) if reward.ndim == 0 else reward

    def compute_terminated(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> bool | NDArray[np.bool_]:
        """Whether the step ends the episode: goal reached or hit (as :meth:`compute_reward`)."""
        reached, hit = self._reached_and_hit(achieved_goal, desired_goal, info)
        done = reached | hit
        return bool(done) if done.ndim == 0 else done

    def compute_truncated(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> bool | NDArray[np.bool_]:
        """Always False: truncation is the ``TimeLimit`` wrapper's (``max_episode_steps``)."""
        shape = np.broadcast_shapes(np.shape(achieved_goal), np.shape(desired_goal))[:-1]
        done = np.zeros(shape, dtype=bool)
        return bool(done) if done.ndim == 0 else done

    def _reached_and_hit(
        self, achieved_goal: ArrayLike, desired_goal: ArrayLike, info: Any
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        achieved = np.asarray(achieved_goal)
        desired = np.asarray(desired_goal)
        if achieved.shape[-1:] != (3,) or desired.shape[-1:] != (3,):
            raise ValueError(
                "achieved_goal and desired_goal must be cells (a, b, c) with a last axis of 3, "
                f"got shapes {achieved.shape} and {desired.shape}"
            )
        reached = np.all(achieved == desired, axis=-1)
        return reached, np.broadcast_to(_hits(info, reached.shape), reached.shape)

    # ---------------------------------------------------------------- model for planners
    def dynamics(self) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """Goal-independent model: ``next_state[s, a]`` and ``hit[s, a]``, shape ``(n_cells, 6)``.

        Read off the grid world's tabulated model (``next_state``, ``terminal_table``) for two
        different goals, on shallow copies so this env's own model is untouched: a row is goal
        independent except the goal's own (absorbing) row, which the other goal's model supplies.
        The tip stays where it is on a hit. Rows of obstructed cells (never occupied) read
        "stay, hit". Cached.
        """
        if self._dynamics is None:
            tables = []
            for cell in (self.goal_cells[0], self.goal_cells[-1]):
                probe = copy.copy(self.grid)
                probe.set_target(None, tuple(int(c) for c in cell))
                nxt = probe.next_state.copy()
                hit = probe.terminal_table & (nxt != probe.target_state)
                tables.append((nxt, hit, probe.target_state))
            (nxt, hit, goal), (nxt2, hit2, _) = tables
            nxt[goal], hit[goal] = nxt2[goal], hit2[goal]  # (a tank with one goal keeps its loop)
            nxt.setflags(write=False)
            hit.setflags(write=False)
            self._dynamics = (nxt, hit)
        return self._dynamics


def _hits(info: Any, shape: tuple[int, ...]) -> NDArray[np.bool_]:
    """``info["hit"]`` for one info dict, a sequence / object array of them, or ``None``."""
    if info is None:
        return np.zeros(shape, dtype=bool)
    if isinstance(info, Mapping):
        return np.asarray(info.get("hit", False), dtype=bool)
    if isinstance(info, (Sequence, np.ndarray)) and not isinstance(info, str):
        infos = np.asarray(info, dtype=object)
        flat = [bool(i.get("hit", False)) if isinstance(i, Mapping) else False for i in infos.flat]
        return np.array(flat, dtype=bool).reshape(infos.shape)
    raise TypeError(f"info must be a dict, a sequence of dicts or None, got {type(info).__name__}")
