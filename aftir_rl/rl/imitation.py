"""Behaviour cloning from expert demonstrations into the policy PPO trains.

:func:`load_demos` reads a Minari dataset (as :mod:`aftir_rl.rl.demos` writes it) into arrays:
each step's observation, the expert's action and the discounted return from it.
:func:`clone` fits a fresh SB3 actor-critic policy to them with a small torch loop: the policy
maximises the log-likelihood of the expert's actions and the value head regresses the returns,
so that PPO fine-tuning (``aftir train ppo --demos ...``) starts from the expert's behaviour with
values that fit it. The ``imitation`` library would do the same, but it requires the old ``gym``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError

if TYPE_CHECKING:
    from gymnasium import Space
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    from aftir_rl.rl.sb3.config import SB3Config

__all__ = ["Demos", "clone", "load_demos", "pretrainer"]


@dataclass
class Demos:
    """Expert steps as arrays.

    Attributes:
        observations: per key of the ``Dict`` observation, ``(N, ...)`` (the step's, not the
            next one's).
        actions: ``(N, 3)``.
        returns: discounted return from each step, ``(N,)``.
        episodes: episodes read.
        env_kwargs: the keyword arguments of the env the dataset was made with.

    """

    observations: dict[str, NDArray[np.float32]]
    actions: NDArray[np.float32]
    returns: NDArray[np.float32]
    episodes: int
    env_kwargs: dict[str, Any]


def load_demos(path: str | os.PathLike[str], gamma: float) -> Demos:
    """Read the Minari dataset in ``path`` (``ROOT/namespace/name-vN``).

    Raises:
        ConfigError: Minari is missing, or ``path`` is not a dataset (one line).

    """
    try:
        import minari
    except ImportError:
        raise ConfigError(
            "reading demonstrations needs Minari: pip install 'aftir_rl[demos]'"
        ) from None
    path = Path(path).resolve()
    if not (path / "data").is_dir():
        raise ConfigError(f"{path}: not a Minari dataset (no data/ folder)")
    os.environ["MINARI_DATASETS_PATH"] = str(path.parent.parent)
    try:
        dataset = minari.load_dataset(f"{path.parent.name}/{path.name}")
    except Exception as exc:  # Minari raises ValueError, KeyError, OSError... for bad files
        raise ConfigError(f"{path}: not a readable Minari dataset ({type(exc).__name__})") from None
    obs: dict[str, list[NDArray[np.float32]]] = {}
    actions, returns = [], []
    for episode in dataset.iterate_episodes():
        for key, value in episode.observations.items():
            obs.setdefault(key, []).append(np.asarray(value[:-1], dtype=np.float32))
        actions.append(np.asarray(episode.actions, dtype=np.float32))
        g, back = 0.0, []
        for r in episode.rewards[::-1]:
            g = float(r) + gamma * g
            back.append(g)
        returns.append(np.array(back[::-1], dtype=np.float32))
    if not actions:
        raise ConfigError(f"{path}: the dataset holds no episodes")
    spec = dataset.spec.env_spec
    return Demos(
        observations={k: np.concatenate(v) for k, v in obs.items()},
        actions=np.concatenate(actions),
        returns=np.concatenate(returns),
        episodes=len(actions),
        env_kwargs=dict(spec.kwargs) if spec is not None else {},
    )


def clone(
    model: OnPolicyAlgorithm,
    demos: Demos,
    epochs: int = 10,
    batch_size: int = 1024,
    learning_rate: float = 1e-3,
    value_weight: float = 0.5,
    seed: int = 0,
) -> dict[str, float]:
    """Fit ``model``'s policy (an SB3 ``ActorCriticPolicy``) to ``demos``, in place.

    Returns:
        ``epochs``, ``steps`` (demonstration steps), the last epoch's ``nll`` (negative
        log-likelihood of the expert's actions), ``value_mse``, ``action_mse`` (of the
        deterministic action), and ``seconds``.

    """
    import torch
    import torch.nn.functional as F

    policy = model.policy
    _check_observations(policy.observation_space, demos)
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    device = policy.device
    obs = {k: torch.as_tensor(v, device=device) for k, v in demos.observations.items()}
    acts = torch.as_tensor(demos.actions, device=device)
    rets = torch.as_tensor(demos.returns, device=device)
    opt = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    policy.set_training_mode(True)
    n = len(acts)
    stats: dict[str, float] = {}
    for _ in range(epochs):
        sums = np.zeros(3)
        order = rng.permutation(n)
        for lo in range(0, n, batch_size):
            pick = torch.as_tensor(order[lo : lo + batch_size], device=device)
            o = {k: v[pick] for k, v in obs.items()}
            values, log_prob, _ = policy.evaluate_actions(o, acts[pick])
            nll = -log_prob.mean()
            vloss = F.mse_loss(values.flatten(), rets[pick])
            loss = nll + value_weight * vloss
            opt.zero_grad()
            loss.backward()
            opt.step()
            with torch.no_grad():
                mean = policy.get_distribution(o).mode()  # the Gaussian's mean
                amse = F.mse_loss(mean.clamp(-1, 1), acts[pick])
            w = len(pick)
            sums += w * np.array([nll.item(), vloss.item(), amse.item()])
        stats = dict(zip(("nll", "value_mse", "action_mse"), (sums / n).tolist()))
    policy.set_training_mode(False)
    return {"epochs": epochs, "steps": n, **stats, "seconds": time.perf_counter() - start}


def _check_observations(space: Space[Any], demos: Demos) -> None:
    """A :class:`ConfigError` unless ``demos``' observations fit a policy observing ``space``."""
    from gymnasium import spaces

    if not isinstance(space, spaces.Dict):
        raise ConfigError(f"the policy observes {space}, not the demonstrations' dict of arrays")
    for key, value in demos.observations.items():
        if key not in space.spaces or space[key].shape != value.shape[1:]:
            raise ConfigError(
                f"the demonstrations' observation {key!r} {value.shape[1:]} does not fit the "
                f"policy's {space.spaces.get(key)}; make both with the same env_kwargs"
            )


def pretrainer(
    path: str | os.PathLike[str], config: SB3Config, epochs: int = 20, seed: int = 0
) -> Callable[[BaseAlgorithm], dict[str, float]]:
    """``pretrain(model)`` for :func:`~aftir_rl.rl.sb3.train.train_sb3`: clone ``path``'s demos.

    Raises:
        ConfigError: the demonstrations were made with another ``steer`` (their actions would
            mean something else) or cannot be read.

    """
    gamma = float(config.hyperparameters.get("gamma", 0.99))
    demos = load_demos(path, gamma)
    mine = config.env_kwargs.get("steer", "increment")
    theirs = demos.env_kwargs.get("steer", "increment")
    if mine != theirs:
        raise ConfigError(
            f"{path}: the demonstrations steer by {theirs!r}, the config's env by {mine!r}; "
            "their actions would mean something else"
        )

    def pretrain(model: BaseAlgorithm) -> dict[str, float]:
        from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

        if not isinstance(model, OnPolicyAlgorithm):
            raise ConfigError(f"demonstrations clone into PPO or A2C, not {type(model).__name__}")
        return {"episodes": float(demos.episodes), **clone(model, demos, epochs, seed=seed)}

    return pretrain
