"""Behaviour cloning from expert demonstrations into the policy PPO trains.

:func:`load_demos` reads a Minari dataset (as :mod:`aftir_rl.rl.demos` writes it) into arrays:
each step's observation, the expert's action and the discounted return from it.
:func:`clone` fits a fresh SB3 actor-critic policy to them with a small torch loop: the policy
maximises the log-likelihood of the expert's actions and the value head regresses the returns,
so that PPO fine-tuning (``aftir train ppo --demos ...``) starts from the expert's behaviour with
values that fit it. The ``imitation`` library would do the same, but it requires the old ``gym``.
"""

from __future__ import annotations

import itertools
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


#: The most demonstration steps read (about 700 MB of 87-number observations as float32).
MAX_DEMO_STEPS = 2_000_000


def _episode_arrays(
    episode: Any, keys: set[str] | None, where: str
) -> tuple[dict[str, NDArray[np.float32]], NDArray[np.float32], NDArray[np.float64]]:
    """One episode's observations (without the last), actions and rewards, each checked.

    Raises:
        ConfigError: naming the episode and the field: a key missing or extra, a shape that
            does not fit the others, a value that is not a finite number.

    """

    def array(value: Any, field: str, dtype: type = np.float32) -> NDArray[Any]:
        try:
            out: NDArray[Any] = np.asarray(value, dtype=dtype)
        except (TypeError, ValueError, OverflowError):
            out = np.zeros(())
        if out.ndim == 0:
            raise ConfigError(f"{where}: {field} is not an array of numbers")
        if out.size and not np.all(np.isfinite(out)):
            raise ConfigError(f"{where}: {field} holds a NaN or an infinite value")
        return out

    observations = getattr(episode, "observations", None)
    if not isinstance(observations, dict) or (keys is not None and set(observations) != keys):
        found = sorted(observations) if isinstance(observations, dict) else type(observations)
        want = sorted(keys) if keys else "arrays"
        raise ConfigError(f"{where}: observations must be a dict of {want}, got {found}")
    actions = array(getattr(episode, "actions", None), "actions")
    rewards = array(getattr(episode, "rewards", None), "rewards", np.float64)
    steps = len(actions)
    if actions.ndim != 2 or actions.shape[1] != 3 or steps == 0 or rewards.shape != (steps,):
        raise ConfigError(
            f"{where}: expected actions (T, 3) and rewards (T,) of T > 0 steps, got "
            f"{actions.shape} and {rewards.shape}"
        )
    obs = {}
    for key, value in observations.items():
        values = array(value, f"observations[{key!r}]")
        if values.ndim != 2 or len(values) != steps + 1:
            raise ConfigError(
                f"{where}: observations[{key!r}] must hold T + 1 = {steps + 1} rows, "
                f"got {values.shape}"
            )
        obs[key] = values[:-1]
    return obs, actions, rewards


#: The largest discounted return accepted (the envs' rewards are tens per step at most).
MAX_RETURN = 1e9
#: The largest file of a dataset read [bytes]: :data:`MAX_DEMO_STEPS` steps' HDF5, with room.
MAX_DATASET_BYTES = 4_000_000_000
#: The largest metadata file of a dataset read [bytes].
MAX_METADATA_BYTES = 1_000_000


def _check_dataset_files(path: Path) -> None:
    """Refuse a dataset whose files Minari would open but are not plain files of a sane size.

    Minari opens ``data/metadata.json``, ``data/main_data.hdf5`` and the namespace's
    ``namespace_metadata.json`` as they are: a FIFO there blocks forever, a device or a sparse
    file of terabytes is read. Those files and the first 100 entries of ``data/`` must be
    regular files (not symbolic links), metadata at most :data:`MAX_METADATA_BYTES`, the rest
    at most :data:`MAX_DATASET_BYTES`.

    Raises:
        ConfigError: one line naming the file.

    """
    import stat

    data = path / "data"
    opened = [
        data / "metadata.json",
        data / "main_data.hdf5",
        path.parent / "namespace_metadata.json",
    ]
    others = sorted(itertools.islice(data.iterdir(), 100))  # what else is there, a bounded look
    for entry in dict.fromkeys([*opened, *others]):
        if not os.path.lexists(entry):
            continue
        info = os.lstat(entry)
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(f"{entry}: not a regular file; not a dataset this package wrote")
        cap = MAX_METADATA_BYTES if entry.suffix == ".json" else MAX_DATASET_BYTES
        if info.st_size > cap:
            raise ConfigError(f"{entry}: {info.st_size:,} bytes, more than {cap:,}")


def _returns(rewards: NDArray[Any], gamma: float, where: str) -> NDArray[np.float32]:
    """The discounted return from each step, summed in float64 and checked to fit.

    Raises:
        ConfigError: a return beyond ±:data:`MAX_RETURN` (an inf or NaN sum included).

    """
    g, back = 0.0, []
    for r in rewards[::-1]:
        g = float(r) + gamma * g
        back.append(g)
    out = np.array(back[::-1])
    if not np.all(np.abs(out) <= MAX_RETURN):
        raise ConfigError(
            f"{where}: rewards sum to returns beyond ±{MAX_RETURN:g}; "
            "not a dataset of this package's envs"
        )
    return out.astype(np.float32)


def load_demos(path: str | os.PathLike[str], gamma: float) -> Demos:
    """Read the Minari dataset in ``path`` (``ROOT/namespace/name-vN``), every episode checked.

    Raises:
        ConfigError: Minari is missing, ``path`` is not a dataset, an episode's field is
            missing, of the wrong shape or not finite, or the dataset holds more than
            :data:`MAX_DEMO_STEPS` steps (one line naming the episode and the field).

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
    _check_dataset_files(path)
    os.environ["MINARI_DATASETS_PATH"] = str(path.parent.parent)
    try:
        dataset = minari.load_dataset(f"{path.parent.name}/{path.name}")
    except Exception as exc:  # Minari raises ValueError, KeyError, OSError... for bad files
        raise ConfigError(f"{path}: not a readable Minari dataset ({type(exc).__name__})") from None
    obs: dict[str, list[NDArray[np.float32]]] = {}
    actions, returns, steps = [], [], 0
    episodes = iter(dataset.iterate_episodes())
    for i in itertools.count():
        try:
            episode = next(episodes)
        except StopIteration:
            break
        except Exception as exc:  # noqa: BLE001 - a corrupt file fails in Minari or h5py
            raise ConfigError(f"{path}: episode {i} is unreadable ({type(exc).__name__})") from None
        keys = set(obs) if obs else None
        o, a, rewards = _episode_arrays(episode, keys, f"{path}: episode {i}")
        steps += len(a)
        if steps > MAX_DEMO_STEPS:
            raise ConfigError(f"{path}: more than {MAX_DEMO_STEPS:,} steps; use a smaller dataset")
        for key, value in o.items():
            obs.setdefault(key, []).append(value)
        actions.append(a)
        returns.append(_returns(rewards, gamma, f"{path}: episode {i}"))
    if not actions:
        raise ConfigError(f"{path}: the dataset holds no episodes")
    try:
        spec = dataset.spec.env_spec
    except Exception as exc:  # noqa: BLE001 - Minari reads it from the metadata, unchecked
        raise ConfigError(f"{path}: unreadable dataset metadata ({type(exc).__name__})") from None
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
