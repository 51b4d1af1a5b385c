"""RLlib beside SB3 on the same PPO configs: throughput by env runners, and what a short run learns.

    python benchmarks/bench_rllib.py [--quick] [--iterations K] [--reach-steps T] [--json FILE]

Throughput: ``AFTIR-ArmFTL-v0`` (bay 2, guide, shaping: the shipped entry's env) with 32 env
rows, 64 steps per row per update (2,048 steps), 5 epochs of minibatches of 512 on a 2 × 256
network, for ``K`` updates after one warm-up update, by SB3's PPO (the batched env in this
process) and by RLlib's PPO with 0 env runners (this process samples), 1 and 2 (Ray actors, a
local Ray of 2 CPUs): steps per second, and for RLlib the seconds per update spent sampling
and learning (RLlib's timers), which says what limits it. Learning: ``AFTIR-ArmReach-v0``'s
shipped entry (``configs/hyperparams/ppo.yml``) trained ``T`` steps by ``aftir train ppo`` and
by ``aftir train ppo --rllib`` (1 env runner), seed 0, then both runs and a random policy on
the same 200 held-out targets (seeds 4,000,000..., the card's test of ``ppo-armreach``).
The machine and the FrozenLake 8x8 yardstick are printed with the tables.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from quick_mode import parse_args, print_header  # noqa: E402

from aftir_rl.experiments.bench import env_steps_per_second, write_results  # noqa: E402

QUICK = {"iterations": 2, "reach_steps": 8192}
FTL = "AFTIR-ArmFTL-v0"
FTL_KWARGS = {"bay": 2, "guide": True, "shaping": True}
FTL_HYPER = {
    "n_steps": 64,
    "batch_size": 512,
    "n_epochs": 5,
    "gamma": 0.995,
    "policy_kwargs": {"net_arch": [256, 256]},
}
N_ENVS = 32


def _ftl_config() -> Any:
    from aftir_rl.rl.sb3.config import SB3Config

    return SB3Config(
        env_id=FTL,
        n_envs=N_ENVS,
        policy="MultiInputPolicy",
        hyperparameters=dict(FTL_HYPER),
        env_kwargs=dict(FTL_KWARGS),
    )


def sb3_throughput(iterations: int) -> dict[str, Any]:
    """SB3's PPO on the batched env: steps per second over ``iterations`` updates."""
    from aftir_rl.rl.sb3 import build_model
    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    config = _ftl_config()
    venv = make_batched_vec_env(f"aftir_rl:{FTL}", N_ENVS, 0, config.env_kwargs, ())
    model = build_model("ppo", config, venv, seed=0)
    batch = FTL_HYPER["n_steps"] * N_ENVS
    model.learn(batch)  # warm-up: compiles the kernels
    start = time.perf_counter()
    model.learn(batch * iterations, reset_num_timesteps=False)
    seconds = time.perf_counter() - start
    venv.close()
    return {"library": "SB3", "env_runners": "-", "steps_per_s": batch * iterations / seconds}


def rllib_throughput(iterations: int, env_runners: int) -> dict[str, Any]:
    """RLlib's PPO with ``env_runners`` runners on a local Ray of 2 CPUs."""
    import ray

    from aftir_rl.rl.rllib.config import ppo_config, quiet_rllib

    with quiet_rllib():
        ray.init(num_cpus=2, include_dashboard=False, logging_level="error")
        algo = ppo_config(_ftl_config(), FTL, 0, env_runners).build_algo()
    try:
        warm = algo.train()  # warm-up: compiles the kernels, starts the runners
        first = float(warm["env_runners"]["num_env_steps_sampled_lifetime"])
        sampling, learning = [], []
        start = time.perf_counter()
        for _ in range(iterations):
            result = algo.train()
            timers = result.get("timers", {})
            sampling.append(float(timers.get("env_runner_sampling_timer", np.nan)))
            learning.append(float(timers.get("learner_update_timer", np.nan)))
        seconds = time.perf_counter() - start
        steps = float(result["env_runners"]["num_env_steps_sampled_lifetime"]) - first
    finally:
        algo.stop()
        ray.shutdown()
    return {
        "library": "RLlib",
        "env_runners": env_runners,
        "steps_per_s": steps / seconds,
        "sampling_s": float(np.nanmean(sampling)),
        "learning_s": float(np.nanmean(learning)),
    }


