"""One benchmarked method on one target: what ``python -m aftir_rl.bench`` tabulates.

:func:`method_outcome` runs a posture method of :data:`aftir_rl.planning.posture.registry.REGISTRY`,
the Q-learning pipelines (``q_table+postures``, ``q_table+ftl``) or RRT-Connect (``rrt_connect``) on
one target; :func:`sb3_outcomes` an SB3 run's policy on the reference tank's targets. The methods
and the target sets are described in :mod:`aftir_rl.experiments.bench`.
"""

from __future__ import annotations

import functools
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.core.config import CONFIG_DIR, DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN
from aftir_rl.core.errors import AftirError, PlanningError
from aftir_rl.core.extras import require
from aftir_rl.core.robot import Posture
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.experiments.runs import load_q_table_config, load_sb3_run
from aftir_rl.planning.posture.registry import get_method
from aftir_rl.rl.tabular.paths import learn_cells

if TYPE_CHECKING:
    from aftir_rl.envs.ftl.env import ArmFTLEnv

__all__ = [
    "Outcome",
    "Row",
    "method_outcome",
    "needs_ompl",
    "posture_outcome",
    "q_table_outcome",
    "q_table_ftl_outcome",
    "rrt_outcome",
    "sb3_outcomes",
]


@dataclass
class Outcome:
    """One method on one target.

    Attributes:
        success: reached, by the method's own definition (module docstring).
        tip_error_cm: tip to target [cm] (nan when nothing was produced).
        clearance_cm: smallest distance of the body to the tank [cm] (nan if unknown).
        path_cm: tip path length [cm] of a motion (nan for a single posture).
        seconds: wall time.
        ran: False when the method was not run on this target (the note says why).
        note: what went wrong, or a remark.
        posture: the posture found, ``{"dis", "theta", "phi"}`` (posture planners only).

    """

    success: bool
    tip_error_cm: float = math.nan
    clearance_cm: float = math.nan
    path_cm: float = math.nan
    seconds: float = 0.0
    ran: bool = True
    note: str = ""
    posture: dict[str, Any] | None = None
    deviation_cm: float = math.nan


@dataclass
class Row:
    """A method on a target set: its outcomes and their summary."""

    target_set: str
    method: str
    outcomes: list[Outcome] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """Success rate and medians over the targets it ran on."""
        ran = [o for o in self.outcomes if o.ran]
        ok = [o for o in ran if o.success]

        def median(values: list[float]) -> float:
            values = [v for v in values if not math.isnan(v)]
            return float(np.median(values)) if values else math.nan

        counts = Counter(o.note for o in self.outcomes if o.note)
        notes = [f"{n} ({k}x)" if k > 1 else n for n, k in counts.most_common(1)]
        return {
            "set": self.target_set,
            "method": self.method,
            "targets": len(ran),
            "not_run": len(self.outcomes) - len(ran),
            "success_rate": len(ok) / len(ran) if ran else math.nan,
            "tip_error_cm": median([o.tip_error_cm for o in ok]),
            "min_clearance_cm": min(
                (o.clearance_cm for o in ok if not math.isnan(o.clearance_cm)), default=math.nan
            ),
            "path_cm": median([o.path_cm for o in ok]),
            "ftl_deviation_cm": max(
                (o.deviation_cm for o in ok if not math.isnan(o.deviation_cm)), default=math.nan
            ),
            "seconds": median([o.seconds for o in ran]),
            "notes": "; ".join(notes) + ("; ..." if len(counts) > 1 else ""),
        }


class Planners:
    """One planner per tank, built once."""

    def __init__(self) -> None:
        self._cache: dict[str, Any] = {}

    def __call__(self, tank: str) -> Any:
        if tank not in self._cache:
            from aftir_rl.planning.posture.planner import Planner

            self._cache[tank] = Planner(tank)
        return self._cache[tank]


