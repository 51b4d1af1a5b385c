"""Choose a policy to ship among trained runs, copy it into the package and write its card.

Run: ``python benchmarks/pretrained_card.py NAME RUN_DIR [RUN_DIR ...] --recipe "..."``.
Every candidate (a run directory, or its ``best/``) plays one deterministic episode on each of
``--validate`` targets its env draws from ``--validate-seed``; the best (success, then tip error)
is copied (``config.json``, ``model.zip``) to ``aftir_rl/rl/policies/NAME/`` and measured on
``--random`` test targets from ``--seed``, a range neither training nor the choice used. The
card (``card.json``) keeps the recipe, the training steps and minutes (the run's
``summary.json``), every candidate's validation score, the test numbers, and ``check``: the
first ``--check`` test targets' numbers, which the tests measure again.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path
from typing import Any

from aftir_rl.core.files import read_json, write_json
from aftir_rl.experiments.bench import machine_facts
from aftir_rl.experiments.runs import evaluate_run
from aftir_rl.rl.pretrained import POLICY_DIR

METRICS = ("success_rate", "tip_error_cm", "collision_rate", "min_clearance_cm")


def measure(run: Path, count: int, seed: int) -> dict[str, float]:
    """The run's metrics on ``count`` targets drawn from ``seed`` (and the seconds it took)."""
    start = time.perf_counter()
    row = evaluate_run(run, draw=(count, seed))
    return {**{k: float(row[k]) for k in METRICS}, "seconds": time.perf_counter() - start}


def _label(run: Path) -> str:
    """A candidate's name on the card: its run directory's name (``.../best`` for ``best/``)."""
    return f"{run.parent.name}/best" if run.name == "best" else run.name


def _training(run: Path) -> dict[str, Any]:
    """Steps and minutes of the run that wrote ``run`` (``best/`` reads its parent's summary)."""
    top = run.parent if run.name == "best" else run
    summary = read_json(top / "summary.json", "summary.json")
    out = {"timesteps": int(summary["timesteps"]), "minutes": float(summary["seconds"]) / 60}
    if run.name == "best":
        out["timesteps"] = int(read_json(run / "best.json", "best.json").get("timesteps", 0))
    return out


def main() -> None:
    """Choose, copy, measure, write the card."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("name", help="the policy's name, e.g. ppo-armreach")
    parser.add_argument("runs", nargs="+", type=Path, help="candidate run directories")
    parser.add_argument("--recipe", required=True, help="how the candidates were trained")
    parser.add_argument("--validate", type=int, default=100)
    parser.add_argument("--validate-seed", type=int, default=3_000_000)
    parser.add_argument("--random", type=int, default=200)
    parser.add_argument("--seed", type=int, default=4_000_000)
    parser.add_argument("--check", type=int, default=20)
    args = parser.parse_args()

    scores = {}
    for run in args.runs:
        scores[_label(run)] = measure(run, args.validate, args.validate_seed)
        print(f"{run}: {scores[_label(run)]}", flush=True)
    chosen = max(
        args.runs,
        key=lambda r: (scores[_label(r)]["success_rate"], -scores[_label(r)]["tip_error_cm"]),
    )
    out = POLICY_DIR / args.name
    out.mkdir(parents=True, exist_ok=True)
    for file in ("config.json", "model.zip"):
        shutil.copyfile(chosen / file, out / file)
    config = read_json(out / "config.json", "config.json")
    test = measure(out, args.random, args.seed)
    check = measure(out, args.check, args.seed)
    card = {
        "name": args.name,
        "algo": config["algo"],
        "env_id": config["env_id"],
        "env_kwargs": config.get("env_kwargs", {}),
        "recipe": args.recipe,
        "seed": config.get("seed"),
        "training": _training(chosen),
        "chosen": {
            "from": _label(chosen),
            "by": f"success, then tip error, on {args.validate} targets from seed "
            f"{args.validate_seed}",
            "candidates": scores,
        },
        "test": {"targets": args.random, "seed": args.seed, **test},
        "check": {"targets": args.check, "seed": args.seed, **check},
        "machine": machine_facts(),
    }
    write_json(out / "card.json", card)
    print(f"{args.name}: {chosen} -> {out}; test {test}")


if __name__ == "__main__":
    main()
