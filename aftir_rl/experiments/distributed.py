"""Ray plumbing: independent jobs of ``bench``, ``evaluate`` and ``tune`` fanned out as Ray tasks.

Ray is an optional extra (``pip install "aftir_rl[ray]"``); nothing here imports it before a
function is called, so the serial paths never need it. ``--ray ADDRESS`` of the command lines
names where the tasks run (:func:`ray_session`): ``local`` (an in-process Ray with ``--workers``
CPUs), ``auto`` (the cluster this machine joined with ``ray start``) or ``HOST:PORT`` (or
``ray://HOST:PORT``, a head node started with ``ray start --head``).

:func:`run_tasks` runs calls as Ray tasks and returns their results in the order of the calls; a
call that raises, or whose worker dies, comes back as a :class:`TaskFailure` holding its error,
so one failure never loses the other results. :func:`benchmark_on_ray` and :func:`evaluate_on_ray`
are what ``bench`` and ``evaluate`` run on it. Clusters (installs, shared filesystems, tokens):
docs/reference.md, "Past one machine: Ray".
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import signal
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from aftir_rl.core.config import error_line, shorten
from aftir_rl.core.errors import AftirError, CheckpointError
from aftir_rl.core.tank.raster import format_point

__all__ = [
    "INSTALL_HINT",
    "RayError",
    "TaskFailure",
    "require_ray",
    "check_address",
    "check_ray_options",
    "ray_session",
    "run_tasks",
    "benchmark_on_ray",
    "evaluate_on_ray",
]

#: How to get Ray, in every error that needs it.
INSTALL_HINT = 'pip install "aftir_rl[ray]"'

_ADDRESS = re.compile(r"^(ray://)?[A-Za-z0-9._-]{1,253}:\d{1,5}$")


class RayError(AftirError, RuntimeError):
    """Ray is missing, the address is malformed, or the cluster cannot be reached."""


@dataclass(frozen=True)
class TaskFailure:
    """A Ray task that raised or whose worker died.

    Attributes:
        error: ``"<ExceptionType>: <message>"``, one line.
        details: the traceback (the worker's, when it raised), for logs.

    """

    error: str
    details: str = ""


def require_ray() -> ModuleType:
    """Import and return ``ray``.

    Raises:
        RayError: Ray is not installed; the message says how to install it.

    """
    try:
        import ray
    except ImportError:
        raise RayError(
            f"--ray needs Ray, which is not installed; install it with {INSTALL_HINT}"
        ) from None
    return ray


def check_address(address: str) -> str:
    """``address`` if it is ``local``, ``auto``, ``HOST:PORT`` or ``ray://HOST:PORT``.

    Raises:
        RayError: anything else.

    """
    if address in ("local", "auto") or _ADDRESS.match(address):
        return address
    raise RayError(
        f"--ray {shorten(repr(address), 80)}: use local, auto, HOST:PORT or ray://HOST:PORT"
    )


def check_workers(workers: int | None) -> int | None:
    """``workers`` (CPUs of a local Ray) if ``None`` or from 1 to 1024.

    Raises:
        RayError: out of range.

    """
    if workers is not None and not 1 <= workers <= 1024:
        raise RayError(f"--workers must be from 1 to 1024, got {workers}")
    return workers


def check_ray_options(address: str | None, workers: int | None) -> None:
    """Check ``--ray`` and ``--workers`` of a command line before any work, Ray importable.

    Raises:
        RayError: a malformed address, ``--workers`` without ``--ray local`` or out of range, or
            Ray not installed (the message says how to install it).

    """
    if address is None:
        if workers is not None:
            raise RayError("--workers needs --ray local")
        return
    check_address(address)
    check_workers(workers)
    if workers is not None and address != "local":
        raise RayError("--workers sets the CPUs of --ray local; a cluster has its own")
    require_ray()


@contextlib.contextmanager
def ray_session(
    address: str, workers: int | None = None, log_to_driver: bool = False
) -> Iterator[ModuleType]:
    """Connect to Ray for the duration of a ``with`` block; yields the ``ray`` module.

    ``local`` starts an in-process Ray with ``workers`` CPUs (default: every core) and stops it
    at the end; ``auto`` and ``HOST:PORT`` join an existing cluster and leave it running. A Ray
    this process already started (a caller's own ``ray.init``) is used as it is.

    Raises:
        RayError: Ray missing, a malformed address, or no cluster at the address.

    """
    ray = require_ray()
    check_address(address)
    check_workers(workers)
    if ray.is_initialized():
        yield ray
        return
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    kwargs: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": log_to_driver,
        "logging_level": "error",
    }
    if address not in ("local", "auto"):
        _check_reachable(address)
    try:
        if address == "local":
            # "local": always a new instance, never a cluster `ray start` left on this machine
            ray.init(address="local", num_cpus=workers or os.cpu_count() or 1, **kwargs)
        else:
            ray.init(address=address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError, TimeoutError, OSError) as exc:
        raise RayError(
            f"cannot start or reach Ray at {address!r} ({error_line(exc, 160)}); start a cluster "
            "with `ray start --head` or use --ray local (a cluster with token authentication, "
            "the default of `ray start`, also needs RAY_AUTH_MODE=token and its token here)"
        ) from None
    try:
        yield ray
    finally:
        ray.shutdown()


def kill_local_workers(titles: Sequence[str], root: int | None = None) -> int:
    """SIGKILL the Ray workers below ``root`` whose process title starts with one of ``titles``.

    ``root`` defaults to this process: a local Ray it started has its raylet, and so its
    workers, below it. Process titles are ``ray::ImplicitFunc.train`` and the like. Returns how
    many were killed (0 where there is no ``/proc``).
    """
    children: dict[int, list[int]] = {}
    titles_of: dict[int, str] = {}
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmdline = (entry / "cmdline").read_bytes().split(b"\0", 1)[0]
        except (OSError, IndexError, ValueError):
            continue  # ended meanwhile, or not ours to read
        children.setdefault(ppid, []).append(int(entry.name))
        titles_of[int(entry.name)] = cmdline.decode(errors="replace")
    killed, todo = 0, list(children.get(os.getpid() if root is None else root, []))
    while todo:
        pid = todo.pop()
        todo.extend(children.get(pid, []))
        if titles_of.get(pid, "").startswith(tuple(titles)):
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
                killed += 1
    return killed


def _check_reachable(address: str, seconds: float = 10.0) -> None:
    """Fail fast (Ray itself retries for minutes) when nothing listens at ``HOST:PORT``."""
    import socket

    host, port = address.removeprefix("ray://").rsplit(":", 1)
    try:
        with socket.create_connection((host, int(port)), timeout=seconds):
            pass
    except OSError as exc:
        raise RayError(
            f"cannot reach a Ray cluster at {address} ({exc.strerror or exc}); start one with "
            "`ray start --head` there, or use --ray local"
        ) from None


def _guarded(fn: Callable[..., Any], args: tuple[Any, ...]) -> Any:
    """``fn(*args)``, or a :class:`TaskFailure` holding what it raised (runs in the worker)."""
    try:
        return fn(*args)
    except Exception as exc:  # a failed task is a result, never a lost run
        return _failure(exc)


def _failure(exc: BaseException) -> TaskFailure:
    text = " ".join(str(exc).split())
    return TaskFailure(
        shorten(f"{type(exc).__name__}: {text}" if text else type(exc).__name__, 200),
        "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)),
    )


def run_tasks(
    fn: Callable[..., Any],
    calls: Sequence[tuple[Any, ...]],
    progress: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """Run ``fn(*call)`` for every call as a Ray task; results in the order of ``calls``.

    Needs a connected Ray (:func:`ray_session`). ``fn`` must be importable on the workers (a
    module-level function of an installed package). Each task takes one CPU.

    Args:
        fn: the function run by each task.
        calls: positional arguments of each task.
        progress: called as ``progress(index, result)`` as each task finishes.

    Returns:
        ``fn``'s return value per call, or a :class:`TaskFailure` where it raised or its worker
        died.

    """
    import ray

    task = ray.remote(num_cpus=1, max_retries=0)(_guarded)
    fn_ref = ray.put(fn)
    refs = [task.remote(fn_ref, tuple(call)) for call in calls]
    index = {ref: i for i, ref in enumerate(refs)}
    results: list[Any] = [None] * len(refs)
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        for ref in done:
            try:
                result = ray.get(ref)
            except Exception as exc:  # the worker died (RayTaskError, WorkerCrashedError...)
                result = _failure(exc)
            results[index[ref]] = result
            if progress is not None:
                progress(index[ref], result)
    return results


# ---------------------------------------------------------------- bench

_PLANNERS: Any = None
#: Submission rank of the methods that take longest (lower first).
_SLOW_FIRST = {"q_table+postures": 0, "rrt_connect": 1, "q_table+ftl": 2}


def _bench_item(method: str, tank: str, target: np.ndarray, options: dict[str, Any]) -> Any:
    """One benchmark outcome (runs in a worker, which builds a planner once per tank)."""
    global _PLANNERS
    from aftir_rl.experiments.outcomes import Planners, method_outcome

    if _PLANNERS is None:
        _PLANNERS = Planners()
    return method_outcome(_PLANNERS(tank), method, target, **options)


def _failed_outcome(failure: TaskFailure) -> Any:
    from aftir_rl.experiments.outcomes import Outcome

    return Outcome(False, note=f"task failed: {failure.error}")


def benchmark_on_ray(
    sets: dict[str, list[tuple[str, np.ndarray]]],
    methods: dict[str, Sequence[str]],
    options: dict[str, Any],
    models: Sequence[str | Path] = (),
    progress: Callable[[str], None] | None = None,
) -> list[Any]:
    """The rows of :func:`~aftir_rl.experiments.bench.run_benchmark`, one Ray task per item.

    Needs a connected Ray (:func:`ray_session`). The rows come in the serial order with the same
    outcomes (:func:`aftir_rl.experiments.bench.method_outcome` restarts OMPL's seed for every item,
    so no result depends on what ran before it in a process); each SB3 run directory is one task. A
    task that fails is an outcome (or, for a run directory, a row) whose note holds its error.

    Args:
        sets: the target sets (:func:`aftir_rl.experiments.bench.target_sets`).
        methods: methods per set name.
        options: keyword arguments of :func:`aftir_rl.experiments.bench.method_outcome` (seed,
        margin...).
        models: SB3 run directories.
        progress: called with a line as each task finishes.

    """
    from aftir_rl.experiments.outcomes import sb3_outcomes

    items = [
        (name, method, tank, target)
        for name, items_ in sets.items()
        for method in methods.get(name, ())
        for tank, target in items_
    ]
    # The longest items first (the time-budgeted OMPL ones, then Q-learning), so no long task
    # starts last while the other workers idle; results are put back in the serial order.
    order = sorted(range(len(items)), key=lambda i: _SLOW_FIRST.get(items[i][1], 9))
    calls: list[tuple[Any, ...]] = [(_bench_item, items[i][1:] + (options,)) for i in order]
    calls += [(sb3_outcomes, (str(run_dir), sets)) for run_dir in models]

    def report(k: int, result: Any) -> None:
        if progress is not None:
            state = "failed" if isinstance(result, TaskFailure) else "done"
            if k < len(items):
                name, method, _, target = items[order[k]]
                progress(f"{state}: {name} {method} {format_point(target)}")
            else:
                progress(f"{state}: {models[k - len(items)]}")

    submitted = run_tasks(_call, calls, report)
    results: list[Any] = [None] * len(items) + submitted[len(items) :]
    for k, i in enumerate(order):
        results[i] = submitted[k]
    return _bench_rows(sets, methods, models, results)


def _bench_rows(
    sets: dict[str, list[tuple[str, np.ndarray]]],
    methods: dict[str, Sequence[str]],
    models: Sequence[str | Path],
    results: list[Any],
) -> list[Any]:
    """The benchmark's rows from the tasks' results in the serial order (items, then models).

    A failed task becomes an outcome (or, for a run directory, a row) whose note holds its error.
    """
    from aftir_rl.experiments.outcomes import Row

    rows: list[Any] = []
    k = 0
    for name, items_ in sets.items():
        for method in methods.get(name, ()):
            row = Row(name, method)
            for _ in items_:
                result = results[k]
                row.outcomes.append(
                    _failed_outcome(result) if isinstance(result, TaskFailure) else result
                )
                k += 1
            rows.append(row)
    for run_dir, result in zip(models, results[k:]):
        if isinstance(result, TaskFailure):
            rows.append(Row("-", Path(run_dir).name, [_failed_outcome(result)]))
        else:
            rows += result
    return rows


def _call(fn: Callable[..., Any], args: tuple[Any, ...]) -> Any:
    """``fn(*args)``: one remote function runs several module-level helpers."""
    return fn(*args)


# ---------------------------------------------------------------- evaluate


def failed_evaluation(error: str) -> dict[str, Any]:
    """A row of ``evaluate``'s table for a run whose evaluation failed."""
    nan = math.nan
    return {
        "agent": "-",
        "targets": 0,
        "success_rate": nan,
        "tip_error_cm": nan,
        "path_length_cm": nan,
        "min_clearance_cm": nan,
        "seconds_per_target": nan,
        "note": f"task failed: {error}",
    }


def evaluate_on_ray(
    runs: Sequence[str | Path],
    targets: list[np.ndarray] | None,
    motion: str,
    margin: float,
    progress: Callable[[str], None] | None = None,
    draw: tuple[int, int] | None = None,
    tank: str | None = None,
    policy_seed: int | None = None,
) -> list[dict[str, Any]]:
    """:func:`aftir_rl.cli.evaluate.evaluate_run` of every run directory, each a Ray task.

    Needs a connected Ray (:func:`ray_session`). Results in the order of ``runs``; a run whose
    evaluation fails is a row whose note holds the error (:func:`failed_evaluation`).
    """
    from aftir_rl.experiments.runs import evaluate_run, run_kind

    for r in runs:  # a path that is no run directory is the user's error, before any task
        if run_kind(r) not in ("q_table", "sb3", "rllib"):
            raise CheckpointError(
                f"{r}: not a run directory (no q_table.npz, nor model.zip or rllib.json with "
                "config.json)"
            )

    def report(k: int, result: Any) -> None:
        if progress is not None:
            state = "failed" if isinstance(result, TaskFailure) else "done"
            progress(f"{state}: {runs[k]}")

    calls = [(str(r), targets, motion, margin, draw, tank, policy_seed) for r in runs]
    results = run_tasks(evaluate_run, calls, report)
    return [failed_evaluation(r.error) if isinstance(r, TaskFailure) else r for r in results]
