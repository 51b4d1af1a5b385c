"""SB3 ``VecEnv`` over a Gymnasium ``VectorEnv`` that resets rows within the step (``SameStep``).

Stable-Baselines3 steps a ``VecEnv``: ``step`` returns the next observations with finished rows
already reset, ``dones``, and one info dict per row holding ``terminal_observation`` and
``TimeLimit.truncated``. A Gymnasium vector env with ``autoreset_mode=SameStep`` returns the same
information as ``info["final_obs"]`` and the ``truncated`` flags; :class:`SB3VectorEnv` converts
one into the other, so the batched ``AFTIR-ArmFTL-v0`` (one numpy pass for all rows) trains with
every SB3 algorithm. ``env_method`` and ``get_attr`` reach the vector env itself: HER's
``compute_reward`` is vectorised there.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from aftir_rl.core.errors import ConfigError
from aftir_rl.envs.registration import registered_env_id

__all__ = ["SB3VectorEnv", "make_batched_vec_env", "make_sb3_vec_env"]


class SB3VectorEnv(VecEnv):
    """Stable-Baselines3 view of a Gymnasium vector env in ``SameStep`` autoreset mode.

    Args:
        venv: the vector env; its ``metadata["autoreset_mode"]`` must be ``SameStep``.
        running_info_keys: the info keys rows that did not finish get; ``None`` (default):
            every key, as every row of a ``VecEnv`` has. Finished rows always get every key.
            SB3 reads the infos of finished rows only (``Monitor``'s episode, ``is_success``,
            ``terminal_observation``) except in ``HerReplayBuffer``, which keeps every row's: so
            PPO, and SAC or TD3 without HER, train the same with ``()``, and their steps skip
            building one dict per row.

    """

    def __init__(
        self,
        venv: gym.vector.VectorEnv[Any, Any, Any],
        running_info_keys: Sequence[str] | None = None,
    ) -> None:
        if venv.metadata.get("autoreset_mode") is not AutoresetMode.SAME_STEP:
            raise ConfigError("SB3VectorEnv needs a vector env with autoreset_mode='SameStep'")
        self.venv = venv
        self.running_info_keys = None if running_info_keys is None else tuple(running_info_keys)
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self) -> VecEnvObs:
        """Reset every row (with the seeds given to :meth:`seed`, once)."""
        seed = self._seeds[0] if self._seeds and self._seeds[0] is not None else None
        obs, info = self.venv.reset(seed=seed)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Remember the actions of the next :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every row; finished rows come back reset, their last observation in the info."""
        assert self._actions is not None
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        dones = np.logical_or(terminated, truncated)
        keys = [
            k
            for k, v in info.items()
            if not k.startswith("_")
            and k != "final_obs"
            and isinstance(v, np.ndarray)
            and len(v) == self.num_envs
        ]
        infos: list[dict[str, Any]]
        if self.running_info_keys is None:
            # one conversion per key (rows of 1-D arrays as Python scalars), then one dict per row
            columns = [info[k].tolist() if info[k].ndim == 1 else list(info[k]) for k in keys]
            infos = (
                [dict(zip(keys, row)) for row in zip(*columns)]
                if keys
                else [{} for _ in range(self.num_envs)]
            )
        else:
            running = [k for k in keys if k in self.running_info_keys]
            infos = (
                [{k: _item(info[k], i) for k in running} for i in range(self.num_envs)]
                if running
                else [{} for _ in range(self.num_envs)]
            )
        final = info.get("final_obs")
        ended = np.flatnonzero(dones)
        if self.running_info_keys is not None and len(ended):
            # the finished rows get every key: one conversion per key, as above
            done_columns = [
                info[k][ended].tolist() if info[k].ndim == 1 else list(info[k][ended]) for k in keys
            ]
            for i, values in zip(ended.tolist(), zip(*done_columns)):
                infos[i].update(zip(keys, values))
        for i in ended.tolist():
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if final is not None:
                infos[i]["terminal_observation"] = final[i]
        return obs, np.asarray(reward, dtype=np.float32), dones, infos

    def close(self) -> None:
        """Close the vector env."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute, once per requested row."""
        return [getattr(self.venv, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the vector env (shared by all rows)."""
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        """Call a method of the vector env once (it is vectorised), for the first row asked."""
        return [getattr(self.venv, method_name)(*method_args, **kwargs)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper[Any, Any, Any, Any]], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Rows are not gymnasium-wrapped."""
        return [False] * len(self._indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The batched env does not render."""
        return [None] * self.num_envs

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)


def _item(column: np.ndarray, row: int) -> Any:
    """Row ``row`` of an info column as the full-info path gives it (a scalar or an array)."""
    value = column[row]
    return value.item() if column.ndim == 1 else value


def make_batched_vec_env(
    env_id: str,
    n_envs: int,
    seed: int | None,
    env_kwargs: dict[str, Any] | None = None,
    running_info_keys: Sequence[str] | None = None,
) -> VecEnv | None:
    """SB3 ``VecEnv`` of ``n_envs`` rows of a batched env (with ``VecMonitor``), or None.

    None when ``env_id`` has no ``vector_entry_point`` (or ``n_envs`` is 1): the caller makes
    per-env copies as usual. ``running_info_keys``: see :class:`SB3VectorEnv`.
    """
    spec = gym.spec(env_id.split(":")[-1])  # the "aftir_rl:" module prefix is for make only
    if spec.vector_entry_point is None or n_envs < 2:
        return None
    kwargs = dict(env_kwargs or {})
    if spec.max_episode_steps is not None:
        kwargs.setdefault("max_episode_steps", spec.max_episode_steps)
    venv = gym.make_vec(
        env_id,
        num_envs=n_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **kwargs,
    )
    out = VecMonitor(SB3VectorEnv(venv, running_info_keys))
    out.seed(seed)
    return out


def make_sb3_vec_env(
    env_id: str, n_envs: int = 1, seed: int | None = None, **env_kwargs: Any
) -> VecEnv:
    """The SB3 ``VecEnv`` of ``n_envs`` copies of one of this package's envs, for other code.

    An env with a batched version (``AFTIR-ArmFTL-v0``) gives one batched env of ``n_envs``
    rows (one numpy pass for all rows, reset within the step as SB3 expects); the others give
    ``n_envs`` copies in a ``DummyVecEnv``; either logs its episodes (``VecMonitor``,
    ``Monitor``)::

        venv = make_sb3_vec_env("AFTIR-ArmFTL-v0", n_envs=64, seed=0, bay=2, guide=True)
        PPO("MultiInputPolicy", venv).learn(100_000)

    Raises:
        ConfigError: ``env_id`` is not one of this package's envs, or ``n_envs`` is below 1.

    """
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    if not isinstance(n_envs, int) or n_envs < 1:
        raise ConfigError(f"n_envs must be a whole number of at least 1, got {n_envs!r}")
    env_id = f"aftir_rl:{registered_env_id(env_id, 'make_sb3_vec_env')}"
    venv = make_batched_vec_env(env_id, n_envs, seed, env_kwargs)
    if venv is None:  # each copy in SB3's Monitor
        venv = make_vec_env(env_id, n_envs, seed, vec_env_cls=DummyVecEnv, env_kwargs=env_kwargs)
    return venv
