"""The options of ``AFTIR-ArmFTL-v0`` as frozen dataclasses, built from keyword arguments once.

An env is composed of three parts, each built from the spec that lives beside it: the arm's
state (:class:`~aftir_rl.envs.ftl.state.FTLBatch`, from
:class:`~aftir_rl.envs.ftl.state.TaskSpec`: the tank, the arm, the task and what the policy
observes), the reward (:class:`~aftir_rl.envs.ftl.reward.FTLReward`, from
:class:`~aftir_rl.envs.ftl.reward.RewardSpec`) and the target sampler
(:class:`~aftir_rl.envs.ftl.targets.TargetSampler`, from
:class:`~aftir_rl.envs.ftl.targets.TrainingSpec`: training-only, evaluations drop it).
:meth:`FTLSpec.from_kwargs` routes each keyword of ``gym.make`` to its spec and checks what
needs no tank; :data:`TRAINING_ONLY_KWARGS`, :data:`MOTION_FREE_KWARGS` and
:data:`CONFIG_KWARG_TYPES` are derived from the fields. The arguments are described in
:class:`~aftir_rl.envs.ftl.env.ArmFTLEnv`.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any, Union

from aftir_rl.core.errors import ConfigError, UnexpectedArgumentError
from aftir_rl.envs.ftl.reward import MAX_STEP_COST, SHAPING_KINDS, RewardSpec
from aftir_rl.envs.ftl.state import STEER_MODES, TaskSpec
from aftir_rl.envs.ftl.targets import TrainingSpec

__all__ = [
    "CONFIG_KWARG_TYPES",
    "MAX_SLACK",
    "MAX_STEP_COST",
    "MOTION_FREE_KWARGS",
    "SHAPING_KINDS",
    "STEER_MODES",
    "TRAINING_ONLY_KWARGS",
    "FTLSpec",
    "RewardSpec",
    "TaskSpec",
    "TrainingSpec",
]

#: ``slack`` stays below this [cm] (and below ``success_tolerance``).
MAX_SLACK = 5.0


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


_SPECS: tuple[type, ...] = (TaskSpec, RewardSpec, TrainingSpec)


@dataclasses.dataclass(frozen=True)
class FTLSpec:
    """Every option of an FTL env: task, reward and training-only parts."""

    task: TaskSpec = dataclasses.field(default_factory=TaskSpec)
    reward: RewardSpec = dataclasses.field(default_factory=RewardSpec)
    training: TrainingSpec = dataclasses.field(default_factory=TrainingSpec)

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> FTLSpec:
        """Route each keyword argument to its spec.

        An unknown one is an :class:`UnexpectedArgumentError`, a :class:`ConfigError` and a
        ``TypeError``.
        """
        parts: list[dict[str, Any]] = [{} for _ in _SPECS]
        for key, value in kwargs.items():
            for part, spec in zip(parts, _SPECS):
                if key in _FIELDS[spec]:
                    part[key] = value
                    break
            else:
                known = ", ".join(sorted(n for s in _SPECS for n in _FIELDS[s]))
                raise UnexpectedArgumentError(
                    f"unexpected keyword argument {key!r} of AFTIR-ArmFTL-v0; use {known}"
                )
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

#: Keyword arguments that leave the arm's motion under given actions as it is: what the policy
#: observes or aims at, the reward and training's options. A replay of actions drops them.
MOTION_FREE_KWARGS: tuple[str, ...] = (
    tuple(f.name for f in dataclasses.fields(TaskSpec) if f.metadata.get("motion_free"))
    + _FIELDS[RewardSpec]
    + TRAINING_ONLY_KWARGS
)

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
