"""PPO, SAC and TD3 runs (Stable-Baselines3) on the arm envs: :func:`train_run`, :func:`train_sb3`.

A :class:`~aftir_rl.rl.sb3.config.TrainConfig` is trained as it was checked (:func:`train_run`):
its stages one after the other, each resumed from the run of the one before
(:func:`train_curriculum`), under ``LOGDIR/stage<k>/`` when there are several.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from aftir_rl.core import interrupts
from aftir_rl.core.errors import AftirError
from aftir_rl.core.files import check_writable_dir, staged_dir, unfinished_start, write_json
from aftir_rl.core.tank.loading import keep_run_tank
from aftir_rl.rl.common import check_env_id, hyperparameter_text, run_name
from aftir_rl.rl.logs import run_logger
from aftir_rl.rl.sb3.config import (
    SB3_ENV_IDS,
    Origins,
    SB3Config,
    TrainConfig,
    check_sb3_values,
)

if TYPE_CHECKING:
    from aftir_rl.rl.sb3.evaluation import ArmEvalCallback

__all__ = ["DIVERGED", "TrainingDiverged", "train_curriculum", "train_run", "train_sb3"]

#: ``pretrain(model)``: numbers of what was done to a new model before training, logged.
Pretrain = Callable[[BaseAlgorithm], dict[str, float]]
#: ``on_evaluation(model, metrics)``: called after each evaluation is logged.
OnEvaluation = Callable[[BaseAlgorithm, dict[str, Any]], None]


def train_run(run: TrainConfig, pretrain: Pretrain | None = None) -> list[dict[str, Any]]:
    """Train the checked ``run``: its one config, or its stages each resumed from the one before.

    ``pretrain`` applies to the new model of a one-stage run (:func:`train_sb3`).

    Returns:
        Each stage's summary (``run_dir`` holds its run directory).

    """
    if len(run.stages) > 1:
        return train_curriculum(
            _train_checked,
            run.algo,
            list(run.stages),
            run.seed,
            run.logdir,
            run.resume,
            progress_bar=run.progress_bar,
        )
    only, bar = run.stages[0], run.progress_bar
    return [_train_checked(run.algo, only, run.seed, run.logdir, run.resume, bar, None, pretrain)]


def train_curriculum(
    train: Callable[..., dict[str, Any]],
    algo: str,
    configs: list[SB3Config],
    seed: int,
    logdir: str | os.PathLike[str],
    resume: str | os.PathLike[str] | None = None,
    **kwargs: Any,
) -> list[dict[str, Any]]:
    """Train ``configs`` one after the other, each resumed from the previous stage's run.

    ``train`` is :func:`train_sb3` (or one of the same call); ``resume`` starts the first stage
    from a model; ``kwargs`` go to every call.

    Returns:
        Each stage's summary (``run_dir`` holds its run directory).

    """
    summaries = []
    for k, config in enumerate(configs):
        stage_dir = Path(logdir) / f"stage{k}"  # made and checked by ``train`` (one line if not)
        summary = train(algo, config, seed=seed, logdir=stage_dir, resume=resume, **kwargs)
        summaries.append(summary)
        resume = summary["run_dir"]
    return summaries


def train_sb3(
    algo: str,
    config: SB3Config,
    seed: int = 0,
    logdir: str | os.PathLike[str] = "runs",
    resume: str | os.PathLike[str] | None = None,
    progress_bar: bool = True,
    on_evaluation: OnEvaluation | None = None,
    pretrain: Pretrain | None = None,
) -> dict[str, Any]:
    """Train PPO, SAC or TD3 on an arm env; one run directory with the model and its logs.

    The run directory holds ``model.zip`` (atomic), ``checkpoints/``, ``config.json``,
    ``summary.json``, ``progress.csv``, the TensorBoard events (``rollout/*``, ``train/*``,
    ``eval/*``, ``paths/eval``, the hyperparameters as text) and ``best/``, the best model
    evaluated during training as a run directory of its own (:class:`ArmEvalCallback`). It is
    built under a hidden ``.<name>.partial`` name and renamed once ``model.zip`` is written, so an
    interrupted run never looks finished. On a stop request (Ctrl-C or SIGTERM under the command
    line, :mod:`aftir_rl.core.interrupts`) the model as of its last update is saved to
    ``checkpoints/model_<steps>.zip`` of the partial directory. Resuming from such an unfinished
    run finishes it: it trains what is left of ``total_timesteps`` counted from where that run
    started, so it ends where an uninterrupted run would; resuming a finished run trains
    ``total_timesteps`` more. ``on_evaluation(model, metrics)``, if given, is called after each
    evaluation is logged (``aftir tune`` reports to Ray Tune there). ``pretrain(model)`` is
    applied to a new model first (:mod:`aftir_rl.rl.imitation`), its numbers logged as
    ``pretrain/*``; ``total_timesteps`` 0 only evaluates the model.

    Raises:
        ConfigError: the config, ``logdir`` or the hyperparameters are refused (before any
            training).
        CheckpointError: ``resume`` is unreadable, or does not fit this config.
        KeyboardInterrupt: a stop request, once the model is saved; its message says where.
        WriteError: a full disk or a failing device; the partial directory is kept.

    """
    bare = check_env_id(config.env_id, SB3_ENV_IDS, algo)
    check_sb3_values(config, algo, bare, Origins("config"))
    return _train_checked(algo, config, seed, logdir, resume, progress_bar, on_evaluation, pretrain)


def _train_checked(
    algo: str,
    config: SB3Config,
    seed: int,
    logdir: str | os.PathLike[str],
    resume: str | os.PathLike[str] | None,
    progress_bar: bool = True,
    on_evaluation: OnEvaluation | None = None,
    pretrain: Pretrain | None = None,
) -> dict[str, Any]:
    """:func:`train_sb3` of a config already checked for ``algo``."""
    from aftir_rl.rl.sb3 import evaluation_targets, newest_model

    bare = config.env_id.removeprefix("aftir_rl:")
    env_id = f"aftir_rl:{bare}"
    folder = check_writable_dir(logdir)
    resume_path = newest_model(resume) if resume is not None else None
    targets = evaluation_targets(env_id, config.eval_targets, env_kwargs=config.env_kwargs)
    venv = _make_venv(env_id, config, seed)
    run = (algo, bare, config, venv, seed, folder, resume_path, targets)
    try:
        return _train_run(
            *run, progress_bar=progress_bar, on_evaluation=on_evaluation, pretrain=pretrain
        )
    finally:
        try:
            venv.close()
        except (OSError, EOFError):
            pass


def _make_venv(env_id: str, config: SB3Config, seed: int) -> VecEnv:
    """The training envs: a batched env when the env has one, else copies (Ctrl-C held back)."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    # a batched env (one numpy pass for all rows) when the env has one, else copies
    # only HER's replay buffer reads the infos of rows that did not finish
    venv = make_batched_vec_env(
        env_id, config.n_envs, seed, config.env_kwargs, None if config.her else ()
    )
    if venv is None:
        vec_cls = SubprocVecEnv if config.n_envs > 1 else DummyVecEnv
        with _ctrl_c_held():
            venv = make_vec_env(
                env_id,
                n_envs=config.n_envs,
                seed=seed,
                vec_env_cls=vec_cls,
                env_kwargs=config.env_kwargs,
            )
    return _FiniteActions(venv)


class ActionsNotFinite(ValueError):
    """The policy asked for a NaN action: its outputs overflowed (its weights may be finite)."""


class _FiniteActions(VecEnvWrapper):
    """The training envs, refusing a NaN action before any env sees it.

    A policy whose weights grew huge but stayed finite can still put out NaN; an env would refuse
    it in a worker process, and the main process would see only a closed pipe.
    """

    def step_async(self, actions: np.ndarray) -> None:
        if not np.all(np.isfinite(np.asarray(actions, dtype=np.float64))):
            raise ActionsNotFinite("the policy's actions are NaN")
        self.venv.step_async(actions)

    def reset(self) -> Any:
        return self.venv.reset()

    def step_wait(self) -> Any:
        return self.venv.step_wait()


@contextmanager
def _ctrl_c_held() -> Iterator[None]:
    """Hold SIGINT back from this thread while subprocess workers start.

    The workers inherit the signal mask, so Ctrl-C never reaches them (the main process stops
    them once the model is saved); a Ctrl-C meanwhile is delivered to the main process when the
    block ends, never lost. Only the main thread's signals matter (a Ray Tune trial runs in
    another one).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _train_run(
    algo: str,
    bare: str,
    config: SB3Config,
    venv: VecEnv,
    seed: int,
    logdir: Path,
    resume_path: Path | None,
    targets: list[np.ndarray],
    *,
    progress_bar: bool,
    on_evaluation: OnEvaluation | None,
    pretrain: Pretrain | None = None,
) -> dict[str, Any]:
    """Build (or load) the model, train it and write its run directory under ``logdir``.

    A partial directory that holds a checkpoint is kept on failure (resumable); any other is
    removed, but on a full disk or a failing device (kept with its logs).
    """
    from aftir_rl.rl.sb3 import build_model, load_model, save_model

    if resume_path is not None:
        model = load_model(algo, resume_path, env=venv, config=config, evaluation=False)
    else:
        model = build_model(algo, config, venv, seed=seed)
    start = _run_start(resume_path, int(model.num_timesteps))
    model.num_timesteps = _learnt_steps(model, start)
    steps = max(0, config.total_timesteps - (int(model.num_timesteps) - start))
    run_dir = logdir / run_name(algo, bare, "random", seed)
    # a partial run that holds a checkpoint is kept on failure (resumable)
    staged = staged_dir(run_dir, keep=_kept_on_failure, start={"timesteps": start})
    with staged as partial, run_logger(partial) as logger:
        model.set_logger(logger)
        _write_config(partial, logger, algo, config, seed, resume_path)
        cloned = pretrain(model) if pretrain is not None and resume_path is None else {}
        for key, value in cloned.items():
            logger.record(f"pretrain/{key}", value)
        evaluator, callbacks = _callbacks(
            f"aftir_rl:{bare}", config, targets, on_evaluation, partial
        )
        with interrupts.deferred():  # a stop request ends training at the next step
            seconds = _learn(model, steps, callbacks, progress_bar, resume_path, partial)
            save_model(model, partial / "model.zip")
        summary = {
            "algo": algo,
            "env_id": config.env_id,
            "timesteps": int(model.num_timesteps),
            "seconds": seconds,
            "run_dir": str(run_dir),
            **evaluator.last_metrics,
            "best": evaluator.best_metrics,
            **({"pretrain": cloned} if cloned else {}),
        }
        write_json(partial / "summary.json", summary)
    return summary


def _learnt_steps(model: BaseAlgorithm, start: int) -> int:
    """The steps a loaded model has learnt from, counted in its run that began at ``start``.

    An on-policy model (PPO, A2C) updates its weights only after a whole rollout: a checkpoint
    saved inside one (a periodic checkpoint of a run killed before it could tidy up, such as a
    sweep's trial) holds the weights of the rollout's start, where training must go on from.
    """
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    steps = int(model.num_timesteps)
    if not isinstance(model, OnPolicyAlgorithm) or steps <= start:
        return steps
    rollout = int(model.n_steps) * int(model.n_envs)
    return start + (steps - start) // rollout * rollout


def _run_start(resume_path: Path | None, steps: int) -> int:
    """The step count this run counts ``total_timesteps`` from (``steps``: the model's now).

    Resuming an unfinished run (stopped by Ctrl-C) continues it: from that run's own start.
    """
    start = (unfinished_start(resume_path) or {}).get("timesteps") if resume_path else None
    return start if start is not None and start <= steps else steps


def _write_config(
    partial: Path, logger: Logger, algo: str, config: SB3Config, seed: int, resume_path: Path | None
) -> None:
    """Write ``config.json`` and log it as text."""
    params = {
        **dataclasses.asdict(config),
        "algo": algo,
        "seed": seed,
        "resume": str(resume_path) if resume_path else None,
    }
    if "tank" in config.env_kwargs:  # a tank given by path travels with the run
        tank = keep_run_tank(config.env_kwargs["tank"], partial)
        params["env_kwargs"] = {**config.env_kwargs, "tank": tank}
    write_json(partial / "config.json", params)
    logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))


def _callbacks(
    env_id: str,
    config: SB3Config,
    targets: list[np.ndarray],
    on_evaluation: OnEvaluation | None,
    partial: Path,
) -> tuple[ArmEvalCallback, list[BaseCallback]]:
    """The evaluation callback (best model under ``best/``) and the list of training callbacks."""
    from aftir_rl.rl.sb3 import ArmEvalCallback, AtomicCheckpoint

    evaluator = ArmEvalCallback(
        env_id,
        targets,
        config.eval_freq,
        config.env_kwargs,
        on_evaluate=on_evaluation,
        best_dir=partial / "best",
    )
    callbacks = [evaluator, AtomicCheckpoint(partial / "checkpoints", config.checkpoint_freq)]
    return evaluator, callbacks


#: The file a diverged run's folder holds: the step, and the last step its weights were finite.
DIVERGED = "diverged.json"


class TrainingDiverged(AftirError):
    """Training produced NaN or infinite weights: the run folder is kept with its logs."""


def _finite(model: BaseAlgorithm) -> bool:
    """Whether every parameter of the model's policy is a finite number."""
    return all(bool(p.isfinite().all()) for p in model.policy.parameters())


class _StopOnDivergence(BaseCallback):
    """Stop at the first step after an update that left a weight NaN or infinite.

    The weights are checked at each rollout's start (after the update before it) and at the end;
    ``finite_step`` is the last step they were seen finite, ``diverged_step`` the first not.
    """

    finite_step = 0
    diverged_step: int | None = None

    def _on_training_start(self) -> None:
        self.finite_step = int(self.model.num_timesteps)

    def _on_rollout_start(self) -> None:
        if self.diverged_step is None:
            if _finite(self.model):
                self.finite_step = int(self.model.num_timesteps)
            else:
                self.diverged_step = int(self.model.num_timesteps)

    def _on_step(self) -> bool:
        return self.diverged_step is None


def _diverged(model: BaseAlgorithm, watch: _StopOnDivergence, partial: Path) -> NoReturn:
    """Keep the run's logs and its finite checkpoints, say where, and raise TrainingDiverged."""
    step = watch.diverged_step if watch.diverged_step is not None else int(model.num_timesteps)
    folder = partial / "checkpoints"
    for path in folder.glob("model_*.zip"):  # saved after the last finite weights: not finite
        tail = path.stem[len("model_") :]
        if tail.isdigit() and int(tail) > watch.finite_step:
            path.unlink(missing_ok=True)
    write_json(partial / DIVERGED, {"step": step, "last_finite_step": watch.finite_step})
    kept = f"; the last finite checkpoint is in {folder}" if _has_checkpoint(partial) else ""
    raise TrainingDiverged(
        f"training diverged at step {step:,}: the policy's weights or actions became NaN or "
        "infinite "
        f"(a smaller learning_rate or max_grad_norm helps); the logs are kept in {partial}{kept}"
    )


class _StopOnRequest(BaseCallback):
    """End training at the next step once a stop is requested; remember where the rollout began.

    The model's weights change only between rollouts, so the steps of an unfinished rollout
    were never learnt from: the model is saved as of the rollout's start.
    """

    rollout_start = 0

    def _on_training_start(self) -> None:
        self.rollout_start = int(self.model.num_timesteps)

    def _on_rollout_start(self) -> None:
        self.rollout_start = int(self.model.num_timesteps)

    def _on_step(self) -> bool:
        return not interrupts.requested()


class _ProgressBar(BaseCallback):
    """A progress bar over the steps the run really takes (plain tqdm, no rich).

    SB3's own bar counts to the asked steps, but a model steps all its envs at once and PPO
    collects whole rollouts: ``--total-timesteps 20000`` with 128 rows of 128 steps trains
    32,768 steps.
    """

    def _on_training_start(self) -> None:
        from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
        from tqdm import tqdm

        per = self.model.n_envs  # off-policy models step all envs at once, too
        if isinstance(self.model, OnPolicyAlgorithm):
            per *= self.model.n_steps
        asked = int(self.locals["total_timesteps"]) - int(self.model.num_timesteps)
        self.pbar = tqdm(total=-(-asked // per) * per, unit="step", unit_scale=True)

    def _on_step(self) -> bool:
        self.pbar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self.pbar.refresh()
        self.pbar.close()


def _learn(
    model: BaseAlgorithm,
    steps: int,
    callbacks: list[BaseCallback],
    progress_bar: bool,
    resume_path: Path | None,
    partial: Path,
) -> float:
    """Train ``steps`` more steps; on a stop request save a checkpoint and say where.

    Returns:
        The seconds training took.

    Raises:
        KeyboardInterrupt: a stop request, once the model is saved under
            ``partial/checkpoints``.

    """
    stop, watch = _StopOnRequest(), _StopOnDivergence()
    start = time.perf_counter()
    try:
        model.learn(
            steps,
            callback=[watch, *callbacks, stop, *([_ProgressBar()] if progress_bar else [])],
            reset_num_timesteps=resume_path is None,
        )
    except KeyboardInterrupt:
        pass  # a stop requested during an evaluation: saved as between two steps
    except ValueError as exc:  # torch's distributions refuse NaN parameters; NaN actions
        if _finite(model) and not isinstance(exc, ActionsNotFinite):
            raise
        _diverged(model, watch, partial)
    if watch.diverged_step is not None or not _finite(model):
        _diverged(model, watch, partial)
    if interrupts.requested():
        _save_stopped(model, stop.rollout_start, partial)
    return time.perf_counter() - start


def _save_stopped(model: BaseAlgorithm, steps: int, partial: Path) -> None:
    """Save the stopped model as of step ``steps`` (its last update) and raise KeyboardInterrupt.

    Periodic checkpoints of the unfinished rollout hold the same weights under later step
    counts: they are removed, so ``--resume`` takes this one and ends where the run would.
    """
    from aftir_rl.rl.sb3 import save_model

    model.num_timesteps = steps
    folder = partial / "checkpoints"
    save_model(model, folder / f"model_{steps}.zip")
    for path in folder.glob("model_*.zip"):
        tail = path.stem[len("model_") :]
        if tail.isdigit() and int(tail) > steps:
            path.unlink(missing_ok=True)
    raise KeyboardInterrupt(
        f"the model at step {steps} is saved in {folder}; continue with --resume {partial}"
    )


def _has_checkpoint(partial: Path) -> bool:
    return any((partial / "checkpoints").glob("model_*.zip"))


def _kept_on_failure(partial: Path) -> bool:
    """Keep a failed run's folder when it can be resumed or it diverged (its logs say how)."""
    return _has_checkpoint(partial) or (partial / DIVERGED).exists()