class _Random:
    """A policy of uniform random actions (seeded), with SB3's ``predict``."""

    def __init__(self, space: Any) -> None:
        self.space = space
        self.space.seed(0)

    def predict(self, observation: Any, *, deterministic: bool = True) -> tuple[Any, None]:
        return self.space.sample(), None


def learning(steps: int) -> list[dict[str, Any]]:
    """ArmReach's shipped PPO entry by SB3 and by RLlib, and a random policy, on 200 targets."""
    import gymnasium as gym
    import ray

    from aftir_rl.experiments.runs import evaluate_run
    from aftir_rl.rl.rllib.config import quiet_rllib
    from aftir_rl.rl.rllib.train import train_rllib
    from aftir_rl.rl.sb3 import evaluate_policy_on_targets, evaluation_targets, train_config
    from aftir_rl.rl.sb3.train import train_sb3

    env_id = "aftir_rl:AFTIR-ArmReach-v0"
    targets = evaluation_targets(env_id, 200, seed=4_000_000)
    numbers = {"total_timesteps": steps, "eval_freq": steps, "eval_targets": 20}
    config = train_config(
        "ppo", env="AFTIR-ArmReach-v0", numbers=numbers, progress_bar=False
    ).stages[0]
    rows = []
    with tempfile.TemporaryDirectory() as logdir:
        start = time.perf_counter()
        sb3 = train_sb3("ppo", config, seed=0, logdir=logdir, progress_bar=False)
        rows.append(("SB3 PPO", sb3["run_dir"], time.perf_counter() - start))
        with quiet_rllib():
            ray.init(num_cpus=1, include_dashboard=False, logging_level="error")
        try:
            start = time.perf_counter()
            rl = train_rllib(config, seed=0, logdir=logdir, env_runners=1, progress_bar=False)
            rows.append(("RLlib PPO", rl["run_dir"], time.perf_counter() - start))
        finally:
            ray.shutdown()
        out = []
        for name, run_dir, seconds in rows:
            m = evaluate_run(run_dir, targets=targets)
            out.append({"policy": name, "steps": steps, "minutes": seconds / 60, **m})
    env = gym.make(env_id)
    m, _ = evaluate_policy_on_targets(_Random(env.action_space), env_id, targets)
    out.append({"policy": "random", "steps": 0, "minutes": 0.0, **m})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--iterations", type=int, default=5, help="timed updates (default 5)")
    parser.add_argument(
        "--reach-steps", type=int, default=200_000, help="ArmReach training steps (200,000)"
    )
    parser.add_argument("--json", help="write the rows and the machine here")
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    yardstick = env_steps_per_second("FrozenLake-v1", 50_000, map_name="8x8", is_slippery=False)
    rows: list[dict[str, Any]] = [sb3_throughput(args.iterations)]
    for runners in (0, 1, 2):
        rows.append(rllib_throughput(args.iterations, runners))
    base = rows[0]["steps_per_s"]
    print(
        f"PPO on {FTL} (bay 2), {N_ENVS} rows × {FTL_HYPER['n_steps']} steps per update, "
        f"{args.iterations} updates after one warm-up; FrozenLake 8x8 {yardstick:,.0f} steps/s\n"
    )
    print("| library | env runners | steps/s | × SB3 | sampling s/update | learning s/update |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['library']} | {r['env_runners']} | {r['steps_per_s']:,.0f} | "
              f"{r['steps_per_s'] / base:.2f} | {r.get('sampling_s', float('nan')):.2f} | "
              f"{r.get('learning_s', float('nan')):.2f} |")  # fmt: skip
    learned = learning(args.reach_steps)
    print(f"\nAFTIR-ArmReach-v0, the shipped PPO entry, {args.reach_steps:,} steps, seed 0; "
          "200 held-out targets (seeds 4,000,000...)\n")  # fmt: skip
    print("| policy | steps | minutes | success | tip error (cm) | collisions |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in learned:
        print(f"| {r['policy']} | {r['steps']:,} | {r['minutes']:.1f} | {r['success_rate']:.1%} | "
              f"{r['tip_error_cm']:.1f} | {r['collision_rate']:.1%} |")  # fmt: skip
    write_results(args.json, args, [*rows, *learned, {"frozenlake_steps_per_s": yardstick}])


if __name__ == "__main__":
    main()
