"""Goal-conditioned Q-learning (every target in one run) against one Q-table per target.

Run: ``python benchmarks/bench_goal.py``. Prints a markdown table measured in this one run on this
machine: wall time, goals, transitions and how many greedy paths are BFS-optimal, for
``train_all_targets`` (one ``(cell, goal, action)`` table, every goal's episodes stepped in
parallel) and for one :class:`~aftir_rl.rl.tabular.QLearning` trained per reachable cell, both with
the
hyperparameters of ``configs/q_table.yaml`` and the same number of episodes per target.
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
from aftir_rl.core.tank import load_tank
from aftir_rl.rl.tabular import QLearning, QLearningConfig, greedy_rollout, train_all_targets

QUICK = {"cells": 50}


def separate_tables(cfg: QLearningConfig, seed: int, limit: int | None) -> dict:
    """Train one QLearning per reachable free cell (the start excepted); time the training."""
    tank = load_tank(cfg.tank)
    cells = [tuple(int(v) for v in c) for c in np.argwhere(tank.reachable > 0)][:limit]
    seconds, optimal, steps = 0.0, 0, 0
    wall = time.perf_counter()
    for cell in cells:
        env = gym.make(cfg.env_id, target_cell=cell, max_episode_steps=cfg.max_episode_steps)
        agent = QLearning.from_config(env, cfg, seed=seed)
        start = time.perf_counter()
        agent.learn(cfg.episodes)
        seconds += time.perf_counter() - start
        steps += agent.num_timesteps
        states, ok = greedy_rollout(agent, env)
        optimal += ok and len(states) - 1 == int(tank.reachable[cell])
    return {
        "goals": len(cells),
        "seconds": seconds,
        "wall": time.perf_counter() - wall,
        "steps": steps,
        "optimal": optimal,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=int, help="episodes per target (default: config)")
    parser.add_argument(
        "--cells", type=int, help="train separate tables for the first N cells only (quick check)"
    )
    args = parse_args(parser, QUICK)
    cfg = QLearningConfig()
    if args.episodes:
        cfg = QLearningConfig(**{**cfg.__dict__, "episodes": args.episodes})

    print_header(args, QUICK)
    print(
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, {platform.processor() or '?'}, "
        f"Python {platform.python_version()}, gymnasium {gym.__version__}, numpy {np.__version__}"
    )
    print()
    start = time.perf_counter()
    agent, goal = train_all_targets(episodes=cfg.episodes, seed=args.seed, config=cfg)
    goal_wall = time.perf_counter() - start
    sep = separate_tables(cfg, args.seed, args.cells)
    print(
        f"Every reachable target of {cfg.tank}, {cfg.episodes} episodes per target "
        f"(configs/q_table.yaml), seed {args.seed}; training wall time (greedy-path checks and "
        "env construction excluded; with them: "
        f"{goal_wall:.1f} s and {sep['wall']:.1f} s):"
    )
    print()
    print("| run | goals | transitions | wall time | greedy paths BFS-optimal |")
    print("|---|---:|---:|---:|---:|")
    print(
        f"| goal-conditioned, one (cell, goal, action) table (`train_all_targets`) | "
        f"{goal['n_goals']} | {goal['num_timesteps']:,} | {goal['seconds']:.1f} s | "
        f"{goal['n_optimal']}/{goal['n_goals']} ({'yes' if goal['all_optimal'] else 'NO'}) |"
    )
    print(
        f"| one `QLearning` table per cell | {sep['goals']} | {sep['steps']:,} | "
        f"{sep['seconds']:.1f} s | {sep['optimal']}/{sep['goals']} "
        f"({'yes' if sep['optimal'] == sep['goals'] else 'NO'}) |"
    )
    print()
    per_goal = sep["seconds"] / sep["goals"] * goal["n_goals"]
    note = ", separate tables extrapolated to all goals" if sep["goals"] < goal["n_goals"] else ""
    print(
        f"Speed-up of the goal-conditioned run: {per_goal / goal['seconds']:.1f}x "
        f"({per_goal:.1f} s / {goal['seconds']:.1f} s{note})"
    )


if __name__ == "__main__":
    main()
