"""Compile the package's numba kernels once, into numba's cache beside the sources.

    python scripts/warm_kernels.py

Run by ``make install``: the follow-the-leader planner's kernels, the ``AFTIR-ArmFTL-v0`` step
and the goal-conditioned Q-learning sweep otherwise compile on first use (about 40 s in all on 2
cores). Nothing is written but numba's cache files.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

import aftir_rl  # noqa: F401  (registers the envs)
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.plan import warm_up
from aftir_rl.rl.tabular.q_table_goal import train_all_targets


def main() -> None:
    """Compile (or load) each family of kernels by running it once."""
    start = time.perf_counter()
    warm_up(load_tank("b737_center"))
    env = gym.make("AFTIR-ArmFTL-v0")
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()
    train_all_targets(tank="b737_center", episodes=1, seed=0)
    print(f"numba kernels compiled or loaded in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
