"""``python -m aftir_rl.bench``: every method measured on the same fixed target sets in one run.

The planners of the papers (:mod:`aftir_rl.core.papers`), the learning agents and RRT-Connect.

Target sets (each target in its own tank), named after the papers:

- ``jace``: jace Table II's three targets, open space, ``l = 25`` cm.
- ``icra2014``: icra2014 Table II's target ``[30, 18, 51]`` with 0, 1, 2 and 3 of its spherical
  obstacles (``configs/tanks/open_space*.yaml``).
- ``st2014``: st2014 Tables 1 and 2 in the single cabin (Table 2's vertices 3 cm inside).
- ``filomat2018``: the four bay-2 corner targets of the reference tank (filomat2018 Table 2
  analogues).
- ``bay1``, ``bay2``: random free targets at least 5 cm from any surface on each side of the
  baffle of the reference tank, drawn with a fixed seed.

The methods:

- the posture planners of :data:`aftir_rl.planning.posture.registry.REGISTRY`, each on the sets it
  names
  (a set named after a paper lists that paper's methods first); success is a posture that
  passes the planner's checks (forward kinematics within 0.01 cm, or within the search zone for
  ``blind`` and ``region_clipping``, which stop at the search step as in the papers; python-fcl;
  the panel rule). Blind search is not run where its grid would exceed
  :data:`~aftir_rl.planning.posture.search.BLIND_LIMIT` (5·10⁷) combinations.
- ``q_table+postures`` (filomat2018's pipeline): tabular Q-learning on ``AFTIR-Tank-v0``
  (``configs/q_table.yaml``), its greedy cell path, and a posture for every cell
  (:func:`~aftir_rl.planning.posture.trajectory.plan_trajectory`); success is a complete trajectory
  (every waypoint a posture, every move collision-free when checked densely; a colliding move
  gets ``--bridge-seconds`` of RRT-Connect, :func:`~aftir_rl.planning.jointspace.bridge`).
- ``q_table+ftl``: the same greedy cell path turned into a follow-the-leader motion
  (:func:`~aftir_rl.planning.ftl.plan.plan_motion`); success is a complete motion whose arm keeps
  ``--margin`` (1 cm) along the whole, densely checked motion; the FTL deviation column is the
  largest distance of the body from the tip's traced curve.
- ``rrt_connect``: OMPL's RRT-Connect in joint space from the start posture (the arm straight,
  its tip at the tank's start point) to the planner's posture for the target, with our forward
  kinematics and python-fcl scene as its validity checker
  (:func:`~aftir_rl.planning.jointspace.rrt_connect`); success is a path that passes our dense
  check.
- SB3 agents, when run directories are given (``--model``): their deterministic policy in their
  own arm env, one episode per target of the reference tank's sets that lies in the region their
  env draws targets from (``AFTIR-ArmReach-v0``: in front of the panel in bay 1).

Columns: success rate, median tip error [cm], smallest clearance to the tank [cm] (for
RRT-Connect over about 50 postures sampled along the path, for Q-learning + postures over the
waypoints' postures and about 50 sampled along the whole motion, bridges included: upper
bounds), median tip path length [cm] (for the motions: Q-learning's cell path through its
postures, RRT-Connect's densified path, the SB3 episode), median seconds per target.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aftir_rl.core import papers
from aftir_rl.core.config import DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN
from aftir_rl.experiments.outcomes import Outcome, Planners, Row, method_outcome
from aftir_rl.experiments.outcomes import sb3_outcomes as sb3_outcomes
from aftir_rl.planning.posture.registry import REGISTRY

__all__ = [
    "Outcome",
    "Row",
    "target_sets",
    "method_outcome",
    "run_benchmark",
    "format_table",
]

POSTURE_METHODS = tuple(REGISTRY)
SETS = ("jace", "icra2014", "st2014", "filomat2018", "bay1", "bay2")
# The sets' former names (by the papers' file numbers), still accepted, not shown.
OLD_SET_NAMES = {
    "seed004": "jace",
    "seed000": "icra2014",
    "seed001": "st2014",
    "seed002": "filomat2018",
}
PIPELINES = {
    "q_table+ftl": ("filomat2018", "bay1", "bay2"),
    "q_table+postures": ("filomat2018", "bay1", "bay2"),
    "rrt_connect": ("filomat2018", "bay1", "bay2"),
}
"""The methods that are not posture planners, and the sets they run on."""


def methods_for(target_set: str) -> tuple[str, ...]:
    """The methods run on a target set.

    The registered posture methods that name it (its own paper's first, then in the registry's
    order), then the pipelines.
    """
    posture = [m for m in REGISTRY.values() if target_set in m.bench_sets]
    posture.sort(key=lambda m: m.paper != target_set)  # stable: the registry's order otherwise
    pipelines = [name for name, sets in PIPELINES.items() if target_set in sets]
    return tuple(m.name for m in posture) + tuple(pipelines)


METHODS_FOR = {name: methods_for(name) for name in SETS}
"""The methods of every target set."""


def target_sets(n_random: int = 10, seed: int = 7) -> dict[str, list[tuple[str, np.ndarray]]]:
    """The fixed target sets: ``{name: [(tank, target), ...]}``."""
    from aftir_rl.planning.posture.planner import Planner, random_free_targets

    def points(tank: str, targets: Sequence[Sequence[float]]) -> list[tuple[str, np.ndarray]]:
        return [(tank, np.array(t, float)) for t in targets]

    st2014 = [t for t, _, _ in papers.ST2014_TABLE1] + [r.target for r in papers.ST2014_TABLE2]
    sets = {
        "jace": points("open_space", [r.target for r in papers.JACE_TABLE2]),
        "icra2014": [(tank, np.array(papers.ICRA2014_TARGET)) for tank in papers.ICRA2014_TANKS],
        "st2014": points("single_cabin", st2014),
        "filomat2018": points("b737_center", [r.target for r in papers.FILOMAT2018_TABLE2]),
    }
    drawn = random_free_targets(Planner("b737_center"), n_random, seed)
    sets["bay1"] = [("b737_center", t) for t in drawn["bay1"]]
    sets["bay2"] = [("b737_center", t) for t in drawn["bay2"]]
    return sets


def run_benchmark(
    sets: dict[str, list[tuple[str, np.ndarray]]],
    methods: dict[str, Sequence[str]] | None = None,
    rrt_seconds: float = 10.0,
    seed: int = 0,
    models: Sequence[str | Path] = (),
    bridge_seconds: float = DEFAULT_BRIDGE_SECONDS,
    progress: Callable[[str], None] | None = None,
    margin: float = DEFAULT_MARGIN,
    ray: str | None = None,
    workers: int | None = None,
) -> list[Row]:
    """Run every method of ``methods`` (default :data:`METHODS_FOR`) on its target sets.

    With ``ray`` (``local``, ``auto`` or ``HOST:PORT``), every (set, method, target) is a Ray
    task (:func:`aftir_rl.experiments.distributed.benchmark_on_ray`; ``workers``: CPUs of a local
    Ray): the
    same rows, and a task that fails is an outcome holding its error.
    """
    table: dict[str, Sequence[str]] = dict(methods or METHODS_FOR)
    options: dict[str, Any] = {
        "seed": seed,
        "margin": margin,
        "bridge_seconds": bridge_seconds,
        "rrt_seconds": rrt_seconds,
    }
    if ray is not None:
        from aftir_rl.experiments.distributed import benchmark_on_ray, ray_session

        with ray_session(ray, workers):
            return benchmark_on_ray(sets, table, options, models, progress)
    planners = Planners()
    rows = []
    for name, items in sets.items():
        for method in table.get(name, ()):
            row = Row(name, method)
            for tank, target in items:
                planner = planners(tank)
                if progress:
                    progress(f"{name} {method} {tuple(np.round(target, 1))}")
                row.outcomes.append(method_outcome(planner, method, target, **options))
            rows.append(row)
    for run_dir in models:
        rows += sb3_outcomes(run_dir, sets)
    return rows


def _fmt(value: float, digits: str = ".2f") -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return "–"
    return format(value, digits)


def format_table(rows: Sequence[Row]) -> str:
    """The markdown table of docs/benchmarks.md."""
    lines = [
        "| set | method | targets | success | tip error (cm) | min clearance (cm) | "
        "FTL deviation (cm) | path (cm) | s / target | note |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in rows:
        s = row.summary()
        targets = f"{s['targets']}" + (f" (+{s['not_run']} not run)" if s["not_run"] else "")
        lines.append(
            f"| {s['set']} | {s['method']} | {targets} | {_fmt(100 * s['success_rate'], '.0f')}% "
            f"| {_fmt(s['tip_error_cm'], '.2g')} | {_fmt(s['min_clearance_cm'])} | "
            f"{_fmt(s['ftl_deviation_cm'])} | {_fmt(s['path_cm'], '.0f')} | "
            f"{_fmt(s['seconds'], '.3f')} | {s['notes']} |"
        )
    return "\n".join(lines)
