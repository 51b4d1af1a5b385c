"""Hyperparameters keyed by env id, the RL Zoo way, and the named configs built over them.

``configs/hyperparams/<algo>.yml`` (``ppo``, ``sac``, ``td3``) maps env ids to an entry in RL
Zoo's format: ``n_timesteps``, ``policy``, ``n_envs``, ``env_kwargs``, HER as
``replay_buffer_class: HerReplayBuffer``, and the algorithm's keyword arguments; YAML anchors
share blocks. ``aftir train ALGO --env ID`` trains the env's entry (:func:`entry_config`) and
``python -m rl_zoo3.train --algo ALGO --env ID --gym-packages aftir_rl -conf FILE`` reads the same
file. Nothing is evaluated: ``policy_kwargs`` is a mapping, never a string of Python.

A named config (``configs/ppo_ftl.yaml``, a path of your own) holds :class:`SB3Config` fields
over its env's entry (:func:`load_sb3_config`): the fields it gives replace the entry's, its
``env_kwargs`` and ``hyperparameters`` are merged key by key over the entry's, so a config
states only what differs. ``eval_freq`` and ``checkpoint_freq`` that no config gives are every
5% and 10% of ``total_timesteps`` (at least 10,000 and 50,000 steps).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from aftir_rl.core.config import CONFIG_DIR, brief, from_mapping, read_yaml
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.shipped import find_config
from aftir_rl.rl.common import DEFAULT_SB3_ENV_ID, check_env_id
from aftir_rl.rl.sb3.config import (
    HER_KWARGS,
    SB3_ENV_IDS,
    SB3Config,
    check_sb3_config,
    parse_hyperparameters,
    refuse_tank,
)

__all__ = [
    "DEFAULT_ENV_ID",
    "config_from_mapping",
    "entry_config",
    "entry_env_ids",
    "hyperparams_file",
    "is_hyperparams_file",
    "load_sb3_config",
]

#: The env of a config that names none.
DEFAULT_ENV_ID = DEFAULT_SB3_ENV_ID
#: RL Zoo's keys of an entry that are fields of :class:`SB3Config` (RL Zoo name: field name).
_ZOO_FIELDS = {
    "n_timesteps": "total_timesteps",
    "policy": "policy",
    "n_envs": "n_envs",
    "env_kwargs": "env_kwargs",
}
#: The fields derived from ``total_timesteps`` when no config gives them: (share, at least).
_DERIVED = {"eval_freq": (20, 10_000), "checkpoint_freq": (10, 50_000)}


def hyperparams_file(algo: str) -> Path:
    """``configs/hyperparams/<algo>.yml`` of the package."""
    return CONFIG_DIR / "hyperparams" / f"{algo}.yml"


def _entries(algo: str, path: Path | None = None) -> tuple[Path, dict[str, Any]]:
    """The file (default: ``algo``'s) and its entries for the package's envs (not anchors)."""
    path = path or hyperparams_file(algo)
    data = read_yaml(path)
    return path, {k: v for k, v in data.items() if isinstance(k, str) and k.startswith("AFTIR-")}


def entry_env_ids(algo: str) -> list[str]:
    """The env ids ``configs/hyperparams/<algo>.yml`` has an entry for."""
    return list(_entries(algo)[1])


def is_hyperparams_file(name: str | os.PathLike[str]) -> bool:
    """Whether the config ``name`` stands for is keyed by env id (RL Zoo's format)."""
    data = read_yaml(find_config(name))
    fields = {f.name for f in dataclasses.fields(SB3Config)} | {"stages"}
    envs = [k for k in data if isinstance(k, str) and k.startswith("AFTIR-")]
    return bool(envs) and not fields & set(data)


def _zoo_fields(entry: Any, algo: str, source: str) -> dict[str, Any]:
    """The :class:`SB3Config` fields of an RL Zoo entry (``hyperparameters``: the rest)."""
    if not isinstance(entry, dict):
        raise ConfigError(f"{source}: expected a mapping of hyperparameters, got {brief(entry)}")
    rest = dict(entry)
    fields = {name: rest.pop(key) for key, name in _ZOO_FIELDS.items() if key in rest}
    steps = fields.get("total_timesteps")
    if isinstance(steps, float) and steps.is_integer():  # RL Zoo writes !!float 2e7
        fields["total_timesteps"] = int(steps)
    buffer, buffer_kwargs = (
        rest.pop("replay_buffer_class", None),
        rest.pop("replay_buffer_kwargs", None),
    )
    if buffer is not None or buffer_kwargs is not None:
        if buffer != "HerReplayBuffer" or buffer_kwargs not in (None, HER_KWARGS):
            raise ConfigError(
                f"{source}: replay_buffer_class: only HerReplayBuffer with replay_buffer_kwargs "
                f"{HER_KWARGS} (or none), got {brief(buffer)} with {brief(buffer_kwargs)}"
            )
        fields["her"] = True
    fields["hyperparameters"] = parse_hyperparameters(rest, algo, source)
    return fields


def entry_config(algo: str, env_id: str, path: str | os.PathLike[str] | None = None) -> SB3Config:
    """The checked config of ``env_id``'s entry in ``configs/hyperparams/<algo>.yml``.

    ``path``: another file of the same format (a name or a path), e.g. your own RL Zoo file.

    Raises:
        ConfigError: the env has no entry (the message names those that have one), or the
            entry is refused (naming the file, the env and the key).

    """
    bare = check_env_id(env_id, SB3_ENV_IDS, algo)
    path, entries = _entries(algo, None if path is None else find_config(path))
    if bare not in entries:
        raise ConfigError(
            f"no {algo} hyperparameters for {bare} in {path.name}; it has an entry for "
            f"{', '.join(entries) or 'no env'} (or give --config FILE with env_id: {bare})"
        )
    source = f"{path}: {bare}"
    fields = _zoo_fields(entries[bare], algo, source)
    config = from_mapping(
        SB3Config, {k: v for k, v in fields.items() if k != "hyperparameters"}, source
    )
    config = dataclasses.replace(
        config, env_id=env_id, hyperparameters=fields["hyperparameters"], **_derived(config, {})
    )
    refuse_tank(config.env_kwargs, source)
    check_sb3_config(config, algo, source)
    return config


def _derived(config: SB3Config, given: dict[str, Any]) -> dict[str, Any]:
    """``eval_freq`` and ``checkpoint_freq`` from ``config.total_timesteps``, unless given."""
    steps = config.total_timesteps
    return {k: max(low, steps // share) for k, (share, low) in _DERIVED.items() if k not in given}


def _mapping(data: dict[str, Any], key: str, source: str) -> dict[str, Any]:
    value = data.pop(key, None) or {}
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise ConfigError(f"{source}: {key}: expected a mapping of names, got {brief(value)}")
    return value


def config_from_mapping(
    data: dict[str, Any], algo: str, source: str, base: SB3Config | None = None
) -> SB3Config:
    """The checked config of ``data`` (:class:`SB3Config` fields) over ``base``.

    ``base``: by default the entry of ``data``'s ``env_id`` (:data:`DEFAULT_ENV_ID` if none) in
    the hyperparameter file of ``algo``, or the plain defaults for an env without one.

    Raises:
        ConfigError: a key, type or value is refused (naming ``source`` and the key).

    """
    data = dict(data)
    env_kwargs = _mapping(data, "env_kwargs", source)
    hyper = parse_hyperparameters(_mapping(data, "hyperparameters", source), algo, source)
    given = {k: getattr(from_mapping(SB3Config, data, source), k) for k in data}
    derive = base is None
    if base is None:
        env_id = given.get("env_id", DEFAULT_ENV_ID)
        bare = check_env_id(env_id, SB3_ENV_IDS, algo)
        base = (
            entry_config(algo, env_id) if bare in entry_env_ids(algo) else SB3Config(env_id=env_id)
        )
    config = dataclasses.replace(
        base,
        **given,
        env_kwargs={**base.env_kwargs, **env_kwargs},
        hyperparameters={**base.hyperparameters, **hyper},
    )
    if derive:
        config = dataclasses.replace(config, **_derived(config, given))
    refuse_tank(env_kwargs, source)
    check_sb3_config(config, algo, source)
    return config


def load_sb3_config(path: str | os.PathLike[str], algo: str) -> SB3Config:
    """Read and check a named config (a path, or a shipped name such as ``ppo_ftl``).

    Numbers written as strings (``3e-4``) are parsed; see :func:`config_from_mapping`.
    """
    path = find_config(path)
    return config_from_mapping(read_yaml(path), algo, str(path))
