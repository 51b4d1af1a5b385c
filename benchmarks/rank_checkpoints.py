"""Rank the checkpoints of an `AFTIR-ArmFTL-v0` run on validation targets, in one batched pass each.

Run: ``python benchmarks/rank_checkpoints.py RUN_DIR [--fresh N] [--corners N] [--extreme N]
[--seed S] [--target X Y Z ...]``.
``RUN_DIR`` is a (finished or interrupted) SB3 run: its ``config.json`` and
``checkpoints/model_*.zip``, loaded without unpickling (:func:`aftir_rl.rl.sb3.load_model`).

Three validation sets, drawn by the run's env as it is evaluated (10 cm from every surface,
the training-only kwargs left out), with seeds no evaluation uses by default (``evaluate`` draws
from 1,000,000, the docs' test sets from 777,000 and 2,000,000, training's fixed set from 12,345):

- *fresh*: ``--fresh`` targets drawn uniformly, seeds ``S .. S + N - 1``;
- *corners*: ``--corners`` targets drawn in the corners of the target region as
  ``corner_bias=1`` draws them (10-25 cm inward from one of its eight corners), seeds
  ``S + 500,000 ..``;
- *extreme*: ``--extreme`` targets within 2 cm of the eight points ``target_clearance`` (10 cm)
  inward from the corners of the target region (the corners in turn, each point drawn from the
  generator seeded ``S + 900,000``, kept if 10 cm from every surface): the innermost corners an
  evaluation can draw, where the four reference targets of bay 2 lie (4 of its 8 points). One
  episode per reference target says little; 12 near each of the 8 points measure that kind of
  target. Reported only: the best checkpoint is marked on the first two sets.

``--target X Y Z`` (repeatable; e.g. the four reference targets) adds a column: how many of those
targets each checkpoint reaches, each rolled out alone (a one-row batched env, the single env's
transitions and predictions, as ``python -m aftir_rl.evaluate --target`` runs them). Reported
only, like *extreme*.

Each checkpoint's deterministic policy runs every target once, all targets as rows of the batched
env (the same transitions as the single env for the same actions:
``tests/envs/test_arm_ftl.py``; the policy's actions for a batch differ from one-by-one
predictions by about 1e-6, float32 rounding, which can turn an episode that grazes a wall or
the tolerance either way). Prints a markdown table with the success and contact rates per set,
and the checkpoint with the best mean success marked. Choose a checkpoint here, then measure it
on test targets with ``python -m aftir_rl.evaluate``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

import aftir_rl  # noqa: F401
from aftir_rl.cli.args import OneLineParser, bounded_int, coordinate
from aftir_rl.cli.guard import cli
from aftir_rl.core.collision import point_clearance
from aftir_rl.core.errors import AftirError
from aftir_rl.core.files import read_json
from aftir_rl.rl.sb3 import evaluation_env_kwargs, load_model
from aftir_rl.rl.sb3.loading import sb3_config_from_run

ENV_ID = "AFTIR-ArmFTL-v0"
CORNER_SEED_OFFSET = 500_000
EXTREME_SEED_OFFSET = 900_000
#: How far [cm] inward of the innermost corner points the *extreme* targets may lie, per axis.
EXTREME_DEPTH = 2.0


def validation_targets(kwargs: dict, count: int, seed: int, corners: bool) -> np.ndarray:
    """``count`` targets of ``ArmFTLEnv(**kwargs)``, reset ``i`` seeded ``seed + i``."""
    if corners:
        kwargs = {**kwargs, "corner_bias": 1.0}
    env = gym.make(ENV_ID, **kwargs)
    return np.array([env.reset(seed=seed + i)[1]["target"] for i in range(count)])


def extreme_targets(kwargs: dict, count: int, seed: int) -> np.ndarray:
    """``count`` targets near the points ``target_clearance`` inward from the region's corners.

    Target ``j`` lies within :data:`EXTREME_DEPTH` cm inward (per axis) of corner ``j mod 8``'s
    point and ``target_clearance`` from every surface (drawn again until it is, at most 100
    times). Raises :class:`AftirError` when a corner has no such point.
    """
    env = gym.make(ENV_ID, **kwargs).unwrapped
    (lo, hi), clearance = env.sampler.region, float(env.sampler.spec.target_clearance)
    high = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=bool)
    rng = np.random.default_rng(seed)
    out = np.empty((count, 3))
    for j in range(count):
        for _ in range(100):
            depth = clearance + rng.uniform(0.0, EXTREME_DEPTH, 3)
            point = np.where(high[j % 8], hi - depth, lo + depth)
            if point_clearance(env.tank, point[None])[0] >= clearance:
                out[j] = point
                break
        else:
            raise AftirError(f"no free point near corner {j % 8} of the target region")
    env.close()
    return out


def rollout(model, kwargs: dict, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Success and contact of the deterministic policy's first episode on every target."""
    venv = gym.make_vec(
        ENV_ID, num_envs=len(targets), vectorization_mode="vector_entry_point", **kwargs
    )
    obs, _ = venv.reset(seed=0, options={"target": targets})
    done = np.zeros(len(targets), dtype=bool)
    success, contact = np.zeros_like(done), np.zeros_like(done)
    while not done.all():
        action, _ = model.predict(obs, deterministic=True)
        obs, _, terminated, truncated, info = venv.step(action)
        new = (terminated | truncated) & ~done
        success[new], contact[new] = info["is_success"][new], info["collision"][new]
        done |= new
    venv.close()
    return success, contact


