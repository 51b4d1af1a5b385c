"""An SB3 PPO config as RLlib's ``PPOConfig``, and the RLModule a run's weights go into.

The same :class:`~aftir_rl.rl.sb3.config.SB3Config` (an entry of
``configs/hyperparams/ppo.yml`` or a named config, with the command line's overrides) trains
with either library: :data:`PPO_TRAINING_KEYS` maps SB3's PPO hyperparameters to RLlib's, the
ones a config leaves out take SB3's defaults (:data:`SB3_PPO_DEFAULTS`), so both libraries run
the same algorithm settings: ``n_steps`` per env between updates (RLlib's rollout fragment),
``n_envs`` envs in all, minibatches of ``batch_size``, ``n_epochs`` passes, clipping, no KL
penalty, separate policy and value networks of ``policy_kwargs.net_arch`` with tanh.

``Dict`` observations (the goal-conditioned FTL env) are flattened by RLlib's own
``FlattenObservations`` connector in training and by the same function in
:class:`~aftir_rl.rl.rllib.policy.RLlibPolicy`. A batched env (``AFTIR-ArmFTL-v0``) is made by
each env runner as one vector env through its ``vector_entry_point``, never as copies.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from aftir_rl.core.config import brief
from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3.config import BATCHED_ENV_IDS, SB3Config

if TYPE_CHECKING:
    import gymnasium as gym
    from ray.rllib.algorithms.ppo import PPOConfig

__all__ = [
    "INSTALL_HINT",
    "LIBRARY",
    "MAX_ENV_RUNNERS",
    "PPO_TRAINING_KEYS",
    "SB3_PPO_DEFAULTS",
    "check_rllib_config",
    "ppo_config",
    "observation_space",
    "build_module",
    "quiet_rllib",
]

#: How to get RLlib, in every error that needs it.
INSTALL_HINT = 'pip install "aftir_rl[rllib]"'
#: ``library`` of an RLlib run's ``config.json``.
LIBRARY = "rllib"
#: The most env runner processes a run asks for (each a Ray actor with one CPU).
MAX_ENV_RUNNERS = 256

#: SB3's PPO hyperparameters and the keyword of RLlib's ``PPOConfig.training`` each becomes.
#: ``n_steps`` is the rollout fragment (steps per env between updates) and ``policy_kwargs``
#: takes ``net_arch`` only (a list of layer widths, the same for the policy and the value).
PPO_TRAINING_KEYS = {
    "learning_rate": "lr",
    "batch_size": "minibatch_size",
    "n_epochs": "num_epochs",
    "gamma": "gamma",
    "gae_lambda": "lambda_",
    "clip_range": "clip_param",
    "ent_coef": "entropy_coeff",
    "vf_coef": "vf_loss_coeff",
    "max_grad_norm": "grad_clip",
}
#: SB3's PPO defaults (stable_baselines3.PPO), for the keys a config leaves out.
SB3_PPO_DEFAULTS: dict[str, Any] = {
    "learning_rate": 3e-4,
    "n_steps": 2048,
    "batch_size": 64,
    "n_epochs": 10,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.0,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "policy_kwargs": {"net_arch": [64, 64]},
}


def check_rllib_config(config: SB3Config, env_runners: int, source: str = "config") -> None:
    """Refuse what RLlib's PPO cannot train as SB3 would, in one line naming the key.

    Raises:
        ConfigError: HER, a hyperparameter without an RLlib counterpart, a ``policy_kwargs``
            other than ``net_arch``, a schedule instead of a number, or ``n_envs`` that the env
            runners cannot share equally.

    """
    if config.her:
        raise ConfigError(f"{source}: her: RLlib's PPO takes no replay buffer")
    if not isinstance(env_runners, int) or not 0 <= env_runners <= MAX_ENV_RUNNERS:
        raise ConfigError(f"--env-runners must be from 0 to {MAX_ENV_RUNNERS}")
    for key, value in config.hyperparameters.items():
        if key == "policy_kwargs":
            _net_arch(value, source)
        elif key not in PPO_TRAINING_KEYS and key != "n_steps":
            raise ConfigError(
                f"{source}: hyperparameters: {brief(key)} has no counterpart in RLlib's PPO "
                f"(it takes {', '.join(['n_steps', *PPO_TRAINING_KEYS, 'policy_kwargs'])})"
            )
        elif isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{source}: hyperparameters: {key} must be a number for RLlib")
    if env_runners and config.n_envs % env_runners:
        raise ConfigError(
            f"n_envs {config.n_envs} cannot be shared by {env_runners} env runners: "
            "give a multiple of --env-runners"
        )


def _net_arch(policy_kwargs: Any, source: str) -> list[int]:
    """The layer widths of ``policy_kwargs`` (``{"net_arch": [256, 256]}``)."""
    if not isinstance(policy_kwargs, dict) or set(policy_kwargs) - {"net_arch"}:
        raise ConfigError(f"{source}: policy_kwargs: RLlib's PPO takes net_arch only")
    arch = policy_kwargs.get("net_arch", SB3_PPO_DEFAULTS["policy_kwargs"]["net_arch"])
    if not isinstance(arch, list) or not all(type(w) is int and w > 0 for w in arch):
        raise ConfigError(f"{source}: policy_kwargs.net_arch: a list of layer widths for RLlib")
    return list(arch)


def _hyper(config: SB3Config) -> dict[str, Any]:
    """The config's PPO hyperparameters over SB3's defaults."""
    return {**SB3_PPO_DEFAULTS, **config.hyperparameters}


def model_config(config: SB3Config) -> dict[str, Any]:
    """RLlib's ``model_config`` of the default PPO module: SB3's MlpPolicy's networks."""
    arch = _net_arch(_hyper(config)["policy_kwargs"], "config")
    return {"fcnet_hiddens": arch, "fcnet_activation": "tanh", "vf_share_layers": False}


