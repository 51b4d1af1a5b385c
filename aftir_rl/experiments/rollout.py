"""A trained policy's motion to a target, as the planner's ``trajectory.json``; and its frames.

:func:`rollout` runs the policy of an SB3 run once (its mean actions, or sampled), from the
env's start to the target, and keeps every posture the arm took, its clearance and the tip
error, in the ``trajectory.json`` contract of the planner (``docs/design.md`` §9), so ``aftir
view`` draws a policy's motion exactly as it draws a planned one, and the two overlay on one
page.
:func:`record_frames` keeps the env's ``rgb_array`` frames of the same episode instead.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from aftir_rl.rl.sb3.evaluation import arm_clearance, evaluation_env_kwargs, sampling

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

__all__ = ["rollout", "record_frames"]


@contextmanager
def _episode(
    env_id: str, env_kwargs: dict[str, Any] | None, target: Any, render: bool = False
) -> Iterator[tuple[gym.Env[Any, Any], Any, Any, dict[str, Any]]]:
    """The evaluation env reset to ``target``: ``(env, its unwrapped arm env, obs, info)``."""
    kwargs = evaluation_env_kwargs(env_kwargs)
    env = gym.make(env_id, render_mode="rgb_array" if render else None, **kwargs)
    try:
        obs, info = env.reset(options={"target": np.asarray(target, dtype=np.float64)})
        yield env, env.unwrapped, obs, info
    finally:
        env.close()


def rollout(
    model: BaseAlgorithm,
    env_id: str,
    env_kwargs: dict[str, Any] | None,
    target: Any,
    policy_seed: int | None = None,
) -> dict[str, Any]:
    """One episode of ``model`` to ``target``, in the ``trajectory.json`` contract.

    The policy's mean actions, or with ``policy_seed`` actions sampled from it
    (:func:`~aftir_rl.rl.sb3.evaluation.sampling`).

    Returns:
        ``complete`` (reached within the env's tolerance without contact), ``method``,
        ``section_length``, ``target``, ``motion`` (one ``{dis, theta, phi}`` per step, the start
        included), ``waypoint_index``, ``min_clearance_cm``, ``tip_error_cm``,
        ``tip_path_length_cm``, ``collision``, ``steps`` and ``seconds``.

    Raises:
        TargetError: the env refuses the target (outside the tank, inside a solid...).

    """
    start = time.perf_counter()
    with _episode(env_id, env_kwargs, target) as (env, arm, obs, info):
        motion, tips = [arm.posture.to_dict()], [arm.tip]
        clearance = arm_clearance(arm)
        done, deterministic = False, sampling(policy_seed)
        while not done:
            action, _ = model.predict(obs, deterministic=deterministic)
            obs, _, terminated, truncated, info = env.step(action)
            motion.append(arm.posture.to_dict())
            tips.append(arm.tip)
            clearance = min(clearance, arm_clearance(arm))
            done = bool(terminated or truncated)
        length = float(np.sum(np.linalg.norm(np.diff(np.array(tips), axis=0), axis=1)))
        collision = bool(info.get("collision", False))
        return {
            "complete": bool(info.get("is_success", False)) and not collision,
            "method": f"policy ({type(model).__name__}{'' if deterministic else ', sampled'})",
            "section_length": float(arm.arm.section_length),
            "target": [float(v) for v in arm.target],
            "motion": motion,
            "waypoint_index": [0, len(motion) - 1],
            "min_clearance_cm": clearance,
            "tip_error_cm": float(info.get("distance_cm", np.linalg.norm(arm.tip - arm.target))),
            "tip_path_length_cm": length,
            "collision": collision,
            "steps": len(motion) - 1,
            "seconds": time.perf_counter() - start,
        }


def record_frames(
    model: BaseAlgorithm,
    env_id: str,
    env_kwargs: dict[str, Any] | None,
    target: Any,
    policy_seed: int | None = None,
) -> list[NDArray[np.uint8]]:
    """The ``rgb_array`` frames of one episode of ``model`` to ``target`` (as :func:`rollout`)."""
    with _episode(env_id, env_kwargs, target, render=True) as (env, _, obs, _):
        frames: list[Any] = [env.render()]  # rgb_array frames
        done, deterministic = False, sampling(policy_seed)
        while not done:
            action, _ = model.predict(obs, deterministic=deterministic)
            obs, _, terminated, truncated, _ = env.step(action)
            frames.append(env.render())
            done = bool(terminated or truncated)
    return [np.asarray(f, dtype=np.uint8) for f in frames if f is not None]
