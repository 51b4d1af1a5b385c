"""``AFTIR-Tank-v0``: the rasterised fuel tank of filomat2018 as a Gymnasium grid world."""

from __future__ import annotations

import operator
from collections.abc import Sequence
from enum import IntEnum
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.errors import InvalidActionError, TargetError
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank import Tank, load_tank

__all__ = ["Action", "TankGridEnv", "step_reward", "target_options"]

TARGET_REWARD = 100.0
OBSTACLE_REWARD = -100.0


def step_reward(hit: ArrayLike, reached: ArrayLike, step_penalty: float) -> NDArray[np.float64]:
    """filomat2018 eq. 2: −100 where ``hit``, else +100 where ``reached``, else -step_penalty."""
    return np.where(hit, OBSTACLE_REWARD, np.where(reached, TARGET_REWARD, -step_penalty))


def target_options(options: dict[str, Any] | None) -> tuple[Any, Any]:
    """``(target, target_cell)`` of ``reset``'s ``options`` (None where not given).

    Raises:
        ValueError: an option other than ``target`` and ``target_cell``.

    """
    options = options or {}
    unknown = sorted(set(options) - {"target", "target_cell"})
    if unknown:
        raise ValueError(f"unknown reset option {unknown[0]!r}; use 'target' or 'target_cell'")
    return options.get("target"), options.get("target_cell")


class Action(IntEnum):
    """Move the tip one cell along an axis."""

    X_PLUS = 0
    X_MINUS = 1
    Y_PLUS = 2
    Y_MINUS = 3
    Z_PLUS = 4
    Z_MINUS = 5


_MOVES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])


