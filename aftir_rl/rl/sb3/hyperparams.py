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
resumed run's ``config.json`` into one :class:`~aftir_rl.rl.sb3.config.TrainConfig`: each
stage's sources are merged first, the source of every key kept, then checked once.
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
    TANK_ENV_IDS,
    Origins,
    SB3Config,
    TrainConfig,
    check_sb3_values,
    parse_hyperparameters,
    sb3_config_from_run,
)

__all__ = [
    "DEFAULT_ENV_ID",
    "MAX_ITEMS",
    "MAX_STAGES",
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
#: The options of the command line's SB3Config fields, named as their source.
_OPTIONS = {
    "env_id": "--env",
    "total_timesteps": "--total-timesteps",
    "n_envs": "--n-envs",
    "eval_freq": "--eval-freq",
    "eval_targets": "--eval-episodes",
    "checkpoint_freq": "--save-freq",
}


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
    every stage; each stage is then checked once, a refused value named with its source.

    Raises:
        ConfigError: a file, an item or the merged config is refused (one line, naming where).
        CheckpointError: the resumed run's ``config.json`` is unreadable.

    """
    drafts = _drafts(algo, config, env, resume)
    items = _items(env_kwargs, hyperparams)
    given = {k: v for k, v in {"env_id": env, **(numbers or {})}.items() if v is not None}
    stages = []
    for draft in drafts:
        for key, value in given.items():
            draft.over({key: value}, _OPTIONS.get(key, "the command line"))
        for name, (option, values) in items.items():
            draft.over({name: values}, option)
        if tank is not None:
            if draft.bare not in TANK_ENV_IDS:
                raise ConfigError(f"--tank: only {', '.join(TANK_ENV_IDS)} takes a tank")
            draft.put("env_kwargs", {"tank": tank}, "--tank")
        stages.append(draft.checked())
    if demos is not None and (algo != "ppo" or len(stages) != 1 or resume is not None):
        raise ConfigError("--demos: behaviour cloning starts a new PPO run of one config")
    return TrainConfig(algo, tuple(stages), seed, logdir, resume, progress_bar, demos, bc_epochs)


class _Draft:
    """A config merged from its sources, lowest first, each key's source and the env kept.

    ``bare`` is the env id resolved once, when a source names the env; :meth:`checked` checks
    the merged values once, naming the source of a refused one.
    """

    def __init__(self, algo: str, env_id: Any, source: str) -> None:
        self.algo, self.source = algo, source
        self.fields: dict[str, Any] = {"env_kwargs": {}, "hyperparameters": {}}
        self.keys: dict[str, str] = {}
        self.bare = ""
        self.over({"env_id": env_id}, source)

    @classmethod
    def of_config(cls, algo: str, config: SB3Config, source: str) -> _Draft:
        """A draft of a config checked already (a resumed run's, which may name its tank)."""
        draft = cls(algo, config.env_id, source)
        draft.fields = dataclasses.asdict(config)
        return draft

    def over(self, data: Mapping[str, Any], source: str) -> _Draft:
        """Merge ``data`` (SB3Config fields of ``source``, which names no tank) over the draft.

        Raises:
            ConfigError: an unknown key, a value of the wrong type, a hyperparameter the
                algorithm does not take, an env it cannot train on, a tank (naming ``source``).

        """
        data = dict(data)
        env_kwargs = _names(data, "env_kwargs", source)
        hyper = parse_hyperparameters(_names(data, "hyperparameters", source), self.algo, source)
        refuse_tank(env_kwargs, source)
        values = from_mapping(SB3Config, data, source)
        if "env_id" in data and values.env_id != self.fields.get("env_id"):
            self.bare = check_env_id(values.env_id, SB3_ENV_IDS, self.algo)
        self.fields.update({key: getattr(values, key) for key in data})
        self.keys.update(dict.fromkeys(data, source))
        self.put("env_kwargs", env_kwargs, source)
        return self.put("hyperparameters", hyper, source)

    def put(self, name: str, values: dict[str, Any], source: str) -> _Draft:
        """Merge ``values`` into the mapping field ``name``, key by key."""
        self.fields[name] = {**self.fields[name], **values}
        self.keys.update({f"{name}.{key}": source for key in values})
        return self

    def derive(self) -> _Draft:
        """``eval_freq`` and ``checkpoint_freq`` from ``total_timesteps``, unless given."""
        steps = self.fields.get("total_timesteps", SB3Config.total_timesteps)
        for key, (share, low) in _DERIVED.items():
            if key not in self.fields:
                self.fields[key] = max(low, steps // share)
                self.keys[key] = self.keys.get("total_timesteps", self.source)
        return self

    def checked(self) -> SB3Config:
        """The merged config, its values checked once (naming each refused value's source)."""
        config = SB3Config(**self.fields)
        check_sb3_values(config, self.algo, self.bare, Origins(self.source, self.keys))
        return config


def _drafts(algo: str, config: str | None, env: str | None, resume: str | None) -> list[_Draft]:
    """The configs a run trains before the command line's overrides (:func:`train_config`)."""
    own = saved_config(resume) if config is None and resume else None
    if own is not None:
        if own[0] != algo:
            raise ConfigError(f"--resume {resume}: a {own[0]} run, not {algo}")
        return [_Draft.of_config(algo, own[1], f"--resume {resume}")]
    if config is None:
        return [_entry(algo, env or DEFAULT_ENV_ID, "--env").derive()]
    path, data = _read(config)
    if "stages" in data:
        if env:
            raise ConfigError(f"--env: {config} is a stage file; its stages name their env")
        return _stages(data, path, algo)
    if _is_zoo(data):  # RL Zoo's -conf: the entry of --env
        return [_entry(algo, env or DEFAULT_ENV_ID, "--env", (path, data)).derive()]
    return [_named(data, str(path), algo)]


def _read(name: str | os.PathLike[str]) -> tuple[Path, dict[str, Any]]:
    """The file a config name or path stands for, and its mapping."""
    path = find_config(name)
    return path, read_yaml(path)


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
    return list(_entries(_read(hyperparams_file(algo))[1]))


def _is_zoo(data: dict[str, Any]) -> bool:
    return bool(_entries(data)) and not (_FIELDS | {"stages"}) & set(data)


def is_hyperparams_file(name: str | os.PathLike[str]) -> bool:
    """Whether the config ``name`` stands for is keyed by env id (RL Zoo's format)."""
    return _is_zoo(_read(name)[1])


def _zoo_fields(entry: Any, source: str) -> dict[str, Any]:
    """The :class:`SB3Config` fields of an RL Zoo entry (``hyperparameters``: the rest)."""
    if not isinstance(entry, dict):
        raise ConfigError(f"{source}: expected a mapping of hyperparameters, got {brief(entry)}")
    rest = dict(entry)
    fields = {name: rest.pop(key) for key, name in _ZOO_FIELDS.items() if key in rest}
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
    return {**fields, "hyperparameters": rest}


def entry_config(algo: str, env_id: str, path: str | os.PathLike[str] | None = None) -> SB3Config:
    """The checked config of ``env_id``'s entry in ``configs/hyperparams/<algo>.yml``.

    ``path``: another file of the same format (a name or a path), e.g. your own RL Zoo file.

    Raises:
        ConfigError: the env has no entry (the message names those that have one), or the
            entry is refused (naming the file, the env and the key).

    """
    file = None if path is None else _read(path)
    return _entry(algo, env_id, "env_id", file).derive().checked()


def _entry(
    algo: str,
    env_id: Any,
    env_source: str,
    file: tuple[Path, dict[str, Any]] | None = None,
    missing_ok: bool = False,
) -> _Draft:
    """The draft of ``env_id``'s entry in ``file`` (default ``algo``'s hyperparameter file).

    ``missing_ok``: an env without an entry has the plain defaults, instead of a ConfigError.
    """
    path, data = file or _read(hyperparams_file(algo))
    draft = _Draft(algo, env_id, env_source)
    entries = _entries(data)
    if draft.bare not in entries:
        if missing_ok:
            return draft
        raise ConfigError(
            f"no {algo} hyperparameters for {draft.bare} in {path.name}; it has an entry for "
            f"{', '.join(entries) or 'no env'} (or give --config FILE with env_id: {draft.bare})"
        )
    draft.source = f"{path}: {draft.bare}"
    return draft.over(_zoo_fields(entries[draft.bare], draft.source), draft.source)


def _names(data: dict[str, Any], key: str, source: str) -> dict[str, Any]:
    """The mapping of names ``data`` gives as ``key`` (removed from ``data``), else ``{}``."""
    value = data.pop(key, None) or {}
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise ConfigError(f"{source}: {key}: expected a mapping of names, got {brief(value)}")
    return value


def _named(data: dict[str, Any], source: str, algo: str) -> _Draft:
    """The draft of a named config's ``data`` over its env's entry (:func:`load_sb3_config`).

    The entry is the one of ``data``'s ``env_id`` (:data:`DEFAULT_ENV_ID` if none) in the
    hyperparameter file of ``algo``, or the plain defaults for an env without one.
    """
    draft = _entry(algo, data.get("env_id", DEFAULT_ENV_ID), source, missing_ok=True)
    draft.source = source
    return draft.over(data, source).derive()


def load_sb3_config(path: str | os.PathLike[str], algo: str) -> SB3Config:
    """Read and check a named config (a path, or a shipped name such as ``ppo_ftl``).

    Its fields go over its env's entry; numbers written as strings (``3e-4``) are parsed.

    Raises:
        ConfigError: a key, type or value is refused (naming the file, or the entry, and the key).

    """
    found, data = _read(path)
    return _named(data, str(found), algo).checked()


def is_curriculum(name: str | os.PathLike[str]) -> bool:
    """Whether the config ``name`` stands for is a stage file (its one key is ``stages``)."""
    return "stages" in _read(name)[1]


def load_curriculum(name: str | os.PathLike[str], algo: str) -> list[SB3Config]:
    """The checked configs of a stage file's stages, in order.

    Raises:
        ConfigError: the file is not a stage file, or a stage is refused (one line, naming the
            stage and the key).

    """
    path, data = _read(name)
    return [draft.checked() for draft in _stages(data, path, algo)]


def _stages(data: dict[str, Any], path: Path, algo: str) -> list[_Draft]:
    """The drafts of the stages of the stage file ``path``, read as ``data``."""
    stages = data.get("stages")
    if set(data) != {"stages"} or not isinstance(stages, list) or not stages:
        raise ConfigError(f"{path}: a stage file holds one key, stages: a list of stages")
    if len(stages) > MAX_STAGES:
        raise ConfigError(f"{path}: stages: at most {MAX_STAGES}, got {len(stages)}")
    drafts = [_stage(entry, k, algo, str(path)) for k, entry in enumerate(stages)]
    env_ids = {draft.fields["env_id"] for draft in drafts}
    if len(env_ids) > 1:
        raise ConfigError(f"{path}: every stage must train the same env, got {sorted(env_ids)}")
    return drafts


def _stage(entry: Any, k: int, algo: str, source: str) -> _Draft:
    """The draft of stage ``k``: its fields over its ``config``, or over its env's entry."""
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
    if "config" not in fields:
        return _named(fields, where, algo)
    name = fields.pop("config")
    if not isinstance(name, str):
        raise ConfigError(f"{where}.config: expected a config's name or path")
    found, data = _read(name)
    if "stages" in data:
        raise ConfigError(f"{where}.config: {name} is a stage file itself")
    return _named(data, str(found), algo).over(fields, where)


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


def _items(env_kwargs: Sequence[str], hyperparams: Sequence[str]) -> dict[str, tuple[str, Any]]:
    """The ``--env-kwargs`` and ``--hyperparams`` items: ``{field: (option, {KEY: value})}``."""
    return {
        "env_kwargs": ("--env-kwargs", parse_key_values(env_kwargs, "--env-kwargs")),
        "hyperparameters": ("--hyperparams", parse_key_values(hyperparams, "--hyperparams")),
    }


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
    items = _items(env_kwargs, hyperparams)
    draft = _Draft.of_config(algo, config, "config")
    for name, (option, values) in items.items():
        draft.over({name: values}, option)
    return draft.checked()
