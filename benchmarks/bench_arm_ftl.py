"""AFTIR-ArmFTL-v0: env steps/s, single env against the batched vector env, in one run.

Run: ``python benchmarks/bench_arm_ftl.py [--steps N]``. One process, random actions (the push
biased inwards, so the arm deploys and bends as in training), autoreset; FrozenLake-v1 8x8 timed
in the same run as a yardstick. Prints a markdown table; ratios are to the single env measured
here, side by side.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium as gym
import numpy as np

import aftir_rl  # noqa: F401

ENV_ID = "AFTIR-ArmFTL-v0"


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


def ppo_env_share(num_envs: int, steps: int) -> tuple[float, float]:
    """PPO (SB3) on the batched env through the VecEnv adapter: steps/s and the env's share."""
    from stable_baselines3 import PPO

    from aftir_rl.agents.vec_adapter import make_batched_vec_env

    venv = make_batched_vec_env(f"aftir_rl:{ENV_ID}", num_envs, 0, {"guide": True, "shaping": True})
    inner = venv.venv  # VecMonitor -> SB3VectorEnv
    spent = [0.0]
    step_wait = inner.step_wait

    def timed():
        start = time.perf_counter()
        out = step_wait()
        spent[0] += time.perf_counter() - start
        return out

    inner.step_wait = timed
    model = PPO(
        "MultiInputPolicy",
        venv,
        n_steps=64,
        batch_size=4096,
        n_epochs=5,
        seed=0,
        policy_kwargs={"net_arch": [256, 256]},
    )
    start = time.perf_counter()
    model.learn(steps)
    total = time.perf_counter() - start
    return model.num_timesteps / total, spent[0] / total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per row")
    args = parser.parse_args()
    rows = [
        ("FrozenLake-v1 8x8 (single)", single_rate("FrozenLake-v1", args.steps, map_name="8x8"))
    ]
    single = single_rate(ENV_ID, args.steps)
    rows.append((f"{ENV_ID} single env", single))
    rows.append((f"{ENV_ID} single env, shaping", single_rate(ENV_ID, args.steps, shaping=True)))
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
        (f"{ENV_ID} vector env, 256 envs, guide", vector_rate(256, 20 * args.steps, guide=True))
    )
    field = {"guide": True, "shaping": "field"}
    rows.append(
        (
            f"{ENV_ID} vector env, 256 envs, guide + field shaping",
            vector_rate(256, 20 * args.steps, **field),
        )
    )
    ppo_rate, share = ppo_env_share(256, 10 * args.steps)
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, one process\n")
    print("| env | steps/s | vs single ArmFTL |")
    print("|---|---:|---:|")
    for name, rate in rows:
        print(f"| {name} | {rate:,.0f} | {rate / single:.1f}x |")
    print(
        f"\nPPO (SB3 2.x, MultiInputPolicy 256x256, n_steps 64, batch 4096, 5 epochs) on the "
        f"256-env batched env with the guide: {ppo_rate:,.0f} steps/s; the env's share of the "
        f"time: {100 * share:.1f}%"
    )


if __name__ == "__main__":
    main()
