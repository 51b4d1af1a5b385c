"""The options of ``AFTIR-ArmFTL-v0`` as frozen dataclasses, built from keyword arguments once.

:class:`TaskSpec` (the tank, the arm, the task and what the policy observes), :class:`RewardSpec`
and :class:`TrainingSpec` (training-only: how targets are drawn and judged while learning;
evaluations drop them). :meth:`FTLSpec.from_kwargs` routes each keyword of ``gym.make`` to its
spec and checks what needs no tank; :data:`TRAINING_ONLY_KWARGS` and :data:`CONFIG_KWARG_TYPES`
are derived from the fields. The arguments are described in
:class:`~aftir_rl.envs.ftl.env.ArmFTLEnv`.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Union

import numpy as np

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.tank import Tank

__all__ = [
    "CONFIG_KWARG_TYPES",
    "MAX_SLACK",
    "MAX_STEP_COST",
    "SHAPING_KINDS",
    "STEER_MODES",
    "TRAINING_ONLY_KWARGS",
    "FTLSpec",
    "RewardSpec",
    "TaskSpec",
    "TrainingSpec",
]

#: The largest ``step_cost``: 300 steps of it stay below the contact penalty, so ending an
#: episode on contact never pays better than waiting.
MAX_STEP_COST = 0.03
#: ``slack`` stays below this [cm] (and below ``success_tolerance``).
MAX_SLACK = 5.0
#: What the two steering actions may command: a change of the steered ``κ``, or ``κ`` itself.
STEER_MODES = ("increment", "target")
#: The ``shaping`` values and the potential each one adds.
SHAPING_KINDS = {False: "", True: "raster", "raster": "raster", "field": "field"}


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """The tank, the arm, the task and what the policy observes (lengths in cm, angles in rad)."""

    tank: str | Path | Tank = "b737_center"
    n_sections: int | None = None
    target: Sequence[float] | None = None
    bay: int | None = None
    success_tolerance: float = 2.0
    margin: float = 1.0
    kappa_step: float = 0.1
    push_step: float = 5.0
    start_height: float = 10.0
    samples_per_section: int = 10
    steer: str = "increment"
    guide: bool = False
    near_goal: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.near_goal, bool | np.bool_):
            raise ConfigError(f"near_goal must be true or false, got {self.near_goal!r}")
        if self.steer not in STEER_MODES:
            raise ConfigError(f"steer must be 'increment' or 'target', got {self.steer!r}")
        for name in ("kappa_step", "push_step", "success_tolerance"):
            value = getattr(self, name)
            if not 0 < value < math.inf:
                raise ConfigError(f"{name} must be positive and finite, got {value}")
        if not 0 <= self.margin < 20:
            raise ConfigError("margin must be in [0, 20) cm and target_clearance in [0, 100) cm")
        if self.samples_per_section < 2:
            raise ConfigError(
                f"samples_per_section must be at least 2, got {self.samples_per_section}"
            )


@dataclasses.dataclass(frozen=True)
class RewardSpec:
    """The reward's options: the potential term (``shaping``) and a cost per step."""

    shaping: bool | str = False
    step_cost: float = 0.0

    @property
    def shaping_kind(self) -> str:
        """``""``, ``"raster"`` or ``"field"`` (``True`` is the raster)."""
        return SHAPING_KINDS[self.shaping]

    def __post_init__(self) -> None:
        if not (isinstance(self.shaping, bool | str) and self.shaping in SHAPING_KINDS):
            raise ConfigError(
                f"shaping must be false, true, 'raster' or 'field', got {self.shaping!r}"
            )
        if not (_number(self.step_cost) and 0 <= self.step_cost <= MAX_STEP_COST):
            raise ConfigError(
                f"step_cost must be in [0, {MAX_STEP_COST:g}], got {self.step_cost!r}"
            )


