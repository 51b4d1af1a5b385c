"""Where an SB3 run's config comes from, resolved in one pass: :func:`train_config`.

``configs/hyperparams/<algo>.yml`` maps env ids to RL Zoo entries (``n_timesteps``, ``policy``,
``n_envs``, ``env_kwargs``, HER as ``replay_buffer_class: HerReplayBuffer``, the algorithm's
keyword arguments; YAML anchors share blocks; nothing is evaluated): ``aftir train ALGO --env ID``
trains the env's entry (:func:`entry_config`), as ``python -m rl_zoo3.train -conf FILE`` reads it.
A named config holds :class:`SB3Config` fields over its env's entry (:func:`load_sb3_config`):
its ``env_kwargs`` and ``hyperparameters`` merge key by key, and ``eval_freq`` and
``checkpoint_freq`` that no config gives are every 5% and 10% of ``total_timesteps`` (at least
10,000 and 50,000). A stage file (one key, ``stages``: at most :data:`MAX_STAGES` such mappings,
each over its ``config`` or its env's entry) is a curriculum, each stage resumed from the one
before. ``--env-kwargs`` and ``--hyperparams`` give ``KEY:VALUE`` items, each value read as YAML
(:func:`parse_key_values`). :func:`train_config` merges the command line, the files and a
resumed run's ``config.json`` into one checked :class:`~aftir_rl.rl.sb3.config.TrainConfig`.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from aftir_rl.core.config import CONFIG_DIR, brief, from_mapping, read_yaml
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.files import read_json
from aftir_rl.core.shipped import find_config
from aftir_rl.rl.common import DEFAULT_SB3_ENV_ID, check_env_id
from aftir_rl.rl.sb3.config import (
    HER_KWARGS,
    SB3_ENV_IDS,
    SB3Config,
    TrainConfig,
    check_sb3_config,
    parse_hyperparameters,
    sb3_config_from_run,
)

__all__ = [
    "DEFAULT_ENV_ID",
    "MAX_ITEMS",
    "MAX_STAGES",
    "config_from_mapping",
    "entry_config",
    "entry_env_ids",
    "hyperparams_file",
    "is_curriculum",
    "is_hyperparams_file",
    "load_curriculum",
    "load_sb3_config",
    "parse_key_values",
    "refuse_tank",
    "saved_config",
    "train_config",
    "with_overrides",
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
_FIELDS = frozenset(f.name for f in dataclasses.fields(SB3Config))
#: Most stages a stage file may hold.
MAX_STAGES = 10
_STAGE_KEYS = {"config"} | _FIELDS
#: Most ``KEY:VALUE`` items one option takes.
MAX_ITEMS = 64
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
#: The source the command line's overrides are checked under.
_OVERRIDES = "--env-kwargs/--hyperparams"


def train_config(
    algo: str,
    config: str | None = None,
    *,
    env: str | None = None,
    resume: str | None = None,
    tank: str | None = None,
    env_kwargs: Sequence[str] = (),
    hyperparams: Sequence[str] = (),
    numbers: Mapping[str, int | None] | None = None,
    seed: int = 0,
    logdir: str = "runs",
    progress_bar: bool = True,
    demos: str | None = None,
    bc_epochs: int = 20,
) -> TrainConfig:
    """The checked run of ``aftir train ALGO``: its stages with the command line over them.

    The stages are ``config``'s (a named config, an RL Zoo file's entry of ``env``, or a stage
    file's stages), else ``env``'s entry in ``algo``'s hyperparameter file, else (with
    ``resume`` alone) the resumed run's own. ``numbers`` (SB3Config fields), ``env`` (over a
    named config's), ``env_kwargs``, ``hyperparams`` and ``tank`` (loaded by the caller) apply to
    every stage; each stage is then checked, once.

    Raises:
        ConfigError: a file, an item or the merged config is refused (one line, naming where).
        CheckpointError: the resumed run's ``config.json`` is unreadable.

    """
    stages = _stages(algo, config, env, resume)
    extra_env, extra_hyper = _overrides(algo, env_kwargs, hyperparams)
    given: dict[str, Any] = {"env_id": env, **(numbers or {})}
    given = {k: v for k, v in given.items() if v is not None}
    if tank is not None:
        extra_env["tank"] = tank
    source = _OVERRIDES if env_kwargs or hyperparams else "config"
    merged = []
    for stage in stages:
        stage = dataclasses.replace(stage, **given)
        if tank is not None and stage.env_id.split(":")[-1] != "AFTIR-ArmFTL-v0":
            raise ConfigError("--tank: only AFTIR-ArmFTL-v0 takes a tank")
        stage = dataclasses.replace(
            stage,
            env_kwargs={**stage.env_kwargs, **extra_env},
            hyperparameters={**stage.hyperparameters, **extra_hyper},
        )
        check_env_id(stage.env_id, SB3_ENV_IDS, algo)
        check_sb3_config(stage, algo, source)
        merged.append(stage)
    if demos is not None and (algo != "ppo" or len(merged) != 1 or resume is not None):
        raise ConfigError("--demos: behaviour cloning starts a new PPO run of one config")
    return TrainConfig(algo, tuple(merged), seed, logdir, resume, progress_bar, demos, bc_epochs)


def _stages(algo: str, config: str | None, env: str | None, resume: str | None) -> list[SB3Config]:
    """The configs a run trains before the command line's overrides (:func:`train_config`)."""
    own = saved_config(resume) if config is None and resume else None
    if own is not None:
        if own[0] != algo:
            raise ConfigError(f"--resume {resume}: a {own[0]} run, not {algo}")
        return [own[1]]
    if config is None:
        return [entry_config(algo, env or DEFAULT_ENV_ID)]
    path = find_config(config)
    data = read_yaml(path)
    if "stages" in data:
        if env:
            raise ConfigError(f"--env: {config} is a stage file; its stages name their env")
        return _load_stages(data, path, algo)
    if _is_zoo(data):  # RL Zoo's -conf: the entry of --env
        return [_entry_config(algo, env or DEFAULT_ENV_ID, path, data)]
    return [config_from_mapping(data, algo, str(path))]


