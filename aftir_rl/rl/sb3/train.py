"""PPO, SAC and TD3 runs (Stable-Baselines3) on the arm envs: :func:`train_sb3`."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

from aftir_rl.core.files import check_writable_dir, staged_dir, write_json
from aftir_rl.rl.common import check_env_id, hyperparameter_text, run_name

__all__ = ["train_sb3"]


def train_sb3(
    algo: str,
    config: Any,
    seed: int = 0,
    logdir: str | Path = "runs",
    resume: str | Path | None = None,
    progress_bar: bool = True,
    on_evaluation: Any = None,
) -> dict[str, Any]:
    """Train PPO, SAC or TD3 on an arm env; one run directory with the model and its logs.

    The run directory holds ``model.zip`` (atomic), ``checkpoints/``, ``config.json``,
    ``summary.json``, ``progress.csv``, the TensorBoard events (``rollout/*``, ``train/*``,
    ``eval/*``, ``paths/eval``, the hyperparameters as text) and ``best/``, the best model
    evaluated during training as a run directory of its own (:class:`ArmEvalCallback`). It is
    built under a hidden ``.<name>.partial`` name and renamed once ``model.zip`` is written, so an
    interrupted run never looks finished. On Ctrl-C the model is saved to
    ``checkpoints/model_<steps>.zip`` of the partial directory, which ``--resume`` continues
    from. ``on_evaluation(model, metrics)``, if
    given, is called after each evaluation is logged (``aftir tune`` reports to Ray Tune there).

    Raises:
        ConfigError: the config, ``logdir`` or the hyperparameters are refused (before any
            training).
        CheckpointError: ``resume`` is unreadable, or does not fit this config.
        KeyboardInterrupt: Ctrl-C, once the model is saved; its message says where.

    """
    from aftir_rl.rl.sb3 import check_sb3_config, evaluation_targets, newest_model
    from aftir_rl.rl.sb3.config import SB3_ENV_IDS

    bare = check_env_id(config.env_id, SB3_ENV_IDS, algo)
    check_sb3_config(config, algo, "config")
    env_id = f"aftir_rl:{bare}"
    logdir = check_writable_dir(logdir)
    resume_path = newest_model(resume) if resume is not None else None
    targets = evaluation_targets(env_id, config.eval_targets, env_kwargs=config.env_kwargs)
    venv = _make_venv(env_id, config, seed)
    try:
        return _train_run(
            algo,
            bare,
            config,
            venv,
            seed,
            logdir,
            resume_path,
            targets,
            progress_bar=progress_bar,
            on_evaluation=on_evaluation,
        )
    finally:
        try:
            venv.close()
        except (OSError, EOFError):
            pass


def _make_venv(env_id: str, config: Any, seed: int) -> Any:
    """The training envs: a batched env when the env has one, else copies (Ctrl-C ignored)."""
    import signal
    import threading

    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    vec_cls = SubprocVecEnv if config.n_envs > 1 else DummyVecEnv
    # Workers ignore Ctrl-C: the main process stops them once the model is saved. Only the main
    # thread may set handlers (a Ray Tune trial runs in another one).
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
    try:
        # a batched env (one numpy pass for all rows) when the env has one, else copies
        # only HER's replay buffer reads the infos of rows that did not finish
        venv = make_batched_vec_env(
            env_id, config.n_envs, seed, config.env_kwargs, None if config.her else ()
        )
        if venv is None:
            venv = make_vec_env(
                env_id,
                n_envs=config.n_envs,
                seed=seed,
                vec_env_cls=vec_cls,
                env_kwargs=config.env_kwargs,
            )
    finally:
        if main_thread:
            signal.signal(signal.SIGINT, previous)
    return venv


def _train_run(
    algo: str,
    bare: str,
    config: Any,
    venv: Any,
    seed: int,
    logdir: Path,
    resume_path: Path | None,
    targets: Any,
    *,
    progress_bar: bool,
    on_evaluation: Any,
) -> dict[str, Any]:
    """Build (or load) the model, train it and write its run directory under ``logdir``.

    A partial directory that holds a checkpoint is kept on failure (resumable); any other is
    removed.
    """
    from aftir_rl.rl.sb3 import build_model, load_model, save_model

    if resume_path is not None:
        model = load_model(algo, resume_path, env=venv, config=config, evaluation=False)
    else:
        model = build_model(algo, config, venv, seed=seed)
    name = run_name(algo, bare, "random", seed)
    run_dir = logdir / name
    # a partial run that holds a checkpoint is kept on failure (resumable)
    with staged_dir(run_dir, keep=_has_checkpoint) as partial:
        logger = _open_logger(model, partial, algo, config, seed, resume_path)
        evaluator, callbacks = _callbacks(
            f"aftir_rl:{bare}", config, targets, on_evaluation, partial
        )
        seconds = _learn(model, config, callbacks, progress_bar, resume_path, partial, logger)
        save_model(model, partial / "model.zip")
        logger.close()
        summary = {
            "algo": algo,
            "env_id": config.env_id,
            "timesteps": int(model.num_timesteps),
            "seconds": seconds,
            "run_dir": str(run_dir),
            **evaluator.last_metrics,
            "best": evaluator.best_metrics,
        }
        write_json(partial / "summary.json", summary)
    return summary


def _open_logger(
    model: Any, partial: Path, algo: str, config: Any, seed: int, resume_path: Path | None
) -> Any:
    """The run's CSV and TensorBoard logger, set on ``model``; writes ``config.json``."""
    from stable_baselines3.common.logger import configure

    logger = configure(str(partial), ["csv", "tensorboard"])
    model.set_logger(logger)
    params = {
        **dataclasses.asdict(config),
        "algo": algo,
        "seed": seed,
        "resume": str(resume_path) if resume_path else None,
    }
    write_json(partial / "config.json", params)
    logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))
    return logger


def _callbacks(
    env_id: str, config: Any, targets: Any, on_evaluation: Any, partial: Path
) -> tuple[Any, list[Any]]:
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


def _learn(
    model: Any,
    config: Any,
    callbacks: list[Any],
    progress_bar: bool,
    resume_path: Path | None,
    partial: Path,
    logger: Any,
) -> float:
    """Train for ``config.total_timesteps``; on Ctrl-C save a checkpoint and say where.

    Returns:
        The seconds training took.

    Raises:
        KeyboardInterrupt: Ctrl-C, once the model is saved under ``partial/checkpoints``.

    """
    from aftir_rl.rl.sb3 import save_model

    start = time.perf_counter()
    try:
        model.learn(
            config.total_timesteps,
            callback=callbacks,
            progress_bar=progress_bar,
            reset_num_timesteps=resume_path is None,
        )
    except KeyboardInterrupt:
        steps = int(model.num_timesteps)
        save_model(model, partial / "checkpoints" / f"model_{steps}.zip")
        logger.close()
        raise KeyboardInterrupt(
            f"the model at step {steps} is saved in {partial}/checkpoints; continue with "
            f"--resume {partial}"
        ) from None
    return time.perf_counter() - start


def _has_checkpoint(partial: Path) -> bool:
    return any((partial / "checkpoints").glob("model_*.zip"))
