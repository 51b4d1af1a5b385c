"""The greedy path of a learnt Q-table as a run logs it: pictures, FTL motion or postures.

:func:`log_greedy_path` records the greedy cell path of one target's run and turns it into a
follow-the-leader motion (:func:`aftir_rl.planning.ftl.plan.plan_motion`) or the papers'
postures per cell (:func:`aftir_rl.planning.posture.trajectory.plan_trajectory`), as
:class:`MotionOptions` say; :func:`aftir_rl.rl.tabular.train.train_q_table` writes the result.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from aftir_rl.planning.ftl.plan import motion_summary
from aftir_rl.rl.common import target_tag

if TYPE_CHECKING:
    import gymnasium as gym

    from aftir_rl.envs.tank_grid import TankGridEnv

__all__ = ["MotionOptions", "log_greedy_path"]


@dataclasses.dataclass(frozen=True)
class MotionOptions:
    """How :func:`train_q_table` turns a greedy cell path into arm motion (its arguments)."""

    postures: bool
    bridge_seconds: float
    motion: str
    margin: float


def log_greedy_path(
    logger: Any,
    env: gym.Env[Any, Any],
    summary: dict[str, Any],
    target: Sequence[float],
    seed: int,
    options: MotionOptions,
) -> Any:
    """Log the greedy cell path, and the motion or postures along it, with their pictures.

    Returns:
        The FTL plan or posture trajectory (``None`` without ``postures``).

    """
    from stable_baselines3.common.logger import Image

    from aftir_rl.viz.plotting import render_path

    base = cast("TankGridEnv", env.unwrapped)
    success, optimum = summary["success"], summary["bfs_optimal_steps"]
    tip_error, length_cm = summary["tip_error_cm"], summary["path_length_cm"]
    points, steps = np.array(summary["points_cm"]), summary["length_steps"]
    logger.record("eval/path_length_steps", steps)
    logger.record("eval/bfs_optimal_steps", optimum)
    picture = render_path(
        base.tank,
        points,
        base.target_point,
        title=f"Q-learning greedy path to {target_tag(target)} ({steps} steps, BFS {optimum})",
    )
    logger.record(
        f"paths/{target_tag(target)}",
        Image(picture, "HWC"),
        exclude=("stdout", "log", "json", "csv"),
    )
    trajectory = None
    if options.postures and options.motion == "ftl":
        trajectory = _log_motion(logger, base, summary, target, options.margin)
    elif options.postures:
        trajectory = _log_trajectory(
            logger, base, points, target, summary, options.bridge_seconds, seed
        )
        logger.record("eval/success_rate", float(success))
        logger.record("eval/tip_error_cm", tip_error)
        logger.record("eval/path_length_cm", length_cm)
    else:
        logger.record("eval/success_rate", float(success))
    if trajectory is None or getattr(trajectory, "motion", None) is None:
        # one picture card in every run: the cell path where there is no FTL motion
        logger.record("paths/eval", Image(picture, "HWC"), exclude=("stdout", "log", "json", "csv"))
    return trajectory


def _log_motion(
    logger: Any, env: TankGridEnv, summary: dict[str, Any], target: Sequence[float], margin: float
) -> Any:
    """A follow-the-leader motion along the learned cells: logged, pictured, summarised."""
    from stable_baselines3.common.logger import Image

    from aftir_rl.planning.ftl.plan import plan_motion
    from aftir_rl.viz.plotting import render_path

    plan = plan_motion(env.tank, target, summary["cells"], margin=margin)
    summary["motion"] = motion_summary(plan)
    # The same tags, with the same meaning, as every other algorithm (the arm's tip).
    logger.record("eval/success_rate", float(plan.complete))
    logger.record("eval/collision_rate", 0.0 if plan.complete else 1.0)
    if plan.motion is not None:
        logger.record("eval/tip_error_cm", plan.tip_error_cm)
        logger.record("eval/path_length_cm", plan.tip_path_length_cm)
        logger.record("eval/min_clearance_cm", plan.min_clearance_cm)
        assert plan.ftl_deviation_cm is not None  # measured with every motion
        logger.record("eval/ftl_deviation_max_cm", plan.ftl_deviation_cm[0])
        m = plan.motion
        shown = sorted(set(np.linspace(0, len(m) - 1, 7).astype(int)))
        arms = [m.posture(i).points(m.route.section_length, 10) for i in shown]
        picture = render_path(
            env.tank,
            m.tips(),
            env.target_point,
            arms=arms,
            title=f"follow-the-leader motion to {target_tag(target)} "
            f"({len(m)} entries, clearance {plan.min_clearance_cm:.1f} cm)",
        )
        logger.record("paths/eval", Image(picture, "HWC"), exclude=("stdout", "log", "json", "csv"))
    return plan


def _log_trajectory(
    logger: Any,
    env: TankGridEnv,
    points: np.ndarray,
    target: Sequence[float],
    summary: dict[str, Any],
    bridge_seconds: float,
    seed: int,
) -> Any:
    """Postures along the greedy path: logged, pictured and summarised into ``summary``."""
    from stable_baselines3.common.logger import Image

    from aftir_rl.planning.posture import Planner
    from aftir_rl.planning.posture.trajectory import plan_trajectory
    from aftir_rl.viz.plotting import render_path

    trajectory = plan_trajectory(
        Planner(env.tank), points, target, bridge_seconds=bridge_seconds, seed=seed
    )
    found = [p for p in trajectory.postures if p is not None]
    summary["trajectory"] = {
        "postures": len(found),
        "waypoints": len(trajectory.waypoints),
        "failures": [f"waypoint {i} {pt}: {why}" for i, pt, why in trajectory.failures],
        "moves": len(trajectory.moves),
        "blocked_moves": len(trajectory.blocked_moves),
        "bridged_moves": len(trajectory.bridged),
        "max_joint_step_deg": trajectory.max_joint_step_deg,
    }
    logger.record("eval/postures_found", len(found) / len(trajectory.waypoints))
    logger.record("eval/blocked_moves", len(trajectory.blocked_moves))
    if found:
        last = found[-1]
        logger.record("eval/posture_tip_error_cm", last.error_cm)
        logger.record("eval/clearance_cm", min(p.clearance_cm for p in found))
        shown = found[:: max(1, len(found) // 5)] + [last]
        arms = [p.posture.points(p.section_length, 10) for p in shown]
        picture = render_path(
            env.tank,
            points,
            env.target_point,
            arms=arms,
            title=f"arm postures along the path to {target_tag(target)}",
        )
        logger.record(
            f"paths/{target_tag(target)}_arm",
            Image(picture, "HWC"),
            exclude=("stdout", "log", "json", "csv"),
        )
    return trajectory