def saved_config(resume: str | os.PathLike[str]) -> tuple[str, SB3Config] | None:
    """``(algo, config)`` of the run that ``--resume`` names, or None if it has no ``config.json``.

    ``resume`` is a run directory or a model inside one (``model.zip``, ``best/model.zip``,
    ``checkpoints/model_<steps>.zip``); the run's own config makes ``--resume DIR`` alone finish
    that run as it was started.

    Raises:
        CheckpointError: the run's ``config.json`` is unreadable or not a training run's.

    """
    path = Path(resume)
    for folder in (path, *list(path.parents)[:2]):
        if folder.is_dir() and (folder / "config.json").exists():
            source = str(folder / "config.json")
            return sb3_config_from_run(read_json(source, "config.json"), source)
    return None


def hyperparams_file(algo: str) -> Path:
    """``configs/hyperparams/<algo>.yml`` of the package."""
    return CONFIG_DIR / "hyperparams" / f"{algo}.yml"


def _entries(data: dict[str, Any]) -> dict[str, Any]:
    """The entries of a hyperparameter file's ``data`` for the package's envs (not anchors)."""
    return {k: v for k, v in data.items() if isinstance(k, str) and k.startswith("AFTIR-")}


def entry_env_ids(algo: str) -> list[str]:
    """The env ids ``configs/hyperparams/<algo>.yml`` has an entry for."""
    return list(_entries(read_yaml(hyperparams_file(algo))))


def _is_zoo(data: dict[str, Any]) -> bool:
    return bool(_entries(data)) and not (_FIELDS | {"stages"}) & set(data)


def is_hyperparams_file(name: str | os.PathLike[str]) -> bool:
    """Whether the config ``name`` stands for is keyed by env id (RL Zoo's format)."""
    return _is_zoo(read_yaml(find_config(name)))


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
    found = hyperparams_file(algo) if path is None else find_config(path)
    return _entry_config(algo, env_id, found, read_yaml(found))


def _entry_config(algo: str, env_id: str, path: Path, data: dict[str, Any]) -> SB3Config:
    """:func:`entry_config` of the file ``path`` already read as ``data``."""
    bare = check_env_id(env_id, SB3_ENV_IDS, algo)
    entries = _entries(data)
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
        path = hyperparams_file(algo)
        file = read_yaml(path)
        own = bare in _entries(file)
        base = _entry_config(algo, env_id, path, file) if own else SB3Config(env_id=env_id)
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
    found = find_config(path)
    return config_from_mapping(read_yaml(found), algo, str(found))


def is_curriculum(name: str | os.PathLike[str]) -> bool:
    """Whether the config ``name`` stands for is a stage file (its one key is ``stages``)."""
    return "stages" in read_yaml(find_config(name))


def load_curriculum(name: str | os.PathLike[str], algo: str) -> list[SB3Config]:
    """The checked configs of a stage file's stages, in order.

    Raises:
        ConfigError: the file is not a stage file, or a stage is refused (one line, naming the
            stage and the key).

    """
    path = find_config(name)
    return _load_stages(read_yaml(path), path, algo)


