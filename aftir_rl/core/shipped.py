"""The configs shipped with the package, found by name wherever it is installed; the default tank.

``--config ppo_ftl``, ``--config ppo_ftl.yaml`` and ``--config configs/ppo_ftl.yaml`` all name
``configs/ppo_ftl.yaml`` of the package (inside the wheel, or the checkout's ``configs/``); a
path to a file that exists always wins. ``aftir configs`` lists them.
"""

from __future__ import annotations

import os
from pathlib import Path

from aftir_rl.core.config import CONFIG_DIR, brief
from aftir_rl.core.errors import ConfigError

__all__ = ["DEFAULT_TANK", "find_config", "shipped_configs"]

#: The shipped tank every env, planner and command uses unless given another.
DEFAULT_TANK = "b737_center"

_SUFFIXES = (".yaml", ".yml")


def shipped_configs(folder: str = "") -> list[str]:
    """The names of the shipped configs (``ppo``, ``search_spaces/ppo``...), sorted.

    ``folder``: only those in this sub-folder of ``configs/`` (e.g. ``tanks``), named within it.
    """
    top = CONFIG_DIR / folder
    found = [p for p in top.rglob("*") if p.suffix in _SUFFIXES and p.is_file()]
    return sorted(p.relative_to(top).with_suffix("").as_posix() for p in found)


def find_config(name: str | os.PathLike[str], folder: str = "") -> Path:
    """The file a config name or path stands for.

    Args:
        name: a path to an existing file, or a shipped config's name, with or without ``.yaml``
            and a leading ``configs/`` (and ``folder``).
        folder: the sub-folder of ``configs/`` names are looked up in (``""``: the top).

    Raises:
        ConfigError: neither a file nor a shipped config; the message lists the shipped ones.

    """
    path = Path(name)
    if path.is_file():
        return path
    parts = [p for p in path.parts if p not in ("configs", folder)] if path.parts else []
    top = (CONFIG_DIR / folder).resolve()
    if parts and ".." not in parts and not path.is_absolute():
        stem = Path(*parts)
        for candidate in (stem, *(stem.with_name(stem.name + s) for s in _SUFFIXES)):
            full = (top / candidate).resolve()
            if full.suffix in _SUFFIXES and full.is_relative_to(top) and full.is_file():
                return full
    names = [n for n in shipped_configs(folder) if "/" not in n]
    raise ConfigError(
        f"{brief(str(name))}: no such file and no shipped config of that name; shipped: "
        f"{', '.join(names)} (aftir configs lists them all)"
    )
