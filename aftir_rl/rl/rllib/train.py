"""PPO and SAC with RLlib on the arm envs, on this machine or a Ray cluster: :func:`train_rllib`.

``aftir train ppo|sac --rllib [--ray ADDRESS] [--env-runners N]`` trains the same config as
``aftir train ppo|sac`` (:mod:`aftir_rl.rl.rllib.config`), with RLlib's algorithm: ``N`` env runner
processes (Ray actors, anywhere on the cluster) step ``n_envs`` envs between them, the learner
runs in this process. The run directory is an SB3 run's in form: ``config.json`` (the same
keys), ``rllib.json`` (the library, its version, the env runners), TensorBoard events and
``progress.csv`` with the same ``eval/*`` tags (fixed evaluation targets, python-fcl clearance),
``rllib_module.pt`` (the policy's weights), ``checkpoints/learner_<steps>.pt`` (weights and the
optimizer's state, to resume), ``best/`` and ``summary.json``; ``aftir evaluate``, ``rollout``,
``record`` and ``view`` read it (:func:`load_rllib_run`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from aftir_rl.core import interrupts
from aftir_rl.core.config import error_line
from aftir_rl.core.errors import AftirError, CheckpointError, ConfigError
from aftir_rl.core.files import (
    atomic_open,
    check_writable_dir,
    read_json,
    run_file,
    staged_dir,
    unfinished_start,
    write_json,
)
from aftir_rl.core.tank.loading import keep_run_tank
from aftir_rl.rl.common import check_env_id, hyperparameter_text, run_name
from aftir_rl.rl.logs import run_logger
from aftir_rl.rl.rllib.config import (
    ALGORITHMS,
    INSTALL_HINT,
    LIBRARY,
    build_module,
    check_rllib_config,
    quiet_rllib,
    rllib_config,
)
from aftir_rl.rl.rllib.policy import MODULE_FILE, RLlibPolicy, learner_checkpoints
from aftir_rl.rl.sb3.config import SB3_ENV_IDS, Origins, SB3Config, check_sb3_values
from aftir_rl.rl.sb3.train import DIVERGED
from aftir_rl.rl.tensors import as_tensors, load_tensors, save_tensors

if TYPE_CHECKING:
    from stable_baselines3.common.logger import Logger

__all__ = [
    "RLLIB_FILE",
    "check_rllib_run",
    "require_rllib",
    "train_rllib",
    "load_rllib_run",
]

#: The file that marks an RLlib run directory: the library, its version and the env runners.
RLLIB_FILE = "rllib.json"
#: Before the algorithm in run directory names (``rllib-ppo__AFTIR-ArmFTL-v0__random__0__...``).
RUN_PREFIX = "rllib-"


def require_rllib() -> None:
    """Import RLlib, or say how to get it.

    Raises:
        ConfigError: RLlib (``aftir_rl[rllib]``) is not installed.

    """
    try:
        import ray.rllib  # noqa: F401
    except ImportError:
        raise ConfigError(f"--rllib needs RLlib: {INSTALL_HINT}") from None


def check_rllib_run(config: SB3Config, env_runners: int, algo: str = "ppo") -> str:
    """Check a run of ``algo`` before Ray starts; the env's bare id.

    Raises:
        ConfigError: an env ``algo`` does not train here, a value out of range, what RLlib
            cannot train as SB3 would (:func:`check_rllib_config`), or RLlib missing.

    """
    check_rllib_config(config, env_runners, algo=algo)
    bare = check_env_id(config.env_id, SB3_ENV_IDS, algo)
    check_sb3_values(config, algo, bare, Origins("config"))
    require_rllib()
    return bare


def _policy(config: SB3Config, env_id: str, algo: str) -> RLlibPolicy:
    """A new policy of ``algo`` (random weights) for the env ``config`` trains on."""
    import gymnasium as gym

    from aftir_rl.rl.sb3.evaluation import evaluation_env_kwargs

    env = gym.make(env_id, **evaluation_env_kwargs(config.env_kwargs))
    try:
        module = build_module(config, env.observation_space, env.action_space, algo)
        return RLlibPolicy(module, env.observation_space, env.action_space)
    finally:
        env.close()


def load_rllib_run(run_dir: str | Path) -> tuple[str, SB3Config, str, RLlibPolicy]:
    """``(algo, config, env_id, policy)`` of an RLlib run directory (or its ``best/``).

    The same as :func:`aftir_rl.rl.sb3.load_run` gives for an SB3 run.

    ``config.json`` is checked key by key as an SB3 run's; the weights are ``rllib_module.pt``,
    or the newest learner checkpoint of an unfinished run, read as tensors only.

    Raises:
        CheckpointError: not an RLlib run, or unreadable files.
        ConfigError: RLlib is not installed.

    """
    from aftir_rl.envs.registration import registered_env_id
    from aftir_rl.rl.sb3.config import sb3_config_from_run

    run_dir = Path(run_dir)
    source = str(run_dir / "config.json")
    read_json(run_file(run_dir, RLLIB_FILE), RLLIB_FILE)
    algo, config = sb3_config_from_run(read_json(run_file(run_dir, "config.json")), source)
    env_id = f"aftir_rl:{registered_env_id(config.env_id, source)}"
    if algo not in ALGORITHMS:
        raise CheckpointError(f"{source}: algo {algo}: RLlib runs are {', '.join(ALGORITHMS)}")
    require_rllib()
    policy = _policy(config, env_id, algo)
    weights_file = run_dir / MODULE_FILE
    if weights_file.exists():
        weights = load_tensors(run_file(run_dir, MODULE_FILE), "an RLlib run's weights")
    else:
        found = learner_checkpoints(run_dir)
        if not found:
            raise CheckpointError(f"{run_dir}: no {MODULE_FILE} and no learner checkpoint")
        state = load_tensors(found[-1][1], "an RLlib run's learner state")
        weights = policy.acting(_module_weights(state, str(found[-1][1])))
    policy.load_weights(weights, str(weights_file))
    return algo, config, env_id, policy


def _module_weights(state: Any, source: str) -> dict[str, Any]:
    """The policy's ``state_dict`` in a learner state (``LearnerGroup.get_state``'s form)."""
    for key in ("learner", "rl_module", "default_policy"):
        if not isinstance(state, dict) or not isinstance(state.get(key), dict):
            raise CheckpointError(f"{source}: not an RLlib learner state")
        state = state[key]
    return cast(dict[str, Any], state)


def _learner_state(algo: Any) -> dict[str, Any]:
    """The learner's module weights and optimizer state (no metrics)."""
    return algo.learner_group.get_state(components=["learner/rl_module", "learner/optimizer"])


