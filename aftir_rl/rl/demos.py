"""Expert demonstrations of ``AFTIR-ArmFTL-v0`` as a Minari dataset.

:func:`write_dataset` plans each episode's motion with :class:`~aftir_rl.rl.expert.FTLExpert`
(in ``workers`` processes), then steps the env through it and writes the episodes with Minari:
observations as the env gives them, actions, rewards, terminations and the step infos
``compute_reward`` needs (``prev_achieved_goal``, for HER). Episode ``j`` draws its target with
the reset seed ``seed + j'``, where ``j'`` counts targets tried: a target the expert finds no
motion for within its budget is skipped (and counted). Episodes are written in chunks, so a run
stopped between chunks resumes from the dataset on disk with the same seeds.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import re
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError
from aftir_rl.envs.registration import ARM_FTL

__all__ = ["DATASET_ID", "check_dataset_id", "write_dataset"]

#: The dataset id :func:`write_dataset` writes by default.
DATASET_ID = "aftir/armftl-expert-v0"
_DATASET_ID = re.compile(r"[A-Za-z0-9_-]+/[A-Za-z0-9_.-]+-v[0-9]+")
#: Episodes per chunk written to disk.
_CHUNK = 25
_EXPERT: Any = None  # a worker's expert (made once per process)


def _init_worker(env_kwargs: dict[str, Any], max_seconds: float) -> None:
    global _EXPERT  # the expert plans in numpy and numba: no torch in the workers
    import numba

    from aftir_rl.rl.expert import FTLExpert

    if multiprocessing.parent_process() is not None:  # the processes share the cores
        numba.set_num_threads(1)
    _EXPERT = FTLExpert(max_seconds=max_seconds, **env_kwargs)


def _plan(job: tuple[int, NDArray[np.float64]]) -> tuple[int, NDArray[np.float32] | None]:
    seed, target = job
    plan = _EXPERT.plan(target)
    return seed, None if plan is None else plan.actions


@contextlib.contextmanager
def _planner(workers: int, env_kwargs: dict[str, Any], max_seconds: float) -> Iterator[Any]:
    """``map`` over ``workers`` planning processes (in this process for one).

    A worker that dies (killed, or failing to start) is a :class:`ConfigError`, not a hang.
    """
    if workers <= 1:
        _init_worker(env_kwargs, max_seconds)
        yield map
        return
    ctx = multiprocessing.get_context("spawn")
    init = (env_kwargs, max_seconds)
    with ProcessPoolExecutor(workers, ctx, initializer=_init_worker, initargs=init) as pool:
        try:
            yield pool.map
        except BrokenProcessPool:
            raise ConfigError(
                "a planning worker died (out of memory, killed, or unable to start); try "
                "--workers 1"
            ) from None


def _targets(env_kwargs: dict[str, Any], first_seed: int) -> Iterator[tuple[int, Any]]:
    env = gym.make(ARM_FTL, **env_kwargs)
    seed = first_seed
    while True:
        _, info = env.reset(seed=seed)
        yield seed, np.asarray(info["target"], dtype=np.float64)
        seed += 1


def _episode(env: gym.Env[Any, Any], seed: int, actions: NDArray[np.float32]) -> Any:
    """Step ``env`` from ``reset(seed)`` through ``actions``: Minari's buffer of the episode.

    The infos hold the same keys at reset and at every step: what ``compute_reward`` reads
    (``prev_achieved_goal``), ``is_success`` and ``contact``.
    """
    from minari.data_collector.episode_buffer import EpisodeBuffer

    obs, _ = env.reset(seed=seed)
    tip = np.asarray(obs["achieved_goal"], np.float32)
    observations, rewards, terms, truncs = [obs], [], [], []
    infos: dict[str, list[Any]] = {"prev_achieved_goal": [tip], "is_success": [False]}
    infos["contact"] = [False]
    for a in actions:
        obs, reward, term, trunc, info = env.step(a)
        observations.append(obs)
        rewards.append(float(reward))
        terms.append(bool(term))
        truncs.append(bool(trunc))
        for key in infos:
            infos[key].append(info[key])
    stacked = {k: np.stack([o[k] for o in observations]) for k in observations[0]}
    return EpisodeBuffer(
        seed=seed,
        observations=stacked,
        actions=np.asarray(actions, dtype=np.float32),
        rewards=rewards,
        terminations=terms,
        truncations=truncs,
        infos={k: np.asarray(v) for k, v in infos.items()},
    )


def check_dataset_id(dataset_id: str) -> None:
    """Refuse a dataset id that is not ``namespace/name-vN`` (a name, never a path).

    Raises:
        ConfigError: one line.

    """
    if not _DATASET_ID.fullmatch(dataset_id):
        raise ConfigError(
            f"dataset id {dataset_id[:80]!r}: expected namespace/name-vN (letters, digits, - _ .)"
        )


def _minari(dataset_id: str) -> Any:
    """The ``minari`` module, once ``dataset_id`` is checked."""
    try:
        import minari
    except ImportError:
        raise ConfigError("writing datasets needs Minari: pip install 'aftir_rl[demos]'") from None
    check_dataset_id(dataset_id)
    return minari


def _resume_point(
    minari: Any, dataset_id: str, env_kwargs: dict[str, Any], seed: int
) -> tuple[int, int]:
    """``(episodes on disk, next seed)`` of ``dataset_id``; ``(0, seed)`` when there is none.

    Raises:
        ConfigError: the dataset on disk was made with other env arguments.

    """
    if dataset_id not in minari.list_local_datasets():
        return 0, seed
    old = minari.load_dataset(dataset_id)
    made = old.spec.env_spec.kwargs if old.spec.env_spec is not None else None
    spec = gym.make(ARM_FTL, **env_kwargs).spec
    if spec is None or made != spec.kwargs:
        raise ConfigError(
            f"{dataset_id}: made with other env arguments ({made}); resume it "
            "with those or write another dataset id"
        )
    done = old.total_episodes
    metas = old.storage.get_episode_metadata(range(done))
    return done, (max(int(m["seed"]) for m in metas) + 1 if done else seed)


def _save(minari: Any, dataset_id: str, buffers: list[Any], env: gym.Env[Any, Any]) -> None:
    """Add ``buffers`` to the dataset on disk, or create it with them."""
    if dataset_id in minari.list_local_datasets():
        minari.load_dataset(dataset_id).storage.update_episodes(buffers)
    else:
        with warnings.catch_warnings():  # Minari's advice to name an author, a permalink...
            warnings.filterwarnings("ignore", category=UserWarning, module=r"minari\.")
            minari.create_dataset_from_buffers(
                dataset_id,
                buffers,
                env=env,
                algorithm_name="aftir_rl.rl.expert.FTLExpert",
                description="Follow-the-leader expert episodes of AFTIR-ArmFTL-v0",
            )


def write_dataset(
    root: str | os.PathLike[str],
    episodes: int,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
    dataset_id: str = DATASET_ID,
    workers: int = 1,
    max_seconds: float = 30.0,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Write (or complete) a Minari dataset of ``episodes`` expert episodes under ``root``.

    Args:
        root: the datasets root (what ``MINARI_DATASETS_PATH`` names).
        episodes: the episodes the dataset should hold.
        seed: the reset seed of the first target tried.
        env_kwargs: the env's keyword arguments (``steer``, ``bay``, ``guide``...).
        dataset_id: Minari's id, ``namespace/name-vN``.
        workers: processes that plan.
        max_seconds: the expert's budget per target [s].
        progress: called with ``(episodes written, episodes)`` after each episode.

    Returns:
        ``episodes`` (on disk now), ``before`` (on disk before: a dataset is completed, never
        rewritten), ``skipped`` (targets without a motion), ``steps`` (added now),
        ``dataset_id``, ``path``.

    Raises:
        ConfigError: Minari is not installed, or the dataset on disk was made differently.

    """
    minari = _minari(dataset_id)
    env_kwargs = dict(env_kwargs or {})
    os.environ["MINARI_DATASETS_PATH"] = str(Path(root).resolve())
    done, next_seed = _resume_point(minari, dataset_id, env_kwargs, seed)
    before, skipped = done, 0
    env = gym.make(ARM_FTL, **env_kwargs)
    jobs = _targets(env_kwargs, next_seed)
    steps = 0
    with _planner(workers, env_kwargs, max_seconds) as imap:
        while done < episodes:
            want = min(_CHUNK, episodes - done)
            buffers = []
            for s, actions in imap(_plan, (next(jobs) for _ in range(want))):
                if actions is None:
                    skipped += 1
                    continue
                buffers.append(_episode(env, s, actions))
                steps += len(actions)
                if progress is not None:
                    progress(done + len(buffers), episodes)
            if buffers:
                _save(minari, dataset_id, buffers, env)
            done += len(buffers)
    path = str(Path(root) / dataset_id)
    return dict(
        episodes=done, before=before, skipped=skipped, steps=steps, dataset_id=dataset_id, path=path
    )
