"""What every training run shares: its directory name and its hyperparameters as text."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Any

__all__ = ["target_tag", "run_name", "hyperparameter_text"]


def target_tag(target: Sequence[float]) -> str:
    """A target as it appears in run names and TensorBoard tags, ``"10_-5_30"``."""
    return "_".join(f"{float(v):g}" for v in target)


def run_name(algo: str, env_id: str, target: Sequence[float] | str, seed: int) -> str:
    """``{algo}__{env}__{target}__{seed}__{time}`` (design.md §8)."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    tag = target if isinstance(target, str) else target_tag(target)
    return f"{algo}__{env_id}__{tag}__{seed}__{stamp}"


def hyperparameter_text(params: dict[str, Any]) -> str:
    """The markdown table of the hyperparameters TensorBoard shows as text."""
    rows = "\n".join(f"|{k}|{v}|" for k, v in params.items())
    return "|param|value|\n|-|-|\n" + rows