def _load_stages(data: dict[str, Any], path: Path, algo: str) -> list[SB3Config]:
    """:func:`load_curriculum` of the file ``path`` already read as ``data``."""
    stages = data.get("stages")
    if set(data) != {"stages"} or not isinstance(stages, list) or not stages:
        raise ConfigError(f"{path}: a stage file holds one key, stages: a list of stages")
    if len(stages) > MAX_STAGES:
        raise ConfigError(f"{path}: stages: at most {MAX_STAGES}, got {len(stages)}")
    configs = [_stage(entry, k, algo, str(path)) for k, entry in enumerate(stages)]
    env_ids = {c.env_id for c in configs}
    if len(env_ids) > 1:
        raise ConfigError(f"{path}: every stage must train the same env, got {sorted(env_ids)}")
    return configs


def _stage(entry: Any, k: int, algo: str, source: str) -> SB3Config:
    where = f"{source}: stages[{k}]"
    if not isinstance(entry, dict) or not ({"config", "env_id"} & set(entry)):
        raise ConfigError(
            f"{where}: expected a mapping with a config or an env_id, got {brief(entry)}"
        )
    unknown = set(entry) - _STAGE_KEYS
    if unknown:
        raise ConfigError(
            f"{where}: unknown key {brief(sorted(map(str, unknown))[0])}; allowed keys are "
            f"{', '.join(sorted(_STAGE_KEYS))}"
        )
    fields = dict(entry)
    base = None
    if "config" in fields:
        name = fields.pop("config")
        if not isinstance(name, str):
            raise ConfigError(f"{where}.config: expected a config's name or path")
        found = find_config(name)
        data = read_yaml(found)
        if "stages" in data:
            raise ConfigError(f"{where}.config: {name} is a stage file itself")
        base = config_from_mapping(data, algo, str(found))
    return config_from_mapping(fields, algo, where, base)


def refuse_tank(env_kwargs: dict[str, Any], source: str) -> None:
    """A config file or ``--env-kwargs`` names no tank (a shared file points at no other file).

    Raises:
        ConfigError: ``env_kwargs`` has ``tank``; ``--tank`` gives one.

    """
    if "tank" in env_kwargs:
        raise ConfigError(f"{source}: env_kwargs.tank: a config names no tank; give --tank")


def parse_key_values(items: Sequence[str], option: str) -> dict[str, Any]:
    """``{KEY: value}`` of ``KEY:VALUE`` items, each value read as YAML (nothing evaluated).

    Raises:
        ConfigError: an item without ``:``, a key that is not a name, a key given twice, a value
            that is not valid YAML (bounded like a config file), or more than :data:`MAX_ITEMS`.

    """
    if len(items) > MAX_ITEMS:
        raise ConfigError(f"{option}: at most {MAX_ITEMS} KEY:VALUE items, got {len(items)}")
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition(":")
        if not sep or not _KEY.fullmatch(key):
            raise ConfigError(f"{option}: expected KEY:VALUE with KEY a name, got {brief(item)}")
        if "\n" in value or "\r" in value or len(value) > 10_000:
            raise ConfigError(f"{option} {key}: the value must be one line of at most 10,000 chars")
        if key in out:
            raise ConfigError(f"{option}: {key} is given twice")
        out[key] = read_yaml(Path(f"{option} {key}"), f"value: {value}".encode())["value"]
    return out


def _overrides(
    algo: str, env_kwargs: Sequence[str], hyperparams: Sequence[str]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The ``--env-kwargs`` and ``--hyperparams`` items as mappings, their keys checked."""
    given = parse_key_values(env_kwargs, "--env-kwargs")
    refuse_tank(given, "--env-kwargs")
    hyper = parse_key_values(hyperparams, "--hyperparams")
    return given, parse_hyperparameters(hyper, algo, _OVERRIDES)


def with_overrides(
    config: SB3Config,
    algo: str,
    env_kwargs: Sequence[str] = (),
    hyperparams: Sequence[str] = (),
) -> SB3Config:
    """``config`` with ``--env-kwargs`` and ``--hyperparams`` items merged in, then checked.

    Raises:
        ConfigError: an item is malformed, or the merged config is refused (one line, naming the
            option and the key).

    """
    if not env_kwargs and not hyperparams:
        return config
    given, extra = _overrides(algo, env_kwargs, hyperparams)
    merged = dataclasses.replace(
        config,
        env_kwargs={**config.env_kwargs, **given},
        hyperparameters={**config.hyperparameters, **extra},
    )
    check_sb3_config(merged, algo, _OVERRIDES)
    return merged
