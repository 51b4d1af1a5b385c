"""The four papers this project comes from, and their reference tables, by short name.

- ``icra2014``: *Collision Free Path Planning Based on Region Clipping* (ICRA 2014).
- ``st2014``: *Path planning based on region division* (Sensors & Transducers, 2014).
- ``filomat2018``: *Path Planning Based on Q-learning and Three-segment Method* (Filomat, 2018).
- ``jace``: *Dimension Reduction and Region Clipping* (J. Autom. Control Eng.).

The tables hold the numbers as the papers print them (angles in rad or deg as printed, lengths in
cm, times in s of the papers' machines), and, where we plan for other points, ours beside them.
Tests, benchmarks, ``python -m aftir_rl.bench`` and the notebooks read them from here.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "Paper",
    "PAPERS",
    "paper",
    "ICRA2014_TARGET",
    "ICRA2014_OBSTACLES",
    "ICRA2014_TANKS",
    "ICRA2014_TABLE2",
    "IcraRow",
    "ST2014_TABLE1",
    "ST2014_TABLE2",
    "RegionDivisionRow",
    "FILOMAT2018_TABLE2",
    "TsmRow",
    "JACE_TABLE2",
    "JaceRow",
    "SearchRow",
]

Point = tuple[float, float, float]


@dataclass(frozen=True)
class Paper:
    """One source paper.

    Attributes:
        short: the short name used in code, CLI set names and the README.
        title: the paper's title.
        venue: where it appeared.
        gives: what this project takes from it.

    """

    short: str
    title: str
    venue: str
    gives: str


PAPERS: tuple[Paper, ...] = (
    Paper(
        "icra2014",
        "Collision Free Path Planning Based on Region Clipping",
        "ICRA 2014",
        "obstacle zones, projection strategy, region clipping with collision detection, Table II",
    ),
    Paper(
        "st2014",
        "Path planning based on region division",
        "Sensors & Transducers 2014",
        "single-cabin tank 361.7 x 97 x 86 cm, numerical methods I-III, Tables 1-2",
    ),
    Paper(
        "filomat2018",
        "Path Planning Based on Q-learning and Three-segment Method",
        "Filomat 2018",
        "15 x 10 x 5 raster, +-100 rewards, Q-learning, TGA + TSM, Table 2",
    ),
    Paper(
        "jace",
        "Dimension Reduction and Region Clipping",
        "J. Autom. Control Eng.",
        "dimension reduction, region clipping, MDS, blind-search comparison Table II",
    ),
)


def paper(short: str) -> Paper:
    """The paper of a short name.

    Raises:
        KeyError: no such paper.

    """
    for p in PAPERS:
        if p.short == short:
            return p
    raise KeyError(f"no paper {short!r}; the papers are {', '.join(p.short for p in PAPERS)}")


# --------------------------------------------------------------------------------------------
# icra2014: collision-free region clipping among spherical obstacles (l = 25 cm, open space)

ICRA2014_TARGET: Point = (30.0, 18.0, 51.0)
"""The target of Table II [cm]."""
ICRA2014_OBSTACLES: tuple[Point, ...] = (
    (3.90, 2.25, 5.45),
    (6.15, 10.67, 23.86),
    (21.34, 14.93, 43.35),
)
"""Centres of the spherical obstacles of §IV (radius ``r0 = 2`` cm), added one by one [cm]."""
ICRA2014_TANKS: tuple[str, ...] = (
    "open_space",
    "open_space_obstacles1",
    "open_space_obstacles2",
    "open_space_obstacles3",
)
"""Our tanks for Table II's rows (a)-(d): 0, 1, 2 and 3 of the obstacles."""


@dataclass(frozen=True)
class IcraRow:
    """One posture of icra2014 Table II.

    Attributes:
        theta: bending angles [rad].
        phi: rotation angles [rad].
        dis: rising distance [cm].
        tip: the tip as printed [cm].

    """

    theta: tuple[float, ...]
    phi: tuple[float, ...]
    dis: float
    tip: Point


ICRA2014_TABLE2: tuple[IcraRow, ...] = (
    IcraRow((0.62, -0.15, 0.32), (0.54, 0.54, 0.54), -13.99, (30.01, 18.01, 51.00)),
    IcraRow((0.49, 0.65, -0.10), (1.22, 6.00, 6.79), -11.34, (30.03, 17.95, 51.00)),
    IcraRow((0.71, 0.96, 0.57), (1.35, 5.41, 1.44), -9.57, (30.02, 17.94, 51.00)),
    IcraRow((0.60, 1.07, 1.13), (1.42, 6.24, 3.99), -7.08, (29.95, 17.97, 51.00)),
)
"""icra2014 Table II, rows (a)-(d): the postures found with 0 to 3 obstacles."""


# --------------------------------------------------------------------------------------------
# st2014: region division in the single cabin (l = 25 cm)


