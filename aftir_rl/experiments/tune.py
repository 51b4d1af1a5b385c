"""A hyperparameter sweep (``aftir tune ALGO``) of PPO, SAC or TD3 on Ray Tune.

Optuna (``OptunaSearch``) samples the algorithm's search space
(``configs/search_spaces/<algo>.yaml``,
:func:`aftir_rl.experiments.search_space.load_search_space`); ASHA stops the trials that trail
on ``eval/success_rate`` at each evaluation. Every trial is a normal SB3 run directory, so
``evaluate``, ``bench --model`` and ``view`` take it as they take any run. A sweep writes
``LOGDIR/tune__<algo>__<env>__<time>/``: one run directory per trial (one stopped early says
``"stopped_early": true`` in its ``summary.json``), ``trials.csv``, ``best.yaml`` (the best
trial's config, for ``aftir train ALGO --config``) and ``ray/`` (Ray Tune's state).

With ``--ray local`` (the default) Ray starts on this machine; ``--ray auto`` or ``HOST:PORT``
runs the trials on a cluster. Needs the ray extra: ``pip install "aftir_rl[ray]"``. More:
docs/reference.md, "Past one machine: Ray", and docs/design.md §9.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import threading
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aftir_rl.core import interrupts
from aftir_rl.core.errors import AftirError
from aftir_rl.core.files import UNFINISHED, atomic_open, check_writable_dir, write_json
from aftir_rl.experiments.distributed import kill_local_workers
from aftir_rl.experiments.search_space import DISTRIBUTIONS, Dimension, load_search_space

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

    from aftir_rl.rl.sb3.config import SB3Config

__all__ = [
    "DISTRIBUTIONS",
    "Dimension",
    "TuneError",
    "load_search_space",
    "run_sweep",
    "write_config_yaml",
]

ALGOS = ("ppo", "sac", "td3")
#: Bounds of the command line's numbers.
MAX_TRIALS, MAX_EVALUATIONS = 10_000, 100
METRIC = "eval/success_rate"
#: The file in a sweep folder that tells its trials to stop (written on Ctrl-C or SIGTERM).
STOP_FILE = ".stop"
#: Process titles of a trial's Ray worker (its actor, or a worker about to become one).
TRIAL_PROCESSES = ("ray::ImplicitFunc", "ray::_trial", "ray::IDLE")
#: Ray Tune's settings for a sweep: its own CSV/JSON/TensorBoard loggers off (the trials' run
#: directories hold the logs), and Ctrl-C left to :mod:`aftir_rl.core.interrupts`, which ends
#: the trials (``_stop_on_request``).
TUNE_ENVIRONMENT = {
    "TUNE_DISABLE_AUTO_CALLBACK_LOGGERS": "1",
    "RAY_AIR_NEW_OUTPUT": "0",
    "TUNE_DISABLE_SIGINT_HANDLER": "1",
}


class TuneError(AftirError, RuntimeError):
    """A sweep produced no trial to take a config from."""


# ---------------------------------------------------------------- one trial (a Ray worker)


def _final_name(partial: Path) -> Path:
    """``.<name>.partial`` -> ``<name>`` (train_sb3's run directory)."""
    return partial.with_name(partial.name[1 : -len(".partial")])


def _plain(value: Any) -> Any:
    """Python scalars for YAML and JSON (Optuna may give numpy types)."""
    return value.item() if hasattr(value, "item") else value


def _trial(params: dict[str, Any], algo: str, base: Any, logdir: str, seed: int) -> None:
    """Train one trial with ``params`` and report every evaluation to Ray Tune."""
    finished = threading.Event()
    flag = Path(logdir) / STOP_FILE
    threading.Thread(target=_wait_for_stop, args=(flag, finished), daemon=True).start()
    try:
        _train_trial(params, algo, base, logdir, seed)
    except KeyboardInterrupt:
        pass  # the sweep asked: the run stays unfinished with its checkpoint, to resume
    finally:
        finished.set()


def _train_trial(params: dict[str, Any], algo: str, base: Any, logdir: str, seed: int) -> None:
    from ray import tune

    from aftir_rl.rl.sb3.evaluation import save_model
    from aftir_rl.rl.sb3.train import train_sb3

    if interrupts.requested():
        return
    hyper = {**base.hyperparameters, **{k: _plain(v) for k, v in params.items()}}
    config = dataclasses.replace(base, hyperparameters=hyper)
    total = config.total_timesteps

    def metrics_of(
        model: BaseAlgorithm, metrics: dict[str, float], run_dir: Path
    ) -> dict[str, Any]:
        return {
            **{f"eval/{k}": float(v) for k, v in metrics.items()},
            "timesteps": int(model.num_timesteps),
            "run_dir": str(run_dir),
        }

    last: dict[str, Any] = {}

    def report(model: BaseAlgorithm, metrics: dict[str, float]) -> None:
        assert model.logger.dir is not None  # train_sb3 logs into the run's folder
        partial = Path(model.logger.dir)
        if model.num_timesteps >= total:  # the last one: reported once the run is complete
            last.update(metrics_of(model, metrics, _final_name(partial)))
            return
        # ASHA may stop this trial here, ending the process: the run keeps its model as it is
        save_model(model, partial / "model.zip")
        tune.report(metrics_of(model, metrics, _final_name(partial)))

    summary = train_sb3(
        algo, config, seed=seed, logdir=logdir, progress_bar=False, on_evaluation=report
    )
    tune.report({**last, "run_dir": summary["run_dir"], "completed": 1})


def _wait_for_stop(flag: Path, finished: threading.Event, grace: float = 1.5) -> None:
    """A trial's watcher thread: the sweep's stop file becomes this process's stop request.

    Ray Tune stops a trial when it reports (at an evaluation), or kills its actor 10 s after
    asking. Training stops at its next step instead, with a checkpoint; a trial still starting
    (imports) or in an evaluation after ``grace`` seconds ends its process, its run keeping its
    last checkpoint (every write is atomic).
    """
    while not flag.exists():
        if finished.wait(0.1):
            return
    interrupts.request()
    if not finished.wait(grace):
        os._exit(0)


def _finish_stopped(run_dir: Path, result: dict[str, Any], algo: str, env_id: str) -> None:
    """Turn the partial directory of a trial that ASHA stopped into a finished run directory."""
    partial = run_dir.with_name(f".{run_dir.name}.partial")
    if run_dir.exists() or not (partial / "model.zip").exists():
        return
    metrics = {k[len("eval/") :]: v for k, v in result.items() if k.startswith("eval/")}
    write_json(
        partial / "summary.json",
        {
            "algo": algo,
            "env_id": env_id,
            "timesteps": int(result.get("timesteps", 0)),
            "seconds": float(result.get("time_total_s", math.nan)),
            "run_dir": str(run_dir),
            "stopped_early": True,
            **metrics,
        },
    )
    (partial / UNFINISHED).unlink(missing_ok=True)
    partial.rename(run_dir)


# ---------------------------------------------------------------- the sweep


def run_sweep(
    algo: str,
    base: Any,
    space: Sequence[Dimension],
    trials: int,
    logdir: str | Path = "runs",
    ray: str = "local",
    workers: int | None = None,
    seed: int = 0,
    verbose: int = 1,
) -> dict[str, Any]:
    """Run ``trials`` trials of ``algo`` over ``space``; write the sweep folder (module doc).

    Args:
        algo: ``ppo``, ``sac`` or ``td3``.
        base: the :class:`~aftir_rl.rl.sb3.SB3Config` every trial starts from (its
            ``eval_freq`` sets ASHA's rungs).
        space: the search space (:func:`load_search_space`).
        trials: number of trials.
        logdir: parent of the sweep folder.
        ray: ``local``, ``auto`` or ``HOST:PORT`` (:mod:`aftir_rl.experiments.distributed`).
        workers: CPUs of a local Ray (default: every core).
        seed: seed of every trial's training and of Optuna's sampler.
        verbose: Ray Tune's verbosity (0: quiet).

    Returns:
        ``{"sweep_dir", "best_yaml", "best", "trials": [row, ...]}``; each row has the trial's
        hyperparameters, ``success_rate``, ``tip_error_cm``, ``timesteps``, ``run_dir``,
        ``stopped_early`` and ``error``.

    Raises:
        ConfigError: ``logdir`` cannot be written.
        RayError: Ray missing or unreachable.
        TuneError: every trial failed.
        KeyboardInterrupt: a stop request (Ctrl-C or SIGTERM under the command line): the
            trials end, ``trials.csv`` is written and the message says where.

    """
    from aftir_rl.experiments.distributed import ray_session, require_ray

    require_ray()
    env_id = base.env_id
    sweep = _make_sweep_dir(logdir, algo, env_id)
    for key, value in TUNE_ENVIRONMENT.items():
        os.environ.setdefault(key, value)
    with ray_session(ray, workers):
        tuner = _make_tuner(algo, base, space, trials, sweep, seed, verbose, ray == "local")
        with interrupts.deferred():
            grid = tuner.fit()
        rows = [_trial_row(grid[i], space, algo, env_id) for i in range(len(grid))]
    _write_trials_csv(sweep / "trials.csv", rows)
    if interrupts.requested():
        raise KeyboardInterrupt(f"the sweep so far is in {sweep} (trials.csv, no best.yaml)")
    best = _best_trial(rows, sweep)
    best_config = dataclasses.replace(
        base, hyperparameters={**base.hyperparameters, **{d.key: best[d.key] for d in space}}
    )
    best_yaml = sweep / "best.yaml"
    write_config_yaml(best_yaml, best_config, algo, best)
    return {"sweep_dir": str(sweep), "best_yaml": str(best_yaml), "best": best, "trials": rows}


def _make_sweep_dir(logdir: str | Path, algo: str, env_id: str) -> Path:
    """Create ``logdir/tune__<algo>__<env>__<time>/``.

    Raises:
        ConfigError: ``logdir`` cannot be written.

    """
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S-%f")
    sweep = check_writable_dir(logdir).resolve() / f"tune__{algo}__{env_id}__{stamp}"
    sweep.mkdir(parents=True)
    return sweep


def _make_tuner(
    algo: str,
    base: Any,
    space: Sequence[Dimension],
    trials: int,
    sweep: Path,
    seed: int,
    verbose: int,
    local: bool,
) -> Any:
    """Ray Tune's tuner: Optuna samples ``space``, ASHA stops trailing trials at each rung.

    ``local``: Ray runs on this machine, started by this process.
    """
    import optuna
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    optuna.logging.set_verbosity(optuna.logging.WARNING)  # not "A new study created" on stderr
    trainable = tune.with_resources(
        tune.with_parameters(_trial, algo=algo, base=base, logdir=str(sweep), seed=seed),
        {"cpu": base.n_envs},
    )
    rungs = max(1, base.total_timesteps // base.eval_freq)
    scheduler = ASHAScheduler(
        time_attr="timesteps",
        max_t=base.total_timesteps,
        grace_period=min(base.eval_freq, base.total_timesteps),
        reduction_factor=2 if rungs < 8 else 3,
    )
    return tune.Tuner(
        trainable,
        param_space={d.key: d.to_tune() for d in space},
        tune_config=tune.TuneConfig(
            metric=METRIC,
            mode="max",
            num_samples=trials,
            scheduler=scheduler,
            search_alg=OptunaSearch(seed=seed),
        ),
        run_config=tune.RunConfig(
            name="ray",
            storage_path=str(sweep),
            verbose=verbose,
            log_to_file=True,
            stop=_stop_on_request(sweep / STOP_FILE, local=local),
        ),
    )


def _stop_on_request(flag: Path, local: bool, grace: float = 1.0) -> Any:
    """A Tune stopper that ends every trial once a stop is requested (Ctrl-C, SIGTERM).

    It also writes ``flag``, which the trials watch (:func:`_wait_for_stop`): each stops at its
    next step instead of at its next evaluation. With a ``local`` Ray, trials still starting
    (Ray Tune would wait 10 s for them) are killed after ``grace`` seconds.
    """
    from ray.tune import Stopper

    def end_the_rest() -> None:
        time.sleep(grace)
        kill_local_workers(TRIAL_PROCESSES)

    class StopOnRequest(Stopper):
        def __call__(self, trial_id: str, result: dict[str, Any]) -> bool:
            return False

        def stop_all(self) -> bool:
            if interrupts.requested() and not flag.exists():
                flag.touch()
                if local:
                    threading.Thread(target=end_the_rest, daemon=True).start()
            return interrupts.requested()

    return StopOnRequest()


def _trial_row(result: Any, space: Sequence[Dimension], algo: str, env_id: str) -> dict[str, Any]:
    """One row of ``trials.csv``; finishes the run directory of a trial ASHA stopped."""
    metrics = dict(result.metrics or {})
    params = {d.key: _plain((result.config or {}).get(d.key)) for d in space}
    run_dir = Path(metrics["run_dir"]) if metrics.get("run_dir") else None
    stopped = bool(run_dir) and not metrics.get("completed") and result.error is None
    if run_dir is not None and stopped:
        _finish_stopped(run_dir, metrics, algo, env_id)
    error = ""
    if result.error is not None:
        cause = getattr(result.error, "cause", None) or result.error
        text = " ".join(str(cause).split()[-40:])
        error = f"{type(cause).__name__}: {text}"[-200:]
    return {
        **params,
        "success_rate": metrics.get(METRIC, math.nan),
        "tip_error_cm": metrics.get("eval/tip_error_cm", math.nan),
        "timesteps": metrics.get("timesteps", 0),
        "stopped_early": stopped,
        "run_dir": str(run_dir) if run_dir else "",
        "error": error,
    }


def _write_trials_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write the trials' rows as CSV (an ``error`` column alone when there is none)."""
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["error"])
        writer.writeheader()
        writer.writerows(rows)


def _best_trial(rows: list[dict[str, Any]], sweep: Path) -> dict[str, Any]:
    """The highest success rate, ties broken by the lower tip error.

    Raises:
        TuneError: no trial finished without an error and reported a success rate.

    """
    done = [r for r in rows if not r["error"] and not math.isnan(r["success_rate"])]
    if not done:
        first = next((r["error"] for r in rows if r["error"]), "no trial reported")
        raise TuneError(f"every trial of the sweep failed ({first}); see {sweep}/ray")
    return max(done, key=lambda r: (r["success_rate"], -_or_inf(r["tip_error_cm"])))


def _or_inf(value: float) -> float:
    return math.inf if math.isnan(value) else value


def write_config_yaml(path: Path, config: SB3Config, algo: str, trial: dict[str, Any]) -> None:
    """Write ``config`` as a YAML that ``aftir train ALGO --config`` reads."""
    import yaml

    data = dataclasses.asdict(config)
    data["hyperparameters"] = {k: _plain(v) for k, v in data["hyperparameters"].items()}
    head = (
        f"# Best trial of `aftir tune {algo}`: success {trial['success_rate']:.0%}, tip error "
        f"{trial['tip_error_cm']:.2f} cm after {trial['timesteps']} steps\n"
        f"# ({trial['run_dir']}). Train it with: aftir train {algo} --config {path.name}\n"
        "# (raise total_timesteps for a full run).\n"
    )
    with atomic_open(path, "w") as fh:
        fh.write(head + yaml.safe_dump(data, sort_keys=False))
