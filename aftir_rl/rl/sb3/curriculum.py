"""A curriculum: configs trained one after the other, each resumed from the previous stage's model.

A stage file is a config whose only key is ``stages``, a list of at most :data:`MAX_STAGES`
mappings of :class:`~aftir_rl.rl.sb3.config.SB3Config` fields, each over ``config`` (a named
config or a path) if it gives one, else over its ``env_id``'s entry in the hyperparameter file
(:func:`~aftir_rl.rl.sb3.hyperparams.config_from_mapping`: ``env_kwargs`` and
``hyperparameters`` merged key by key). ``aftir train ppo --config NAME`` trains a stage file
like any config: stage ``k`` writes its run directory under ``LOGDIR/stage<k>/`` and the next
stage resumes from it (``--resume``), so the recipe is one command::

    stages:
      - config: ppo_ftl_cost_bay1
      - {env_id: AFTIR-ArmFTL-v0, total_timesteps: 58032128, env_kwargs: {bay: 2}}
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aftir_rl.core.config import brief, read_yaml
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.shipped import find_config
from aftir_rl.rl.sb3.config import SB3Config
from aftir_rl.rl.sb3.hyperparams import config_from_mapping, load_sb3_config

__all__ = ["MAX_STAGES", "is_curriculum", "load_curriculum", "train_curriculum"]

#: Most stages a stage file may hold.
MAX_STAGES = 10
_STAGE_KEYS = {"config"} | {f.name for f in dataclasses.fields(SB3Config)}


def is_curriculum(name: str | os.PathLike[str]) -> bool:
    """Whether the config ``name`` stands for is a stage file (its one key is ``stages``)."""
    return "stages" in read_yaml(find_config(name))


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
        if is_curriculum(name):
            raise ConfigError(f"{where}.config: {name} is a stage file itself")
        base = load_sb3_config(name, algo)
    return config_from_mapping(fields, algo, where, base)


def load_curriculum(name: str | os.PathLike[str], algo: str) -> list[SB3Config]:
    """The checked configs of a stage file's stages, in order.

    Raises:
        ConfigError: the file is not a stage file, or a stage is refused (one line, naming the
            stage and the key).

    """
    path = find_config(name)
    data = read_yaml(path)
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


def train_curriculum(
    train: Callable[..., dict[str, Any]],
    algo: str,
    configs: list[SB3Config],
    seed: int,
    logdir: str | os.PathLike[str],
    resume: str | os.PathLike[str] | None = None,
    **kwargs: Any,
) -> list[dict[str, Any]]:
    """Train ``configs`` one after the other, each resumed from the previous stage's run.

    ``train`` is :func:`aftir_rl.rl.sb3.train.train_sb3` (passed in, so this module stays light);
    ``resume`` starts the first stage from a model; ``kwargs`` go to every call.

    Returns:
        Each stage's summary (``run_dir`` holds its run directory).

    """
    summaries = []
    for k, config in enumerate(configs):
        stage_dir = Path(logdir) / f"stage{k}"  # made and checked by ``train`` (one line if not)
        summary = train(algo, config, seed=seed, logdir=stage_dir, resume=resume, **kwargs)
        summaries.append(summary)
        resume = summary["run_dir"]
    return summaries
