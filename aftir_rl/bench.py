"""``python -m aftir_rl.bench``: every method measured on the same fixed target sets in one run.

The planners of the papers, the learning agents and RRT-Connect.

Target sets (each target in its own tank):

- ``seed004``: seed 004 Table II's three targets, open space, ``l = 25`` cm.
- ``seed000``: seed 000 Table II's target ``[30, 18, 51]`` with 0, 1, 2 and 3 of its spherical
  obstacles (``configs/tanks/open_space*.yaml``).
- ``seed001``: seed 001 Tables 1 and 2 in the single cabin (Table 2's vertices 3 cm inside).
- ``seed002``: the four bay-2 corner targets of the reference tank (seed 002 Table 2 analogues).
- ``bay1``, ``bay2``: random free targets at least 5 cm from any surface on each side of the
  baffle of the reference tank, drawn with a fixed seed.

Methods:
- the posture planners ``blind``, ``region_clipping``, ``tga``, ``tsm``, ``obstacle_clipping``,
  ``region_division`` (:class:`~aftir_rl.posture.planner.Planner`); success is a posture that
  passes the planner's checks (forward kinematics within 0.01 cm, or within the search zone for
  ``blind`` and ``region_clipping``, which stop at the search step as in the papers; python-fcl;
  the panel rule). Blind search is not run where its grid would exceed 5·10⁷ combinations.
- ``q_table+postures`` (seed 002's pipeline): tabular Q-learning on ``AFTIR-Tank-v0``
  (``configs/q_table.yaml``), its greedy cell path, and a posture for every cell
  (:func:`~aftir_rl.posture.trajectory.plan_trajectory`); success is a complete trajectory
  (every waypoint a posture, every move collision-free when checked densely; a colliding move
  gets ``--bridge-seconds`` of RRT-Connect, :func:`~aftir_rl.posture.motion.bridge`).
- ``q_table+ftl``: the same greedy cell path turned into a follow-the-leader motion
  (:func:`~aftir_rl.motion.plan.plan_motion`); success is a complete motion whose arm keeps
  ``--margin`` (1 cm) along the whole, densely checked motion; the FTL deviation column is the
  largest distance of the body from the tip's traced curve.
- ``rrt_connect``: OMPL's RRT-Connect in joint space from the start posture (the arm straight,
  its tip at the tank's start point) to the planner's posture for the target, with our forward
  kinematics and python-fcl scene as its validity checker
  (:func:`~aftir_rl.posture.motion.rrt_connect`); success is a path that passes our dense check.
- SB3 agents, when run directories are given (``--model``): their deterministic policy in their
  own arm env, one episode per target of the reference tank's sets that lies in the region their
  env draws targets from (``AFTIR-ArmReach-v0``: in front of the panel in bay 1).

Columns: success rate, median tip error [cm], smallest clearance to the tank [cm] (for
RRT-Connect over about 50 postures sampled along the path, for Q-learning + postures over the
waypoints' postures and about 50 sampled along the whole motion, bridges included: upper
bounds), median tip
path length [cm] (for the motions: Q-learning's cell path through its postures, RRT-Connect's
densified path, the SB3 episode), median seconds per target.

"""

from __future__ import annotations

import argparse
import functools
import math
import os
import platform
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from aftir_rl.atomic import write_json
from aftir_rl.config import DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN
from aftir_rl.errors import AftirError, PlanningError
from aftir_rl.safety import cli

if TYPE_CHECKING:
    from aftir_rl.envs.arm import ArmEnv
    from aftir_rl.envs.tank_grid import TankGridEnv

__all__ = [
    "Outcome",
    "Row",
    "target_sets",
    "method_outcome",
    "run_benchmark",
    "format_table",
    "main",
]