@cli
def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", metavar="RUN_DIR", help="an SB3 run of AFTIR-ArmFTL-v0")
    count = bounded_int(1, 4096)
    parser.add_argument("--fresh", type=count, default=200, help="uniform targets (200; to 4096)")
    parser.add_argument("--corners", type=count, default=96, help="corner targets (96; to 4096)")
    parser.add_argument(
        "--extreme",
        type=count,
        default=96,
        help="targets at the innermost corner points (96; to 4096)",
    )
    parser.add_argument(
        "--seed", type=bounded_int(0, 2**31), default=3_000_000, help="first seed (3,000,000)"
    )
    parser.add_argument(
        "--target",
        nargs=3,
        type=coordinate,
        action="append",
        default=[],
        metavar=("X", "Y", "Z"),
        help="a target [cm] rolled out alone on every checkpoint, reported only (repeatable, 64)",
    )
    args = parser.parse_args(argv)
    if len(args.target) > 64:
        print("error: at most 64 --target", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    try:
        source = str(Path(args.run, "config.json"))  # checked key by key; no model loaded
        algo, config = sb3_config_from_run(read_json(source, "config.json"), source)
        if config.env_id != ENV_ID:
            raise AftirError(f"{args.run} is a run of {config.env_id}, not {ENV_ID}")
        paths = sorted(
            Path(args.run, "checkpoints").glob("model_*.zip"),
            key=lambda p: int(p.stem.split("_")[-1]),
        )
        if not paths:
            raise AftirError(f"{args.run} has no checkpoints/model_*.zip")
        kwargs = evaluation_env_kwargs(config.env_kwargs)
        fresh = validation_targets(kwargs, args.fresh, args.seed, corners=False)
        corner = validation_targets(
            kwargs, args.corners, args.seed + CORNER_SEED_OFFSET, corners=True
        )
        extreme = extreme_targets(kwargs, args.extreme, args.seed + EXTREME_SEED_OFFSET)
        named = np.array(args.target, dtype=np.float64).reshape(-1, 3)
        check = gym.make(ENV_ID, **kwargs)
        for target in named:  # a TargetError (an AftirError) names a target outside or blocked
            check.reset(options={"target": tuple(float(v) for v in target)})
        check.close()
        rows = []
        for path in tqdm(paths, desc="checkpoints", file=sys.stderr):
            model = load_model(algo, path, config=config)
            f_ok, f_hit = rollout(model, kwargs, fresh)
            c_ok, c_hit = rollout(model, kwargs, corner)
            x_ok, _ = rollout(model, kwargs, extreme)
            alone = [rollout(model, kwargs, target[None]) for target in named]
            reached = sum(bool(ok[0]) for ok, _ in alone)
            touched = sum(bool(hit[0]) for _, hit in alone)
            rows.append(
                (path.name, f_ok.mean(), f_hit.mean(), c_ok.mean(), c_hit.mean(), x_ok.mean())
                + (f"{reached}/{len(named)}" + (f" ({touched} contact)" if touched else ""),)
            )
    except AftirError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    best = max(range(len(rows)), key=lambda i: rows[i][1] + rows[i][3])
    print(
        f"{args.run}: {len(fresh)} fresh targets (seeds {args.seed}+), {len(corner)} corner "
        f"targets (seeds {args.seed + CORNER_SEED_OFFSET}+), {len(extreme)} extreme corner "
        f"targets (seed {args.seed + EXTREME_SEED_OFFSET}), deterministic; best: the highest "
        "fresh + corner success\n"
    )
    extra = len(named) > 0
    print(
        "| checkpoint | fresh success | fresh contact | corner success | corner contact "
        "| extreme corner success |" + (" --target reached |" if extra else "")
    )
    print("|---|---:|---:|---:|---:|---:|" + ("---:|" if extra else ""))
    for i, (name, fs, fc, cs, cc, xs, named_cell) in enumerate(rows):
        mark = " **best**" if i == best else ""
        line = f"| {name}{mark} | {fs:.1%} | {fc:.1%} | {cs:.1%} | {cc:.1%} | {xs:.1%} |"
        print(line + (f" {named_cell} |" if extra else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
