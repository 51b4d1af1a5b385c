"""The arm's body as an elastic rod: its mass and stiffnesses, for the physics check.

A tank YAML's ``arm.rod`` sets them (every key optional; defaults below, SI units: kg, m, N, s).
The physics check (:mod:`aftir_rl.experiments.physics`) builds a Cosserat rod with the arm's
section length and radius and these properties, and re-runs a timed motion on it under gravity.

No data sheet of the AFTIR arm is public, so the defaults are an assumption stated once here and
in docs/robot.md ("Physics"): the body of a thin-walled aluminium tube of the arm's diameter
(5 cm) with 1 mm walls (E = 70 GPa, G = 26 GPa, second moment of area 4.6e-8 m⁴, wall area
1.54e-4 m²), carrying vertebrae, cables and the camera's line (1.5 kg/m in all). A real
continuum arm's stiffness comes from its backbone and its cables' tension; the docs' table says
how stiff each measured motion needs it to be.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from aftir_rl.core.config import brief, numbers_from_mapping
from aftir_rl.core.errors import ConfigError

__all__ = ["RodProperties"]

#: The largest value any property may take (a bound for hostile files: 1e12 N is far above any
#: arm's axial stiffness).
MAX_PROPERTY = 1e12


@dataclasses.dataclass(frozen=True)
class RodProperties:
    """Mass and stiffness of the arm's body (SI units), and the gravity it is under.

    Attributes:
        mass_per_length: the body's mass per metre [kg/m].
        bending_stiffness: ``E·I`` about either axis across the body [N·m²].
        twist_stiffness: ``G·J`` about the body's axis [N·m²].
        shear_stiffness: ``α·G·A``, across the body [N].
        axial_stiffness: ``E·A``, along it [N].
        gravity: the acceleration of gravity [m/s²], along −z of frame S (the access panel is
            in the tank's floor, ``z`` points up); 0 turns it off.

    """

    mass_per_length: float = 1.5
    bending_stiffness: float = 3000.0
    twist_stiffness: float = 2400.0
    shear_stiffness: float = 2.0e6
    axial_stiffness: float = 1.08e7
    gravity: float = 9.81

    def __post_init__(self) -> None:
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"rod.{item.name} must be a number, got {brief(value)}")
            low_ok = value >= 0 if item.name == "gravity" else value > 0
            if not (low_ok and value <= MAX_PROPERTY):
                sign = "not negative" if item.name == "gravity" else "positive"
                raise ConfigError(f"rod.{item.name} must be {sign} and at most 1e12, got {value:g}")

    @classmethod
    def from_mapping(cls, data: Any, where: str) -> RodProperties:
        """Properties from a YAML mapping (``where`` names it in errors); unknown keys refused."""
        return numbers_from_mapping(cls, data, where, "rod properties", MAX_PROPERTY)

    def scaled(self, stiffness: float) -> RodProperties:
        """The same body with every stiffness multiplied by ``stiffness``."""
        return dataclasses.replace(
            self,
            bending_stiffness=self.bending_stiffness * stiffness,
            twist_stiffness=self.twist_stiffness * stiffness,
            shear_stiffness=self.shear_stiffness * stiffness,
            axial_stiffness=self.axial_stiffness * stiffness,
        )

    def to_json(self) -> dict[str, float]:
        """The properties as a plain mapping (the keys of ``arm.rod``)."""
        return dataclasses.asdict(self)