@dataclass(frozen=True)
class _Resumed:
    """Where a resumed run goes on from: its learner state, steps and its run's start."""

    state: dict[str, Any]
    steps: int
    start: int
    path: Path


def _resumed(resume: str | Path) -> _Resumed:
    """The newest learner checkpoint of the RLlib run ``resume`` names.

    Raises:
        CheckpointError: not an RLlib run, or no readable checkpoint.

    """
    folder = Path(resume)
    if folder.is_file():  # a checkpoint file inside a run
        folder = folder.parent.parent
    if not (folder / RLLIB_FILE).is_file():
        raise CheckpointError(f"--resume {resume}: not an RLlib run directory (no {RLLIB_FILE})")
    found = learner_checkpoints(folder)
    if not found:
        raise CheckpointError(f"--resume {resume}: no checkpoints/learner_<steps>.pt to resume")
    steps, path = found[-1]
    state = load_tensors(path, "an RLlib run's learner state")
    _module_weights(state, str(path))
    started = (unfinished_start(folder) or {}).get("timesteps")
    start = started if started is not None and started <= steps else steps
    return _Resumed(state, steps, start, path)


class TrainingFailed(AftirError):
    """RLlib's training stopped with an error (an env runner died, NaN weights...)."""


def train_rllib(
    config: SB3Config,
    *,
    algo: str = "ppo",
    seed: int = 0,
    logdir: str | Path = "runs",
    resume: str | Path | None = None,
    env_runners: int = 1,
    progress_bar: bool = True,
) -> dict[str, Any]:
    """Train ``algo`` (``ppo``, ``sac``) with RLlib on ``config``'s env; one run directory.

    The run directory and its files: the module docstring. SAC resumes its networks and
    optimizers; its replay buffer starts empty again.

    Runs on the Ray this process is connected to (``aftir`` connects to ``--ray ADDRESS``,
    :func:`aftir_rl.experiments.distributed.ray_session`); without one, RLlib starts a local
    Ray. ``resume``: an RLlib run directory whose newest learner checkpoint training continues
    from; an unfinished one (stopped by Ctrl-C) is finished where an uninterrupted run would
    end, a finished one trains ``total_timesteps`` more.

    Raises:
        ConfigError: the config, the options or ``logdir`` are refused, RLlib is missing, or
            the cluster has fewer CPUs than ``env_runners``.
        CheckpointError: ``resume`` is unreadable.
        KeyboardInterrupt: a stop request, once the learner state is saved; its message says
            where.
        TrainingFailed: RLlib's training raised, or a loss is no longer finite (the run folder
            is kept when it holds a checkpoint).

    """
    bare = check_rllib_run(config, env_runners, algo)
    import ray

    from aftir_rl.rl.sb3.evaluation import evaluation_targets

    folder = check_writable_dir(logdir)
    resumed = _resumed(resume) if resume is not None else None
    env_id = f"aftir_rl:{bare}"
    targets = evaluation_targets(env_id, config.eval_targets, env_kwargs=config.env_kwargs)
    policy = _policy(config, env_id, algo)
    with quiet_rllib():
        if not ray.is_initialized():
            ray.init(
                num_cpus=max(env_runners, 1), include_dashboard=False, logging_level=logging.ERROR
            )
        cluster = _cluster(env_runners)
        rl: Any = rllib_config(algo, config, env_id, seed, env_runners).build_algo()
    try:
        if resumed is not None:
            _restore(rl, resumed, policy)
        trainer = _Trainer(rl, algo, config, env_id, policy, targets, seed, resumed)
        run_dir = folder / run_name(RUN_PREFIX + algo, bare, "random", seed)
        return trainer.run(run_dir, progress_bar, {"env_runners": env_runners, **cluster})
    finally:
        rl.stop()


