"""The arm's actuator limits: the linear module, the sections' bending, and their cables.

A tank YAML's ``arm.limits`` sets them (every key optional; defaults below); the time
parametrisation (:mod:`aftir_rl.planning.timing`) keeps every one and ``aftir check`` re-checks
them. The cable model is :mod:`aftir_rl.core.cables`; docs/robot.md explains both.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.config import brief, numbers_from_mapping
from aftir_rl.core.errors import ConfigError

__all__ = ["ActuatorLimits"]

#: The largest value any limit may take (a bound for hostile files, far above any real arm).
MAX_LIMIT = 1e6


@dataclasses.dataclass(frozen=True)
class ActuatorLimits:
    """Speed, acceleration and travel limits of the arm's actuators (cm, rad, s).

    Attributes:
        module_speed: the linear module's largest speed [cm/s].
        module_accel: its largest acceleration [cm/s²].
        bend_rate: largest rate of each bending-vector component ``κ = (θ cos φ, θ sin φ)`` of a
            section [rad/s] (``φ`` has no rate where a section is straight; ``κ`` always has).
        bend_accel: largest acceleration of each component [rad/s²].
        cable_offset: distance of every cable from the backbone [cm].
        cable_stagger_deg: each section's three cables (120° apart) are turned by this much from
            the previous section's, so that the cables of different sections do not share a path.
        cable_speed: largest rate of a cable's length change [cm/s].
        cable_accel: largest acceleration of a cable's length [cm/s²].
        cable_travel: largest change of a cable's length from the straight arm [cm].

    """

    module_speed: float = 5.0
    module_accel: float = 10.0
    bend_rate: float = 0.2
    bend_accel: float = 0.5
    cable_offset: float = 2.0
    cable_stagger_deg: float = 10.0
    cable_speed: float = 2.0
    cable_accel: float = 5.0
    cable_travel: float = 40.0

    def __post_init__(self) -> None:
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"{item.name} must be a number, got {brief(value)}")
            if item.name == "cable_stagger_deg":
                if not -360 <= value <= 360:
                    raise ConfigError(f"cable_stagger_deg must be within ±360, got {value:g}")
            elif not 0 < value <= MAX_LIMIT:
                raise ConfigError(f"{item.name} must be positive and at most 1e6, got {value:g}")

    @property
    def cable_stagger(self) -> float:
        """:attr:`cable_stagger_deg` in radians."""
        return math.radians(self.cable_stagger_deg)

    @classmethod
    def from_mapping(cls, data: Any, where: str) -> ActuatorLimits:
        """Limits from a YAML mapping (``where`` names it in errors); unknown keys are refused."""
        return numbers_from_mapping(cls, data, where, "limits", MAX_LIMIT)

    def rate_bounds(self, n_sections: int, kind: str) -> NDArray[np.float64]:
        """Speed (``kind="speed"``) or acceleration bounds, ``(1 + 5N,)``.

        In order: ``dis``, the ``2N`` bending-vector components and the ``3N`` cables.
        """
        module, bend, cable = (
            (self.module_speed, self.bend_rate, self.cable_speed)
            if kind == "speed"
            else (self.module_accel, self.bend_accel, self.cable_accel)
        )
        n = n_sections
        return np.concatenate([[module], np.full(2 * n, bend), np.full(3 * n, cable)])

    def to_json(self) -> dict[str, float]:
        """The limits as a plain mapping (the keys of ``arm.limits``)."""
        return dataclasses.asdict(self)
