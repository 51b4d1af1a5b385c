"""Command-line overrides of an SB3 config, RL Zoo's way: ``--env-kwargs bay:1 guide:true``.

Each item is ``KEY:VALUE``; the value is read as YAML by the same bounded safe loader as the
config files (``2`` an int, ``true`` a bool, ``[256, 256]`` a list, ``{net_arch: [64, 64]}`` a
mapping; nothing is evaluated as Python), and the overridden config is checked key by key like a
file: :data:`~aftir_rl.rl.sb3.config.ENV_KWARGS` for the env, the algorithm's constructor for the
hyperparameters.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aftir_rl.core.config import brief, read_yaml
from aftir_rl.core.errors import ConfigError
from aftir_rl.rl.sb3.config import (
    SB3Config,
    check_sb3_config,
    parse_hyperparameters,
    refuse_tank,
)

__all__ = ["MAX_ITEMS", "parse_key_values", "with_overrides"]

#: Most ``KEY:VALUE`` items one option takes.
MAX_ITEMS = 64
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")


def parse_key_values(items: Sequence[str], option: str) -> dict[str, Any]:
    """``{KEY: value}`` of ``KEY:VALUE`` items, each value read as YAML.

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
    source = "--env-kwargs/--hyperparams"
    given = parse_key_values(env_kwargs, "--env-kwargs")
    refuse_tank(given, "--env-kwargs")
    kwargs = {**config.env_kwargs, **given}
    extra = parse_hyperparameters(parse_key_values(hyperparams, "--hyperparams"), algo, source)
    merged = dataclasses.replace(
        config, env_kwargs=kwargs, hyperparameters={**config.hyperparameters, **extra}
    )
    check_sb3_config(merged, algo, source)
    return merged
