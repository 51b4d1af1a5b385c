"""Stable-Baselines3 baselines (PPO, SAC, TD3) on the arm envs, logged like the Q-table runs.

Configuration: ``configs/{ppo,sac,td3}.yaml`` load into :class:`SB3Config`; ``hyperparameters``
go to the algorithm's constructor and are checked against its signature (an unknown key is a
:class:`~aftir_rl.errors.ConfigError` naming the file and the key).

:class:`ArmEvalCallback` runs the deterministic policy on a fixed set of evaluation targets and
logs ``eval/success_rate``, ``eval/tip_error_cm``, ``eval/path_length_cm``,
``eval/collision_rate`` and a picture of the tip path and arm under ``paths/eval`` through the
model's SB3 logger, so SB3 runs and Q-learning runs overlay in one TensorBoard.
Checkpoints are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import inspect
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Image

from aftir_rl.atomic import atomic_open
from aftir_rl.config import from_mapping, read_yaml, to_float
from aftir_rl.errors import CheckpointError, ConfigError

__all__ = ["ALGORITHMS", "SB3Config", "load_sb3_config", "ArmEvalCallback", "AtomicCheckpoint",
           "evaluation_targets", "evaluate_policy_on_targets", "load_model"]  # fmt: skip

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}


@dataclass(frozen=True)
class SB3Config:
    """A run of an SB3 algorithm (``configs/<algo>.yaml``).

    Attributes:
        env_id: environment id (``AFTIR-ArmReach-v0``...).
        total_timesteps: training steps.
        n_envs: parallel envs (subprocesses when more than one).
        eval_freq: environment steps between evaluations.
        eval_targets: number of fixed evaluation targets.
        checkpoint_freq: environment steps between checkpoints.
        policy: SB3 policy name.
        hyperparameters: keyword arguments of the algorithm.

    """

    env_id: str = "AFTIR-ArmReach-v0"
    total_timesteps: int = 100_000
    n_envs: int = 1
    eval_freq: int = 10_000
    eval_targets: int = 20
    checkpoint_freq: int = 50_000
    policy: str = "MlpPolicy"
    hyperparameters: dict[str, Any] = field(default_factory=dict)


def load_sb3_config(path: str | os.PathLike[str], algo: str) -> SB3Config:
    """Read and check an SB3 config; numbers written as strings (``3e-4``) are parsed."""
    data = read_yaml(path)
    hyper = data.pop("hyperparameters", None) or {}
    if not isinstance(hyper, dict):
        raise ConfigError(f"{path}: hyperparameters: expected a mapping")
    config = from_mapping(SB3Config, data, str(path))
    allowed = set(inspect.signature(ALGORITHMS[algo].__init__).parameters) - {
        "self", "policy", "env", "seed", "tensorboard_log", "verbose", "_init_setup_model",
    }  # fmt: skip
    parsed = {}
    for key, value in hyper.items():
        if key not in allowed:
            raise ConfigError(
                f"{path}: hyperparameters: unknown key {key!r} for {algo.upper()}; allowed keys "
                f"are {', '.join(sorted(allowed))}"
            )
        if isinstance(value, str):
            try:
                value = to_float(value, f"{path}: hyperparameters.{key}")
            except ConfigError:
                pass
        parsed[key] = value
    return SB3Config(**{**config.__dict__, "hyperparameters": parsed})


def evaluation_targets(env_id: str, count: int, seed: int = 12345) -> list[np.ndarray]:
    """A fixed set of targets drawn by the env's own sampler with a fixed seed."""
    env = gym.make(env_id)
    targets = []
    for i in range(count):
        _, info = env.reset(seed=seed + i)
        targets.append(np.asarray(info["target"], dtype=float))
    env.close()
    return targets


