"""An SB3 PPO or SAC config as RLlib's, and the RLModule a run's weights go into.

The same :class:`~aftir_rl.rl.sb3.config.SB3Config` (an entry of
``configs/hyperparams/<algo>.yml`` or a named config, with the command line's overrides) trains
with either library (:func:`rllib_config`): SB3's hyperparameters map to RLlib's, the ones a
config leaves out take SB3's defaults (:data:`SB3_DEFAULTS`), so both libraries run the same
settings. PPO: ``n_steps`` per env between updates (RLlib's rollout fragment), ``n_envs`` envs
in all, minibatches of ``batch_size``, ``n_epochs`` passes, clipping, no KL penalty, separate
policy and value networks of ``policy_kwargs.net_arch`` with tanh. SAC: one learning rate for
actor, critics and temperature, a uniform replay buffer of ``buffer_size``, ``learning_starts``,
``gradient_steps`` updates of ``batch_size`` per ``train_freq`` steps of every env (RLlib's
training intensity), the temperature learnt from ``ent_coef`` ``auto`` or ``auto_X``, twin
critics, ReLU networks of ``net_arch``.

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

__all__ = [
    "INSTALL_HINT",
    "LIBRARY",
    "MAX_ENV_RUNNERS",
    "ALGORITHMS",
    "PPO_TRAINING_KEYS",
    "SAC_KEYS",
    "SB3_DEFAULTS",
    "SB3_PPO_DEFAULTS",
    "SB3_SAC_DEFAULTS",
    "check_rllib_config",
    "rllib_config",
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

#: The algorithms RLlib trains here.
ALGORITHMS = ("ppo", "sac")

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
#: SB3's SAC hyperparameters RLlib's SAC takes (how each maps: :func:`rllib_config`).
SAC_KEYS = (
    "learning_rate",
    "buffer_size",
    "learning_starts",
    "batch_size",
    "tau",
    "gamma",
    "train_freq",
    "gradient_steps",
    "ent_coef",
    "target_entropy",
)
#: SB3's SAC defaults (stable_baselines3.SAC), for the keys a config leaves out.
SB3_SAC_DEFAULTS: dict[str, Any] = {
    "learning_rate": 3e-4,
    "buffer_size": 1_000_000,
    "learning_starts": 100,
    "batch_size": 256,
    "tau": 0.005,
    "gamma": 0.99,
    "train_freq": 1,
    "gradient_steps": 1,
    "ent_coef": "auto",
    "target_entropy": "auto",
    "policy_kwargs": {"net_arch": [256, 256]},
}
#: Each algorithm's SB3 defaults.
SB3_DEFAULTS = {"ppo": SB3_PPO_DEFAULTS, "sac": SB3_SAC_DEFAULTS}


def check_rllib_config(
    config: SB3Config, env_runners: int, source: str = "config", algo: str = "ppo"
) -> None:
    """Refuse what RLlib's ``algo`` cannot train as SB3 would, in one line naming the key.

    Raises:
        ConfigError: HER, a hyperparameter without an RLlib counterpart, a ``policy_kwargs``
            other than ``net_arch``, a schedule instead of a number, a fixed SAC temperature,
            or ``n_envs`` that the env runners cannot share equally.

    """
    if algo not in ALGORITHMS:
        raise ConfigError(f"RLlib trains {' and '.join(ALGORITHMS)} here, not {brief(algo)}")
    if config.her:
        raise ConfigError(f"{source}: her: RLlib's replay buffers have no HER here")
    if not isinstance(env_runners, int) or not 0 <= env_runners <= MAX_ENV_RUNNERS:
        raise ConfigError(f"--env-runners must be from 0 to {MAX_ENV_RUNNERS}")
    known = ("n_steps", *PPO_TRAINING_KEYS) if algo == "ppo" else SAC_KEYS
    for key, value in config.hyperparameters.items():
        if key == "policy_kwargs":
            _net_arch(value, source, algo)
        elif key not in known:
            raise ConfigError(
                f"{source}: hyperparameters: {brief(key)} has no counterpart in RLlib's "
                f"{algo.upper()} (it takes {', '.join([*known, 'policy_kwargs'])})"
            )
        elif algo == "sac" and key in ("ent_coef", "target_entropy"):
            _temperature(key, value, source)
        elif isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{source}: hyperparameters: {key} must be a number for RLlib")
    if env_runners and config.n_envs % env_runners:
        raise ConfigError(
            f"n_envs {config.n_envs} cannot be shared by {env_runners} env runners: "
            "give a multiple of --env-runners"
        )


def _temperature(key: str, value: Any, source: str) -> float | str:
    """SAC's ``ent_coef`` or ``target_entropy`` as RLlib takes them.

    ``ent_coef``: ``auto`` or ``auto_X``, the initial temperature (1 or X); ``target_entropy``:
    ``auto`` or a number.
    """
    if key == "target_entropy":
        if value == "auto" or (isinstance(value, (int, float)) and not isinstance(value, bool)):
            return value if value == "auto" else float(value)
        raise ConfigError(f"{source}: hyperparameters: target_entropy: auto or a number")
    if isinstance(value, str) and (value == "auto" or value.startswith("auto_")):
        try:
            initial = 1.0 if value == "auto" else float(value[len("auto_") :])
        except ValueError:
            initial = -1.0
        if initial > 0 and math.isfinite(initial):
            return initial
    raise ConfigError(
        f"{source}: hyperparameters: ent_coef: RLlib's SAC learns its temperature: auto or "
        "auto_X (X the initial one)"
    )


def _net_arch(policy_kwargs: Any, source: str, algo: str = "ppo") -> list[int]:
    """The layer widths of ``policy_kwargs`` (``{"net_arch": [256, 256]}``)."""
    if not isinstance(policy_kwargs, dict) or set(policy_kwargs) - {"net_arch"}:
        raise ConfigError(f"{source}: policy_kwargs: RLlib's {algo.upper()} takes net_arch only")
    arch = policy_kwargs.get("net_arch", SB3_DEFAULTS[algo]["policy_kwargs"]["net_arch"])
    if not isinstance(arch, list) or not all(type(w) is int and w > 0 for w in arch):
        raise ConfigError(f"{source}: policy_kwargs.net_arch: a list of layer widths for RLlib")
    return list(arch)


def _hyper(config: SB3Config, algo: str = "ppo") -> dict[str, Any]:
    """The config's hyperparameters over SB3's defaults for ``algo``."""
    return {**SB3_DEFAULTS[algo], **config.hyperparameters}


def model_config(config: SB3Config, algo: str = "ppo") -> dict[str, Any]:
    """RLlib's ``model_config`` of the default module: SB3's networks.

    Tanh for PPO, ReLU for SAC, as SB3's policies.
    """
    arch = _net_arch(_hyper(config, algo)["policy_kwargs"], "config", algo)
    if algo == "sac":
        return {"fcnet_hiddens": arch, "fcnet_activation": "relu"}
    return {"fcnet_hiddens": arch, "fcnet_activation": "tanh", "vf_share_layers": False}


def flatten_connector(env: object = None, spaces: object = None, device: object = None) -> Any:
    """RLlib's ``FlattenObservations``: ``Dict`` observations as one vector (env runners')."""
    from ray.rllib.connectors.env_to_module import FlattenObservations

    return FlattenObservations()


def rllib_config(algo: str, config: SB3Config, env_id: str, seed: int, env_runners: int) -> Any:
    """RLlib's ``PPOConfig`` or ``SACConfig`` of a checked ``config`` (:func:`check_rllib_config`).

    ``env_runners`` processes (0: the driver samples) share ``n_envs`` envs, each making a
    batched env through its ``vector_entry_point`` (others as Gymnasium's sync vector env).
    """
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.algorithms.sac import SACConfig

    hyper = _hyper(config, algo)
    bare = env_id.removeprefix("aftir_rl:")
    fragment = int(hyper["n_steps"] if algo == "ppo" else hyper["train_freq"])
    rl: Any = PPOConfig() if algo == "ppo" else SACConfig()
    rl = (
        rl.environment(f"aftir_rl:{bare}", env_config=dict(config.env_kwargs))
        .env_runners(
            num_env_runners=env_runners,
            num_envs_per_env_runner=config.n_envs // max(env_runners, 1),
            num_cpus_per_env_runner=1,
            rollout_fragment_length=fragment,
            gym_env_vectorize_mode="vector_entry_point" if bare in BATCHED_ENV_IDS else "sync",
            env_to_module_connector=flatten_connector,
        )
        .training(
            **(_ppo_training(hyper, config) if algo == "ppo" else _sac_training(hyper, config))
        )
        .rl_module(model_config=model_config(config, algo))
        .fault_tolerance(restart_failed_env_runners=False)  # a failure ends the run, said
        .debugging(seed=seed, log_level="ERROR")
    )
    return rl


def _ppo_training(hyper: dict[str, Any], config: SB3Config) -> dict[str, Any]:
    """``PPOConfig.training``'s keywords: one update is ``n_steps × n_envs`` steps, as SB3's."""
    return {
        **{rl: hyper[sb3] for sb3, rl in PPO_TRAINING_KEYS.items()},
        "train_batch_size_per_learner": int(hyper["n_steps"]) * config.n_envs,
        "use_kl_loss": False,
        "vf_clip_param": math.inf,  # SB3 clips the policy's ratio, not the value loss
    }


def _sac_training(hyper: dict[str, Any], config: SB3Config) -> dict[str, Any]:
    """``SACConfig.training``'s keywords.

    SB3's ``gradient_steps`` updates of ``batch_size`` per ``train_freq`` steps of every env
    become RLlib's training intensity (steps trained over steps sampled).
    """
    sampled = int(hyper["train_freq"]) * config.n_envs
    return {
        "actor_lr": hyper["learning_rate"],
        "critic_lr": hyper["learning_rate"],
        "alpha_lr": hyper["learning_rate"],
        "train_batch_size_per_learner": int(hyper["batch_size"]),
        "tau": hyper["tau"],
        "gamma": hyper["gamma"],
        "num_steps_sampled_before_learning_starts": int(hyper["learning_starts"]),
        "training_intensity": int(hyper["gradient_steps"]) * int(hyper["batch_size"]) / sampled,
        "initial_alpha": _temperature("ent_coef", hyper["ent_coef"], "config"),
        "target_entropy": _temperature("target_entropy", hyper["target_entropy"], "config"),
        "twin_q": True,
        "replay_buffer_config": {
            "type": "EpisodeReplayBuffer",  # uniform, as SB3's
            "capacity": int(hyper["buffer_size"]),
        },
    }


def ppo_config(config: SB3Config, env_id: str, seed: int, env_runners: int) -> Any:
    """RLlib's ``PPOConfig`` of a checked PPO ``config`` (:func:`rllib_config`)."""
    return rllib_config("ppo", config, env_id, seed, env_runners)


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


def build_module(
    config: SB3Config, space: gym.Space[Any], action_space: gym.Space[Any], algo: str = "ppo"
) -> Any:
    """A new inference-only module of ``algo`` (torch, CPU): what acts, without critics."""
    rl = rllib_config(algo, config, "aftir_rl:AFTIR-ArmReach-v0", 0, 0)
    spec = rl.get_default_rl_module_spec()
    spec.observation_space = observation_space(space)
    spec.action_space = action_space
    spec.model_config = rl.model_config
    spec.inference_only = True
    with quiet_rllib():
        return spec.build()
