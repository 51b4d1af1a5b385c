"""Configs of the Stable-Baselines3 baselines (PPO, SAC, TD3), checked before anything is built.

A config (:class:`SB3Config`; a run of ``aftir train``, its stages and the rest, is a
:class:`TrainConfig`; both read by :mod:`aftir_rl.rl.sb3.hyperparams` from the command line,
the env-keyed hyperparameter files and the named configs) is checked by :func:`check_sb3_config`:
``hyperparameters`` go to the algorithm's constructor and are checked against its signature and
against bounds (an unknown key or a value out of range is a
:class:`~aftir_rl.core.errors.ConfigError` naming the file and the key), as is a run directory's
``config.json`` (:func:`sb3_config_from_run`). A config merged from several sources is checked
once by :func:`check_sb3_values`, its :class:`Origins` naming the source of a refused value.
:func:`build_model` makes the model of a checked config.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import GymEnv

from aftir_rl.core.config import brief, from_mapping, shorten, to_float
from aftir_rl.core.errors import CheckpointError, ConfigError
from aftir_rl.core.tank.loading import resolve_run_tank
from aftir_rl.envs.ftl.spec import (
    CONFIG_KWARG_TYPES,
    SHAPING_KINDS,
    STEER_MODES,
)
from aftir_rl.envs.registration import registered_env_id

__all__ = [
    "rollout_steps",
    "MAX_MODEL_BYTES",
    "model_bytes",
    "ALGORITHMS",
    "SB3Config",
    "TrainConfig",
    "ENV_KWARGS",
    "GOAL_ENV_IDS",
    "SB3_ENV_IDS",
    "HER_KWARGS",
    "OBJECT_KEYS",
    "INTEGER_KEYS",
    "LINEAR_PREFIX",
    "linear_start",
    "check_range",
    "check_hyperparameters",
    "parse_hyperparameters",
    "check_sb3_config",
    "Origins",
    "check_sb3_values",
    "sb3_config_from_run",
    "constructor_keys",
    "build_model",
]

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}


@dataclass(frozen=True)
class SB3Config:
    """A run of an SB3 algorithm (an entry of ``configs/hyperparams/<algo>.yml``, a named config).

    Attributes:
        env_id: environment id (``AFTIR-ArmReach-v0``...).
        total_timesteps: training steps.
        n_envs: parallel envs (subprocesses when more than one).
        eval_freq: environment steps between evaluations.
        eval_targets: number of fixed evaluation targets.
        checkpoint_freq: environment steps between checkpoints.
        policy: SB3 policy name.
        hyperparameters: keyword arguments of the algorithm.
        her: SAC/TD3 with SB3's ``HerReplayBuffer`` (goal-conditioned envs only; future
            strategy, 4 relabelled goals per transition, the infos kept for ``compute_reward``).
        env_kwargs: keyword arguments of the env (plain values, :data:`ENV_KWARGS` only).

    """

    env_id: str = "AFTIR-ArmReach-v0"
    total_timesteps: int = 100_000
    n_envs: int = 1
    eval_freq: int = 10_000
    eval_targets: int = 20
    checkpoint_freq: int = 50_000
    policy: str = "MlpPolicy"
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    her: bool = False
    env_kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TrainConfig:
    """One run of ``aftir train ppo|sac|td3``, resolved and checked once.

    Built by :func:`aftir_rl.rl.sb3.hyperparams.train_config`, then read, never resolved again.

    Attributes:
        algo: ``ppo``, ``sac`` or ``td3``.
        stages: the configs trained one after the other, each resumed from the one before (one
            for a plain run; a stage file's otherwise).
        seed: random seed of every stage.
        logdir: parent of the run directory (of ``stage<k>/`` folders for several stages).
        resume: a model or run directory the first stage continues from.
        progress_bar: show SB3's progress bar.
        demos: a Minari dataset behaviour-cloned into the new PPO policy first.
        bc_epochs: passes over ``demos``.

    """

    algo: str
    stages: tuple[SB3Config, ...]
    seed: int = 0
    logdir: str = "runs"
    resume: str | None = None
    progress_bar: bool = True
    demos: str | None = None
    bc_epochs: int = 20


@dataclass(frozen=True)
class Origins:
    """Where the values of a config came from, for the one line that refuses one.

    Attributes:
        source: the file or option of every key that ``keys`` does not name.
        keys: the source of each key (``n_envs``, ``hyperparameters.gamma``, ``env_kwargs.bay``)
            that another source gave, in a config merged from several.

    """

    source: str
    keys: Mapping[str, str] = field(default_factory=dict)

    def of(self, key: str) -> str:
        """The source of ``key``."""
        return self.keys.get(key, self.source)


def rollout_steps(algo: str, config: SB3Config) -> int:
    """The steps an update of ``algo`` collects: ``n_steps × n_envs`` for PPO, else ``n_envs``."""
    n_steps = int(config.hyperparameters.get("n_steps", 2048)) if algo == "ppo" else 1
    return n_steps * config.n_envs


def parse_hyperparameters(hyper: dict[str, Any], algo: str, source: str) -> dict[str, Any]:
    """``hyper`` with its keys checked against ``algo``'s constructor, ``3e-4`` strings parsed.

    The values are checked by :func:`check_sb3_config`.

    Raises:
        ConfigError: a key the algorithm does not take, naming ``source``.

    """
    allowed = constructor_keys(algo)
    parsed = {}
    for key, value in hyper.items():
        if key not in allowed:
            raise ConfigError(
                f"{source}: hyperparameters: unknown key {brief(key)} for {algo.upper()}; allowed "
                f"keys are {', '.join(sorted(allowed))}"
            )
        if isinstance(value, str):
            try:
                value = to_float(value, f"{source}: hyperparameters.{key}")
            except ConfigError:
                pass
        parsed[key] = value
    return parsed


# Bounds of what a config may ask for: each is far above what the shipped configs use, and keeps
# the memory and time of building a model small (a replay buffer of 2e6 transitions of the arm
# envs is about 0.5 GB).
_INT_RANGES: dict[str, tuple[int, int]] = {
    "n_steps": (1, 1_000_000),
    "batch_size": (1, 1_000_000),
    "n_epochs": (1, 1000),
    "buffer_size": (1, 2_000_000),
    "learning_starts": (0, 1_000_000_000),
    "gradient_steps": (-1, 10_000),
    "policy_delay": (1, 1000),
    "target_update_interval": (1, 1_000_000),
    "sde_sample_freq": (-1, 1_000_000),
    "stats_window_size": (1, 100_000),
}
#: The hyperparameters that take integers (a search space must draw integers for them).
INTEGER_KEYS = frozenset(_INT_RANGES)
_FLOAT_RANGES: dict[str, tuple[float, float]] = {
    "learning_rate": (1e-12, 10.0),
    "gamma": (0.0, 1.0),
    "gae_lambda": (0.0, 1.0),
    "clip_range": (1e-12, 100.0),
    "vf_coef": (0.0, 1e6),
    "max_grad_norm": (1e-12, 1e9),
    "tau": (0.0, 1.0),
    "target_policy_noise": (0.0, 1e3),
    "target_noise_clip": (0.0, 1e3),
}
_OPTIONAL_FLOATS: dict[str, tuple[float, float]] = {
    "clip_range_vf": (1e-12, 1e6),
    "target_kl": (1e-12, 1e6),
}
_BOOLS = ("normalize_advantage", "use_sde", "use_sde_at_warmup", "optimize_memory_usage")
#: Keys a YAML config cannot give: they take Python objects (classes, noise processes).
OBJECT_KEYS = (
    "rollout_buffer_class",
    "rollout_buffer_kwargs",
    "replay_buffer_class",
    "replay_buffer_kwargs",
    "action_noise",
)
_POLICY_KWARGS = {
    "net_arch",
    "log_std_init",
    "ortho_init",
    "n_critics",
    "share_features_extractor",
    "squash_output",
    "full_std",
    "use_expln",
}
_POLICY_BOOLS = ("ortho_init", "share_features_extractor", "squash_output", "full_std", "use_expln")


#: Prefix of a learning rate that falls linearly to 0 over a run (RL Zoo's ``lin_3e-4``). With
#: ``--resume``, SB3's progress counts every step of the model: the rate starts the resumed stage
#: at ``start · (1 − resumed / (resumed + stage))`` and reaches 0 at its end.
LINEAR_PREFIX = "lin_"


def linear_start(value: Any) -> float | None:
    """The starting value of a ``lin_<number>`` schedule (NaN if not a number), else None."""
    if not (isinstance(value, str) and value.startswith(LINEAR_PREFIX)):
        return None
    try:
        return float(value[len(LINEAR_PREFIX) :])
    except ValueError:
        return math.nan


def check_range(value: Any, lo: float, hi: float, where: str, integer: bool) -> None:
    """Check that ``value`` is a number (an integer if ``integer``) from ``lo`` to ``hi``.

    Raises:
        ConfigError: naming ``where``.

    """
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if integer and math.isfinite(number) and not number.is_integer():
        raise ConfigError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")
    if not (math.isfinite(number) and lo <= number <= hi):
        raise ConfigError(f"{where}: expected {kind} from {lo:g} to {hi:g}, got {brief(value)}")


def _check_net_arch(value: Any, where: str) -> None:
    """Check ``net_arch``: a list of layer widths, or one per ``pi``, ``vf`` and ``qf``."""

    def layers(v: Any, w: str) -> None:
        if not isinstance(v, list) or len(v) > 8:
            raise ConfigError(f"{w}: expected a list of at most 8 layer widths, got {brief(v)}")
        for i, width in enumerate(v):
            check_range(width, 1, 4096, f"{w}[{i}]", integer=True)

    if isinstance(value, dict):
        for key, v in value.items():
            if key not in ("pi", "vf", "qf"):
                raise ConfigError(f"{where}: unknown key {brief(key)}; allowed keys are pi, qf, vf")
            layers(v, f"{where}.{key}")
    else:
        layers(value, where)


def check_hyperparameters(hyperparameters: dict[str, Any], algo: str, origins: Origins) -> None:
    """Check every value of a config's ``hyperparameters`` (``algo``: ``ppo``, ``sac``...).

    Raises:
        ConfigError: naming the key and its source in ``origins``.

    """
    for key, value in hyperparameters.items():
        where = f"hyperparameters.{key}"
        _check_hyperparameter(key, value, algo, f"{origins.of(where)}: {where}")


def _check_hyperparameter(key: Any, value: Any, algo: str, where: str) -> None:
    """Check the value of one hyperparameter against its bounds or type.

    Raises:
        ConfigError: naming ``where``.

    """
    if key in _INT_RANGES:
        check_range(value, *_INT_RANGES[key], where, integer=True)
    elif key == "learning_rate" and isinstance(value, str):
        _check_linear_rate(value, where)
    elif key in _FLOAT_RANGES:
        check_range(value, *_FLOAT_RANGES[key], where, integer=False)
    elif key in _OPTIONAL_FLOATS:
        if value is not None:
            check_range(value, *_OPTIONAL_FLOATS[key], where, integer=False)
    elif key in _BOOLS:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {brief(value)}")
    elif key in OBJECT_KEYS:
        raise ConfigError(f"{where}: takes a Python object, which a config file cannot give")
    elif key in ("ent_coef", "target_entropy"):
        _check_entropy(key, value, algo, where)
    elif key == "train_freq":
        _check_train_freq(value, where)
    elif key == "device":
        if value not in ("auto", "cpu", "cuda"):
            raise ConfigError(f"{where}: expected auto, cpu or cuda, got {brief(value)}")
    elif key == "policy_kwargs":
        _check_policy_kwargs(value, where)
    elif not (value is None or isinstance(value, (bool, int, float, str))):
        raise ConfigError(f"{where}: expected a plain value, got {brief(value)}")


def _check_linear_rate(value: str, where: str) -> None:
    """Check a learning rate given as text: ``lin_<number>`` within the learning rate's bounds."""
    start, (low, high) = linear_start(value), _FLOAT_RANGES["learning_rate"]
    if start is None or not (math.isfinite(start) and low <= start <= high):
        raise ConfigError(
            f"{where}: expected a number or {LINEAR_PREFIX}<number> from {low:g} to "
            f"{high:g} (falling linearly to 0), got {brief(value)}"
        )


def _check_entropy(key: str, value: Any, algo: str, where: str) -> None:
    """Check ``ent_coef`` or ``target_entropy``: a number, or ``auto``/``auto_<number>`` (SAC)."""
    auto = isinstance(value, str) and (value == "auto" or value.startswith("auto_"))
    if not (auto and algo == "sac"):
        check_range(value, -1e6 if key == "target_entropy" else 0.0, 1e6, where, False)
    elif value.startswith("auto_"):  # the initial coefficient: a positive, finite number
        try:
            start = float(value[5:])
        except ValueError:
            start = math.nan
        if not (math.isfinite(start) and 0 < start <= 1e6):
            raise ConfigError(
                f"{where}: expected 'auto' or 'auto_<number>' with a number in (0, 1e6], "
                f"got {brief(value)}"
            )


def _check_train_freq(value: Any, where: str) -> None:
    """Check ``train_freq``: ``N`` or ``[N, step|episode]``."""
    ok = isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 10**6
    if isinstance(value, list) and len(value) == 2:
        ok = value[1] in ("step", "episode")
        check_range(value[0], 1, 10**6, f"{where}[0]", integer=True)
    if not ok:
        raise ConfigError(f"{where}: expected N or [N, step|episode], got {brief(value)}")


def _check_policy_kwargs(value: Any, where: str) -> None:
    """Check ``policy_kwargs``: known keys only, each within its bounds."""
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping, got {brief(value)}")
    for k, v in value.items():
        if k not in _POLICY_KWARGS:
            raise ConfigError(
                f"{where}: unknown or unsupported key {brief(k)}; allowed keys are "
                f"{', '.join(sorted(_POLICY_KWARGS))}"
            )
        if k == "net_arch":
            _check_net_arch(v, f"{where}.net_arch")
        elif k in _POLICY_BOOLS:
            if not isinstance(v, bool):
                raise ConfigError(f"{where}.{k}: expected true or false, got {brief(v)}")
        elif k == "n_critics":
            check_range(v, 1, 10, f"{where}.{k}", integer=True)
        else:
            check_range(v, -20, 20, f"{where}.{k}", integer=False)


#: Bounds of the fields of :class:`SB3Config`.
_CONFIG_RANGES = {
    "total_timesteps": (0, 1_000_000_000),
    "n_envs": (1, 64),
    "eval_freq": (1, 1_000_000_000),
    "eval_targets": (1, 1000),
    "checkpoint_freq": (1, 1_000_000_000),
}


def check_sb3_config(config: SB3Config, algo: str, source: str) -> None:
    """Check every value of an SB3 config before anything is built: types, ranges, sizes.

    Raises:
        ConfigError: naming ``source`` and the key.

    """
    bare = registered_env_id(config.env_id, source)
    check_sb3_values(config, algo, bare, Origins(source))


def check_sb3_values(config: SB3Config, algo: str, bare: str, origins: Origins) -> None:
    """:func:`check_sb3_config` of a config whose env id is resolved already, to ``bare``.

    Raises:
        ConfigError: naming the key and its source in ``origins``.

    """
    for key, (lo, hi) in _CONFIG_RANGES.items():
        if key == "n_envs" and bare in BATCHED_ENV_IDS:
            hi = MAX_BATCHED_ENVS  # rows of one numpy batch, not processes
        check_range(getattr(config, key), lo, hi, f"{origins.of(key)}: {key}", integer=True)
    aliases = getattr(ALGORITHMS[algo], "policy_aliases", {})
    if config.policy not in aliases:
        raise ConfigError(
            f"{origins.of('policy')}: policy: {brief(config.policy)} is not a {algo.upper()} "
            f"policy; use one of {', '.join(aliases)}"
        )
    check_hyperparameters(config.hyperparameters, algo, origins)
    batch, steps = config.hyperparameters.get("batch_size"), config.hyperparameters.get("n_steps")
    if algo == "ppo" and steps is not None and steps * config.n_envs < 2:
        where = origins.of("hyperparameters.n_steps")
        raise ConfigError(f"{where}: hyperparameters.n_steps: n_steps * n_envs must exceed 1")
    if algo == "ppo" and batch is not None and batch < 2:
        where = origins.of("hyperparameters.batch_size")
        raise ConfigError(f"{where}: hyperparameters.batch_size: must be at least 2 for PPO")
    _check_goal_settings(config, algo, bare, origins)


def sb3_config_from_run(data: Any, source: str) -> tuple[str, SB3Config]:
    """``(algo, config)`` from a run directory's ``config.json``, every key checked.

    Raises:
        CheckpointError: a key this package does not write, or a value out of range.

    """
    if not isinstance(data, dict):
        raise CheckpointError(f"{source}: expected a JSON object")
    algo = data.get("algo")
    if not isinstance(algo, str) or algo not in ALGORITHMS:
        raise CheckpointError(f"{source}: algo must be one of {', '.join(ALGORITHMS)}")
    fields = {f.name for f in dataclasses.fields(SB3Config)}
    written = fields | {"algo", "seed", "resume"}
    unknown = sorted(set(data) - written, key=str)
    if unknown:
        raise CheckpointError(f"{source}: unknown key {brief(unknown[0])}; not a training run's")
    try:
        kwargs = {k: v for k, v in data.items() if k in fields}
        hyper = kwargs.pop("hyperparameters", {}) or {}
        config = from_mapping(SB3Config, kwargs, source)
        if not isinstance(hyper, dict):
            raise ConfigError(f"{source}: hyperparameters: expected a mapping")
        allowed = constructor_keys(algo)
        for key in hyper:
            if key not in allowed:
                raise ConfigError(f"{source}: hyperparameters: unknown key {brief(key)}")
        config = dataclasses.replace(config, hyperparameters=dict(hyper))
        check_sb3_config(config, algo, source)
        if "tank" in config.env_kwargs:  # a shipped tank or a file inside the run, unread yet
            tank = resolve_run_tank(config.env_kwargs["tank"], Path(source).parent)
            config = dataclasses.replace(config, env_kwargs={**config.env_kwargs, "tank": tank})
    except ConfigError as exc:
        raise CheckpointError(str(exc)) from None
    return algo, config


#: Env keyword arguments a config may give, per env id, with their types. ``guide`` changes the
#: observation space: a model is always loaded into an env made with its run's ``env_kwargs``.
ENV_KWARGS: dict[str, dict[str, tuple[type, ...]]] = {
    "AFTIR-ArmFull-v0": {"bay": (int, type(None))},
    # a stream of tanks' options (--tank wing:B:F+) are the batched env's
    "AFTIR-ArmFTL-v0": {**CONFIG_KWARG_TYPES, "tanks_at_once": (int,), "tank_episodes": (int,)},
}
#: Envs that take a ``tank`` (``--tank``; a run records it): never from a config file.
TANK_ENV_IDS = ("AFTIR-ArmFTL-v0",)
#: Env keyword arguments whose values are one of a few.
ENV_KWARG_CHOICES: dict[str, tuple[object, ...]] = {
    "shaping": tuple(SHAPING_KINDS),
    "steer": STEER_MODES,
}
#: Envs with a batched implementation: ``n_envs`` are rows of one process (at most
#: :data:`MAX_BATCHED_ENVS`), not subprocesses (at most 64).
BATCHED_ENV_IDS = ("AFTIR-ArmFTL-v0",)
MAX_BATCHED_ENVS = 4096
#: The envs SB3 algorithms train on.
SB3_ENV_IDS = ("AFTIR-ArmReach-v0", "AFTIR-Arm-v0", "AFTIR-ArmFull-v0", "AFTIR-ArmFTL-v0")
#: Goal-conditioned envs (``Dict`` observations with ``compute_reward``): the ones HER takes.
GOAL_ENV_IDS = ("AFTIR-ArmFTL-v0",)
#: HerReplayBuffer's settings when ``her`` is on.
HER_KWARGS = {"n_sampled_goal": 4, "goal_selection_strategy": "future", "copy_info_dict": True}


def _check_goal_settings(config: SB3Config, algo: str, bare: str, origins: Origins) -> None:
    """Check ``her`` and ``env_kwargs`` of a config (plain values of known keys only).

    Raises:
        ConfigError: naming the key and its source in ``origins``.

    """
    source = origins.of("her")
    if not isinstance(config.her, bool):
        raise ConfigError(f"{source}: her: expected true or false, got {brief(config.her)}")
    if config.her and (algo not in ("sac", "td3") or bare not in GOAL_ENV_IDS):
        raise ConfigError(
            f"{source}: her: only SAC and TD3 on {', '.join(GOAL_ENV_IDS)} use HER, not "
            f"{algo.upper()} on {brief(config.env_id)}"
        )
    if not isinstance(config.env_kwargs, dict):
        raise ConfigError(
            f"{origins.of('env_kwargs')}: env_kwargs: expected a mapping, got "
            f"{brief(config.env_kwargs)}"
        )
    for key in ("guide", "near_goal"):
        if config.her and config.env_kwargs.get(key) is True:
            raise ConfigError(
                f"{origins.of(f'env_kwargs.{key}')}: env_kwargs.{key}: the {key} columns observe "
                f"the goal, which HER relabels; use {key} with PPO, or her without {key}"
            )
    if config.her:
        _check_her_start(config, algo, bare, origins.of("hyperparameters.learning_starts"))
    allowed = ENV_KWARGS.get(bare, {})
    for key, value in config.env_kwargs.items():
        source = origins.of(f"env_kwargs.{key}")
        if key == "tank" and bare in TANK_ENV_IDS:  # the command line's or a run's (not a file's)
            if not isinstance(value, str) or not 0 < len(value) <= 255:
                raise ConfigError(f"{source}: env_kwargs.tank: unexpected value {brief(value)}")
            continue
        if key not in allowed:
            raise ConfigError(
                f"{source}: env_kwargs: unknown key {brief(key)} for {bare}; allowed keys are "
                f"{', '.join(sorted(allowed)) or 'none'}"
            )
        types = allowed[key]
        if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
            raise ConfigError(f"{source}: env_kwargs.{key}: unexpected value {brief(value)}")
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{source}: env_kwargs.{key}: expected a finite number")
        choices = ENV_KWARG_CHOICES.get(key)
        if choices is not None and not any(type(value) is type(c) and value == c for c in choices):
            names = ", ".join(str(c).lower() if isinstance(c, bool) else str(c) for c in choices)
            raise ConfigError(
                f"{source}: env_kwargs.{key}: expected one of {names}, got {brief(value)}"
            )


def _check_her_start(config: SB3Config, algo: str, env_id: str, source: str) -> None:
    """HER samples only finished episodes: learning must not start before every env has one.

    ``learning_starts`` counts the steps of all ``n_envs`` envs together, so each env has made
    ``learning_starts / n_envs`` of them when the first gradient step needs a finished episode.
    """
    limit = gym.spec(env_id).max_episode_steps
    default = inspect.signature(ALGORITHMS[algo]).parameters["learning_starts"].default
    starts = config.hyperparameters.get("learning_starts", default)
    if limit is not None and starts < config.n_envs * limit:
        raise ConfigError(
            f"{source}: hyperparameters.learning_starts: {starts} steps over {config.n_envs} envs "
            f"may end before any episode does ({env_id} episodes last up to {limit} steps), and "
            f"HER samples finished episodes only; use learning_starts >= {config.n_envs * limit}"
        )


def constructor_keys(algo: str) -> set[str]:
    """The keywords of ``algo``'s constructor a config's ``hyperparameters`` may give."""
    return set(inspect.signature(ALGORITHMS[algo].__init__).parameters) - {
        "self",
        "policy",
        "env",
        "seed",
        "tensorboard_log",
        "verbose",
        "_init_setup_model",
    }


#: The most bytes a model's entries may inflate to, in all, counted as they are read
#: (:mod:`aftir_rl.rl.sb3.loading`); the records of its ``.pth`` files (the tensors) have a
#: budget as large. A new model whose file could exceed it is refused (:func:`build_model`).
MAX_MODEL_BYTES = 64_000_000


def model_bytes(model: BaseAlgorithm) -> int:
    """An upper bound of the bytes the model's saved tensors take [bytes].

    Each parameter of the policy (float32, 4 bytes) is saved with the two moments Adam keeps for
    it (SB3 saves the optimizers' states too): 12 bytes a parameter.
    """
    return 12 * sum(int(p.numel()) for p in model.policy.parameters())


def build_model(
    algo: str, config: SB3Config, env: GymEnv, seed: int | None = 0, evaluation: bool = False
) -> BaseAlgorithm:
    """A new model of ``algo`` for ``env`` from a checked ``config``.

    ``evaluation``: a one-transition replay buffer (off-policy algorithms), for a model only
    loaded to act; PPO's warning that its batch size does not divide a one-env rollout (the
    run trained with more envs) is not shown then.

    Raises:
        ConfigError: the algorithm refuses the hyperparameters, or a new model's file could be
            larger than the loader reads (:data:`MAX_MODEL_BYTES`: ``net_arch`` too wide).

    """
    model = _new_model(algo, config, env, seed, evaluation)
    size = model_bytes(model)
    if not evaluation and size > MAX_MODEL_BYTES:
        arch = (config.hyperparameters.get("policy_kwargs") or {}).get("net_arch")
        raise ConfigError(
            f"net_arch {brief(arch)} "
            f"makes a model of up to {size / 1e6:.0f} MB, more than the {MAX_MODEL_BYTES / 1e6:.0f}"
            " MB a run's model may hold (it could not be loaded again): use narrower layers"
        )
    return model


def _new_model(
    algo: str, config: SB3Config, env: GymEnv, seed: int | None, evaluation: bool
) -> BaseAlgorithm:
    """:func:`build_model` without the size check."""
    hyper = dict(config.hyperparameters)
    start = linear_start(hyper.get("learning_rate"))
    if start is not None:
        from stable_baselines3.common.utils import LinearSchedule

        hyper["learning_rate"] = LinearSchedule(start, 0.0, 1.0)
    if config.her and not evaluation:
        from stable_baselines3 import HerReplayBuffer

        hyper.update(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(HER_KWARGS))
    if evaluation and "buffer_size" in constructor_keys(algo):
        hyper["buffer_size"] = 1
        hyper.pop("optimize_memory_usage", None)
    try:
        with warnings.catch_warnings():
            if evaluation:
                warnings.filterwarnings("ignore", "You have specified a mini-batch size")
            return ALGORITHMS[algo](config.policy, env, seed=seed, verbose=0, **hyper)
    except (ValueError, TypeError, AssertionError, KeyError) as exc:
        raise ConfigError(
            f"{algo.upper()} refuses these hyperparameters: {shorten(str(exc) or repr(exc), 200)}"
        ) from None
