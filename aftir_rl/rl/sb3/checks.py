"""Checks of the values an SB3 config gives: bounds, types and sizes, before anything is built.

:func:`check_hyperparameters` checks every key of a config's ``hyperparameters`` against its
bounds (a value out of range, of the wrong type or one only Python code can give is a
:class:`~aftir_rl.core.errors.ConfigError` naming the source and the key); :func:`check_range`
checks one number. :func:`aftir_rl.rl.sb3.config.check_sb3_config` checks a whole config with
them; this module imports nothing of the rest of :mod:`aftir_rl.rl.sb3`.
"""

from __future__ import annotations

import math
from typing import Any

from aftir_rl.core.config import brief
from aftir_rl.core.errors import ConfigError

__all__ = [
    "INTEGER_KEYS",
    "LINEAR_PREFIX",
    "OBJECT_KEYS",
    "check_hyperparameters",
    "check_range",
    "linear_start",
]

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


def check_hyperparameters(hyperparameters: dict[str, Any], algo: str, source: str) -> None:
    """Check every value of a config's ``hyperparameters`` (``algo``: ``ppo``, ``sac``...).

    Raises:
        ConfigError: naming ``source`` and the key.

    """
    for key, value in hyperparameters.items():
        _check_hyperparameter(key, value, algo, f"{source}: hyperparameters.{key}")


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
    elif value.startswith("auto_"):
        try:
            float(value[5:])
        except ValueError:
            raise ConfigError(f"{where}: expected 'auto' or 'auto_<number>'") from None


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
