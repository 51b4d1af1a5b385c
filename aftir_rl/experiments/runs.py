"""A run directory of any kind: load it, replay its greedy policy, measure what it does.

The kinds (:func:`run_kind`; their files: docs/design.md §9): ``q_table`` (``q_table.npz``, one
target, :func:`load_q_table_run`), ``q_table_goal`` (``q_table_goal.npz``, every reachable cell,
:func:`load_goal_run`), ``sb3`` (``model.zip`` with ``config.json``, :func:`load_sb3_run`:
the config checked key by key, the model loaded without unpickling) and ``rllib``
(``rllib.json`` with ``config.json``, :func:`load_rllib_run`: the same config, the weights read
as tensors only). :func:`load_policy_run` loads either policy run.

The workflow shared by ``train``, ``evaluate`` and ``bench``: a tabular agent's greedy cells
(:func:`greedy_cells`, :func:`learn_cells`) become a follow-the-leader motion
(:func:`aftir_rl.planning.ftl.plan.plan_motion`, summarised by :func:`motion_summary`) or the
papers' postures per cell (:func:`aftir_rl.planning.posture.trajectory.plan_trajectory`);
:func:`evaluate_run` gives the measures of one run directory. Environment ids read from a file
or a config are checked before anything is made (:func:`check_env_id`): no module is imported.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from aftir_rl.core.config import DEFAULT_MARGIN, from_mapping, read_yaml
from aftir_rl.core.errors import CheckpointError, ConfigError
from aftir_rl.core.files import run_file
from aftir_rl.core.shipped import DEFAULT_TANK, find_config
from aftir_rl.core.tank.loading import resolve_run_tank
from aftir_rl.envs.registration import ARM_FTL, bare_env_id
from aftir_rl.rl.tabular.paths import greedy_cells

if TYPE_CHECKING:
    import gymnasium as gym
    from stable_baselines3.common.base_class import BaseAlgorithm

    from aftir_rl.envs.tank_grid import TankGridEnv
    from aftir_rl.rl.sb3.config import SB3Config
    from aftir_rl.rl.tabular.q_table import QLearning
    from aftir_rl.rl.tabular.q_table_goal import GoalQLearning

__all__ = [
    "QTableRun",
    "GoalRun",
    "SB3Run",
    "load_q_table_config",
    "run_kind",
    "load_run",
    "load_q_table_run",
    "load_goal_run",
    "load_sb3_run",
    "load_rllib_run",
    "load_policy_run",
    "evaluate_run",
]

#: The file that marks each kind of run directory.
RUN_FILES = {
    "q_table": "q_table.npz",
    "q_table_goal": "q_table_goal.npz",
    "sb3": "model.zip",
    "rllib": "rllib.json",
}


def load_q_table_config(path: str | Path) -> Any:
    """Read a config (a path, or a shipped name such as ``q_table``) into a ``QLearningConfig``."""
    from aftir_rl.rl.tabular.q_table import QLearningConfig

    path = find_config(path)
    return from_mapping(QLearningConfig, read_yaml(path), str(path))


# ---------------------------------------------------------------- loading


@dataclass
class QTableRun:
    """A ``q_table`` run: the agent in the env of the target it was trained for."""

    run_dir: Path
    agent: QLearning
    env: gym.Env[Any, Any]
    target: list[float]


@dataclass
class GoalRun:
    """A ``q_table_goal`` run: one goal-conditioned agent for every reachable cell."""

    run_dir: Path
    agent: GoalQLearning
    env: gym.Env[Any, Any]


@dataclass
class SB3Run:
    """An ``sb3`` run: its algorithm, checked config, ``aftir_rl:``-prefixed env id and model.

    An ``rllib`` run loads as one too (:func:`load_rllib_run`): ``model`` is then its policy
    with SB3's ``predict`` and ``library`` is ``"rllib"``.
    """

    run_dir: Path
    algo: str
    config: SB3Config
    env_id: str
    model: BaseAlgorithm
    library: str = "sb3"


def run_kind(run_dir: str | Path) -> str | None:
    """``"q_table"``, ``"sb3"``, ``"rllib"``, ``"q_table_goal"`` or None (not a run directory)."""
    run = Path(run_dir)
    if (run / RUN_FILES["q_table"]).exists():
        return "q_table"
    if (run / RUN_FILES["rllib"]).exists() and (run / "config.json").exists():
        return "rllib"
    if (run / RUN_FILES["sb3"]).exists() and (run / "config.json").exists():
        return "sb3"
    if (run / RUN_FILES["q_table_goal"]).exists():
        return "q_table_goal"
    return None


def load_run(
    run_dir: str | Path, kinds: Sequence[str] = ("q_table", "sb3", "q_table_goal")
) -> QTableRun | GoalRun | SB3Run:
    """Load a run directory of one of ``kinds``.

    Raises:
        CheckpointError: not a run directory of those kinds, or unreadable files.

    """
    run = Path(run_dir)
    kind = run_kind(run)
    if kind is None or kind not in kinds:
        files = " nor ".join(
            f"{RUN_FILES[k]} with config.json" if k in ("sb3", "rllib") else RUN_FILES[k]
            for k in kinds
        )
        raise CheckpointError(f"{run}: not a run directory (no {files})")
    loaders: dict[str, Callable[[Path], QTableRun | GoalRun | SB3Run]]
    loaders = {
        "q_table": load_q_table_run,
        "sb3": load_sb3_run,
        "rllib": load_rllib_run,
        "q_table_goal": load_goal_run,
    }
    return loaders[kind](run)


def load_q_table_run(run_dir: str | Path) -> QTableRun:
    """The Q-table of a run and the env of its target (its metadata's env id, tank, target)."""
    import gymnasium as gym

    from aftir_rl.rl.tabular.q_table import QLearning

    path = run_file(run_dir, RUN_FILES["q_table"])
    _, meta = QLearning.read_checkpoint(path)  # the env id checked (rl.tabular.checkpoint)
    target = meta.get("target")
    if target is None:
        raise CheckpointError(f"{run_dir}: the Q-table has no target in its metadata")
    env = gym.make(
        meta.get("env_id", "AFTIR-Tank-v0"),
        tank=resolve_run_tank(meta.get("tank", DEFAULT_TANK), run_dir),
        target=tuple(target),
    )
    return QTableRun(Path(run_dir), QLearning.load(path, env), env, list(target))


def load_goal_run(run_dir: str | Path) -> GoalRun:
    """The goal-conditioned Q-table of an ``--all-targets`` run, in an env of its tank."""
    import gymnasium as gym

    from aftir_rl.rl.tabular.q_table_goal import GoalQLearning

    path = run_file(run_dir, RUN_FILES["q_table_goal"])
    _, _, meta = GoalQLearning.read_checkpoint(path)
    config = meta.get("config")
    tank = meta.get("tank") or (config.get("tank") if isinstance(config, dict) else None)
    env = gym.make("AFTIR-TankGoal-v0", tank=resolve_run_tank(tank or DEFAULT_TANK, run_dir))
    return GoalRun(Path(run_dir), GoalQLearning.load(path, env), env)


def load_sb3_run(run_dir: str | Path) -> SB3Run:
    """An SB3 run (``config.json`` checked key by key, the model loaded without unpickling)."""
    from aftir_rl.rl.sb3 import load_run as load_sb3

    algo, config, env_id, model = load_sb3(run_dir)
    return SB3Run(Path(run_dir), algo, config, env_id, model)


def load_rllib_run(run_dir: str | Path) -> SB3Run:
    """An RLlib run (``aftir train ppo --rllib``), its ``model`` with SB3's ``predict``.

    The config is checked as an SB3 run's, the policy's weights read as tensors only.

    Raises:
        CheckpointError: unreadable files.
        ConfigError: RLlib (``aftir_rl[rllib]``) is not installed.

    """
    from aftir_rl.rl.rllib.train import load_rllib_run as load

    algo, config, env_id, policy = load(run_dir)
    model = cast("BaseAlgorithm", policy)  # only its predict is called
    return SB3Run(Path(run_dir), algo, config, env_id, model, "rllib")


def load_policy_run(run_dir: str | Path) -> SB3Run:
    """An SB3 or RLlib run directory: ``aftir rollout`` and ``record`` replay its policy.

    Raises:
        CheckpointError: neither, or unreadable files.

    """
    return cast(SB3Run, load_run(run_dir, ("sb3", "rllib")))


# ---------------------------------------------------------------- measuring


def _evaluate_q_table(run: QTableRun, motion: str, margin: float) -> dict[str, Any]:
    from aftir_rl.planning.posture import Planner
    from aftir_rl.planning.posture.trajectory import plan_trajectory

    start = time.perf_counter()
    cells, reached = greedy_cells(run.agent, run.env)
    grid = cast("TankGridEnv", run.env.unwrapped)
    if motion == "ftl":
        from aftir_rl.planning.ftl.plan import plan_motion

        plan = plan_motion(grid.tank, run.target, cells, margin=margin)
        nan = float("nan")
        return {
            "agent": "q_table + FTL motion",
            "targets": 1,
            "success_rate": float(reached and plan.complete),
            "tip_error_cm": plan.tip_error_cm if plan.complete else nan,
            "path_length_cm": plan.tip_path_length_cm if plan.complete else nan,
            "min_clearance_cm": plan.min_clearance_cm if plan.complete else nan,
            "seconds_per_target": time.perf_counter() - start,
            "note": "" if plan.complete else (plan.reason or "")[:80],
        }
    points = [grid.raster.cell_center(c) for c in cells]
    planner = Planner(grid.tank)
    trajectory = plan_trajectory(planner, points, run.target)
    seconds = time.perf_counter() - start
    m = trajectory.measures(planner.scene)
    return {
        "agent": "q_table + TGA/TSM",
        "targets": 1,
        "success_rate": float(reached and trajectory.complete),
        "tip_error_cm": m["tip_error_cm"],
        "path_length_cm": m["path_cm"],
        "min_clearance_cm": m["min_clearance_cm"],
        "seconds_per_target": seconds,
        "note": trajectory.note,
    }


def _evaluate_sb3(
    run: SB3Run,
    targets: list[np.ndarray] | None,
    draw: tuple[int, int] | None = None,
    tank: str | None = None,
    policy_seed: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    from aftir_rl.rl.sb3 import EVAL_SEED, evaluate_policy_on_targets, evaluation_targets

    kwargs = dict(run.config.env_kwargs or {})  # the env the model was trained on (spaces)
    if tank is not None:
        if bare_env_id(run.env_id) != ARM_FTL:
            raise ConfigError(
                f"{tank}: {run.env_id} takes no tank; {ARM_FTL} runs do", param="tank"
            )
        kwargs["tank"] = tank
    if not targets:
        count, seed = draw or (run.config.eval_targets, EVAL_SEED)
        targets = evaluation_targets(run.env_id, count, seed=seed, env_kwargs=kwargs)
    metrics, _ = evaluate_policy_on_targets(
        run.model, run.env_id, targets, True, kwargs, policy_seed, progress
    )
    note = f"{metrics['collision_rate']:.1%} collided" if metrics["collision_rate"] else ""
    sampled = "" if policy_seed is None else f", sampled from seed {policy_seed}"
    library = " RLlib" if run.library == "rllib" else ""
    agent = f"{run.algo}{library} ({run.config.env_id}{sampled})"
    return {"agent": agent, "targets": len(targets), **metrics, "note": note}


def evaluate_run(
    run_dir: str | Path,
    targets: list[np.ndarray] | None = None,
    motion: str = "ftl",
    margin: float = DEFAULT_MARGIN,
    draw: tuple[int, int] | None = None,
    tank: str | None = None,
    policy_seed: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Evaluate one run directory (Q-table, SB3 or RLlib): a row of ``python -m aftir_rl.evaluate``.

    A Q-table run is evaluated on the target it was trained for: its greedy path becomes a
    follow-the-leader motion keeping ``margin`` [cm] (``motion="ftl"``) or the papers' postures
    per cell (``"progressive"``). An SB3 run on ``targets``, else on ``draw = (count, seed)``
    targets drawn by its env (seeds ``seed .. seed + count − 1``), else on the fixed evaluation
    targets its training measured it on; one episode each, of the deterministic policy, or
    with actions sampled from it given a ``policy_seed``
    (:func:`~aftir_rl.rl.sb3.evaluation.evaluate_policy_on_targets`). ``tank``: an
    ``AFTIR-ArmFTL-v0`` run's policy in another tank or pool than its own (a pool's target ``i``
    lies in its tank ``i mod K``). ``progress``: called with ``(targets done, targets)`` as an
    SB3 run's episodes end.

    Raises:
        CheckpointError: not a run directory this knows, or unreadable files.
        ConfigError: ``tank`` or ``policy_seed`` for a Q-table run, or ``tank`` for a run
            whose env takes none (its ``param`` names which).

    """
    run = load_run(run_dir, ("q_table", "sb3", "rllib"))
    if isinstance(run, QTableRun):
        if tank is not None:
            raise ConfigError(
                f"{tank}: {run_dir} is a Q-table run, evaluated in its own tank", param="tank"
            )
        if policy_seed is not None:
            raise ConfigError(
                f"seed {policy_seed}: {run_dir} is a Q-table run, evaluated greedily",
                param="policy_seed",
            )
        return _evaluate_q_table(run, motion, margin)
    return _evaluate_sb3(cast(SB3Run, run), targets, draw, tank, policy_seed, progress)
