"""Generated wing tanks: a row of bays between ribs with holes, stringers and pipes, by seed.

:func:`wing_tank` draws a wing box from :class:`WingRanges` with a seeded generator and returns
it as the mapping a tank YAML holds (:func:`~aftir_rl.core.tank.loading.tank_from_mapping` reads
it; ``aftir tank generate`` writes it). The span runs along x, the chord along y; the access
panel is in the floor of bay 1. Every rib has one access hole (oval or rectangular) on a chain
near the middle of the chord, and lightening holes (circles) beside it; the box tapers in depth
and chord toward the tip; stringers run along the span on the floor, a pipe under the ceiling.
The same seed gives the same tank. Ranges and how reachability is kept: docs/tanks.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError

__all__ = [
    "FAMILIES",
    "MAX_BAYS",
    "MAX_SEED",
    "MIX_BAYS",
    "WingRanges",
    "generated_tank",
    "mixed_kind",
    "wing_family_box",
    "wing_tank",
]

#: Most bays of a generated wing tank (12 sections of 50 cm reach about five).
MAX_BAYS = 8
#: The largest seed of a generated tank (``aftir tank generate --seed``, ``wing:BAYS:SEED``).
MAX_SEED = 2**32 - 1


@dataclass(frozen=True)
class WingRanges:
    """The ranges a wing tank is drawn from [cm]; each ``(low, high)`` is drawn uniformly.

    Sizes are multiples of :attr:`cell_size` where the raster needs it (box, bay lengths).
    """

    bay_length: tuple[float, float] = (80.0, 110.0)
    chord: tuple[float, float] = (140.0, 200.0)
    depth: tuple[float, float] = (80.0, 100.0)
    rib_thickness: tuple[float, float] = (2.0, 4.0)
    access_width: tuple[float, float] = (36.0, 50.0)
    access_height: tuple[float, float] = (32.0, 44.0)
    access_offset: float = 12.0
    access_shapes: tuple[str, ...] = ("oval", "rect")
    lightening_diameter: tuple[float, float] = (14.0, 26.0)
    lightening_holes: tuple[int, int] = (0, 3)
    stringers: tuple[int, int] = (1, 3)
    pipe_radius: tuple[float, float] = (3.0, 5.0)
    #: the tip's depth and chord as fractions of the root's (the box tapers linearly along x)
    taper_depth: tuple[float, float] = (0.8, 1.0)
    taper_chord: tuple[float, float] = (0.85, 1.0)
    cell_size: float = 10.0
    panel_radius: float = 12.0


#: The generator's families by name (the first word of a spec ``FAMILY:BAYS:SEED``): ``wing``
#: draws every default range; ``round`` gives every rib an oval access hole and tries 2 or 3
#: lightening holes beside it (those that fit), so the only ways through are round.
FAMILIES: dict[str, WingRanges] = {
    "wing": WingRanges(),
    "round": WingRanges(access_shapes=("oval",), lightening_holes=(2, 3)),
}
#: The bays a mixed stream ``mix:FIRST+`` draws its wings with (each count alike).
MIX_BAYS = (2, 5)


def generated_tank(family: str, bays: int, seed: int) -> dict[str, Any]:
    """The tank ``FAMILY:BAYS:SEED`` as a tank YAML mapping, named after its family.

    Raises:
        ConfigError: a family not in :data:`FAMILIES`, or what :func:`wing_tank` refuses.

    """
    if family not in FAMILIES:
        raise ConfigError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")
    data = wing_tank(bays, seed, FAMILIES[family])
    if family != "wing":
        data["name"] = f"{family}_{bays}bay_s{seed}"
        data["description"] = data["description"].replace("wing tank", f"{family}-holed wing tank")
    return data


def mixed_kind(seed: int) -> tuple[str, int]:
    """The family and bays of a mixed stream's wing ``seed``: each family and count alike.

    Drawn from ``seed`` alone, so a mixed stream's wing is the same whoever draws it.
    """
    rng = np.random.default_rng([int(seed), 0])
    family = sorted(FAMILIES)[int(rng.integers(len(FAMILIES)))]
    return family, int(rng.integers(MIX_BAYS[0], MIX_BAYS[1] + 1))


def _round_to(value: float, step: float) -> float:
    return float(max(step, round(value / step) * step))


def _ribs(
    rng: np.random.Generator,
    r: WingRanges,
    xs: list[float],
    section: Callable[[float], tuple[float, float]],
) -> list[dict[str, Any]]:
    """The ribs at ``xs``: an access hole near the chord's middle, lightening holes beside.

    ``section(x)`` is the half chord and the depth at ``x`` (the box tapers).
    """
    ribs = []
    for i, x in enumerate(xs):
        half_chord, depth = section(x)
        w, h = rng.uniform(*r.access_width), min(rng.uniform(*r.access_height), depth - 24.0)
        cy = rng.uniform(-r.access_offset, r.access_offset)
        cz = rng.uniform(depth / 2 - 6.0, depth / 2 + 6.0)
        shape = r.access_shapes[int(rng.random() * len(r.access_shapes))]
        holes: list[dict[str, Any]] = [
            {"shape": shape, "center": [x, round(cy, 2), round(cz, 2)],
             "width": round(w, 2), "height": round(h, 2)}
        ]  # fmt: skip
        taken = [(cy - w / 2 - 4, cy + w / 2 + 4)]
        for _ in range(int(rng.integers(r.lightening_holes[0], r.lightening_holes[1] + 1))):
            d = rng.uniform(*r.lightening_diameter)
            y = rng.uniform(-half_chord + d / 2 + 6, half_chord - d / 2 - 6)
            if any(lo - d / 2 < y < hi + d / 2 for lo, hi in taken):
                continue
            taken.append((y - d / 2 - 4, y + d / 2 + 4))
            holes.append({"shape": "circle", "center": [x, round(y, 2), round(cz, 2)],
                          "diameter": round(d, 2)})  # fmt: skip
        thickness = round(rng.uniform(*r.rib_thickness), 2)
        ribs.append(
            {"name": f"rib_{i + 1}", "axis": "x", "position": x, "thickness": thickness,
             "holes": holes}
        )  # fmt: skip
    return ribs


def _obstacles(
    rng: np.random.Generator,
    r: WingRanges,
    lo: list[float],
    hi: list[float],
    ribs: list[dict[str, Any]],
    tip: tuple[float, float],
) -> list[dict[str, Any]]:
    """Stringers on the floor away from the panel; a pipe under the tip's ceiling.

    ``tip`` is the half chord and depth at the tip: both run straight along the span inside it.
    The pipe keeps beside the ribs' access holes; where they leave it no room, there is none.
    """
    half_chord, depth = tip
    out: list[dict[str, Any]] = []
    access = [(h["center"][1] - h["width"] / 2, h["center"][1] + h["width"] / 2)
              for rib in ribs for h in rib["holes"][:1]]  # fmt: skip
    # the pipe keeps off the ribs' access holes (a one-bay wing has none: off the middle)
    low = min((a for a, _ in access), default=0.0) - 6
    high = max((b for _, b in access), default=0.0) + 6
    for where, z0, z1 in (("floor", 0.0, 5.0),):
        for j in range(int(rng.integers(r.stringers[0], r.stringers[1] + 1))):
            y = rng.uniform(-half_chord + 8, half_chord - 8)
            if abs(y) < r.panel_radius + 10:
                continue
            y0, y1 = round(y - 1.5, 2), round(y + 1.5, 2)
            out.append(
                {"name": f"stringer_{where}_{j + 1}", "type": "box", "min": [lo[0], y0, z0],
                 "max": [hi[0], y1, z1]}
            )  # fmt: skip
    radius = rng.uniform(*r.pipe_radius)
    side = 1.0 if rng.random() < 0.5 else -1.0
    near, far = max(abs(low), abs(high)) + radius + 4, half_chord - radius - 6
    if near > far:  # the access holes leave no room beside them at the tip: no pipe
        return out
    y = side * rng.uniform(near, far)
    z = depth - radius - 8
    out.append({"name": "fuel_pipe", "type": "cylinder", "p0": [lo[0], round(y, 2), round(z, 2)],
                "p1": [hi[0], round(y, 2), round(z, 2)], "radius": round(radius, 2)})  # fmt: skip
    return out


def wing_tank(bays: int, seed: int, ranges: WingRanges | None = None) -> dict[str, Any]:
    """A wing tank of ``bays`` bays drawn with ``seed`` from ``ranges``, as a tank YAML mapping.

    ``ranges`` (default ``FAMILIES["wing"]``): :data:`FAMILIES` names the ones specs use.

    Raises:
        ConfigError: ``bays`` outside 1..:data:`MAX_BAYS`, or ``seed`` outside 0..:data:`MAX_SEED`.

    """
    if not 1 <= int(bays) <= MAX_BAYS:
        raise ConfigError(f"bays: a wing tank has 1 to {MAX_BAYS} bays, got {bays}")
    if not 0 <= int(seed) <= MAX_SEED:
        raise ConfigError(f"seed: a wing tank's seed is from 0 to {MAX_SEED:,}, got {seed}")
    r = ranges or WingRanges()
    rng = np.random.default_rng([int(seed), int(bays)])
    step = r.cell_size
    lengths = [_round_to(rng.uniform(*r.bay_length), step) for _ in range(bays)]
    chord = _round_to(rng.uniform(*r.chord), 2 * step)
    depth = _round_to(rng.uniform(*r.depth), step)
    x0 = -_round_to(lengths[0] / 2, step)
    lo = [x0, -chord / 2, 0.0]
    hi = [x0 + sum(lengths), chord / 2, depth]
    # ribs in the middle of a cell: one column of cells each on the raster, not two
    xs = [x0 + float(np.sum(lengths[: i + 1])) + step / 2 for i in range(bays - 1)]
    tip_chord = round(chord / 2 * rng.uniform(*r.taper_chord), 2)
    tip_depth = round(depth * rng.uniform(*r.taper_depth), 2)

    def section(x: float) -> tuple[float, float]:
        t = (x - lo[0]) / (hi[0] - lo[0])
        return chord / 2 + t * (tip_chord - chord / 2), depth + t * (tip_depth - depth)

    ribs = _ribs(rng, r, xs, section)
    obstacles = _obstacles(rng, r, lo, hi, ribs, (tip_chord, tip_depth))
    middles = [lo[0] + 15.0] + [(a + b) / 2 for a, b in zip(xs, [*xs[1:], hi[0]])]
    targets = [[round(x, 2), 0.0, round(section(x)[1] / 2, 2)] for x in middles]
    return {
        "name": f"wing_{bays}bay_s{seed}",
        "description": f"Generated wing tank: {bays} bays, seed {seed} (aftir tank generate)",
        "box": {"min": lo, "max": hi},
        "cell_size": step,
        "panel": {"center": [0.0, 0.0, 0.0], "radius": r.panel_radius},
        "start_point": [0.0, 0.0, 10.0],
        "baffles": ribs,
        "taper": {"along": "x", "end": {"min": [-tip_chord, 0.0], "max": [tip_chord, tip_depth]}},
        "obstacles": obstacles,
        "arm": {"section_length": 50, "max_sections": 12, "radius": 2.5, "theta_max": 1.5708},
        "targets": targets,
    }


def wing_family_box(
    bays: int, ranges: WingRanges | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Corners [cm] of a box that holds every wing tank of ``bays`` bays, whatever its seed.

    From the ranges' largest bay length, chord and depth (each rounded up by a cell): what a
    stream of generated tanks needs to fix its goal space before it has drawn them.
    """
    r = ranges or WingRanges()
    step = r.cell_size
    length, chord, depth = r.bay_length[1] + step, r.chord[1] + 2 * step, r.depth[1] + step
    lo = np.array([-(length / 2 + step), -chord / 2, 0.0])
    hi = np.array([bays * length, chord / 2, depth])
    return lo, hi


def ranges_json(ranges: WingRanges | None = None) -> dict[str, Any]:
    """The ranges as plain data (docs, a run's record)."""
    return asdict(ranges or WingRanges())