POSTURE_METHODS = (
    "blind", "region_clipping", "tga", "tsm", "obstacle_clipping", "region_division",
)  # fmt: skip
SETS = ("seed004", "seed000", "seed001", "seed002", "bay1", "bay2")
_BLIND_LIMIT = 5e7


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
            "set": self.target_set, "method": self.method, "targets": len(ran),
            "not_run": len(self.outcomes) - len(ran),
            "success_rate": len(ok) / len(ran) if ran else math.nan,
            "tip_error_cm": median([o.tip_error_cm for o in ok]),
            "min_clearance_cm": min((o.clearance_cm for o in ok if not math.isnan(o.clearance_cm)),
                                    default=math.nan),
            "path_cm": median([o.path_cm for o in ok]),
            "ftl_deviation_cm": max((o.deviation_cm for o in ok if not math.isnan(o.deviation_cm)),
                                    default=math.nan),
            "seconds": median([o.seconds for o in ran]),
            "notes": "; ".join(notes) + ("; ..." if len(counts) > 1 else ""),
        }  # fmt: skip


def target_sets(n_random: int = 10, seed: int = 7) -> dict[str, list[tuple[str, np.ndarray]]]:
    """The fixed target sets: ``{name: [(tank, target), ...]}``."""
    from aftir_rl.posture.planner import Planner, random_free_targets
    from aftir_rl.posture.region_division import SEED001_TABLE1, SEED001_TABLE2

    obstacle_tanks = ["open_space"] + [f"open_space_obstacles{k}" for k in (1, 2, 3)]
    sets: dict[str, list[tuple[str, np.ndarray]]] = {
        "seed004": [("open_space", np.array(t, float)) for t in
                    ((11, 31, 31), (30, 19, 50), (30, 29, 67))],
        "seed000": [(tank, np.array([30.0, 18.0, 51.0])) for tank in obstacle_tanks],
        "seed001": [("single_cabin", np.array(t, float)) for t, _, _ in SEED001_TABLE1]
        + [("single_cabin", np.array(r.target, float)) for r in SEED001_TABLE2],
        "seed002": [("b737_center", np.array(t, float)) for t in
                    ((230, 140, 90), (-50, 140, 10), (-50, 72, 90), (230, 72, 10))],
    }  # fmt: skip
    drawn = random_free_targets(Planner("b737_center"), n_random, seed)
    sets["bay1"] = [("b737_center", t) for t in drawn["bay1"]]
    sets["bay2"] = [("b737_center", t) for t in drawn["bay2"]]
    return sets


METHODS_FOR = {
    "seed004": ("blind", "region_clipping", "tga", "obstacle_clipping"),
    "seed000": ("obstacle_clipping", "tga"),
    "seed001": ("region_division", "blind", "tga"),
    "seed002": ("tsm", "q_table+ftl", "q_table+postures", "rrt_connect"),
    "bay1": ("tga", "region_clipping", "blind", "obstacle_clipping", "q_table+ftl",
             "q_table+postures", "rrt_connect"),
    "bay2": ("tsm", "q_table+ftl", "q_table+postures", "rrt_connect"),
}  # fmt: skip


class _Planners:
    """One planner per tank, built once."""

    def __init__(self) -> None:
        self._cache: dict[str, Any] = {}

    def __call__(self, tank: str) -> Any:
        if tank not in self._cache:
            from aftir_rl.posture.planner import Planner

            self._cache[tank] = Planner(tank)
        return self._cache[tank]


def posture_outcome(planner: Any, target: ArrayLike, method: str) -> Outcome:
    """A posture planner on one target."""
    target = np.asarray(target, dtype=float)
    if method == "blind":
        n = math.ceil(float(np.linalg.norm(target)) / planner.arm.section_length - 1e-9)
        size = len(np.arange(-planner.arm.theta_max, planner.arm.theta_max + 1e-12,
                             planner.dtheta)) ** n  # fmt: skip
        if size > _BLIND_LIMIT:
            return Outcome(False, ran=False, note=f"blind: {n} sections, grid above 5e7")
    start = time.perf_counter()
    try:
        result = planner.plan(target, method=method)
    except PlanningError as exc:
        return Outcome(False, seconds=time.perf_counter() - start, note=_short(exc))
    p = result.posture
    return Outcome(True, result.error_cm, result.clearance_cm, math.nan,
                   time.perf_counter() - start,
                   posture=p.to_dict())  # fmt: skip


