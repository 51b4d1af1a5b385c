"""Search spaces of ``aftir tune``: ``configs/search_spaces/<algo>.yaml``, read and checked.

A search space names hyperparameters of the algorithm's constructor, each with one
distribution (:data:`DISTRIBUTIONS`): ``{loguniform: [LOW, HIGH]}``, ``{uniform: [LOW, HIGH]}``,
``{randint: [LOW, HIGH]}`` (both included) or ``{choice: [V1, V2, ...]}``; a hyperparameter that
takes integers takes ``randint`` or a ``choice`` of integers. Every bound is checked as a config
value would be, so no trial can ask for what a config file could not (:func:`load_search_space`);
:meth:`Dimension.to_tune` gives Ray Tune's domain.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

from aftir_rl.core.config import brief, read_yaml, to_float
from aftir_rl.core.errors import ConfigError
from aftir_rl.core.shipped import find_config

__all__ = ["DISTRIBUTIONS", "MAX_KEYS", "MAX_CHOICES", "Dimension", "load_search_space"]

#: The distributions a search space may use, as ``{name: [arguments]}``.
DISTRIBUTIONS = ("loguniform", "uniform", "randint", "choice")
#: The most hyperparameters a search space may name, and the most values of one ``choice``.
MAX_KEYS, MAX_CHOICES = 32, 64


@dataclasses.dataclass(frozen=True)
class Dimension:
    """One hyperparameter of a search space.

    Attributes:
        key: the hyperparameter (an argument of the algorithm's constructor).
        kind: one of :data:`DISTRIBUTIONS`.
        values: ``(low, high)`` for the ranges, the values for ``choice``.

    """

    key: str
    kind: str
    values: tuple[Any, ...]

    def extremes(self) -> tuple[Any, ...]:
        """The values that bound what this dimension can sample (each is checked)."""
        return self.values

    def to_tune(self) -> Any:
        """The Ray Tune domain (``tune.loguniform``...)."""
        from ray import tune

        if self.kind == "loguniform":
            return tune.loguniform(*self.values)
        if self.kind == "uniform":
            return tune.uniform(*self.values)
        if self.kind == "randint":
            return tune.randint(self.values[0], self.values[1] + 1)  # tune's upper is excluded
        return tune.choice(list(self.values))


def _number(value: Any, where: str, integer: bool) -> float | int:
    number = to_float(value, where)
    if integer:
        if not float(number).is_integer():
            raise ConfigError(f"{where}: expected an integer, got {brief(value)}")
        return int(number)
    return number


def _dimension(key: str, spec: object, where: str) -> Dimension:
    if not isinstance(spec, dict) or len(spec) != 1:
        raise ConfigError(
            f"{where}: expected one distribution ({', '.join(DISTRIBUTIONS)}), e.g. "
            f"{{loguniform: [1.0e-5, 1.0e-3]}}, got {brief(spec)}"
        )
    ((kind, args),) = spec.items()
    if kind not in DISTRIBUTIONS:
        raise ConfigError(
            f"{where}: unknown distribution {brief(kind)}; use one of {', '.join(DISTRIBUTIONS)}"
        )
    if not isinstance(args, list):
        raise ConfigError(f"{where}.{kind}: expected a list, got {brief(args)}")
    if kind == "choice":
        if not 1 <= len(args) <= MAX_CHOICES:
            raise ConfigError(f"{where}.choice: expected 1 to {MAX_CHOICES} values")
        values = []
        for i, v in enumerate(args):
            if v is not None and not isinstance(v, (bool, int, float, str)):
                raise ConfigError(f"{where}.choice[{i}]: expected a plain value, got {brief(v)}")
            if isinstance(v, str):
                try:
                    v = to_float(v, where)
                except ConfigError:
                    pass
            values.append(v)
        if len(set(map(repr, values))) != len(values):
            raise ConfigError(f"{where}.choice: a value is repeated")
        return Dimension(key, kind, tuple(values))
    if len(args) != 2:
        raise ConfigError(f"{where}.{kind}: expected [LOW, HIGH], got {brief(args)}")
    lo, hi = (_number(v, f"{where}.{kind}", kind == "randint") for v in args)
    if lo > hi or (lo == hi and kind != "randint"):
        raise ConfigError(f"{where}.{kind}: LOW must be below HIGH, got {brief(args)}")
    if kind == "loguniform" and lo <= 0:
        raise ConfigError(f"{where}.loguniform: LOW must be above 0, got {brief(args)}")
    return Dimension(key, kind, (lo, hi))


def _typed(dim: Dimension, where: str, integer: bool) -> Dimension:
    """``dim`` checked against its hyperparameter's type: integers need whole numbers.

    Raises:
        ConfigError: ``uniform`` or ``loguniform`` (they draw fractions), or a ``choice`` that is
            not a whole number, for a hyperparameter that takes integers.

    """
    if not integer:
        return dim
    if dim.kind in ("uniform", "loguniform"):
        raise ConfigError(
            f"{where}: {dim.key} takes integers, and {dim.kind} draws fractions; use "
            "{randint: [LOW, HIGH]} or {choice: [...]} of integers"
        )
    if dim.kind != "choice":
        return dim
    for i, v in enumerate(dim.values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not float(v).is_integer():
            raise ConfigError(f"{where}.choice[{i}]: {dim.key} takes integers, got {brief(v)}")
    return dataclasses.replace(dim, values=tuple(int(v) for v in dim.values))


def load_search_space(path: str | os.PathLike[str], algo: str, base: Any) -> list[Dimension]:
    """Read and check a search space YAML for ``algo`` against the base config ``base``.

    Every bound (``LOW``, ``HIGH``, each ``choice``) is put into ``base`` and checked as a config
    value would be (:func:`aftir_rl.rl.sb3.check_sb3_config`), so no trial can ask for what a
    config file could not.

    Raises:
        ConfigError: naming the file and the key.

    """
    from aftir_rl.rl.sb3.config import INTEGER_KEYS, OBJECT_KEYS, check_sb3_config, constructor_keys

    path = find_config(path, "search_spaces")
    data = read_yaml(path)
    unknown = sorted(set(data) - {"hyperparameters"}, key=str)
    if unknown:
        raise ConfigError(f"{path}: unknown key {brief(unknown[0])}; allowed key: hyperparameters")
    hyper = data.get("hyperparameters")
    if not isinstance(hyper, dict) or not 1 <= len(hyper) <= MAX_KEYS:
        raise ConfigError(f"{path}: hyperparameters: expected a mapping of 1 to {MAX_KEYS} keys")
    allowed = constructor_keys(algo) - set(OBJECT_KEYS) - {"policy_kwargs", "device"}
    space = []
    for key, spec in hyper.items():
        if not isinstance(key, str) or key not in allowed:
            raise ConfigError(
                f"{path}: hyperparameters: unknown key {brief(key)} for {algo.upper()}; allowed "
                f"keys are {', '.join(sorted(allowed))}"
            )
        where = f"{path}: hyperparameters.{key}"
        dim = _typed(_dimension(key, spec, where), where, key in INTEGER_KEYS)
        for value in dim.extremes():
            trial = dataclasses.replace(base, hyperparameters={**base.hyperparameters, key: value})
            check_sb3_config(trial, algo, f"{path} ({dim.kind} bound)")
        space.append(dim)
    return space