def posture_outcome(planner: Any, target: ArrayLike, method: str) -> Outcome:
    """A posture planner on one target."""
    target = np.asarray(target, dtype=float)
    skip = get_method(method).unavailable(planner, target)
    if skip:
        return Outcome(False, ran=False, note=skip)
    start = time.perf_counter()
    try:
        result = planner.plan(target, method=method)
    except PlanningError as exc:
        return Outcome(False, seconds=time.perf_counter() - start, note=_short(exc))
    seconds = time.perf_counter() - start
    posture = result.posture.to_dict()
    return Outcome(True, result.error_cm, result.clearance_cm, seconds=seconds, posture=posture)


def _after_learning(
    planner: Any, target: ArrayLike, seed: int, finish: Callable[[list[Any], float], Outcome]
) -> Outcome:
    """Q-learning on ``target``, then ``finish(cells, start)`` on its greedy cell path.

    The Outcome that says why not when the target cannot be learned or the greedy path fails.
    """
    start = time.perf_counter()
    try:
        cells, reached = learn_cells(planner.tank, target, _q_table_config(), seed)
    except AftirError as exc:
        return Outcome(False, ran=False, note=_short(exc))
    if not reached:
        return Outcome(False, seconds=time.perf_counter() - start, note="greedy path fails")
    return finish(cells, start)


def q_table_outcome(
    planner: Any, target: ArrayLike, seed: int = 0, bridge_seconds: float = DEFAULT_BRIDGE_SECONDS
) -> Outcome:
    """filomat2018's pipeline on one target: Q-learning, greedy path, postures along it."""
    from aftir_rl.planning.posture.trajectory import plan_trajectory

    def postures(cells: list[Any], start: float) -> Outcome:
        points = [planner.tank.raster.cell_center(c) for c in cells]
        trajectory = plan_trajectory(
            planner, points, target, bridge_seconds=bridge_seconds, seed=seed
        )
        seconds = time.perf_counter() - start
        m = trajectory.measures(planner.scene)
        note = trajectory.note if trajectory.blocked_moves else ""
        path = m["path_cm"]
        return Outcome(
            trajectory.complete, m["tip_error_cm"], m["min_clearance_cm"], path, seconds, note=note
        )

    return _after_learning(planner, target, seed, postures)


def q_table_ftl_outcome(
    planner: Any, target: ArrayLike, seed: int = 0, margin: float = DEFAULT_MARGIN
) -> Outcome:
    """Q-learning, its greedy path, and a follow-the-leader motion along it keeping ``margin``."""
    from aftir_rl.planning.ftl.plan import plan_motion

    def motion(cells: list[Any], start: float) -> Outcome:
        plan = plan_motion(planner.tank, target, cells, margin=margin)
        seconds = time.perf_counter() - start
        if not plan.complete:
            return Outcome(False, seconds=seconds, note=_short(PlanningError(plan.reason or "")))
        assert plan.tip_error_cm is not None and plan.min_clearance_cm is not None
        assert plan.tip_path_length_cm is not None and plan.ftl_deviation_cm is not None
        tip, clearance, path = plan.tip_error_cm, plan.min_clearance_cm, plan.tip_path_length_cm
        deviation = plan.ftl_deviation_cm[0]
        return Outcome(True, tip, clearance, path, seconds, deviation_cm=deviation)

    return _after_learning(planner, target, seed, motion)


@functools.cache
def _q_table_config() -> Any:
    """``configs/q_table.yaml``, read once per process."""
    return load_q_table_config(CONFIG_DIR / "q_table.yaml")


def rrt_outcome(planner: Any, target: ArrayLike, seconds: float = 10.0, seed: int = 0) -> Outcome:
    """RRT-Connect from the start posture to the planner's posture for ``target``."""
    from aftir_rl.planning.jointspace import (
        densify,
        pad_sections,
        rrt_connect,
        sampled_clearance,
        tip_path_length,
    )

    try:
        goal = planner.plan(target)
    except PlanningError as exc:
        return Outcome(False, ran=False, note="no goal posture: " + _short(exc))
    l, n = planner.arm.section_length, goal.posture.n_sections
    height = planner.tank.start_point[2] - planner.tank.panel.center[2]
    start = Posture(height - n * l, (0.0,) * n, (goal.posture.phi[0],) * n)
    plan = rrt_connect(planner.scene, start, pad_sections(goal.posture, n, l), seconds, seed=seed)
    if not plan.solved:
        return Outcome(False, seconds=plan.seconds, note=plan.reason)
    clearance = sampled_clearance(planner.scene, plan.postures)
    path = tip_path_length(densify(plan.postures), l)
    return Outcome(True, goal.error_cm, clearance, path, plan.seconds)


