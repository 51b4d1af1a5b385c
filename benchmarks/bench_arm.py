"""The continuous arm envs: steps/s against FrozenLake, and their share of PPO's time per step.

Run: ``python benchmarks/bench_arm.py [--ppo-steps N]``. One process, random actions, through
``gym.make``; PPO (n_envs 1, default hyperparameters but n_steps 1024) timed on the same machine in
the same run.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium as gym
import numpy as np
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder
from stable_baselines3 import PPO

import aftir_rl  # noqa: F401
from aftir_rl.experiments.bench import env_steps_per_second

QUICK = {"ppo_steps": 2_048}


def ppo_rate(env_id: str, steps: int) -> float:
    model = PPO("MlpPolicy", gym.make(env_id), n_steps=1024, seed=0, verbose=0)
    start = time.perf_counter()
    model.learn(steps)
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ppo-steps", type=int, default=4_096, help="PPO steps per env (4,096)")
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    print(
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}"
    )
    print()
    lake = env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8", is_slippery=False)
    print("| env | env steps/s | vs FrozenLake 8x8 | PPO steps/s | env share of PPO's step |")
    print("|---|---:|---:|---:|---:|")
    print(f"| FrozenLake-v1 8x8 | {lake:,.0f} | 1.00x | | |")
    for env_id in ("AFTIR-ArmReach-v0", "AFTIR-Arm-v0"):
        env_rate = env_steps_per_second(env_id, 5_000)
        train_rate = ppo_rate(env_id, args.ppo_steps)
        share = train_rate / env_rate
        print(
            f"| {env_id} | {env_rate:,.0f} | {env_rate / lake:.3f}x | {train_rate:,.0f} | "
            f"{share:.0%} |"
        )


if __name__ == "__main__":
    main()