class TankGridEnv(gym.Env[int, int]):
    """The arm's tip moving cell by cell through the rasterised tank (filomat2018 §2–3).

    ## Description

    The interior of the reference Boeing 737 center tank (two bays joined by a hatch in the
    spanwise beam) is split into 20 cm cubes, 15 × 10 × 5 cells. The agent moves the tip of the
    continuum arm from the cell just inside the access panel to the cell of a target, through free
    cells. The learned cell path is what the posture generators turn into joint variables.

    ## Action Space

    ``Discrete(6)``, :class:`Action`: 0 +x, 1 −x, 2 +y, 3 −y, 4 +z, 5 −z, one cell each.

    ## Observation Space

    ``Discrete(nx·ny·nz)`` (750 for the reference tank): the tip's cell ``(a, b, c)`` as
    ``ravel_multi_index((a, b, c), (nx, ny, nz))``.

    ## Starting State

    The cell containing the tank's ``start_point`` (``(0, 0, 10)`` cm: just inside the panel).

    ## Rewards

    filomat2018 eq. 2: +100 for entering the target cell, −100 for entering an obstructed cell or
    leaving the box, otherwise ``-step_penalty`` (default 0).

    ## Episode End

    Terminated when the target is reached or an obstructed cell / the crust is hit (the tip then
    stays where it was). Truncated by ``max_episode_steps`` (500 at registration).

    ## Arguments

    - ``tank``: tank name in ``configs/tanks`` or a YAML path (default ``"b737_center"``).
    - ``target``: target point ``(x, y, z)`` [cm]; or
    - ``target_cell``: target cell ``(a, b, c)``. With neither, the tank's first reference target.
    - ``step_penalty``: reward subtracted on every move into a free cell (default 0).
    - ``render_mode``: ``"ansi"`` (z-slices) or ``"rgb_array"`` (3D picture of tank and path).

    ``reset(options={"target": (x, y, z)})`` or ``{"target_cell": (a, b, c)}`` changes the target
    for that and later episodes. ``env.unwrapped.P[s][a] == [(1.0, s_next, reward, terminated)]``
    as in FrozenLake, for planners and value iteration.

    ## Version History

    - v0: initial version.
    """

    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}
    # gymnasium types a Discrete space as Space[np.int64] while the states here are plain ints.
    observation_space: spaces.Space[Any]
    action_space: spaces.Space[Any]

    def __init__(
        self,
        tank: str | Path | Tank = DEFAULT_TANK,
        target: tuple[float, float, float] | None = None,
        target_cell: tuple[int, int, int] | None = None,
        step_penalty: float = 0.0,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, "
                f"got {render_mode!r}"
            )
        self.tank = load_tank(tank)
        self.raster = self.tank.raster
        self.step_penalty = float(step_penalty)
        self.render_mode = render_mode
        self.observation_space = spaces.Discrete(self.raster.n_cells)
        self.action_space = spaces.Discrete(len(Action))
        self.start_cell = self.tank.start_cell
        self.start_state = self.raster.index(self.start_cell)
        self._model_target: int | None = None
        self._P: dict[int, dict[int, list[tuple[float, int, float, bool]]]] | None = None
        if target is None and target_cell is None:
            if not self.tank.targets:
                raise TargetError(f"tank {self.tank.name} has no reference target; pass target=")
            target = self.tank.targets[0]
        self.set_target(target, target_cell)
        self._state = self.start_state
        self._path: list[int] = [self.start_state]

    # ---------------------------------------------------------------- target and model
    def set_target(self, target: Sequence[float] | None, target_cell: Sequence[int] | None) -> None:
        """Aim at the point ``target`` [cm] or the cell ``target_cell`` (one of them).

        The model (:attr:`next_state`, :attr:`P`, ...) is tabulated again for a new target cell.

        Raises:
            TargetError: both given, or the point or cell is outside the tank or obstructed.

        """
        if target is not None and target_cell is not None:
            raise TargetError("give either target (a point in cm) or target_cell, not both")
        if target_cell is not None:
            cell = tuple(int(c) for c in target_cell)
            self.tank.check_target_cell(cell)
            point = self.raster.cell_center(cell)
        else:
            point = np.asarray(target, dtype=np.float64)
            cell = self.tank.target_cell(point)
        self.target_cell: tuple[int, int, int] = cell  # type: ignore[assignment]
        self.target_point: NDArray[np.float64] = point
        self.target_state = self.raster.index(cell)
        if self._model_target != self.target_state:
            self._build_model()

    def _build_model(self) -> None:
        """Tabulate next state, reward and termination for every (state, action)."""
        shape = np.array(self.raster.shape)
        cells = np.array(np.unravel_index(np.arange(self.raster.n_cells), tuple(shape))).T
        nxt_cells = cells[:, None, :] + _MOVES[None, :, :]
        inside = np.all((nxt_cells >= 0) & (nxt_cells < shape), axis=-1)
        clipped = np.clip(nxt_cells, 0, shape - 1)
        nxt = np.ravel_multi_index(tuple(np.moveaxis(clipped, -1, 0)), tuple(shape))
        blocked = ~inside | self.raster.obstructed.ravel()[nxt]
        here = np.arange(self.raster.n_cells)[:, None]
        nxt = np.where(blocked, here, nxt)
        reached = ~blocked & (nxt == self.target_state)
        reward = step_reward(blocked, reached, self.step_penalty)
        terminated = blocked | reached
        # Absorbing states (the target, obstructed cells) loop with reward 0, as in FrozenLake.
        absorbing = self.raster.obstructed.ravel().copy()
        absorbing[self.target_state] = True
        nxt[absorbing] = here[absorbing]
        reward[absorbing] = 0.0
        terminated[absorbing] = True
        self.next_state: NDArray[np.int64] = nxt
        self.reward_table: NDArray[np.float64] = reward
        self.terminal_table: NDArray[np.bool_] = terminated
        # Python lists: indexing them is several times faster than numpy scalars in step().
        self._next_l = nxt.tolist()
        self._reward_l = reward.tolist()
        self._term_l = terminated.tolist()
        self._model_target = self.target_state
        self._P = None

    @property
    def P(self) -> dict[int, dict[int, list[tuple[float, int, float, bool]]]]:  # noqa: N802
        """Transition model ``P[s][a] = [(1.0, s_next, reward, terminated)]`` (FrozenLake's)."""
        if self._P is None:
            self._P = {
                s: {
                    a: [(1.0, self._next_l[s][a], self._reward_l[s][a], self._term_l[s][a])]
                    for a in range(len(Action))
                }
                for s in range(self.raster.n_cells)
            }
        return self._P

    # ---------------------------------------------------------------- Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[int, dict[str, Any]]:
        """Put the tip in the start cell; ``options`` may set ``target`` or ``target_cell``."""
        super().reset(seed=seed)
        target, target_cell = target_options(options)
        if target is not None or target_cell is not None:
            self.set_target(target, target_cell)
        self._state = self.start_state
        self._path = [self.start_state]
        return self.start_state, {"prob": 1.0, "target_cell": self.target_cell}

    def step(self, action: int) -> tuple[int, SupportsFloat, bool, bool, dict[str, Any]]:
        """Move the tip one cell; see the class docstring for rewards and termination."""
        try:
            a = operator.index(action)
        except TypeError:
            a = -1
        if not 0 <= a < 6:
            raise InvalidActionError(
                f"invalid action {action!r}: AFTIR-Tank-v0 takes an integer 0..5 "
                "(aftir_rl.envs.Action: +x, -x, +y, -y, +z, -z)"
            )
        s = self._state
        nxt = self._next_l[s][a]
        terminated = self._term_l[s][a]
        self._state = nxt
        if nxt != s:
            self._path.append(nxt)
        return (
            nxt,
            self._reward_l[s][a],
            terminated,
            False,
            {"prob": 1.0, "is_success": nxt == self.target_state},
        )

    # ---------------------------------------------------------------- rendering
    def path_cells(self) -> list[tuple[int, int, int]]:
        """Cells visited by the tip in this episode, start first."""
        return [self.raster.cell(s) for s in self._path]

    def render(self) -> str | NDArray[np.uint8] | None:  # type: ignore[override]
        """Render the tank and the tip's path so far (``ansi`` or ``rgb_array``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode= to make()")
            return None
        cells = self.path_cells()
        if self.render_mode == "ansi":
            marks = {c: "*" for c in cells}
            marks[self.start_cell] = "S"
            marks[self.target_cell] = "T"
            marks[cells[-1]] = "A"
            legend = "# obstructed  . free  S start  T target  * path  A tip"
            return legend + "\n" + self.raster.ascii(marks)
        if getattr(self, "_renderer", None) is None:  # kept: blitting, a few ms per frame
            from aftir_rl.viz.plotting import PathRenderer

            self._renderer = PathRenderer(self.tank, title="AFTIR-Tank-v0")
        points = np.array([self.raster.cell_center(c) for c in cells])
        return self._renderer.render(points, self.target_point)
