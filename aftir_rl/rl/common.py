"""What every training run shares: its env id check, its directory name, its hyperparameters."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Any, Protocol

from aftir_rl.core.config import brief
from aftir_rl.core.errors import ConfigError
from aftir_rl.envs.registration import registered_env_id

__all__ = [
    "DEFAULT_SB3_ENV_ID",
    "Predictor",
    "check_env_id",
    "target_tag",
    "run_name",
    "hyperparameter_text",
]

#: The env ``aftir train ppo|sac|td3`` trains when neither ``--env`` nor ``--config`` is given.
DEFAULT_SB3_ENV_ID = "AFTIR-ArmReach-v0"


class Predictor(Protocol):
    """An agent with SB3's ``predict``: ``(action, state)`` for an observation."""

    def predict(self, observation: Any, *, deterministic: bool = ...) -> tuple[Any, Any]:
        """The action for ``observation`` (greedy with ``deterministic``) and a state."""
        ...


def target_tag(target: Sequence[float]) -> str:
    """A target as it appears in run names and TensorBoard tags, ``"10_-5_30"``."""
    return "_".join(f"{float(v):g}" for v in target)


def run_name(algo: str, env_id: str, target: Sequence[float] | str, seed: int) -> str:
    """``{algo}__{env}__{target}__{seed}__{time}`` (docs/design.md §9)."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    tag = target if isinstance(target, str) else target_tag(target)
    return f"{algo}__{env_id}__{tag}__{seed}__{stamp}"


def hyperparameter_text(params: dict[str, Any]) -> str:
    """The markdown table of the hyperparameters TensorBoard shows as text."""
    rows = "\n".join(f"|{k}|{v}|" for k, v in params.items())
    return "|param|value|\n|-|-|\n" + rows


def check_env_id(env_id: Any, allowed: Sequence[str], algo: str) -> str:
    """The bare id of ``env_id`` (``ID`` or ``aftir_rl:ID``); any other module is never imported.

    Raises:
        ConfigError: ``env_id`` is not one of ``allowed`` (``algo`` cannot train on it).

    """
    try:
        return registered_env_id(env_id, algo, allowed)
    except ConfigError:
        raise ConfigError(
            f"{algo} cannot train on {brief(env_id)}; use one of {', '.join(allowed)} "
            "(--env or env_id)"
        ) from None
