"""``python -m aftir_rl.bench``: every method measured on the same fixed target sets in one run.

The posture planners of the papers (:data:`aftir_rl.planning.posture.registry.REGISTRY`), the
Q-learning pipelines (``q_table+postures``, ``q_table+ftl``), RRT-Connect (``rrt_connect``) and,
with ``--model``, trained SB3 agents, on target sets named after the papers (``jace``,
``icra2014``, ``st2014``, ``filomat2018``) and random targets on each side of the baffle
(``bay1``, ``bay2``). One row per (set, method): success rate, median tip error, least clearance,
median tip path length and seconds per target. The sets, what success means for each method and
what each column measures: docs/reference.md, "The benchmark"; the latest table:
docs/benchmarks.md, "Comparing every method".
"""

from __future__ import annotations

import json
import math
import os
import platform
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aftir_rl.core import papers
from aftir_rl.core.config import DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN
from aftir_rl.core.extras import require
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank.raster import format_point
from aftir_rl.experiments.outcomes import Outcome, Planners, Row, method_outcome, needs_ompl
from aftir_rl.experiments.outcomes import sb3_outcomes as sb3_outcomes
from aftir_rl.planning.posture.registry import REGISTRY

__all__ = [
    "Outcome",
    "Row",
    "target_sets",
    "write_results",
    "method_outcome",
    "run_benchmark",
    "format_table",
    "machine_facts",
    "env_steps_per_second",
]

POSTURE_METHODS = tuple(REGISTRY)
SETS = ("jace", "icra2014", "st2014", "filomat2018", "bay1", "bay2")
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
        "filomat2018": points(DEFAULT_TANK, [r.target for r in papers.FILOMAT2018_TABLE2]),
    }
    drawn = random_free_targets(Planner(DEFAULT_TANK), n_random, seed)
    sets["bay1"] = [(DEFAULT_TANK, t) for t in drawn["bay1"]]
    sets["bay2"] = [(DEFAULT_TANK, t) for t in drawn["bay2"]]
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
    Ray): the same rows, and a task that fails is an outcome holding its error.

    Raises:
        MissingExtraError: a chosen method needs OMPL and it is not installed (before any work).

    """
    table: dict[str, Sequence[str]] = dict(methods or METHODS_FOR)
    chosen = {m for name in sets for m in table.get(name, ())}
    if any(needs_ompl(m, bridge_seconds) for m in chosen):
        require("ompl.util", "ompl")
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
                    progress(f"{name} {method} {format_point(target)}")
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


def machine_facts() -> dict[str, Any]:
    """What a measurement ran on: CPU model, cores, Python, the package's version, torch threads.

    Written beside every benchmark's numbers (``--json``), since the same run is up to five
    times faster on one machine than on another. ``torch_threads`` only when torch is loaded.
    """
    from aftir_rl import __version__

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next(
                (ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), cpu
            )
    except OSError:
        pass
    facts: dict[str, Any] = {
        "cpu": cpu,
        "machine": platform.machine(),
        "system": platform.system(),
        "cores": os.cpu_count() or 1,
        "python": platform.python_version(),
        "aftir_rl": __version__,
    }
    if "torch" in sys.modules:
        facts["torch_threads"] = sys.modules["torch"].get_num_threads()
    return facts


def env_steps_per_second(env_id: str, steps: int, **kwargs: Any) -> float:
    """Random-action steps per second of ``gym.make(env_id, **kwargs)``, resets included.

    The benchmarks' yardstick is ``env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8",
    is_slippery=False)``: the same run on two machines differs by up to five times, so a
    measurement states it beside its own numbers. The actions are drawn (seed 0) before timing.
    """
    import time

    import gymnasium as gym

    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    seconds = time.perf_counter() - start
    env.close()
    return steps / seconds


def write_results(path: str | None, options: Any, rows: list[dict[str, Any]]) -> None:
    """Print the machine below a benchmark's table; with ``path``, write the JSON too.

    The file holds ``{machine, options, rows}`` (``options``: the script's parsed arguments).
    """
    machine = machine_facts()
    print(machine)
    if path:
        out = {"machine": machine, "options": vars(options), "rows": rows}
        Path(path).write_text(json.dumps(out, indent=1))