@dataclasses.dataclass(frozen=True)
class TrainingSpec:
    """Training-only options: how targets are drawn and how strictly they are judged."""

    target_clearance: float = 10.0
    detour_bias: float = 0.0
    corner_bias: float = 0.0
    failure_bias: float = 0.0
    slack: float = 0.0

    def __post_init__(self) -> None:
        if not 0 <= self.target_clearance < 100:
            raise ConfigError("margin must be in [0, 20) cm and target_clearance in [0, 100) cm")
        if not 0 <= self.detour_bias <= 1:
            raise ConfigError(f"detour_bias must be in [0, 1], got {self.detour_bias}")
        for name in ("corner_bias", "failure_bias"):
            value = getattr(self, name)
            if not (_number(value) and 0 <= value <= 1):
                raise ConfigError(f"{name} must be in [0, 1], got {value!r}")
            if value > 0 and self.detour_bias > 0:
                raise ConfigError(f"give detour_bias or {name}, not both")


_SPECS: tuple[type, ...] = (TaskSpec, RewardSpec, TrainingSpec)


@dataclasses.dataclass(frozen=True)
class FTLSpec:
    """Every option of an FTL env: task, reward and training-only parts."""

    task: TaskSpec = dataclasses.field(default_factory=TaskSpec)
    reward: RewardSpec = dataclasses.field(default_factory=RewardSpec)
    training: TrainingSpec = dataclasses.field(default_factory=TrainingSpec)

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> FTLSpec:
        """Route each keyword argument to its spec; an unknown one is a :class:`ConfigError`."""
        parts: list[dict[str, Any]] = [{} for _ in _SPECS]
        for key, value in kwargs.items():
            for part, spec in zip(parts, _SPECS):
                if key in _FIELDS[spec]:
                    part[key] = value
                    break
            else:
                known = ", ".join(sorted(n for s in _SPECS for n in _FIELDS[s]))
                raise ConfigError(f"unknown argument {key!r} of AFTIR-ArmFTL-v0; use {known}")
        task, reward, training = (spec(**part) for spec, part in zip(_SPECS, parts))
        return cls(task, reward, training)

    def __post_init__(self) -> None:
        slack = self.training.slack
        if not (_number(slack) and 0 <= slack < min(self.task.success_tolerance, MAX_SLACK)):
            raise ConfigError(
                f"slack must be in [0, {MAX_SLACK:g}) cm and below success_tolerance, got {slack!r}"
            )


_FIELDS: dict[type, tuple[str, ...]] = {
    spec: tuple(f.name for f in dataclasses.fields(spec)) for spec in _SPECS
}

#: Keyword arguments that only change how training draws and judges its targets: evaluations
#: go without them, so every run of an env is measured on the same targets by the same rule.
TRAINING_ONLY_KWARGS: tuple[str, ...] = _FIELDS[TrainingSpec]

#: What a config's ``env_kwargs`` may not set: the tank, the arm, a fixed target and the
#: sampling stay the registration's, so a shared config cannot point at a file.
_NOT_IN_CONFIGS = ("tank", "n_sections", "target", "samples_per_section")


def _types(annotation: Any) -> tuple[type, ...]:
    """The runtime types a config value of a field may have (an int where a float is asked)."""
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (Union, types.UnionType):
        return tuple(t for a in args for t in _types(a))
    if annotation is type(None):
        return (type(None),)
    return (int, float) if annotation is float else (annotation,)


def _config_kwarg_types() -> dict[str, tuple[type, ...]]:
    out: dict[str, tuple[type, ...]] = {}
    for spec in _SPECS:
        hints = typing.get_type_hints(spec)
        for name in _FIELDS[spec]:
            if name not in _NOT_IN_CONFIGS:
                out[name] = _types(hints[name])
    return out


#: The env keyword arguments a training config may give, with their types.
CONFIG_KWARG_TYPES: dict[str, tuple[type, ...]] = _config_kwarg_types()
