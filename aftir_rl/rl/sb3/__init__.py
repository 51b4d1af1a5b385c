"""Stable-Baselines3 baselines (PPO, SAC, TD3) on the arm envs, logged like the Q-table runs.

One import for the SB3 side of the package, whose main modules are:

- :mod:`aftir_rl.rl.sb3.hyperparams` and :mod:`aftir_rl.rl.sb3.config`: the command line, the
  hyperparameter files, named configs, stage files and a resumed run's config resolve in one
  pass into a checked :class:`TrainConfig` (:mod:`aftir_rl.rl.sb3.train` trains it);
- :mod:`aftir_rl.rl.sb3.evaluation`: :class:`ArmEvalCallback` evaluates the deterministic policy
  on fixed targets and logs the ``eval/*`` tags and ``paths/eval`` shared with the Q-learning
  runs (docs/design.md §10); checkpoints are written atomically (:class:`AtomicCheckpoint`,
  :func:`save_model`);
- :mod:`aftir_rl.rl.sb3.loading`: a saved model is built from its config (:func:`build_model`)
  and loaded without unpickling anything (:func:`load_model`, :func:`load_run`);
- :mod:`aftir_rl.rl.sb3.vec_adapter`: :func:`make_sb3_vec_env`, the SB3 ``VecEnv`` of any env of
  the package (the batched one where it has one), for code of your own.
"""

from __future__ import annotations

from aftir_rl.rl.sb3.config import (
    ALGORITHMS,
    ENV_KWARGS,
    GOAL_ENV_IDS,
    HER_KWARGS,
    OBJECT_KEYS,
    SB3Config,
    TrainConfig,
    build_model,
    check_sb3_config,
    constructor_keys,
    sb3_config_from_run,
)
from aftir_rl.rl.sb3.evaluation import (
    EVAL_SEED,
    ArmEvalCallback,
    AtomicCheckpoint,
    Period,
    evaluate_policy_on_targets,
    evaluation_env_kwargs,
    evaluation_targets,
    save_model,
)
from aftir_rl.rl.sb3.hyperparams import entry_config, load_sb3_config, train_config
from aftir_rl.rl.sb3.loading import MAX_MODEL_BYTES, load_model, load_run, newest_model
from aftir_rl.rl.sb3.vec_adapter import SB3VectorEnv, make_sb3_vec_env

__all__ = [
    "ALGORITHMS",
    "ENV_KWARGS",
    "EVAL_SEED",
    "GOAL_ENV_IDS",
    "HER_KWARGS",
    "MAX_MODEL_BYTES",
    "OBJECT_KEYS",
    "SB3Config",
    "TrainConfig",
    "ArmEvalCallback",
    "AtomicCheckpoint",
    "Period",
    "SB3VectorEnv",
    "build_model",
    "check_sb3_config",
    "constructor_keys",
    "entry_config",
    "evaluate_policy_on_targets",
    "evaluation_env_kwargs",
    "evaluation_targets",
    "load_model",
    "load_run",
    "load_sb3_config",
    "make_sb3_vec_env",
    "newest_model",
    "save_model",
    "sb3_config_from_run",
    "train_config",
]
