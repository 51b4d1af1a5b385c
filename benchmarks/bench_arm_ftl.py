"""AFTIR-ArmFTL-v0: env steps/s, single env against the batched vector env, in one run.

Run: ``python benchmarks/bench_arm_ftl.py [--steps N] [--config CFG]``. One process, random
actions (the push biased inwards, so the arm deploys and bends as in training), autoreset;
FrozenLake-v1 8x8 timed in the same run as a yardstick. The env rows run pinned to one core;
"as trained" rows use the training config's env kwargs (guide, field shaping, ...) with the
guide's fields built first, as a run has them after its first minutes. Then PPO trains on the
config's batched env on every core, and the env's share of its time is measured. Prints a
markdown table; ratios are to the single env measured here, side by side.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium as gym
import numpy as np
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder

import aftir_rl  # noqa: F401
from aftir_rl.rl.sb3 import load_sb3_config
from aftir_rl.rl.sb3.config import SB3Config, build_model

ENV_ID = "AFTIR-ArmFTL-v0"
QUICK = {"steps": 2_000, "ppo_runs": 1}


def actions(shape: tuple[int, ...], count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.uniform(-1, 1, (count, *shape)).astype(np.float32)
    a[..., 2] = np.clip(a[..., 2] + 0.5, -1, 1)  # mostly pushing in
    return a


def single_rate(env_id: str, steps: int, **kwargs) -> float:
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    if isinstance(env.action_space, gym.spaces.Discrete):
        env.action_space.seed(0)
        acts = [env.action_space.sample() for _ in range(steps)]
    else:
        acts = list(actions(env.action_space.shape, steps))
    for a in acts[:200]:  # warm: compiled kernels loaded, caches filled
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    start = time.perf_counter()
    for a in acts:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - start)


def vector_rate(num_envs: int, steps: int, **kwargs) -> float:
    venv = gym.make_vec(
        ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs
    )
    venv.reset(seed=0)
    acts = actions((num_envs, 3), max(1, steps // num_envs))
    start = time.perf_counter()
    for a in acts:
        venv.step(a)
    return len(acts) * num_envs / (time.perf_counter() - start)


def warm_fields(max_draws: int, **kwargs) -> tuple[int, int, int]:
    """Build the guide's fields of the cells drawn targets fall in, as a training run has them.

    A new 10 cm target cell builds its field the first time (about 20-30 ms); a training run
    draws hundreds of thousands of targets and soon has them all, so the rows with the guide
    are timed warm: rounds of 4,096 drawn targets until a round builds no new field (or
    ``max_draws``). Returns the fields built, the targets drawn and the last round's new fields.
    """
    venv = gym.make_vec(ENV_ID, num_envs=4096, vectorization_mode="vector_entry_point", **kwargs)
    fields = venv.unwrapped.batch.guide
    before, draws, new = len(fields), 0, -1
    while draws < max_draws and new != 0:
        count = len(fields)
        venv.reset(seed=draws)
        draws += 4096
        new = len(fields) - count
    return len(fields) - before, draws, new


def ppo_env_share(config: SB3Config, steps: int) -> tuple[float, float]:
    """PPO (SB3) on the batched env as a config trains it: steps/s and the env's share."""
    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    # as aftir_rl.cli.train builds it: only HER reads the infos of rows that did not finish
    venv = make_batched_vec_env(
        f"aftir_rl:{ENV_ID}", config.n_envs, 0, dict(config.env_kwargs), None if config.her else ()
    )
    inner = venv.venv  # VecMonitor -> SB3VectorEnv
    spent = [0.0]
    step_wait = inner.step_wait

    def timed():
        start = time.perf_counter()
        out = step_wait()
        spent[0] += time.perf_counter() - start
        return out

    inner.step_wait = timed
    model = build_model("ppo", config, venv, seed=0)
    start = time.perf_counter()
    model.learn(steps)
    total = time.perf_counter() - start
    return model.num_timesteps / total, spent[0] / total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per row")
    parser.add_argument(
        "--ppo-runs", type=int, default=3, help="PPO runs of 10 x --steps steps each (median)"
    )
    parser.add_argument(
        "--config",
        default="experiments/configs/ppo_ftl_cost.yaml",
        help="training config of the PPO row and of the 'as trained' env rows",
    )
    args = parse_args(parser, QUICK)
    config = load_sb3_config(args.config, "ppo")
    trained = dict(config.env_kwargs)
    all_cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    if all_cores:  # the env rows on one core, as the goals are stated
        os.sched_setaffinity(0, {min(all_cores)})
    built, draws, last = warm_fields(400_000, **trained)
    rows = [
        ("FrozenLake-v1 8x8 (single)", single_rate("FrozenLake-v1", args.steps, map_name="8x8"))
    ]
    single = single_rate(ENV_ID, args.steps)
    rows.append((f"{ENV_ID} single env", single))
    rows.append((f"{ENV_ID} single env, as trained", single_rate(ENV_ID, args.steps, **trained)))
    rows.append(
        (
            "AFTIR-Arm-v0 single env (raw joints, 4 sections)",
            single_rate("AFTIR-Arm-v0", args.steps // 4),
        )
    )
    rows.append(
        (
            "AFTIR-ArmFull-v0 single env (raw joints, 12 sections)",
            single_rate("AFTIR-ArmFull-v0", args.steps // 4),
        )
    )
    for b in (16, 64, 256, 1024):
        rows.append((f"{ENV_ID} vector env, {b} envs", vector_rate(b, 20 * args.steps)))
    rows.append(
        (
            f"{ENV_ID} vector env, 256 envs, as trained",
            vector_rate(256, 20 * args.steps, **trained),
        )
    )
    rows.append(
        (
            f"{ENV_ID} vector env, 128 envs, as trained",
            vector_rate(128, 20 * args.steps, **trained),
        )
    )
    if all_cores:
        os.sched_setaffinity(0, all_cores)
    ppo = [ppo_env_share(config, 10 * args.steps) for _ in range(max(1, args.ppo_runs))]
    print_header(args, QUICK)
    cores = f"{os.cpu_count()} CPUs, the env rows pinned to one core" if all_cores else ""
    print(f"{platform.processor() or platform.machine()}, {cores}, one process\n")
    print(f"'as trained': {args.config}'s env_kwargs {trained}, the guide's fields of")
    print(f"{draws:,} drawn targets built first ({built} fields; the last 4,096 built {last})\n")
    print("| env | steps/s | vs single ArmFTL |")
    print("|---|---:|---:|")
    for name, rate in rows:
        print(f"| {name} | {rate:,.0f} | {rate / single:.1f}x |")
    hyper = config.hyperparameters
    print(
        f"\nPPO (SB3, {args.config}: {config.n_envs} rows, n_steps {hyper['n_steps']}, "
        f"batch {hyper['batch_size']}, {hyper['n_epochs']} epochs, all cores) for "
        f"{10 * args.steps:,} steps, {len(ppo)} runs: "
        f"{', '.join(f'{rate:,.0f}' for rate, _ in ppo)} steps/s; the env's share of the time "
        f"(SB3's step_wait, the adapter included): "
        f"{', '.join(f'{100 * share:.1f}%' for _, share in ppo)} "
        f"(median {100 * float(np.median([share for _, share in ppo])):.1f}%)"
    )


if __name__ == "__main__":
    main()
