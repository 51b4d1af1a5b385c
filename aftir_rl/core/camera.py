"""The tip camera: what the arm sees of the tank's surface from its tip.

A tank YAML's ``arm.camera`` sets it (every key optional; defaults below). The camera looks
along the tip's tangent; a surface point is seen when it lies within the cone of the field of
view and the range, faces the camera within the incidence limits, and nothing stands between.
docs/robot.md ("Seeing the surface") explains the model and the coverage it is used for.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.config import brief, numbers_from_mapping
from aftir_rl.core.errors import ConfigError

__all__ = ["Camera"]


@dataclasses.dataclass(frozen=True)
class Camera:
    """A camera at the tip, looking along the tip's tangent (degrees, cm).

    Attributes:
        fov_deg: full angle of the cone it sees (a borescope's 90° by default).
        range_cm: the farthest distance at which it resolves the surface.
        max_incidence_deg: the largest angle between the line of sight and the surface normal
            (grazing views beyond it resolve nothing).
        min_incidence_deg: the smallest such angle (above 0 where head-on glare blinds it).

    """

    fov_deg: float = 90.0
    range_cm: float = 100.0
    max_incidence_deg: float = 75.0
    min_incidence_deg: float = 0.0

    def __post_init__(self) -> None:
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ConfigError(f"camera.{item.name} must be a number, got {brief(value)}")
        if not 0 < self.fov_deg < 180:
            raise ConfigError(f"camera.fov_deg must be in (0, 180), got {self.fov_deg:g}")
        if not 0 < self.range_cm <= 1e5:
            raise ConfigError(f"camera.range_cm must be in (0, 1e5], got {self.range_cm:g}")
        if not 0 <= self.min_incidence_deg < self.max_incidence_deg <= 90:
            raise ConfigError(
                "camera: need 0 <= min_incidence_deg < max_incidence_deg <= 90, got "
                f"{self.min_incidence_deg:g} and {self.max_incidence_deg:g}"
            )

    @classmethod
    def from_mapping(cls, data: Any, where: str) -> Camera:
        """A camera from a YAML mapping (``where`` names it in errors); unknown keys are refused."""
        return numbers_from_mapping(cls, data, where, "camera settings", 1e5)

    def cosines(self) -> NDArray[np.float64]:
        """``(cos half fov, range, cos max incidence, cos min incidence)`` for the kernels."""
        return np.array(
            [
                math.cos(math.radians(self.fov_deg / 2)),
                self.range_cm,
                math.cos(math.radians(self.max_incidence_deg)),
                math.cos(math.radians(self.min_incidence_deg)),
            ]
        )

    def to_json(self) -> dict[str, float]:
        """The camera as a plain mapping (the keys of ``arm.camera``)."""
        return dataclasses.asdict(self)
