"""Tabular Q-learning (seed 002 eq. 1) for any Gymnasium env with Discrete spaces.

The update is ``Q(s,a) ← Q(s,a) + α [r + γ max_a' Q(s',a') − Q(s,a)]``; with ``α = 1`` it is the
paper's rule ``Q(s,a) = r + γ max_a' Q(s',a')``. Exploration is ε-greedy with ε decaying
geometrically per episode from ``exploration_initial_eps`` to a floor. Truncated episodes bootstrap
from the next state; terminated ones do not.

Why the defaults of ``configs/q_table.yaml`` converge: in the tank a random walk rarely reaches a
target 20 cells away before an exploratory step hits a wall and ends the episode, so a
zero-initialised table never sees the +100 (measured with ε decaying by 0.99 per episode to 0.05:
none of the 4 reference targets in 4,000 episodes). An optimistic table (``initial_q = 100``, the
largest return) makes the greedy policy try every untried action, and with α = 1 in a
deterministic env every entry stays an upper bound of Q*. With ε decaying to 0 and greedy ties
broken by the lowest index in training exactly as in evaluation, the greedy path the agent follows
is corrected each time it passes an overestimate, until it is a shortest path (measured: stable
from about 1,200 episodes on the reference and random targets).

Checkpoints are ``.npz`` files holding the table and a JSON metadata record (hyperparameters,
episodes trained, the random generator's state), written to a temporary file and renamed, so a
crash never leaves half a file. Loading checks the file and raises
:class:`~aftir_rl.errors.CheckpointError` with a message saying what is wrong.
"""

from __future__ import annotations

import json
import os
import random
import time
import zipfile
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from aftir_rl.atomic import atomic_open
from aftir_rl.config import brief, shorten
from aftir_rl.errors import AftirError, CheckpointError

__all__ = ["QLearningConfig", "QLearning", "greedy_rollout"]