def _restore(algo: Any, resumed: _Resumed, policy: RLlibPolicy) -> None:
    """The learner and the env runners' weights as the checkpoint has them.

    The weights are checked against ``policy`` (this config's network) first.

    Raises:
        CheckpointError: the checkpoint does not fit this config's network or optimizer.

    """
    weights = policy.acting(_module_weights(resumed.state, str(resumed.path)))
    policy.load_weights(weights, str(resumed.path))
    try:
        algo.learner_group.set_state(resumed.state)
    except Exception as exc:  # RLlib's and torch's errors for a state of another network
        raise CheckpointError(
            f"{resumed.path}: does not fit this run's network or optimizer ({error_line(exc, 160)})"
        ) from None
    algo.env_runner_group.sync_weights(
        from_worker_or_learner_group=algo.learner_group, inference_only=True
    )


def _cluster(env_runners: int) -> dict[str, int]:
    """The Ray cluster's live nodes and CPUs; refused if too few CPUs for the env runners.

    Raises:
        ConfigError: fewer CPUs than env runners (RLlib would wait for them forever).

    """
    import ray

    nodes = [node for node in ray.nodes() if node.get("Alive")]
    cpus = int(sum(node.get("Resources", {}).get("CPU", 0) for node in nodes))
    if env_runners > cpus:
        raise ConfigError(
            f"--env-runners {env_runners} needs {env_runners} CPUs; the Ray cluster has {cpus}"
        )
    return {"nodes": len(nodes), "cpus": cpus}


#: SB3's TensorBoard tags of the learners' numbers, and RLlib's names of them.
_LOSS_TAGS = {
    "ppo": {
        "train/policy_gradient_loss": "policy_loss",
        "train/value_loss": "vf_loss",
        "train/loss": "total_loss",
    },
    "sac": {
        "train/actor_loss": "policy_loss",
        "train/critic_loss": "qf_loss",
        "train/ent_coef_loss": "alpha_loss",
        "train/ent_coef": "alpha_value",
    },
}


