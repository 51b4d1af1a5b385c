"""An RL recipe from several seeds, measured on the same held-out targets: mean ± std per metric.

Run: ``python benchmarks/bench_seeds.py ppo --config AFTIR-ArmReach-v0 --seeds 0 1 2 --json
OUT.json``. A recipe is one config, named or the entry of an env id (or several: ``--config A
--config B`` trains A, then B resumed from A's model, a curriculum), optionally cloned first from
expert demonstrations (``--demos PATH``, or ``--make-demos N``: the expert's dataset written and
timed in the same run, shared by the seeds). Each seed trains the whole
recipe, then its final model plays one deterministic episode per target on ``--random N``
targets its env draws from ``--eval-seed`` (seeds training never evaluated on). Written to
``--json``: the machine, a FrozenLake 8x8 yardstick (steps/s measured in the same run), every
seed's numbers and their mean and standard deviation; ``benchmarks/results_page.py`` turns the
file into the docs' results page.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from aftir_rl.core.files import write_json
from aftir_rl.experiments.bench import env_steps_per_second, machine_facts
from aftir_rl.experiments.runs import evaluate_run
from aftir_rl.rl.demos import write_dataset
from aftir_rl.rl.imitation import pretrainer
from aftir_rl.rl.sb3 import entry_config, load_sb3_config
from aftir_rl.rl.sb3.train import train_curriculum, train_sb3

METRICS = ("success_rate", "tip_error_cm", "collision_rate", "min_clearance_cm")


def train_seed(
    algo: str, configs: list[Any], seed: int, logdir: Path, demos: Any = None, epochs: int = 20
) -> dict[str, Any]:
    """Train every stage from ``seed`` (the first cloned from ``demos`` if given); the last
    stage's run directory, steps and seconds (behaviour cloning included)."""
    extra = {"pretrain": pretrainer(demos, configs[0], epochs, seed)} if demos else {}
    stages = train_curriculum(
        train_sb3, algo, configs, seed, logdir / f"seed{seed}", progress_bar=False, **extra
    )
    cloned = stages[0].get("pretrain", {})
    cloning = float(cloned.get("seconds", 0.0))
    return {
        "run_dir": stages[-1]["run_dir"],
        "timesteps": int(stages[-1]["timesteps"]),
        "train_seconds": cloning + sum(float(s["seconds"]) for s in stages),
        "clone_seconds": cloning,
        "clone": {k: float(v) for k, v in cloned.items()},
    }


def make_demos(args: argparse.Namespace, config: Any, logdir: Path) -> dict[str, Any]:
    """Write ``--make-demos`` expert episodes with the first stage's env; their facts, timed."""
    if (logdir / "datasets").exists():
        raise SystemExit(f"{logdir / 'datasets'} exists: remove it to time a new dataset")
    start = time.perf_counter()
    made = write_dataset(
        logdir / "datasets",
        args.make_demos,
        seed=args.demos_seed,
        env_kwargs=config.env_kwargs,
        workers=args.demos_workers,
    )
    made["seconds"] = time.perf_counter() - start
    made.update(seed=args.demos_seed, workers=args.demos_workers)
    print(f"demonstrations: {made['episodes']} episodes in {made['seconds']:.0f} s", flush=True)
    return made


def summarize(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Mean and standard deviation (ddof 1) over seeds of each metric."""
    out = {}
    for key in (*METRICS, "train_seconds", "timesteps"):
        values = np.array([r[key] for r in rows], dtype=float)
        std = float(values.std(ddof=1)) if len(values) > 1 else 0.0
        out[key] = {"mean": float(values.mean()), "std": std}
    return out


def main() -> None:
    """Train and measure every seed; write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("algo", choices=("ppo", "sac", "td3"))
    parser.add_argument(
        "--config",
        action="append",
        required=True,
        help="stage config(s): a named config, or an env id for its hyperparameter entry",
    )
    parser.add_argument("--name", help="the recipe's name on the results page")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--total-timesteps", type=int, help="steps of the last stage")
    parser.add_argument("--random", type=int, default=100, help="held-out targets")
    parser.add_argument("--eval-seed", type=int, default=3_000_000)
    demos = parser.add_mutually_exclusive_group()
    demos.add_argument("--demos", help="a Minari dataset to clone into the first stage")
    demos.add_argument(
        "--make-demos", type=int, metavar="N", help="write N expert episodes first, clone those"
    )
    parser.add_argument("--demos-seed", type=int, default=7_000_000, help="their first target")
    parser.add_argument("--demos-workers", type=int, default=2, help="processes that plan them")
    parser.add_argument("--bc-epochs", type=int, default=20, help="cloning passes")
    parser.add_argument("--logdir", default="runs/seeds")
    parser.add_argument("--json", required=True, help="where the results go")
    args = parser.parse_args()

    configs = [
        entry_config(args.algo, name)
        if name.startswith("AFTIR-")
        else load_sb3_config(name, args.algo)
        for name in args.config
    ]
    if args.total_timesteps:
        configs[-1] = dataclasses.replace(configs[-1], total_timesteps=args.total_timesteps)
    name = args.name or " → ".join(args.config)
    logdir = Path(args.logdir) / name.replace(" ", "_").replace("→", "then")
    lake = env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8", is_slippery=False)
    made = make_demos(args, configs[0], logdir) if args.make_demos else None
    demos_path = made["path"] if made else args.demos
    rows = []
    for seed in args.seeds:
        trained = train_seed(args.algo, configs, seed, logdir, demos_path, args.bc_epochs)
        row = {"seed": seed, **trained}
        start = time.perf_counter()
        measured = evaluate_run(row["run_dir"], draw=(args.random, args.eval_seed))
        row["eval_seconds"] = time.perf_counter() - start
        row.update({k: float(measured[k]) for k in METRICS})
        rows.append(row)
        print(
            f"seed {seed}: {row['timesteps']:,} steps in {row['train_seconds'] / 60:.1f} min; "
            + ", ".join(f"{k} {row[k]:.3g}" for k in METRICS),
            flush=True,
        )
    write_json(
        args.json,
        {
            "recipe": name,
            "algo": args.algo,
            "env_id": configs[-1].env_id,
            "configs": args.config,
            "demos": demos_path and {"path": demos_path, "bc_epochs": args.bc_epochs, "made": made},
            "total_timesteps": [c.total_timesteps for c in configs],
            "eval": {
                "targets": args.random,
                "seed": args.eval_seed,
                "env_kwargs": configs[-1].env_kwargs,
            },
            "machine": machine_facts(),
            "frozenlake_8x8_steps_per_s": lake,
            "runs": [{k: v for k, v in r.items() if k != "run_dir"} for r in rows],
            "summary": summarize(rows),
        },
    )
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
