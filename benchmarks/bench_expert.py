"""The follow-the-leader expert on held-out targets: how often it finds a motion, and how fast.

Run: ``python benchmarks/bench_expert.py --random 50 --seed 2000000 --json OUT.json``. Each
target is one the env draws with the reset seeds ``seed .. seed + N - 1`` (the same as
``aftir evaluate --random N --seed S`` measures a policy on); the expert plans with its budget,
its motion is replayed in the env, and python-fcl checks the margin after every step. Printed:
success, contacts, tip error, planning seconds (median, p90, max) and the machine; the rows go
to ``--json``. ``--baseline`` also runs the expert as it was first built (the main search
settings only, routes that start on the floor) on each target in turn, side by side.
``--teacher`` measures the expert as an online teacher: for each target it plays the expert's
motion with its steering perturbed (σ = 0.08 of θ_max, as DART injects noise) up to a random
step, then asks for a motion from that arm twice, side by side: continuing the arm's whole
sections (``continue_plan``) and from the floor (``plan`` with the arm as state). Printed: the
share answered and the milliseconds per query (median, p90) of each.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import aftir_rl  # noqa: F401  (registers the envs)
from aftir_rl.core.collision import CollisionScene
from aftir_rl.experiments.bench import machine_facts
from aftir_rl.planning.ftl.plan import MAIN_VARIANTS
from aftir_rl.rl.expert import EXPERT_SETTINGS, FTLExpert

KWARGS = {"bay": 2, "steer": "target", "guide": True, "shaping": "field", "step_cost": 0.02}


def measure(env: Any, expert: FTLExpert, scene: CollisionScene, seed: int) -> dict[str, Any]:
    """One target: the expert's plan, replayed in ``env`` with python-fcl after every step."""
    _, info = env.reset(seed=seed)
    start = time.perf_counter()
    plan = expert.plan(info["target"])
    seconds = time.perf_counter() - start
    row = {"seed": seed, "target": info["target"].tolist(), "seconds": seconds}
    row.update(success=False, contact=False, steps=0, least_clearance_cm=None)
    if plan is not None:
        least = np.inf
        for a in plan.actions:
            _, _, _, _, step = env.step(a)
            least = min(least, scene.check(env.unwrapped.posture).clearance_cm)
        row.update(
            success=bool(step["is_success"]),
            contact=bool(step["contact"]) or least < 0.0,
            steps=len(plan.actions),
            tip_error_cm=step["distance_cm"],
            least_clearance_cm=float(least),
            slack=plan.slack,
            tries=plan.tries,
        )
    return row


