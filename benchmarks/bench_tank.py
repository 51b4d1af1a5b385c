"""AFTIR-Tank-v0 against Gymnasium's toy-text grids, and Q-learning on the reference targets.

Run: ``python benchmarks/bench_tank.py`` (or ``make bench-full``). Prints markdown tables
measured in this one run on this machine: env steps/s through the same ``gym.make`` wrapper stack
with the same random action sequence, and Q-learning wall time and episodes to the BFS-optimal
greedy path.
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
from aftir_rl.rl.tabular import QLearning, QLearningConfig, greedy_rollout

QUICK = {"steps": 50_000, "repeats": 1}


def steps_per_second(env_id: str, n_steps: int, repeats: int, **kwargs) -> float:
    env = gym.make(env_id, **kwargs)
    n_actions = env.action_space.n
    actions = (np.random.default_rng(0).integers(0, 6, n_steps) % n_actions).tolist()
    best = 0.0
    for _ in range(repeats):
        env.reset(seed=0)
        start = time.perf_counter()
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
        best = max(best, n_steps / (time.perf_counter() - start))
    return best


def q_learning_row(target, cfg: QLearningConfig, seed: int) -> dict:
    tank = load_tank(cfg.tank)
    env = gym.make(cfg.env_id, target=target, max_episode_steps=cfg.max_episode_steps)
    optimum = int(tank.reachable[env.unwrapped.target_cell])

    def make_agent():
        return QLearning.from_config(env, cfg, seed=seed)

    agent = make_agent()
    start = time.perf_counter()
    agent.learn(cfg.episodes)
    full_seconds = time.perf_counter() - start
    states, ok = greedy_rollout(agent, env)
    final_optimal = ok and len(states) - 1 == optimum
    # Episodes (and training seconds) until the greedy path is optimal and stays so.
    agent, trained, last_bad, seconds_at = make_agent(), 0, 0, {}
    while trained < cfg.episodes:
        start = time.perf_counter()
        agent.learn(10)
        trained += 10
        seconds_at[trained] = seconds_at.get(trained - 10, 0.0) + time.perf_counter() - start
        states, ok = greedy_rollout(agent, env)
        if not (ok and len(states) - 1 == optimum):
            last_bad = trained
    to_optimal = last_bad + 10 if last_bad < cfg.episodes else None
    return {
        "target": target,
        "optimum": optimum,
        "final": len(states) - 1,
        "optimal": final_optimal,
        "episodes": cfg.episodes,
        "seconds": full_seconds,
        "episodes_to_optimal": to_optimal,
        "seconds_to_optimal": seconds_at.get(to_optimal) if to_optimal else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000, help="env steps per measurement")
    parser.add_argument("--repeats", type=int, default=3, help="take the best of this many")
    parser.add_argument("--seed", type=int, default=0)
    args = parse_args(parser, QUICK)

    print_header(args, QUICK)
    print(
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, {platform.processor() or '?'}, "
        f"Python {platform.python_version()}, gymnasium {gym.__version__}, numpy {np.__version__}"
    )
    print()
    envs = [
        ("AFTIR-Tank-v0", "AFTIR-Tank-v0", {}),
        (
            "FrozenLake-v1 8x8, not slippery",
            "FrozenLake-v1",
            {"map_name": "8x8", "is_slippery": False},
        ),
        ("CliffWalking-v1", "CliffWalking-v1", {}),
    ]
    rates = {
        name: steps_per_second(env_id, args.steps, args.repeats, **kw) for name, env_id, kw in envs
    }
    base = rates["FrozenLake-v1 8x8, not slippery"]
    print(
        f"Env steps/s through gym.make (random actions, {args.steps:,} steps, "
        f"best of {args.repeats}):"
    )
    print()
    print("| env | steps/s | vs FrozenLake 8x8 |")
    print("|---|---:|---:|")
    for name, rate in rates.items():
        print(f"| {name} | {rate:,.0f} | {rate / base:.2f}x |")
    print()
    cfg = QLearningConfig()
    print(
        f"Q-learning on the reference targets (configs/q_table.yaml: {cfg.episodes} episodes, "
        f"seed {args.seed}):"
    )
    print()
    print(
        "| target (cm) | BFS optimum | greedy path | wall time, all episodes | "
        "episodes to optimal | training s to optimal |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for target in load_tank(cfg.tank).targets:
        r = q_learning_row(target, cfg, args.seed)
        ep = r["episodes_to_optimal"] if r["episodes_to_optimal"] else "not reached"
        sec = f"{r['seconds_to_optimal']:.3f}" if r["seconds_to_optimal"] else "-"
        mark = "" if r["optimal"] else " (NOT optimal)"
        print(
            f"| {tuple(int(v) for v in target)} | {r['optimum']} | {r['final']}{mark} | "
            f"{r['seconds']:.3f} s | {ep} | {sec} |"
        )


if __name__ == "__main__":
    main()
