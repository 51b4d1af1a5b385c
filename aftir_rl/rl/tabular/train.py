"""Tabular Q-learning runs: one run directory per target, or one for every target.

:func:`train_q_table` learns each target (``AFTIR-Tank-v0``), replays the greedy cell path
(:func:`aftir_rl.rl.tabular.paths.path_summary`) and turns it into a follow-the-leader motion or
the papers' postures per cell (:mod:`aftir_rl.rl.tabular.path_logs`); stopped (Ctrl-C), it keeps
its Q-table in its unfinished run directory, which ``resume`` finishes.
:func:`train_q_table_all_targets` runs goal-conditioned Q-learning on ``AFTIR-TankGoal-v0``. The
run directory's files are described in :mod:`aftir_rl.cli.train`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from aftir_rl.core import interrupts
from aftir_rl.core.config import DEFAULT_BRIDGE_SECONDS, DEFAULT_MARGIN, brief, from_mapping
from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.files import DISK_ERRNOS, staged_dir, unfinished_start, write_json
from aftir_rl.core.tank.loading import keep_run_tank, resolve_run_tank
from aftir_rl.rl.common import check_env_id, hyperparameter_text, run_name
from aftir_rl.rl.logs import run_logger
from aftir_rl.rl.tabular.path_logs import MotionOptions, log_greedy_path
from aftir_rl.rl.tabular.paths import path_summary

if TYPE_CHECKING:
    import gymnasium as gym

    from aftir_rl.envs.tank_grid import TankGridEnv
    from aftir_rl.rl.tabular.learning import QLearningConfig, TabularAgent
    from aftir_rl.rl.tabular.q_table import QLearning
    from aftir_rl.rl.tabular.q_table_goal import GoalQLearning

__all__ = ["resumed_target", "train_q_table", "train_q_table_all_targets"]

#: The table of an ``--all-targets`` run.
GOAL_TABLE = "q_table_goal.npz"


def train_q_table(
    config: QLearningConfig,
    targets: Sequence[Sequence[float]],
    seed: int = 0,
    logdir: str | Path = "runs",
    resume: str | Path | None = None,
    progress_bar: bool = True,
    postures: bool = True,
    bridge_seconds: float = DEFAULT_BRIDGE_SECONDS,
    motion: str = "ftl",
    margin: float = DEFAULT_MARGIN,
) -> list[dict[str, Any]]:
    """Train one Q-table per target and write a run directory for each.

    Args:
        config: a ``QLearningConfig``.
        targets: target points [cm].
        seed: seed of exploration and of the env.
        logdir: parent of the run directories.
        resume: a ``q_table.npz`` (or a run directory holding one) to continue training from;
            only with a single target, which must be the checkpoint's. An unfinished run's
            (a ``.partial`` directory, left by a stop request) is finished: it trains what is
            left of ``config.episodes`` counted from where that run started, so it ends with
            the Q-table an uninterrupted run learns; a finished run's trains
            ``config.episodes`` more.
        progress_bar: show a tqdm bar per target.
        postures: turn the greedy path into joint variables (``trajectory.json``, a picture of
            the arm under ``paths/<target>_arm``).
        bridge_seconds: RRT-Connect's budget for each move of that trajectory that collides
            (0: none; see :func:`aftir_rl.planning.jointspace.bridge`); ``progressive`` only.
        motion: ``"ftl"`` (default): a follow-the-leader motion along a route planned from the
            learned cells (:func:`aftir_rl.planning.ftl.plan.plan_motion`); ``"progressive"``: the
            papers' way, a posture per cell continued from the previous one.
        margin: clearance [cm] the arm's surface keeps along the motion (``ftl``).

    Returns:
        One summary dict per target (what ``path.json`` holds, plus ``run_dir`` and ``seconds``).

    Raises:
        TargetError: a target outside the box, in an obstructed cell or unreachable; checked for
            every target before any training starts.
        CheckpointError: ``resume`` is unreadable or was trained for another env or target.
        KeyboardInterrupt: a stop request (Ctrl-C, SIGTERM), once the target's Q-table so far
            is saved in its partial run directory; the message says how to continue.

    """
    check_env_id(config.env_id, ("AFTIR-Tank-v0",), "q_table")
    # Make (and so validate) every env before training anything.
    envs = _make_target_envs(config, targets)
    checkpoint = _checkpoint_path(resume, len(envs))
    options = MotionOptions(postures, bridge_seconds, motion, margin)
    summaries = []
    for target, env in zip(targets, envs):
        agent = _make_agent(config, env, checkpoint, seed)
        start = _run_start(agent, checkpoint)
        summary = _train_target_run(
            agent, env, config, target, seed, start, Path(logdir), progress_bar, options
        )
        summaries.append(summary)
    return summaries


def _make_target_envs(
    config: QLearningConfig, targets: Sequence[Sequence[float]]
) -> list[gym.Env[Any, Any]]:
    """Make one ``AFTIR-Tank-v0`` env per target (which validates every target)."""
    import gymnasium as gym

    return [
        gym.make(
            config.env_id,
            tank=config.tank,
            target=tuple(float(v) for v in t),
            step_penalty=config.step_penalty,
            max_episode_steps=config.max_episode_steps,
        )
        for t in targets
    ]


def _checkpoint_path(resume: str | Path | None, n_targets: int) -> Path | None:
    """The ``q_table.npz`` to resume from (``None``: train from scratch).

    Raises:
        CheckpointError: a checkpoint is given with more than one target.

    """
    if resume is None:
        return None
    checkpoint = _table_path(resume, all_targets=False)
    if n_targets != 1:
        raise CheckpointError("--resume continues one run: give at most one --target")
    return checkpoint


def _table_path(resume: str | Path, all_targets: bool) -> Path:
    """The checkpoint ``resume`` names: itself, or the table file of the run directory it is."""
    path = Path(resume)
    return path / (GOAL_TABLE if all_targets else "q_table.npz") if path.is_dir() else path


def resumed_target(resume: str | Path) -> list[float]:
    """The target a Q-table checkpoint (or the run directory holding one) was trained for.

    Raises:
        CheckpointError: unreadable, or it does not say.

    """
    from aftir_rl.rl.tabular.q_table import QLearning

    checkpoint = _checkpoint_path(resume, 1)
    assert checkpoint is not None
    _, meta = QLearning.read_checkpoint(checkpoint)
    if meta.get("target") is None:  # checked as 3 numbers when present
        raise CheckpointError(f"{checkpoint}: it names no target; give --target")
    return [float(v) for v in meta["target"]]


def resumed_config(resume: str | Path, all_targets: bool = False) -> Any | None:
    """The ``QLearningConfig`` the run of a checkpoint was trained with, in the tank it keeps.

    ``resume`` is a ``q_table.npz`` (``q_table_goal.npz`` with ``all_targets``) or the run
    directory holding it; with this config, ``--resume DIR`` alone finishes the run as it was
    started (its episodes, hyperparameters and tank). None if it holds no config.

    Raises:
        CheckpointError: unreadable.
        ConfigError: its config or tank is not one this package writes.

    """
    from aftir_rl.rl.tabular.q_table import QLearning, QLearningConfig
    from aftir_rl.rl.tabular.q_table_goal import GoalQLearning

    path = _table_path(resume, all_targets)
    meta = (
        GoalQLearning.read_checkpoint(path)[2]
        if all_targets
        else QLearning.read_checkpoint(path)[1]
    )
    data = meta.get("config")
    if not isinstance(data, dict):
        return None
    config = from_mapping(QLearningConfig, data, f"{path}: config")
    return dataclasses.replace(config, tank=resolve_run_tank(meta.get("tank"), path.parent))


def _make_agent(
    config: QLearningConfig, env: gym.Env[Any, Any], checkpoint: Path | None, seed: int
) -> QLearning:
    """A fresh agent, or the checkpoint's after checking it was trained for this target and tank.

    Raises:
        CheckpointError: the checkpoint was trained for another target cell or tank.

    """
    from aftir_rl.rl.tabular.q_table import QLearning

    if checkpoint is None:
        return QLearning.from_config(env, config, seed=seed)
    base = cast("TankGridEnv", env.unwrapped)  # config.env_id is AFTIR-Tank-v0 (checked)
    agent = QLearning.load(checkpoint, env)
    meta = agent.metadata
    if meta.get("target_cell") not in (None, list(base.target_cell)):
        raise CheckpointError(
            f"{checkpoint}: trained for target cell {meta['target_cell']}, not "
            f"{list(base.target_cell)}; resume with the same --target"
        )
    if meta.get("tank_fingerprint", base.tank.fingerprint) != base.tank.fingerprint:
        raise CheckpointError(
            f"{checkpoint}: trained in another tank ({brief(meta.get('tank'))}) than "
            f"{config.tank!r}; resume with the tank it was trained in"
        )
    return agent


def _run_start(agent: TabularAgent, checkpoint: Path | None) -> int:
    """The episode count the run counts ``config.episodes`` from.

    Resuming an unfinished run (stopped by Ctrl-C) continues it: from that run's own start.
    """
    done = agent.episodes_done
    start = (unfinished_start(checkpoint) or {}).get("episodes") if checkpoint else None
    return start if start is not None and start <= done else done


def _train_target_run(
    agent: QLearning,
    env: gym.Env[Any, Any],
    config: QLearningConfig,
    target: Sequence[float],
    seed: int,
    start: int,
    logdir: Path,
    progress_bar: bool,
    options: MotionOptions,
) -> dict[str, Any]:
    """Train ``agent`` on one target, ``config.episodes`` from episode ``start``; its run dir.

    The partial directory holds a checkpoint every ``config.log_interval`` episodes and when
    learning ends; on a stop request (or Ctrl-C) the Q-table so far is saved there too. A run
    that stops, fails or is killed after its first checkpoint leaves the partial directory to
    resume from (``aftir runs`` lists it).

    Returns:
        The target's summary (what ``path.json`` holds, plus ``run_dir`` and ``seconds``).

    Raises:
        KeyboardInterrupt: a stop request, once the Q-table is saved; its message says where.

    """
    episodes = max(0, config.episodes - (agent.episodes_done - start))
    extra = _checkpoint_extra(env, config, target)
    run_dir = logdir / run_name("q_table", config.env_id, target, seed)
    staged = staged_dir(run_dir, keep=_has_q_table, start={"episodes": start})
    with staged as partial, run_logger(partial) as logger:
        try:
            params = {**dataclasses.asdict(config), "seed": seed, "target": list(target)}
            logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))
            extra["tank"] = keep_run_tank(extra["tank"], partial)

            def save(agent: QLearning) -> bool:  # a checkpoint to resume from if killed
                agent.save(partial / "q_table.npz", extra=extra)
                return True

            summary, trajectory = _learn_target(
                agent, env, config, target, seed, logger, episodes, progress_bar, options, save
            )
            _save_target_run(partial, summary, trajectory, extra)
        except (KeyboardInterrupt, OSError) as exc:
            _keep_learnt(agent, partial, extra, exc)
            raise
    summary["run_dir"] = str(run_dir)
    return summary


def _keep_learnt(
    agent: QLearning, partial: Path, extra: dict[str, Any], exc: BaseException
) -> None:
    """Save the Q-table learnt so far in ``partial`` when ``exc`` ended its run, to resume from.

    Raises:
        KeyboardInterrupt: ``exc`` is one (a stop request): once saved, saying where.

    """
    if isinstance(exc, KeyboardInterrupt):
        agent.save(partial / "q_table.npz", extra=extra)
        raise KeyboardInterrupt(
            f"the Q-table after {agent.episodes_done} episodes is saved in {partial}; "
            f"continue with --resume {partial}"
        ) from None
    if isinstance(exc, OSError) and exc.errno in DISK_ERRNOS:
        try:  # a full disk may still take the (small) table that a log write did not fit in
            agent.save(partial / "q_table.npz", extra=extra)
        except OSError:
            pass


def _learn_target(
    agent: QLearning,
    env: gym.Env[Any, Any],
    config: QLearningConfig,
    target: Sequence[float],
    seed: int,
    logger: Any,
    episodes: int,
    progress_bar: bool,
    options: MotionOptions,
    save: Callable[[QLearning], bool],
) -> tuple[dict[str, Any], Any]:
    """Learn ``episodes`` episodes, replay the greedy path and plan its motion; log them.

    ``save`` writes a checkpoint: every ``config.log_interval`` episodes and once learning ends,
    before the motion is planned, so that a killed run leaves a table to resume from.

    Returns:
        The summary and the FTL plan or posture trajectory (``None`` without ``postures``).

    Raises:
        KeyboardInterrupt: a stop request (after the current episode, when learning).

    """
    logger.dump(step=agent.num_timesteps)
    start = time.perf_counter()
    with interrupts.deferred():  # a stop request ends learning after the current episode
        agent.learn(
            episodes,
            callback=save,
            progress_bar=progress_bar,
            logger=logger,
            log_interval=config.log_interval,
        )
    if interrupts.requested():
        raise KeyboardInterrupt
    seconds = time.perf_counter() - start
    save(agent)
    summary = path_summary(agent, env, target, config.max_episode_steps)
    summary["seconds"] = seconds
    trajectory = log_greedy_path(logger, env, summary, target, seed, options)
    logger.dump(step=agent.num_timesteps)
    return summary, trajectory


def _has_q_table(partial: Path) -> bool:
    return (partial / "q_table.npz").is_file()


def _has_goal_table(partial: Path) -> bool:
    return (partial / GOAL_TABLE).is_file()


def _checkpoint_extra(
    env: gym.Env[Any, Any], config: QLearningConfig, target: Sequence[float]
) -> dict[str, Any]:
    """What a target's ``q_table.npz`` holds besides the agent's own metadata."""
    base = cast("TankGridEnv", env.unwrapped)
    return {
        "env_id": config.env_id,
        "tank": config.tank,
        "tank_fingerprint": base.tank.fingerprint,
        "target": [float(v) for v in target],
        "target_cell": list(base.target_cell),
        "config": dataclasses.asdict(config),
    }


def _save_target_run(
    partial: Path,
    summary: dict[str, Any],
    trajectory: Any,
    extra: dict[str, Any],
) -> None:
    """Write ``path.json`` and (if any) ``trajectory.json`` into ``partial``.

    The Q-table is there already (saved when learning ended); ``extra["tank"]`` is what the run
    keeps as its tank (:func:`~aftir_rl.core.tank.keep_run_tank`, done when the run started).
    """
    write_json(partial / "path.json", {**summary, "tank": extra["tank"]})
    if trajectory is not None:
        write_json(partial / "trajectory.json", trajectory.to_json())


def train_q_table_all_targets(
    config: QLearningConfig,
    seed: int = 0,
    logdir: str | Path = "runs",
    progress_bar: bool = True,
    resume: str | Path | None = None,
) -> dict[str, Any]:
    """One goal-conditioned Q-learning run for every reachable cell of the tank.

    Writes ``runs/q_table_goal__AFTIR-TankGoal-v0__all__{seed}__{time}/`` with
    ``q_table_goal.npz``, ``summary.json``, ``progress.csv`` and TensorBoard events
    (``eval/success_rate``: the share of goals whose greedy path reaches them). A stop request
    (Ctrl-C) ends learning after the current sweep over the goals and keeps the table, with its
    generator's state, in the unfinished run directory; ``resume`` (that directory, or its
    ``q_table_goal.npz``) finishes it to the table an uninterrupted run of the seed learns; a
    finished run's trains ``config.episodes`` more.

    Raises:
        CheckpointError: ``resume`` is unreadable or was trained in another tank.
        KeyboardInterrupt: a stop request, once the table is saved; its message says where.

    """
    from aftir_rl.rl.tabular.q_table_goal import train_all_targets

    agent, begin = _goal_agent(config, seed, resume)
    seed = agent.seed if agent.seed is not None else seed
    episodes = max(0, config.episodes - (agent.episodes_done - begin))
    name = run_name("q_table_goal", "AFTIR-TankGoal-v0", "all", seed)
    extra = {"config": dataclasses.asdict(config), "tank": config.tank}
    staged = staged_dir(Path(logdir) / name, keep=_has_goal_table, start={"episodes": begin})
    with staged as partial, run_logger(partial) as logger:
        params = {**dataclasses.asdict(config), "seed": seed, "target": "all"}
        logger.record("hyperparameters", hyperparameter_text(params), exclude=("csv",))
        extra["tank"] = keep_run_tank(config.tank, partial)

        def save(agent: GoalQLearning) -> bool:  # a checkpoint per sweep, to resume from
            agent.save(partial / GOAL_TABLE, extra=extra)
            return not interrupts.requested()

        with interrupts.deferred():  # a stop request ends learning after the current sweep
            agent, summary = train_all_targets(
                config=config,
                episodes=episodes,
                logger=logger,
                progress_bar=progress_bar,
                callback=save,
                agent=agent,
            )
        if interrupts.requested():
            agent.save(partial / GOAL_TABLE, extra=extra)
            raise KeyboardInterrupt(
                f"the table after {agent.episodes_done} episodes per goal is saved in "
                f"{partial}; continue with --all-targets --resume {partial}"
            )
        logger.record("eval/success_rate", summary["n_reached"] / summary["n_goals"])
        logger.record("eval/bfs_optimal_rate", summary["n_optimal"] / summary["n_goals"])
        logger.dump(step=agent.num_timesteps)
        agent.save(partial / GOAL_TABLE, extra=extra)
        summary["tank"] = extra["tank"]
        write_json(partial / "summary.json", summary)
    summary["run_dir"] = str(Path(logdir) / name)
    return summary


def _goal_agent(
    config: QLearningConfig, seed: int, resume: str | Path | None
) -> tuple[GoalQLearning, int]:
    """A new goal-conditioned agent, or ``resume``'s; and the episode count its run starts from.

    Raises:
        CheckpointError: ``resume`` is unreadable or was trained in another tank.

    """
    from aftir_rl.envs.tank_goal import TankGoalEnv
    from aftir_rl.rl.tabular.q_table_goal import GoalQLearning

    env = TankGoalEnv(tank=config.tank, step_penalty=config.step_penalty)
    if resume is None:
        return GoalQLearning.from_config(env, config, seed=seed), 0
    checkpoint = _table_path(resume, all_targets=True)
    agent = GoalQLearning.load(checkpoint, env)
    return agent, _run_start(agent, checkpoint)