def evaluate_policy_on_targets(
    model: Any, env_id: str, targets: list[np.ndarray], clearance: bool = False
) -> tuple[dict[str, float], dict[str, Any]]:
    """Run the deterministic policy once per target.

    Args:
        model: anything with SB3's ``predict``.
        env_id: the arm env.
        targets: evaluation targets [cm].
        clearance: also measure the smallest clearance along each motion (python-fcl distance
            at every step; slower).

    Returns:
        Means over targets (``success_rate``, ``tip_error_cm``, ``path_length_cm``,
        ``collision_rate``, ``seconds_per_target``, and ``min_clearance_cm``, the smallest over
        all motions, when asked) and the first episode's ``tips``, ``arm``, ``target`` and
        ``tank`` for a picture.

    """
    env = gym.make(env_id)
    arm = env.unwrapped
    rows, smallest, first = [], np.inf, {}
    for i, target in enumerate(targets):
        start = time.perf_counter()
        obs, info = env.reset(options={"target": target})
        tips, done = [arm.tip], False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            tips.append(arm.tip)
            if clearance:
                smallest = min(smallest, arm.scene.check(arm.posture).clearance_cm)
            done = terminated or truncated
        path = np.array(tips)
        rows.append((
            float(info.get("is_success", False)), float(info["distance_cm"]),
            float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            float(info.get("collision", False)), time.perf_counter() - start,
        ))  # fmt: skip
        if i == 0:
            first = {"tips": path, "target": target, "arm": arm.body(), "tank": arm.tank}
    env.close()
    mean = np.mean(np.array(rows), axis=0)
    keys = ("success_rate", "tip_error_cm", "path_length_cm", "collision_rate",
            "seconds_per_target")  # fmt: skip
    metrics = {k: float(v) for k, v in zip(keys, mean)}
    if clearance:
        metrics["min_clearance_cm"] = float(smallest)
    return metrics, first


class ArmEvalCallback(BaseCallback):
    """Evaluate on fixed targets every ``eval_freq`` environment steps and log the eval tags."""

    def __init__(self, env_id: str, targets: list[np.ndarray], eval_freq: int) -> None:
        super().__init__()
        self.env_id, self.targets, self.eval_freq = env_id, targets, eval_freq
        self._next = eval_freq

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.eval_freq
            self.evaluate()
        return True

    def _on_training_end(self) -> None:
        self.evaluate()

    def evaluate(self) -> dict[str, float]:
        """Run the evaluation now and log it."""
        from aftir_rl.plotting import render_path

        metrics, first = evaluate_policy_on_targets(self.model, self.env_id, self.targets)
        for key, value in metrics.items():
            self.logger.record(f"eval/{key}", value)
        picture = render_path(first["tank"], first["tips"], first["target"], arms=[first["arm"]],
                              title=f"{self.env_id}: evaluation target 1")  # fmt: skip
        self.logger.record("paths/eval", Image(picture, "HWC"),
                           exclude=("stdout", "log", "json", "csv"))  # fmt: skip
        self.logger.dump(self.num_timesteps)
        self.last_metrics = metrics
        return metrics


class AtomicCheckpoint(BaseCallback):
    """Save ``checkpoints/model_<steps>.zip`` every ``freq`` steps, atomically."""

    def __init__(self, directory: Path, freq: int) -> None:
        super().__init__()
        self.directory, self.freq = Path(directory), freq
        self._next = freq

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.freq
            save_model(self.model, self.directory / f"model_{self.num_timesteps}.zip")
        return True


def save_model(model: BaseAlgorithm, path: Path) -> Path:
    """``model.save`` to a temporary file, then rename."""
    with atomic_open(path, "wb") as fh:
        model.save(fh)
    return path


def load_model(algo: str, path: str | os.PathLike[str], env: Any = None) -> BaseAlgorithm:
    """Load a saved SB3 model, or raise :class:`CheckpointError` saying what is wrong."""
    path = Path(path)
    if path.is_dir():
        path = path / "model.zip"
    if not path.exists():
        raise CheckpointError(f"{path}: no such model file; pass a run directory or a .zip model")
    try:
        return ALGORITHMS[algo].load(path, env=env)
    except Exception as exc:  # SB3 raises many types for a bad zip
        raise CheckpointError(
            f"{path}: not a readable {algo.upper()} model ({type(exc).__name__}: {exc}); "
            "retrain or pass the right file"
        ) from None