FORMAT = "aftir_rl.q_table/1"
#: The most bytes a checkpoint may expand to (a 1e6-cell raster's table is 48 MB).
MAX_CHECKPOINT_BYTES = 256_000_000


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
        initial_q: starting value of every table entry (optimistic: see the module docstring).
        max_episode_steps: truncation limit of an episode.
        step_penalty: reward subtracted per free move (AFTIR envs only).
        log_interval: episodes between two logger dumps.

    """

    env_id: str = "AFTIR-Tank-v0"
    tank: str = "b737_center"
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


def _discrete_sizes(env: gym.Env) -> tuple[int, int]:
    if not isinstance(env.observation_space, spaces.Discrete) or not isinstance(
        env.action_space, spaces.Discrete
    ):
        raise TypeError(
            "tabular Q-learning needs Discrete observation and action spaces, got "
            f"{env.observation_space} and {env.action_space}"
        )
    return int(env.observation_space.n), int(env.action_space.n)


class QLearning:
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

    def __init__(
        self,
        env: gym.Env,
        learning_rate: float = 1.0,
        gamma: float = 0.95,
        exploration_initial_eps: float = 1.0,
        exploration_final_eps: float = 0.05,
        exploration_decay: float = 0.99,
        initial_q: float = 0.0,
        seed: int | None = None,
    ) -> None:
        self.env = env
        n_states, n_actions = _discrete_sizes(env)
        self.learning_rate = float(learning_rate)
        self.gamma = float(gamma)
        self.exploration_initial_eps = float(exploration_initial_eps)
        self.exploration_final_eps = float(exploration_final_eps)
        self.exploration_decay = float(exploration_decay)
        self.initial_q = float(initial_q)
        self.seed = seed
        self.q_table: NDArray[np.float64] = np.full((n_states, n_actions), self.initial_q)
        self.episodes_done = 0
        self.num_timesteps = 0
        self._rng = random.Random(seed)
        self._seeded_env = False
        #: Metadata of the checkpoint this agent was loaded from (empty for a new agent).
        self.metadata: dict[str, Any] = {}

    @classmethod
    def from_config(
        cls, env: gym.Env, config: QLearningConfig, seed: int | None = None
    ) -> QLearning:
        """An untrained agent with the hyperparameters of ``config``."""
        return cls(
            env,
            learning_rate=config.learning_rate,
            gamma=config.gamma,
            exploration_initial_eps=config.exploration_initial_eps,
            exploration_final_eps=config.exploration_final_eps,
            exploration_decay=config.exploration_decay,
            initial_q=config.initial_q,
            seed=seed,
        )

    @property
    def exploration_rate(self) -> float:
        """Current ε."""
        eps = self.exploration_initial_eps * self.exploration_decay**self.episodes_done
        return max(self.exploration_final_eps, eps)

    def hyperparameters(self) -> dict[str, Any]:
        """The agent's hyperparameters as a plain dict."""
        return {
            "learning_rate": self.learning_rate,
            "gamma": self.gamma,
            "exploration_initial_eps": self.exploration_initial_eps,
            "exploration_final_eps": self.exploration_final_eps,
            "exploration_decay": self.exploration_decay,
            "initial_q": self.initial_q,
            "seed": self.seed,
        }

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
            callback: called after every episode with the agent; returning False stops training.
            progress_bar: show a tqdm bar over episodes.
            logger: an SB3 logger; gets ``rollout/ep_rew_mean``, ``rollout/ep_len_mean``,
                ``rollout/exploration_rate`` and ``time/*`` every ``log_interval`` episodes.
            log_interval: episodes between two logger dumps.
            reset_options: passed to every ``env.reset``.

        Returns:
            self, trained further (``episodes_done`` and ``num_timesteps`` advance).

        """
        env, rng = self.env, self._rng
        q = self.q_table.tolist()  # lists index and max() far faster than numpy rows
        alpha, gamma = self.learning_rate, self.gamma
        n_actions = len(q[0])
        returns: deque[float] = deque(maxlen=100)
        lengths: deque[int] = deque(maxlen=100)
        start = time.perf_counter()
        bar = None
        if progress_bar:
            from tqdm.auto import tqdm

            bar = tqdm(total=episodes, desc="Q-learning", unit="ep", leave=False)
        try:
            for _ in range(episodes):
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
                self.episodes_done += 1
                self.num_timesteps += ep_len
                returns.append(ep_return)
                lengths.append(ep_len)
                if bar is not None:
                    bar.update(1)
                if logger is not None and self.episodes_done % log_interval == 0:
                    self._log(logger, returns, lengths, time.perf_counter() - start)
                if callback is not None:
                    self.q_table = np.array(q)
                    if callback(self) is False:
                        break
        finally:
            if bar is not None:
                bar.close()
            self.q_table = np.array(q)
        return self

    def _log(self, logger: Any, returns: deque[float], lengths: deque[int], elapsed: float) -> None:
        logger.record("rollout/ep_rew_mean", float(np.mean(returns)))
        logger.record("rollout/ep_len_mean", float(np.mean(lengths)))
        logger.record("rollout/exploration_rate", self.exploration_rate)
        logger.record("time/episodes", self.episodes_done)
        logger.record("time/total_timesteps", self.num_timesteps)
        logger.record("time/time_elapsed", elapsed)
        logger.dump(step=self.num_timesteps)

    # ------------------------------------------------------------------ acting
    def predict(self, observation: int, deterministic: bool = True) -> tuple[int, None]:
        """Action for ``observation`` (SB3's signature); greedy unless ``deterministic=False``."""
        if not deterministic and self._rng.random() < self.exploration_rate:
            return self._rng.randrange(self.q_table.shape[1]), None
        return int(np.argmax(self.q_table[int(observation)])), None

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str], extra: dict[str, Any] | None = None) -> Path:
        """Write the table and metadata to ``path`` (``.npz``) atomically.

        Args:
            path: destination; ``.npz`` is appended if missing.
            extra: more JSON-serialisable metadata (env id, target...).

        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        meta = {
            "format": FORMAT,
            "hyperparameters": self.hyperparameters(),
            "episodes_done": self.episodes_done,
            "num_timesteps": self.num_timesteps,
            "rng_state": _state_to_json(self._rng.getstate()),
            **(extra or {}),
        }
        with atomic_open(path, "wb") as fh:
            np.savez(fh, q_table=self.q_table, metadata=np.array(json.dumps(meta)))
        return path

    @staticmethod
    def read_checkpoint(path: str | os.PathLike[str]) -> tuple[NDArray[np.float64], dict[str, Any]]:
        """Read ``(q_table, metadata)`` from a checkpoint.

        Raises:
            CheckpointError: missing, corrupt or not a Q-table checkpoint.

        """
        path = Path(path)
        hint = "retrain with `python -m aftir_rl.train q_table` or pass the right file"
        arrays, meta = read_npz_checkpoint(path, ("q_table",), FORMAT, "Q-table", hint)
        q_table = np.asarray(arrays["q_table"], dtype=np.float64)
        if q_table.ndim != 2 or not np.all(np.isfinite(q_table)):
            raise CheckpointError(
                f"{path}: the Q-table is malformed (shape {q_table.shape}); {hint}"
            )
        _check_metadata(meta, f"{path}: metadata")
        return q_table, meta

    @classmethod
    def load(cls, path: str | os.PathLike[str], env: gym.Env) -> QLearning:
        """Load a checkpoint for ``env``; training can then resume with :meth:`learn`.

        Raises:
            CheckpointError: unreadable file, or a table that does not fit ``env``'s spaces.

        """
        q_table, meta = cls.read_checkpoint(path)
        n_states, n_actions = _discrete_sizes(env)
        if q_table.shape != (n_states, n_actions):
            raise CheckpointError(
                f"{path}: the Q-table has shape {q_table.shape} but the env needs "
                f"({n_states}, {n_actions}); load it with the env it was trained on"
            )
        agent = cls(env, **meta["hyperparameters"])  # keys and values checked on reading
        agent.q_table = q_table
        agent.episodes_done = int(meta.get("episodes_done", 0))
        agent.num_timesteps = int(meta.get("num_timesteps", 0))
        if "rng_state" in meta:
            agent._rng.setstate(_state_from_json(meta["rng_state"]))
        agent._seeded_env = True
        agent.metadata = meta
        return agent


_HYPERPARAMETERS = {
    "learning_rate": (1e-12, 1.0), "gamma": (0.0, 1.0), "exploration_initial_eps": (0.0, 1.0),
    "exploration_final_eps": (0.0, 1.0), "exploration_decay": (0.0, 1.0),
    "initial_q": (-1e12, 1e12),
}  # fmt: skip


def _number(value: Any, lo: float, hi: float, where: str, integer: bool = False) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if ok and integer:
        ok = isinstance(value, int)
    if not ok or not (lo <= value <= hi):
        kind = "an integer" if integer else "a number"
        raise CheckpointError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")


def read_npz_checkpoint(
    path: Path, names: Sequence[str], fmt: str, what: str, hint: str
) -> tuple[dict[str, NDArray[Any]], dict[str, Any]]:
    """The arrays ``names`` and the JSON metadata of an ``.npz`` checkpoint, read safely.

    Nothing is unpickled (``allow_pickle=False``), an archive that would expand beyond
    :data:`MAX_CHECKPOINT_BYTES` is refused before reading, and the metadata must be a mapping
    whose ``format`` is ``fmt``.

    Raises:
        CheckpointError: missing, oversized, corrupt or of another format (one line, ``hint``).

    """
    try:
        with zipfile.ZipFile(path) as archive:  # refuse a zip bomb before reading it
            if sum(i.file_size for i in archive.infolist()) > MAX_CHECKPOINT_BYTES:
                raise CheckpointError(f"{path}: larger than a {what} checkpoint; {hint}")
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: np.array(data[name]) for name in names}
            meta = json.loads(str(data["metadata"]))
    except FileNotFoundError:
        raise CheckpointError(f"{path}: no such {what} file; {hint}") from None
    except (
        OSError, ValueError, TypeError, KeyError, zipfile.BadZipFile, EOFError, RecursionError,
    ) as exc:  # fmt: skip
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(
            f"{path}: not a readable {what} checkpoint ({shorten(str(exc), 160)}); {hint}"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != fmt:
        raise CheckpointError(f"{path}: not an aftir_rl {what} checkpoint; {hint}")
    return arrays, meta


def check_hyperparameters(
    meta: dict[str, Any], where: str, integers: dict[str, tuple[int, int]] | None = None
) -> None:
    """Check a checkpoint's ``hyperparameters`` (exactly the constructor's keywords) and counters.

    ``integers`` adds integer keywords with their bounds (e.g. the goal-conditioned agent's
    ``max_episode_steps``), so that loading never passes an unknown or unbounded keyword.

    Raises:
        CheckpointError: a missing, unknown or out-of-range value.

    """
    integers = integers or {}
    keys = [*_HYPERPARAMETERS, *integers, "seed"]
    hyper = meta.get("hyperparameters")
    if not isinstance(hyper, dict) or set(hyper) != set(keys):
        raise CheckpointError(f"{where}: hyperparameters must hold exactly {', '.join(keys)}")
    for key, (lo, hi) in _HYPERPARAMETERS.items():
        _number(hyper[key], lo, hi, f"{where}: hyperparameters.{key}")
    for key, (ilo, ihi) in integers.items():
        _number(hyper[key], ilo, ihi, f"{where}: hyperparameters.{key}", integer=True)
    if hyper["seed"] is not None:
        _number(hyper["seed"], 0, 2**63, f"{where}: hyperparameters.seed", integer=True)
    for key in ("episodes_done", "num_timesteps"):
        _number(meta.get(key, 0), 0, 10**15, f"{where}: {key}", integer=True)


def _check_metadata(meta: dict[str, Any], where: str) -> None:
    """Check every key :meth:`QLearning.load` and the command lines read from a checkpoint.

    Raises:
        CheckpointError: a missing or malformed value; an ``env_id`` that is not this package's
            grid world (nothing is ever imported from a checkpoint).

    """
    check_hyperparameters(meta, where)
    if "rng_state" in meta:
        try:
            random.Random().setstate(_state_from_json(meta["rng_state"]))
        except (TypeError, ValueError, OverflowError):
            raise CheckpointError(f"{where}: rng_state is not a random generator's state") from None
    if "env_id" in meta:
        from aftir_rl.safety import registered_env_id

        try:
            registered_env_id(meta["env_id"], where, ("AFTIR-Tank-v0",))
        except AftirError as exc:
            raise CheckpointError(str(exc)) from None
    if "tank" in meta and (not isinstance(meta["tank"], str) or not 0 < len(meta["tank"]) < 4096):
        raise CheckpointError(f"{where}: tank must be a tank name or a YAML path")
    if "tank_fingerprint" in meta and not isinstance(meta["tank_fingerprint"], str):
        raise CheckpointError(f"{where}: tank_fingerprint must be a string")
    for key, integer in (("target", False), ("target_cell", True)):
        value = meta.get(key)
        if value is None:
            continue
        if not isinstance(value, list) or len(value) != 3:
            raise CheckpointError(f"{where}: {key} must be a list of 3 numbers")
        for i, v in enumerate(value):
            _number(v, -1e6, 1e6, f"{where}: {key}[{i}]", integer=integer)


def greedy_rollout(
    agent: QLearning | Any,
    env: gym.Env,
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


def _state_to_json(state: tuple[Any, ...]) -> list[Any]:
    version, internal, gauss = state
    return [version, list(internal), gauss]


def _state_from_json(data: list[Any]) -> tuple[Any, ...]:
    if not isinstance(data, list) or len(data) != 3 or not isinstance(data[1], list):
        raise ValueError("not a random generator's state")
    version, internal, gauss = data
    if len(internal) != 625 or not all(type(v) is int for v in internal):
        raise ValueError("not a random generator's state")
    return (version, tuple(internal), gauss)