def _learned_cells(planner: Any, target: ArrayLike, seed: int) -> list[Any] | Outcome:
    """Q-learning on ``target`` and its greedy cell path, or the Outcome that says why not."""
    import gymnasium as gym

    from aftir_rl.agents.q_table import QLearning, greedy_rollout

    config = _q_table_config()
    start = time.perf_counter()
    try:
        env = gym.make(
            "AFTIR-Tank-v0", tank=planner.tank, target=tuple(np.asarray(target, dtype=float))
        )
    except AftirError as exc:
        return Outcome(False, ran=False, note=_short(exc))
    agent = QLearning.from_config(env, config, seed=seed)
    agent.learn(config.episodes)
    states, reached = greedy_rollout(agent, env)
    if not reached:
        return Outcome(False, seconds=time.perf_counter() - start, note="greedy path fails")
    raster = cast("TankGridEnv", env.unwrapped).raster
    return [raster.cell(s) for s in states]


def q_table_outcome(
    planner: Any, target: ArrayLike, seed: int = 0, bridge_seconds: float = DEFAULT_BRIDGE_SECONDS
) -> Outcome:
    """Seed 002's pipeline on one target: Q-learning, greedy path, postures along it."""
    from aftir_rl.posture.trajectory import plan_trajectory

    start = time.perf_counter()
    cells = _learned_cells(planner, target, seed)
    if isinstance(cells, Outcome):
        return cells
    points = [planner.tank.raster.cell_center(c) for c in cells]
    trajectory = plan_trajectory(planner, points, target, bridge_seconds=bridge_seconds, seed=seed)
    seconds = time.perf_counter() - start
    m = trajectory.measures(planner.scene)
    return Outcome(
        trajectory.complete,
        m["tip_error_cm"],
        m["min_clearance_cm"],
        m["path_cm"],
        seconds,
        note=trajectory.note if trajectory.blocked_moves else "",
    )


def q_table_ftl_outcome(
    planner: Any, target: ArrayLike, seed: int = 0, margin: float = DEFAULT_MARGIN
) -> Outcome:
    """Q-learning, its greedy path, and a follow-the-leader motion along it keeping ``margin``."""
    from aftir_rl.motion.plan import plan_motion

    start = time.perf_counter()
    cells = _learned_cells(planner, target, seed)
    if isinstance(cells, Outcome):
        return cells
    plan = plan_motion(planner.tank, target, cells, margin=margin)
    seconds = time.perf_counter() - start
    if not plan.complete:
        return Outcome(False, seconds=seconds, note=_short(PlanningError(plan.reason or "")))
    assert plan.tip_error_cm is not None and plan.min_clearance_cm is not None
    assert plan.tip_path_length_cm is not None and plan.ftl_deviation_cm is not None
    return Outcome(
        True, plan.tip_error_cm, plan.min_clearance_cm, plan.tip_path_length_cm, seconds,
        deviation_cm=plan.ftl_deviation_cm[0],
    )  # fmt: skip


@functools.cache
def _q_table_config() -> Any:
    """``configs/q_table.yaml``, read once per process."""
    from aftir_rl.config import CONFIG_DIR
    from aftir_rl.train import load_q_table_config

    return load_q_table_config(CONFIG_DIR / "q_table.yaml")


def rrt_outcome(planner: Any, target: ArrayLike, seconds: float = 10.0, seed: int = 0) -> Outcome:
    """RRT-Connect from the start posture to the planner's posture for ``target``."""
    from aftir_rl.posture.motion import (
        densify,
        pad_sections,
        rrt_connect,
        sampled_clearance,
        tip_path_length,
    )
    from aftir_rl.robot import Posture

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

    from aftir_rl.agents.sb3 import evaluate_policy_on_targets, load_run

    # config.json checked key by key, the model loaded without unpickling (agents.sb3.load_run)
    algo, run_config, env_id, model = load_run(run_dir)
    config = {"env_id": run_config.env_id}
    lo, hi = cast("ArmEnv", gym.make(env_id).unwrapped).target_region
    rows = []
    for name in ("seed002", "bay1", "bay2"):
        targets = [t for tank, t in sets.get(name, []) if tank == "b737_center"]
        if not targets:
            continue
        row = Row(name, f"{algo} ({config['env_id']})")
        for target in targets:
            if np.any(target < lo) or np.any(target > hi):
                row.outcomes.append(Outcome(False, ran=False, note="outside the env's targets"))
                continue
            metrics, _ = evaluate_policy_on_targets(model, env_id, [target], clearance=True)
            row.outcomes.append(Outcome(
                bool(metrics["success_rate"]), metrics["tip_error_cm"],
                metrics["min_clearance_cm"], metrics["path_length_cm"],
                metrics["seconds_per_target"],
                note="collided" if metrics["collision_rate"] else "",
            ))  # fmt: skip
        rows.append(row)
    return rows


