"""Trained policies shipped inside the package, by name: ``load("ppo-armreach")``.

Each lives in ``aftir_rl/rl/policies/<name>/`` as a run directory (``config.json`` and
``model.zip``, loaded by the same safe loader as any run: nothing unpickled) with ``card.json``:
the env and its keyword arguments, the recipe and seed it was trained with, its steps and
minutes, how it was chosen, and what it measured on named held-out targets
(``benchmarks/pretrained_card.py`` writes the card; the tests measure ``check`` again).
``aftir pretrained`` lists them; ``--pretrained NAME`` gives one to ``evaluate``, ``rollout`` and
``record``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from aftir_rl.core.config import brief
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.files import read_json

__all__ = ["POLICY_DIR", "card", "load", "names", "policy_dir"]

#: Where the shipped policies are (inside the installed package).
POLICY_DIR = Path(str(resources.files("aftir_rl.rl"))) / "policies"


def names() -> list[str]:
    """The names of the shipped SB3 policies, sorted (route policies: ``aftir route plan``)."""
    if not POLICY_DIR.is_dir():
        return []
    found = (p for p in POLICY_DIR.iterdir() if (p / "card.json").is_file())
    return sorted(p.name for p in found if (p / "model.zip").is_file())


def policy_dir(name: str) -> Path:
    """The run directory of a shipped policy.

    Raises:
        ConfigError: no shipped policy has this name (the message lists them).

    """
    known = names()
    if not isinstance(name, str) or name not in known:
        raise ConfigError(
            f"no pretrained policy named {brief(name)}; shipped: {', '.join(known) or 'none'} "
            "(aftir pretrained lists them)"
        )
    return POLICY_DIR / name


def card(name: str) -> dict[str, Any]:
    """The card of a shipped policy (``card.json``)."""
    data = read_json(policy_dir(name) / "card.json", "card.json")
    if not isinstance(data, dict):
        raise ConfigError(f"{name}: card.json is not a mapping")
    return data


def load(name: str) -> tuple[Any, str, dict[str, Any]]:
    """A shipped policy: ``(model, env_id, env_kwargs)``.

    ``model`` is the SB3 model (``predict`` as usual), ``env_id`` the id to ``gym.make`` with
    ``**env_kwargs`` (the evaluation env: training-only keywords left out), e.g.::

        model, env_id, kwargs = load("ppo-armreach")
        env = gym.make(env_id, **kwargs)

    Raises:
        ConfigError: no such policy.
        CheckpointError: its files are damaged.

    """
    from aftir_rl.rl.sb3.evaluation import evaluation_env_kwargs
    from aftir_rl.rl.sb3.loading import load_run

    _, config, env_id, model = load_run(policy_dir(name))
    return model, env_id, evaluation_env_kwargs(config.env_kwargs)