class _Trainer:
    """One RLlib run: train, log, evaluate, checkpoint, write the run directory."""

    def __init__(
        self,
        algo: Any,
        name: str,
        config: SB3Config,
        env_id: str,
        policy: RLlibPolicy,
        targets: list[np.ndarray],
        seed: int,
        resumed: _Resumed | None,
    ) -> None:
        from aftir_rl.rl.sb3.evaluation import Period

        self.algo, self.name, self.config = algo, name, config
        self.env_id, self.policy = env_id, policy
        self.targets, self.seed, self.resumed = targets, seed, resumed
        self.offset = resumed.steps if resumed else 0
        self.start = resumed.start if resumed else 0
        self.steps = self.logged = self.offset
        self.evals, self.checkpoints = Period(config.eval_freq), Period(config.checkpoint_freq)
        self.evals.start(self.steps)
        self.checkpoints.start(self.steps)
        self.last_metrics: dict[str, float] = {}
        self.evaluated_at: int | None = None
        self.best: tuple[float, float] | None = None
        self.best_metrics: dict[str, float] = {}

    def run(self, run_dir: Path, progress_bar: bool, extra: dict[str, Any]) -> dict[str, Any]:
        """Train what is left of ``total_timesteps`` and write the run directory."""
        staged = staged_dir(run_dir, keep=_kept_on_failure, start={"timesteps": self.start})
        with staged as partial, run_logger(partial) as logger:
            self._write_config(partial, logger, extra)
            began = time.perf_counter()
            with interrupts.deferred():
                self._train(partial, logger, progress_bar)
                self._set_policy()
                if self.evaluated_at != self.steps:  # the last weights, as SB3's runs end
                    self._evaluate(partial, logger)
                save_tensors(self.policy.module.state_dict(), partial / MODULE_FILE)
                self._checkpoint(partial)
            summary = {
                "algo": self.name,
                "library": LIBRARY,
                "env_id": self.config.env_id,
                "timesteps": self.steps,
                "seconds": time.perf_counter() - began,
                "run_dir": str(run_dir),
                **self.last_metrics,
                "best": self.best_metrics,
            }
            write_json(partial / "summary.json", summary)
        return summary

    def _write_config(self, partial: Path, logger: Logger, extra: dict[str, Any]) -> None:
        """``config.json`` as an SB3 run's, ``rllib.json``; the hyperparameters as text."""
        import ray

        params = {
            **dataclasses.asdict(self.config),
            "algo": self.name,
            "seed": self.seed,
            "resume": str(self.resumed.path) if self.resumed else None,
        }
        if "tank" in self.config.env_kwargs:  # a tank given by path travels with the run
            tank = keep_run_tank(self.config.env_kwargs["tank"], partial)
            params["env_kwargs"] = {**self.config.env_kwargs, "tank": tank}
        write_json(partial / "config.json", params)
        write_json(partial / RLLIB_FILE, {"library": LIBRARY, "ray": ray.__version__, **extra})
        logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))

    def _train(self, partial: Path, logger: Logger, progress_bar: bool) -> None:
        """``algo.train()`` until the run's steps are done, or a stop is requested."""
        from tqdm import tqdm

        goal = self.start + self.config.total_timesteps
        bar = tqdm(total=goal - self.start, unit="step", disable=not progress_bar)
        bar.update(self.steps - self.start)
        try:
            while self.steps < goal:
                if interrupts.requested():
                    self._stopped(partial)
                result = self._iteration(partial)
                bar.update(self.steps - bar.n - self.start)
                self._log(logger, result)
                if self.evals.due(self.steps) and not interrupts.requested():
                    self._set_policy()
                    self._evaluate(partial, logger)
                if self.checkpoints.due(self.steps) and not interrupts.requested():
                    self._checkpoint(partial)
        finally:
            bar.close()
        if interrupts.requested():
            self._stopped(partial)

    def _iteration(self, partial: Path) -> dict[str, Any]:
        """One ``algo.train()``; the run's step count updated.

        A loss that is no longer finite writes ``diverged.json`` (the step), so the run folder
        is kept with its logs, and raises :class:`TrainingFailed` saying where.
        """
        try:
            result = self.algo.train()
        except Exception as exc:  # an env runner's error comes back as Ray's, with a traceback
            raise TrainingFailed(f"RLlib's training failed: {error_line(exc, 300)}") from None
        sampled = result.get("env_runners", {}).get("num_env_steps_sampled_lifetime")
        if sampled is None:
            sampled = result.get("num_env_steps_sampled_lifetime", 0)
        self.steps = self.offset + int(sampled)
        losses = result.get("learners", {}).get("default_policy", {})
        if not all(np.isfinite(float(v)) for k, v in losses.items() if k.endswith("loss")):
            write_json(partial / DIVERGED, {"step": self.steps, "library": LIBRARY})
            raise TrainingFailed(
                f"training diverged at step {self.steps} (a loss is not finite); its logs are "
                f"kept in {partial}; lower the learning rate"
            )
        return result

    def _log(self, logger: Logger, result: dict[str, Any]) -> None:
        """The iteration's numbers under SB3's tags (``rollout/``, ``train/``, ``time/``)."""
        runners = result.get("env_runners", {})
        losses = result.get("learners", {}).get("default_policy", {})
        seconds = float(result.get("time_this_iter_s", 0.0)) or float("nan")
        batch, self.logged = self.steps - self.logged, self.steps
        numbers = {
            "rollout/ep_rew_mean": runners.get("episode_return_mean"),
            "rollout/ep_len_mean": runners.get("episode_len_mean"),
            "time/fps": batch / seconds,
            "time/total_timesteps": self.steps,
        }
        for tag, key in _LOSS_TAGS[self.name].items():
            numbers[tag] = losses.get(key)
        if self.name == "ppo" and losses.get("entropy") is not None:
            numbers["train/entropy_loss"] = -float(losses["entropy"])
        for key, value in numbers.items():
            if value is not None and np.isfinite(float(value)):
                logger.record(key, float(value))
        logger.dump(self.steps)

    def _set_policy(self) -> None:
        """The learner's weights into the policy evaluation runs."""
        state = self.algo.learner_group.get_state(
            components="learner/rl_module", inference_only=True
        )
        weights = _module_weights(as_tensors(state), "the learner")
        self.policy.load_weights(weights, "the learner")

    def _evaluate(self, partial: Path, logger: Logger) -> None:
        """The policy on the fixed evaluation targets: ``eval/*``; the best kept in ``best/``."""
        from aftir_rl.rl.sb3.evaluation import evaluate_policy_on_targets

        metrics, _ = evaluate_policy_on_targets(
            self.policy,
            self.env_id,
            self.targets,
            clearance=True,
            env_kwargs=self.config.env_kwargs,
        )
        for key, value in metrics.items():
            logger.record(f"eval/{key}", value)
        self.last_metrics, self.evaluated_at = metrics, self.steps
        error = metrics["tip_error_cm"]
        score = (metrics["success_rate"], -error if np.isfinite(error) else -np.inf)
        if self.best is None or score > self.best:
            self.best, self.best_metrics = score, {**metrics, "timesteps": self.steps}
            best = partial / "best"
            best.mkdir(exist_ok=True)
            save_tensors(self.policy.module.state_dict(), best / MODULE_FILE)
            for name in ("config.json", RLLIB_FILE):
                with atomic_open(best / name, "wb") as fh:
                    fh.write((partial / name).read_bytes())
            write_json(best / "best.json", self.best_metrics)
            logger.record("eval/best_success_rate", metrics["success_rate"])
        logger.dump(self.steps)

    def _checkpoint(self, partial: Path) -> Path:
        """``checkpoints/learner_<steps>.pt``: the learner's weights and optimizer state."""
        return save_tensors(
            _learner_state(self.algo), partial / "checkpoints" / f"learner_{self.steps}.pt"
        )

    def _stopped(self, partial: Path) -> None:
        """Save the learner as of now and raise KeyboardInterrupt saying how to go on."""
        path = self._checkpoint(partial)
        for steps, other in learner_checkpoints(partial):
            if steps > self.steps:
                other.unlink(missing_ok=True)
        raise KeyboardInterrupt(
            f"the learner at step {self.steps} is saved in {path.parent}; continue with "
            f"--rllib --resume {partial}"
        )


def _kept_on_failure(partial: Path) -> bool:
    """Keep a failed run's folder when it can be resumed or it diverged (its logs say how)."""
    return bool(learner_checkpoints(partial)) or (partial / DIVERGED).exists()