def sb3_outcomes(run_dir: str | Path, sets: dict[str, list[tuple[str, np.ndarray]]]) -> list[Row]:
    """An SB3 run's deterministic policy on the reference tank's targets in its env's region.

    Targets outside the region the env draws its targets from (``target_region``) are not run.
    """
    import gymnasium as gym

    from aftir_rl.rl.sb3 import evaluate_policy_on_targets

    run = load_sb3_run(run_dir)
    env_id, model = run.env_id, run.model
    kwargs = dict(run.config.env_kwargs or {})  # the env the model was trained on (spaces)
    env = gym.make(env_id, **kwargs).unwrapped
    # where the env draws its targets: ArmEnv's target_region, the FTL env's (bay) region
    lo, hi = getattr(env, "target_region", None) or cast("ArmFTLEnv", env).sampler.region
    rows = []
    for name in ("filomat2018", "bay1", "bay2"):
        targets = [t for tank, t in sets.get(name, []) if tank == DEFAULT_TANK]
        if not targets:
            continue
        row = Row(name, f"{run.algo} ({run.config.env_id})")
        for target in targets:
            if np.any(target < lo) or np.any(target > hi):
                row.outcomes.append(Outcome(False, ran=False, note="outside the env's targets"))
                continue
            metrics, _ = evaluate_policy_on_targets(
                model, env_id, [target], clearance=True, env_kwargs=kwargs
            )
            row.outcomes.append(
                Outcome(
                    bool(metrics["success_rate"]),
                    metrics["tip_error_cm"],
                    metrics["min_clearance_cm"],
                    metrics["path_length_cm"],
                    metrics["seconds_per_target"],
                    note="collided" if metrics["collision_rate"] else "",
                )
            )
        rows.append(row)
    return rows


def method_outcome(
    planner: Any,
    method: str,
    target: ArrayLike,
    *,
    seed: int = 0,
    margin: float = DEFAULT_MARGIN,
    bridge_seconds: float = DEFAULT_BRIDGE_SECONDS,
    rrt_seconds: float = 10.0,
) -> Outcome:
    """One method of :data:`~aftir_rl.experiments.bench.METHODS_FOR` on one target (one item).

    OMPL's seed is restarted before each item that draws from it (``rrt_connect``, the bridges of
    ``q_table+postures``), so an outcome does not depend on what ran before it in the process:
    a serial run and a run on Ray (one task per item) give the same table.
    """
    if needs_ompl(method, bridge_seconds):
        _reseed_ompl(seed)
    if method == "q_table+ftl":
        return q_table_ftl_outcome(planner, target, seed, margin)
    if method == "q_table+postures":
        return q_table_outcome(planner, target, seed, bridge_seconds)
    if method == "rrt_connect":
        return rrt_outcome(planner, target, rrt_seconds, seed)
    return posture_outcome(planner, target, method)


def needs_ompl(method: str, bridge_seconds: float) -> bool:
    """Whether ``method`` runs OMPL (RRT-Connect, or the postures' bridges when they have time)."""
    return method == "rrt_connect" or (method == "q_table+postures" and bridge_seconds > 0)


def _reseed_ompl(seed: int) -> None:
    """Restart OMPL's seed generator: the RNGs an item's planners create draw the same seeds."""
    ou = require("ompl.util", "ompl")
    ou.setLogLevel(ou.LOG_NONE)  # OMPL says seeds were drawn already; rrt_connect resets the level
    ou.RNG.setSeed(int(seed) + 1)  # OMPL takes 0 for "pick one"; rrt_connect's first seed too


def _short(exc: BaseException, limit: int = 60) -> str:
    text = str(exc).replace("Cannot reach the target: ", "")
    return text if len(text) <= limit else text[: limit - 3] + "..."
