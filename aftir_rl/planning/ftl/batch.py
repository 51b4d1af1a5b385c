"""Many follow-the-leader motions in one call: :func:`plan_motions`.

Each target is planned by :func:`~aftir_rl.planning.ftl.plan.plan_motion`; the tank's compiled
kernels, clearance grid and guide edges are built once and shared by every target. With
``workers > 1`` the targets are split over that many processes (spawned, so safe beside torch
or Ray in the caller), each of which builds them once; a script that asks for workers must do
so under ``if __name__ == "__main__":``, as for any spawned process.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from tqdm import tqdm

from aftir_rl.core.config import DEFAULT_MARGIN
from aftir_rl.core.errors import ConfigError, PlanningError
from aftir_rl.core.tank import Tank
from aftir_rl.planning.ftl.plan import MotionPlan, plan_motion

__all__ = ["plan_motions"]

#: Targets a worker plans per task (fewer round trips, still balanced).
CHUNK = 8

CellPath = Sequence[Sequence[int]]


def plan_motions(
    tank: Tank,
    targets: ArrayLike,
    cells: Sequence[CellPath | None] | None = None,
    margin: float = DEFAULT_MARGIN,
    workers: int = 1,
    progress: bool = False,
) -> list[MotionPlan]:
    """Plan a motion to each of ``targets (T, 3)`` [cm]; the plans in the targets' order.

    Args:
        tank: the tank.
        targets: the targets [cm], shape ``(T, 3)``.
        cells: per target the learned cell path to guide its route, or None (none for any).
        margin: clearance [cm] the arm's surface keeps along every motion.
        workers: processes to plan in (1: this one; 0: one per core).
        progress: show a progress bar.

    Raises:
        ConfigError: ``targets`` is not ``(T, 3)`` and finite, ``cells`` has another length,
            or ``workers`` is negative.
        PlanningError: a worker process stopped (e.g. a script without the main guard).

    """
    points = np.asarray(targets, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.isfinite(points).all():
        raise ConfigError(f"targets must be finite points of shape (T, 3), got {points.shape}")
    paths: list[CellPath | None] = list(cells) if cells is not None else [None] * len(points)
    if len(paths) != len(points):
        raise ConfigError(f"cells has {len(paths)} paths for {len(points)} targets")
    if workers < 0:
        raise ConfigError(f"workers must be 0 (one per core) or more, got {workers}")
    workers = workers or (os.cpu_count() or 1)
    jobs = [(points[i], paths[i]) for i in range(len(points))]
    bar = tqdm(total=len(jobs), desc="motions", disable=not progress, leave=False)
    if workers == 1 or len(jobs) <= 1:
        plans = []
        for target, path in jobs:
            plans.append(plan_motion(tank, target, path, margin=margin))
            bar.update()
        bar.close()
        return plans
    chunks = [jobs[i : i + CHUNK] for i in range(0, len(jobs), CHUNK)]
    out: list[MotionPlan] = []
    context = get_context("spawn")
    try:
        with ProcessPoolExecutor(workers, context, _start, (tank, margin)) as pool:
            for part in pool.map(_plan_chunk, chunks):
                out.extend(part)
                bar.update(len(part))
    except BrokenProcessPool:
        raise PlanningError(
            "a planning process stopped before it finished; from a script, call plan_motions "
            'with workers other than 1 inside `if __name__ == "__main__":` (each worker '
            "imports the script again)"
        ) from None
    finally:
        bar.close()
    return out


_WORKER: dict[str, Any] = {}


def _start(tank: Tank, margin: float) -> None:
    """A worker's set-up: its tank and margin, one thread (the processes share the cores)."""
    import numba

    numba.set_num_threads(1)
    _WORKER.update(tank=tank, margin=margin)


def _plan_chunk(jobs: list[tuple[np.ndarray, CellPath | None]]) -> list[MotionPlan]:
    """Plan one chunk of ``(target, cells)`` in a worker."""
    tank, margin = _WORKER["tank"], _WORKER["margin"]
    return [plan_motion(tank, target, path, margin=margin) for target, path in jobs]