def method_outcome(
    planner: Any,
    method: str,
    target: ArrayLike,
    seed: int = 0,
    margin: float = DEFAULT_MARGIN,
    bridge_seconds: float = DEFAULT_BRIDGE_SECONDS,
    rrt_seconds: float = 10.0,
) -> Outcome:
    """One method of :data:`METHODS_FOR` on one target (one item of the benchmark).

    OMPL's seed is restarted before each item that draws from it (``rrt_connect``, the bridges of
    ``q_table+postures``), so an outcome does not depend on what ran before it in the process:
    a serial run and a run on Ray (one task per item) give the same table.
    """
    if method in ("rrt_connect", "q_table+postures"):
        _reseed_ompl(seed)
    if method == "q_table+ftl":
        return q_table_ftl_outcome(planner, target, seed, margin)
    if method == "q_table+postures":
        return q_table_outcome(planner, target, seed, bridge_seconds)
    if method == "rrt_connect":
        return rrt_outcome(planner, target, rrt_seconds, seed)
    return posture_outcome(planner, target, method)


def _reseed_ompl(seed: int) -> None:
    """Restart OMPL's seed generator: the RNGs an item's planners create draw the same seeds."""
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)  # OMPL says seeds were drawn already; rrt_connect resets the level
    ou.RNG.setSeed(int(seed) + 1)  # OMPL takes 0 for "pick one"; rrt_connect's first seed too


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
    task (:func:`aftir_rl.distributed.benchmark_on_ray`; ``workers``: CPUs of a local Ray): the
    same rows, and a task that fails is an outcome holding its error.
    """
    table: dict[str, Sequence[str]] = dict(methods or METHODS_FOR)
    if ray is not None:
        from aftir_rl.distributed import benchmark_on_ray, ray_session

        options = {"seed": seed, "margin": margin, "bridge_seconds": bridge_seconds,
                   "rrt_seconds": rrt_seconds}  # fmt: skip
        with ray_session(ray, workers):
            return benchmark_on_ray(sets, table, options, models, progress)
    planners = _Planners()
    rows = []
    for name, items in sets.items():
        for method in table.get(name, ()):
            row = Row(name, method)
            for tank, target in items:
                planner = planners(tank)
                if progress:
                    progress(f"{name} {method} {tuple(np.round(target, 1))}")
                row.outcomes.append(method_outcome(planner, method, target, seed, margin,
                                                   bridge_seconds, rrt_seconds))  # fmt: skip
            rows.append(row)
    for run_dir in models:
        rows += sb3_outcomes(run_dir, sets)
    return rows


def _short(exc: BaseException, limit: int = 60) -> str:
    text = str(exc).replace("Cannot reach the target: ", "")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _fmt(value: float, digits: str = ".2f") -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return "–"
    return format(value, digits)


def format_table(rows: Sequence[Row]) -> str:
    """The markdown table of the README."""
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


@cli
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m aftir_rl.bench``."""
    parser = argparse.ArgumentParser(
        prog="python -m aftir_rl.bench",
        description="Measure every planner, Q-learning + postures, RRT-Connect and trained SB3 "
        "agents on the same fixed target sets; print one markdown table.",
    )
    parser.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS),
                        help="target sets to run (default: all)")  # fmt: skip
    parser.add_argument("--n-random", type=int, default=10, metavar="N",
                        help="random targets per bay (default 10)")  # fmt: skip
    parser.add_argument("--seed", type=int, default=7, help="seed of the random targets")
    parser.add_argument("--rrt-seconds", type=float, default=10.0, metavar="S",
                        help="RRT-Connect's budget per target (default 10)")  # fmt: skip
    parser.add_argument("--bridge-seconds", type=float, default=DEFAULT_BRIDGE_SECONDS,
                        metavar="S", help="RRT-Connect's budget per colliding move of a "
                        f"q_table+postures trajectory, 0 for none (default "
                        f"{DEFAULT_BRIDGE_SECONDS:g})")  # fmt: skip
    parser.add_argument(
        "--model",
        action="append",
        default=[],
        metavar="RUN_DIR",
        help="an SB3 run directory (python -m aftir_rl.train ppo|sac|td3)",
    )
    parser.add_argument("--json", metavar="PATH", help="also write every outcome as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument("--margin", type=float, default=DEFAULT_MARGIN, metavar="CM",
                        help="clearance the q_table+ftl motions keep (default "
                        f"{DEFAULT_MARGIN:g} cm)")  # fmt: skip
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run the items as Ray tasks: local (a Ray on this machine), auto or HOST:PORT (a "
        "cluster started with ray start); needs aftir_rl[ray]",
    )
    parser.add_argument(
        "--workers", type=int, metavar="N", help="CPUs of --ray local (default: every core)"
    )
    args = parser.parse_args(argv)
    if args.n_random < 1 or not 0 < args.rrt_seconds < math.inf:
        parser.error("--n-random must be at least 1 and --rrt-seconds positive and finite")
    if not 0 <= args.bridge_seconds < math.inf:
        parser.error("--bridge-seconds must be a finite 0 or more")
    if not 0 <= args.margin <= 20:
        parser.error("--margin must be between 0 and 20 cm")
    if not 0 <= args.seed < 2**32:
        parser.error("--seed must be from 0 to 2**32 - 1")
    problem = _check_inputs(args.model, args.json)
    if args.ray is not None or args.workers is not None:
        from aftir_rl.distributed import check_ray_options

        check_ray_options(args.ray, args.workers)  # one line and exit 2 (safety.cli)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    start = time.perf_counter()
    try:
        sets = {k: v for k, v in target_sets(args.n_random, args.seed).items() if k in args.sets}
        progress = None if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
        rows = run_benchmark(sets, rrt_seconds=args.rrt_seconds, models=args.model,
                             progress=progress, bridge_seconds=args.bridge_seconds,
                             margin=args.margin, ray=args.ray,
                             workers=args.workers)  # fmt: skip
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    seconds = time.perf_counter() - start
    print(f"machine: {platform.machine()}, {platform.system()}, {_cores()} cores, "
          f"Python {platform.python_version()}; {seconds:.0f} s in all")  # fmt: skip
    print()
    print(format_table(rows))
    if args.json:
        write_json(args.json, [{**r.summary(), "outcomes": [asdict(o) for o in r.outcomes]}
                               for r in rows])  # fmt: skip
    return 0


def _check_inputs(models: Sequence[str], json_path: str | None) -> str:
    """What is wrong with the run directories or the JSON path ("" if nothing), before a run."""
    for run_dir in models:
        run = Path(run_dir)
        if not (run / "model.zip").exists():
            return f"{run_dir}: no model.zip; give a run directory of python -m aftir_rl.train"
        from aftir_rl.agents.sb3 import load_run, sb3_config_from_run
        from aftir_rl.safety import read_json

        try:
            sb3_config_from_run(read_json(run / "config.json", "config.json"), str(run))
        except AftirError as exc:
            return f"{run_dir}: config.json is missing or not a training run's ({exc})"
        try:  # the model too, before any benchmark work (nothing in it is unpickled)
            load_run(run)
        except AftirError as exc:
            return str(exc)
    if json_path is not None:
        folder = Path(json_path).resolve().parent
        if not folder.is_dir() or not os.access(folder, os.W_OK):
            return f"--json {json_path}: cannot write in {folder}"
    return ""


def _cores() -> int:
    return os.cpu_count() or 1


if __name__ == "__main__":
    sys.exit(main())
