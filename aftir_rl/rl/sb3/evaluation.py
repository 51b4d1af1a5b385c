"""Evaluation of the SB3 baselines on fixed targets, and the callbacks of their training.

:class:`ArmEvalCallback` runs the deterministic policy on a fixed set of evaluation targets
(:func:`evaluation_targets`, :func:`evaluate_policy_on_targets`) and logs ``eval/success_rate``,
``eval/tip_error_cm``, ``eval/path_length_cm``, ``eval/collision_rate``,
``eval/min_clearance_cm`` and a picture of the tip path and arm under ``paths/eval`` through the
model's SB3 logger, so SB3 runs and Q-learning runs overlay in one TensorBoard.
:class:`ArmEvalCallback` also keeps the best model evaluated so far, as a run directory of its own.
:class:`AtomicCheckpoint` saves the model periodically; every save is atomic (:func:`save_model`:
temporary file, then rename).
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Image

from aftir_rl.core import interrupts
from aftir_rl.core.config import EVAL_SEED
from aftir_rl.core.files import atomic_open, write_json
from aftir_rl.envs.ftl.pool import STREAM_KWARGS, evaluation_tank
from aftir_rl.envs.ftl.spec import TRAINING_ONLY_KWARGS
from aftir_rl.rl.common import Predictor

__all__ = [
    "EVAL_SEED",
    "arm_clearance",
    "evaluation_env_kwargs",
    "evaluation_targets",
    "evaluate_policy_on_targets",
    "Period",
    "ArmEvalCallback",
    "AtomicCheckpoint",
    "sampling",
    "save_model",
]


def evaluation_env_kwargs(env_kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """A run's env kwargs as evaluations use them: without the training-only ones.

    The keys of :data:`~aftir_rl.envs.ftl.spec.TRAINING_ONLY_KWARGS` change how training
    draws or judges its targets, not the env's spaces: every run of an env is evaluated on the
    same targets by the same rule. A stream of tanks becomes its first wings as a pool
    (:func:`~aftir_rl.envs.ftl.pool.evaluation_tank`), without the stream's options.
    """
    out = {
        k: v
        for k, v in (env_kwargs or {}).items()
        if k not in TRAINING_ONLY_KWARGS and k not in STREAM_KWARGS
    }
    if "tank" in out:
        out["tank"] = evaluation_tank(out["tank"])
    return out


def evaluation_targets(
    env_id: str, count: int, seed: int = EVAL_SEED, env_kwargs: dict[str, Any] | None = None
) -> list[np.ndarray]:
    """A fixed set of targets drawn by the env's own sampler, reset ``i`` seeded ``seed + i``.

    Drawn by the env as evaluated (:func:`evaluation_env_kwargs`), not as its training drew them.
    With a pool of ``K`` tanks, target ``i`` lies in the pool's tank ``i mod K``.
    """
    env = gym.make(env_id, **evaluation_env_kwargs(env_kwargs))
    targets = []
    for i in range(count):
        _, info = env.reset(seed=seed + i, options=_pool_option(env.unwrapped, i))
        targets.append(np.asarray(info["target"], dtype=float))
    env.close()
    return targets


def arm_clearance(arm: Any) -> float:
    """The arm's surface clearance [cm].

    python-fcl where the env has a collision scene, else the numpy signed distance of its
    backbone samples (the FTL env's own contact test).
    """
    if hasattr(arm, "scene"):
        return float(arm.scene.check(arm.posture).clearance_cm)
    from aftir_rl.core.collision import point_clearance

    return float(point_clearance(arm.tank, arm.body()).min()) - arm.arm.radius


def evaluate_policy_on_targets(
    model: Predictor,
    env_id: str,
    targets: list[np.ndarray],
    clearance: bool = False,
    env_kwargs: dict[str, Any] | None = None,
    policy_seed: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[dict[str, float], dict[str, Any]]:
    """Run the policy once per target: its mean action, or sampled with ``policy_seed``.

    Args:
        model: anything with SB3's ``predict``.
        env_id: the arm env.
        targets: evaluation targets [cm].
        clearance: also measure the smallest clearance along each motion (python-fcl distance
            at every step; slower).
        env_kwargs: keyword arguments of the env (the run's ``SB3Config.env_kwargs``; the
            training-only ones are left out, :func:`evaluation_env_kwargs`).
        policy_seed: None for the deterministic policy (the mean action); else the actions are
            sampled from the policy's distribution (RL Zoo's ``--stochastic``), episode ``i``
            with torch's generator seeded ``policy_seed + i``, so each episode is reproducible
            on its own.
        progress: called with ``(targets done, targets)`` after each target.

    Returns:
        Means over targets (``success_rate``, ``tip_error_cm``, ``path_length_cm``,
        ``collision_rate``, ``seconds_per_target``, and ``min_clearance_cm``, the smallest over
        all motions, when asked) and the first episode's ``tips``, ``arm``, ``target`` and
        ``tank`` for a picture.

    Raises:
        KeyboardInterrupt: a stop was requested (:mod:`aftir_rl.core.interrupts`); checked
            before each target.

    """
    env = gym.make(env_id, **evaluation_env_kwargs(env_kwargs))
    arm: Any = env.unwrapped  # an arm env: tip, posture, scene, body(), tank
    rows, smallest, first = [], np.inf, {}
    for i, target in enumerate(targets):
        if interrupts.requested():
            env.close()
            raise KeyboardInterrupt
        start = time.perf_counter()
        options = {"target": target, **(_pool_option(arm, i) or {})}
        deterministic = sampling(None if policy_seed is None else policy_seed + i)
        path, info, smallest = _run_target(
            model, env, arm, options, clearance, smallest, deterministic
        )
        rows.append(
            (
                float(info.get("is_success", False)),
                float(info["distance_cm"]),
                float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
                float(info.get("collision", False)),
                time.perf_counter() - start,
            )
        )
        if i == 0:
            first = {"tips": path, "target": target, "arm": arm.body(), "tank": arm.tank}
        if progress is not None:
            progress(i + 1, len(targets))
    env.close()
    return _mean_metrics(rows, clearance, smallest), first


def sampling(policy_seed: int | None) -> bool:
    """``deterministic`` for one episode's ``predict`` calls, seeding torch for a sampled one.

    None: the policy's mean action (True). A seed: torch's generator is seeded with it and the
    actions are sampled from the policy's distribution (False), so the episode replays.
    """
    if policy_seed is None:
        return True
    torch.manual_seed(policy_seed)
    return False


def _pool_option(arm: Any, i: int) -> dict[str, int] | None:
    """The reset option of target ``i`` in an env with a pool of ``K`` tanks: tank ``i mod K``."""
    pool = getattr(arm, "pool", None)
    return None if pool is None else {"tank": i % len(pool)}


def _run_target(
    model: Predictor,
    env: gym.Env[Any, Any],
    arm: Any,
    options: dict[str, Any],
    clearance: bool,
    smallest: float,
    deterministic: bool = True,
) -> tuple[np.ndarray, dict[str, Any], float]:
    """One episode, reset with ``options`` (the target, and a pool's tank).

    Returns:
        The tip path, the last step's info and ``smallest`` lowered to the smallest clearance
        along the motion (when ``clearance``; else unchanged).

    """
    obs, info = env.reset(options=options)
    tips, done = [arm.tip], False
    while not done:
        action, _ = model.predict(obs, deterministic=deterministic)
        obs, _, terminated, truncated, info = env.step(action)
        tips.append(arm.tip)
        if clearance:
            smallest = min(smallest, arm_clearance(arm))
        done = terminated or truncated
    return np.array(tips), info, smallest


def _mean_metrics(
    rows: Sequence[tuple[float, ...]], clearance: bool, smallest: float
) -> dict[str, float]:
    """The means over targets of the rows' metrics (and the smallest clearance, if measured)."""
    mean = np.mean(np.array(rows), axis=0)
    keys = (
        "success_rate",
        "tip_error_cm",
        "path_length_cm",
        "collision_rate",
        "seconds_per_target",
    )
    metrics = {k: float(v) for k, v in zip(keys, mean)}
    if clearance:
        metrics["min_clearance_cm"] = float(smallest)
    return metrics


class Period:
    """Multiples of ``freq`` environment steps: when a periodic callback is due.

    A resumed model starts at its own step count: the first time due is the next multiple.
    """

    def __init__(self, freq: int) -> None:
        self.freq = freq
        #: The step count at which it is next due.
        self.next_step = freq

    def start(self, num_timesteps: int) -> None:
        """Wait for the multiple of ``freq`` after ``num_timesteps`` (the model's at the start)."""
        self.next_step = (num_timesteps // self.freq + 1) * self.freq

    def due(self, num_timesteps: int) -> bool:
        """Whether ``num_timesteps`` reached the next multiple (then wait for the one after)."""
        if num_timesteps < self.next_step:
            return False
        self.next_step += self.freq
        return True


class ArmEvalCallback(BaseCallback):
    """Evaluate on fixed targets every ``eval_freq`` environment steps and log the eval tags.

    With ``best_dir``, the best model evaluated so far is kept there as a run directory of its
    own (``model.zip``, a copy of the run's ``config.json`` from ``best_dir``'s parent, and
    ``best.json`` with its step count and metrics), so ``python -m aftir_rl.evaluate
    RUN_DIR/best`` measures it: SB3's ``EvalCallback(best_model_save_path=...)`` pattern. Best
    means the highest success rate, then the smaller mean tip error. It is chosen on these
    evaluation targets, so measure it on others (``evaluate --random N --seed S``).
    """

    def __init__(
        self,
        env_id: str,
        targets: list[np.ndarray],
        eval_freq: int,
        env_kwargs: dict[str, Any] | None = None,
        on_evaluate: Any = None,
        best_dir: Path | None = None,
    ) -> None:
        super().__init__()
        self.env_id, self.targets, self.eval_freq = env_id, targets, eval_freq
        self.env_kwargs = dict(env_kwargs or {})
        self._period = Period(eval_freq)
        #: ``on_evaluate(model, metrics)`` after each evaluation is logged (a sweep's report).
        self.on_evaluate = on_evaluate
        self.best_dir = best_dir
        #: ``(success rate, −tip error)`` of the best model kept so far.
        self.best_score: tuple[float, float] | None = None
        self.best_metrics: dict[str, float] = {}

    def _init_callback(self) -> None:
        self._period.start(self.model.num_timesteps)

    def _on_step(self) -> bool:
        if self._period.due(self.num_timesteps) and not interrupts.requested():
            self.evaluate()
        return True

    def _on_training_end(self) -> None:
        if not interrupts.requested():  # stopped on request: saved, not evaluated
            self.evaluate()

    def evaluate(self) -> dict[str, float]:
        """Run the evaluation now and log it."""
        from aftir_rl.viz.plotting import render_path

        metrics, first = evaluate_policy_on_targets(
            self.model, self.env_id, self.targets, clearance=True, env_kwargs=self.env_kwargs
        )
        for key, value in metrics.items():
            self.logger.record(f"eval/{key}", value)
        picture = render_path(
            first["tank"],
            first["tips"],
            first["target"],
            arms=[first["arm"]],
            title=f"{self.env_id}: evaluation target 1",
        )
        self.logger.record(
            "paths/eval", Image(picture, "HWC"), exclude=("stdout", "log", "json", "csv")
        )
        self._keep_if_best(metrics)
        self.logger.dump(self.num_timesteps)
        self.last_metrics = metrics
        if self.on_evaluate is not None:
            self.on_evaluate(self.model, metrics)
        return metrics

    def _keep_if_best(self, metrics: dict[str, float]) -> None:
        if self.best_dir is None:
            return
        error = metrics["tip_error_cm"]
        score = (metrics["success_rate"], -error if np.isfinite(error) else -np.inf)
        if self.best_score is not None and score <= self.best_score:
            return
        self.best_score = score
        self.best_metrics = {**metrics, "timesteps": int(self.num_timesteps)}
        self.best_dir.mkdir(parents=True, exist_ok=True)
        save_model(self.model, self.best_dir / "model.zip")
        with atomic_open(self.best_dir / "config.json", "wb") as fh:
            fh.write((self.best_dir.parent / "config.json").read_bytes())
        write_json(self.best_dir / "best.json", self.best_metrics)
        self.logger.record("eval/best_success_rate", metrics["success_rate"])


class AtomicCheckpoint(BaseCallback):
    """Save ``checkpoints/model_<steps>.zip`` every ``freq`` steps, atomically.

    Not once a stop is requested: the run saves its own then
    (:func:`aftir_rl.rl.sb3.train.train_sb3`).
    """

    def __init__(self, directory: Path, freq: int) -> None:
        super().__init__()
        self.directory, self.freq = Path(directory), freq
        self._period = Period(freq)

    def _init_callback(self) -> None:
        self._period.start(self.model.num_timesteps)

    def _on_step(self) -> bool:
        if self._period.due(self.num_timesteps) and not interrupts.requested():
            save_model(self.model, self.directory / f"model_{self.num_timesteps}.zip")
        return True


def save_model(model: BaseAlgorithm, path: Path) -> Path:
    """``model.save`` to a temporary file, then rename."""
    with atomic_open(path, "wb") as fh:
        model.save(cast(io.BufferedIOBase, fh))  # a binary file: an io.BufferedWriter
    return path