def measure_teacher(
    env: Any, expert: FTLExpert, seed: int, rng: np.random.Generator
) -> dict[str, Any] | None:
    """One noisy arm on the way to ``seed``'s target: both teachers' answers and times."""
    _, info = env.reset(seed=seed)
    plan = expert.plan(info["target"])
    if plan is None:
        return None
    env.reset(seed=seed)
    stop = int(rng.integers(len(plan.actions) // 3, len(plan.actions)))
    for a in plan.actions[:stop]:
        noisy = np.clip(a + np.r_[rng.normal(0.0, 0.08, 2), 0.0], -1.0, 1.0)
        if any(env.step(noisy.astype(np.float32))[2:4]):
            return None  # the noise ended the episode: no arm to teach from
    arm = env.unwrapped
    row: dict[str, Any] = {"seed": seed, "whole_sections": int(arm.batch.k[0])}
    for name, ask in (("continue", expert.continue_plan), ("floor", expert.plan)):
        start = time.perf_counter()
        found = ask(info["target"], arm)
        row[name] = {"answered": found is not None, "ms": 1000 * (time.perf_counter() - start)}
    return row


def summarise_teacher(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per teacher: arms asked, share answered, milliseconds per query (median, p90)."""
    out: dict[str, Any] = {"arms": len(rows)}
    for name in ("continue", "floor"):
        ms = np.array([r[name]["ms"] for r in rows])
        out[name] = {
            "answered": float(np.mean([r[name]["answered"] for r in rows])),
            "ms_median": float(np.median(ms)),
            "ms_p90": float(np.percentile(ms, 90)),
        }
    return out


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Success, contacts, least clearance, seconds (median, p90, max) and steps of ``rows``."""
    times = np.array([r["seconds"] for r in rows])
    ok = [r for r in rows if r["success"]]
    return {
        "targets": len(rows),
        "success_rate": len(ok) / len(rows),
        "contacts": sum(r["contact"] for r in rows),
        "least_clearance_cm": min((r["least_clearance_cm"] for r in ok), default=None),
        "seconds_median": float(np.median(times)),
        "seconds_p90": float(np.percentile(times, 90)),
        "seconds_max": float(times.max()),
        "seconds_total": float(times.sum()),
        "steps_mean": float(np.mean([r["steps"] for r in ok])) if ok else 0.0,
    }


def _main() -> set[Any]:
    """The main search settings of the planner, as the first expert tried them (lead 0)."""
    return {replace(v, slack=0.0, leads=(0.0,)) for v in MAIN_VARIANTS}


def main() -> None:
    """Measure the expert on the drawn targets; print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--random", type=int, default=50, help="targets")
    parser.add_argument("--seed", type=int, default=2_000_000, help="reset seed of the first")
    parser.add_argument("--max-seconds", type=float, default=30.0, help="budget per target")
    parser.add_argument("--baseline", action="store_true", help="the first expert beside")
    parser.add_argument("--teacher", action="store_true", help="the online teacher's cost")
    parser.add_argument("--json", help="where the rows go")
    args = parser.parse_args()
    if args.teacher:
        teach(args)
        return

    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    scene = CollisionScene(env.unwrapped.tank)
    experts = {"expert": FTLExpert(max_seconds=args.max_seconds, **KWARGS)}
    if args.baseline:
        first = tuple(s for s in EXPERT_SETTINGS if s in _main())
        experts["first"] = FTLExpert(args.max_seconds, max_lead=0.0, settings=first, **KWARGS)
    rows: dict[str, list[dict[str, Any]]] = {name: [] for name in experts}
    for seed in range(args.seed, args.seed + args.random):
        for name, expert in experts.items():
            row = measure(env, expert, scene, seed)
            rows[name].append(row)
            verdict = "ok" if row["success"] else "no motion"
            print(f"{seed} {name}: {verdict} in {row['seconds']:.2f} s", flush=True)
    summary = {name: summarise(r) for name, r in rows.items()}
    print(json.dumps(summary, indent=1))
    print(machine_facts())
    if args.json:
        out = {"machine": machine_facts(), "env_kwargs": KWARGS, "options": vars(args)}
        out |= {"summary": summary, "rows": rows}
        Path(args.json).write_text(json.dumps(out, indent=1))


def teach(args: argparse.Namespace) -> None:
    """``--teacher``: continuing the arm's sections against planning from the floor."""
    env = gym.make("AFTIR-ArmFTL-v0", **KWARGS)
    expert = FTLExpert(max_seconds=args.max_seconds, **KWARGS)
    rng = np.random.default_rng(args.seed)
    rows = []
    for seed in range(args.seed, args.seed + args.random):
        row = measure_teacher(env, expert, seed, rng)
        if row is not None:
            rows.append(row)
            print(
                f"{seed}: {row['whole_sections']} whole sections; continue "
                f"{row['continue']['ms']:.0f} ms, floor {row['floor']['ms']:.0f} ms",
                flush=True,
            )
    summary = summarise_teacher(rows)
    print(json.dumps(summary, indent=1))
    print(machine_facts())
    if args.json:
        out = {"machine": machine_facts(), "env_kwargs": KWARGS, "options": vars(args)}
        Path(args.json).write_text(json.dumps(out | {"summary": summary, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