@dataclass(frozen=True)
class RegionDivisionRow:
    """One row of st2014 Table 2, with the target we plan for.

    Attributes:
        paper_target: the target as printed [cm].
        target: ours: coordinates on a wall pulled 3 cm inside (arm radius + 0.5) [cm].
        method: numerical method, "I", "II" or "III".
        rotation_deg: rotation angle ϕ [deg].
        bend_deg: bending angle θ [deg].
        descending_cm: descending distance [cm].
        joints: number of joints needed.

    """

    paper_target: Point
    target: Point
    method: str
    rotation_deg: float
    bend_deg: float
    descending_cm: float
    joints: int


ST2014_TABLE2: tuple[RegionDivisionRow, ...] = (
    RegionDivisionRow((-60, 42.5, 0), (-57, 39.5, 3), "II", 144.7, 128.8, 7.4, 5),
    RegionDivisionRow((-60, -43.5, 0), (-57, -40.5, 3), "II", 215.9, 127.5, 7.7, 5),
    RegionDivisionRow((-60, -43.5, 97), (-57, -40.5, 94), "I", 215.9, 80.2, -9.0, 5),
    RegionDivisionRow((-60, 42.5, 97), (-57, 39.5, 94), "III", 144.7, 79.1, -9.0, 14),
    RegionDivisionRow((301.7, -43.5, 0), (298.7, -40.5, 3), "III", 8.02, 71.7, 6.6, 14),
    RegionDivisionRow((301.7, 42.5, 0), (298.7, 39.5, 3), "III", -81.0, 71.4, 6.8, 14),
    RegionDivisionRow((301.7, -43.5, 97), (298.7, -40.5, 94), "III", -81.0, -71.4, -8.3, 14),
    RegionDivisionRow((301.7, 42.5, 97), (298.7, 39.5, 94), "III", 8.0, -71.4, -8.1, 14),
    RegionDivisionRow((60, 23, 75), (60, 23, 75), "I", 21.0, 91.4, -12.3, 4),
)
"""st2014 Table 2: the eight tank vertices and one arbitrary point."""

ST2014_TABLE1: tuple[tuple[Point, float, float], ...] = (
    ((30, 30, 30), 52.333, 0.208),
    ((42, 12, 26), 54.211, 0.206),
    ((17, 26, 35), 61.826, 0.156),
)
"""st2014 Table 1: target [cm], blind search [s], region division [s] (Matlab, 2014)."""


# --------------------------------------------------------------------------------------------
# filomat2018: TSM through the hatch (l = 50 cm)


@dataclass(frozen=True)
class TsmRow:
    """One row of filomat2018 Table 2, at our analogue of its target.

    Attributes:
        target: ours: 10 cm inside a corner of bay 2 of ``b737_center`` (the paper's targets
            were 5 cm inside its tank's corners) [cm].
        sections: the paper's number of sections.
        error_cm: the paper's tip error [cm].
        seconds: the paper's planning time [s].

    """

    target: Point
    sections: int
    error_cm: float
    seconds: float


FILOMAT2018_TABLE2: tuple[TsmRow, ...] = (
    TsmRow((230, 140, 90), 8, 1.33, 2.441),
    TsmRow((-50, 140, 10), 9, 2.45, 3.452),
    TsmRow((-50, 72, 90), 8, 1.11, 2.427),
    TsmRow((230, 72, 10), 7, 0.82, 1.853),
)
"""filomat2018 Table 2, beside the reference targets of the two-bay tank."""


# --------------------------------------------------------------------------------------------
# jace: blind search (type A) against region clipping (type B), l = 25 cm, open space


@dataclass(frozen=True)
class SearchRow:
    """One search of jace Table II.

    Attributes:
        theta: bending angles [rad].
        dis: rising distance ``d`` [cm].
        evaluations: combinations evaluated (the paper's "loops").
        seconds: the paper's time [s].

    """

    theta: tuple[float, ...]
    dis: float
    evaluations: float
    seconds: float


@dataclass(frozen=True)
class JaceRow:
    """One target of jace Table II: its sections, blind search (A) and region clipping (B)."""

    sections: int
    target: Point
    blind: SearchRow
    clipping: SearchRow


JACE_TABLE2: tuple[JaceRow, ...] = (
    JaceRow(
        2,
        (11, 31, 31),
        SearchRow((1.27, -0.82), -3.51, 8.8e3, 0.58),
        SearchRow((1.22, -0.64), -3.58, 3.0e2, 0.09),
    ),
    JaceRow(
        3,
        (30, 19, 50),
        SearchRow((0.53, 0.17, -0.12), -14.18, 3.3e5, 26.62),
        SearchRow((0.53, 0.21, -0.25), -14.39, 6.0e3, 0.96),
    ),
    JaceRow(
        4,
        (30, 29, 67),
        SearchRow((0.24, 0.54, -0.42, 0.40), -20.91, 1.7e7, 31 * 60),
        SearchRow((0.21, 0.66, -0.55, 0.46), -20.61, 4.0e4, 6.88),
    ),
)
"""jace Table II (dimension reduction: every ``φ_i`` is the target's bearing)."""