def flatten_connector(env: object = None, spaces: object = None, device: object = None) -> Any:
    """RLlib's ``FlattenObservations``: ``Dict`` observations as one vector (env runners')."""
    from ray.rllib.connectors.env_to_module import FlattenObservations

    return FlattenObservations()


def ppo_config(config: SB3Config, env_id: str, seed: int, env_runners: int) -> PPOConfig:
    """RLlib's ``PPOConfig`` of a checked ``config`` (:func:`check_rllib_config`).

    ``env_runners`` processes (0: the driver samples) share ``n_envs`` envs; one training
    batch is ``n_steps × n_envs`` steps, as SB3's rollout.
    """
    from ray.rllib.algorithms.ppo import PPOConfig

    hyper = _hyper(config)
    bare = env_id.removeprefix("aftir_rl:")
    training = {rl: hyper[sb3] for sb3, rl in PPO_TRAINING_KEYS.items()}
    return (
        PPOConfig()
        .environment(f"aftir_rl:{bare}", env_config=dict(config.env_kwargs))
        .env_runners(
            num_env_runners=env_runners,
            num_envs_per_env_runner=config.n_envs // max(env_runners, 1),
            num_cpus_per_env_runner=1,
            rollout_fragment_length=int(hyper["n_steps"]),
            gym_env_vectorize_mode="vector_entry_point" if bare in BATCHED_ENV_IDS else "sync",
            env_to_module_connector=flatten_connector,
        )
        .training(
            **training,
            train_batch_size_per_learner=int(hyper["n_steps"]) * config.n_envs,
            use_kl_loss=False,
            vf_clip_param=math.inf,  # SB3 clips the policy's ratio, not the value loss
        )
        .rl_module(model_config=model_config(config))
        .fault_tolerance(restart_failed_env_runners=False)  # a failure ends the run, said
        .debugging(seed=seed, log_level="ERROR")
    )


@contextmanager
def quiet_rllib() -> Iterator[None]:
    """RLlib's and Ray's warnings (its own deprecations) kept off the terminal in the block."""
    import logging
    import warnings

    loggers = [logging.getLogger(name) for name in ("ray", "ray.rllib")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def observation_space(space: gym.Space[Any]) -> gym.Space[Any]:
    """The observation space the module sees: ``space`` flattened as the connector does."""
    from ray.rllib.connectors.env_to_module import FlattenObservations

    return FlattenObservations(space).observation_space


def build_module(config: SB3Config, space: gym.Space[Any], action_space: gym.Space[Any]) -> Any:
    """A new PPO module (torch) for an env of ``space`` and ``action_space``, on the CPU."""
    from ray.rllib.algorithms.ppo import PPOConfig

    spec = PPOConfig().rl_module(model_config=model_config(config)).get_default_rl_module_spec()
    spec.observation_space = observation_space(space)
    spec.action_space = action_space
    spec.model_config = model_config(config)
    with quiet_rllib():
        return spec.build()
