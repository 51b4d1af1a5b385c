"""What a new tank costs ``AFTIR-ArmFTL-v0``, part by part, and in steps of a fixed tank's env.

    python benchmarks/bench_tank_cost.py [--seeds N] [--bays 2,3,5] [--rows B]

Per generated wing (``--bays``: 2, 3 and 5 bays, generator seeds 900,000... that nothing else
builds, each tank built once, in this process) and the 737 tank: the seconds to generate it, to
make the env's state (raster, clearance grids), the guide (the field guide with its first target
field), and the raster shaping's all-pairs distance table with this tree's compiled BFS and with
the previous numpy relaxation (transcribed below, on a second copy of the tank; both tables must
be equal). Then ``--rows`` rows of the batched env on one of those wings step random actions:
the steps a new tank's cost would buy (with the guide and the field shaping, and with the raster
shaping). Last, SB3's PPO (the wings recipe's network and batch) trains ``--train-steps`` steps on
one new 3-bay wing, on a pool of 8 (seeds 910,000-910,007), and on the stream that starts with
those 8 (``wing:3:910000+``) moving on every 8, 32 or 128 episodes of a group's rows: steps/s,
the wings met, and the share of the one wing's speed (each in a new process: every wing new, so
each builds its guide's fields as training meets targets). Then the route policy's teaching
(``AFTIR-ArmRoute-v1``, the planner labelling each route it follows, as ``aftir route train``
clones): ``--routes`` routes in one new 3-bay wing, and on a stream moving on every 5 routes
or every route, each in a new process: routes/s and the share of the one wing's.
``--tables costs``, ``training`` or ``route`` prints one part.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder

from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.envs.ftl.env import ArmFTLVectorEnv
from aftir_rl.envs.ftl.fields import raster_detour_table, raster_distance_table
from aftir_rl.experiments.bench import machine_facts

QUICK = {"seeds": 1, "bays": "2,3", "rows": 64, "train_steps": 32768, "routes": 20}


def previous_distance_table(tank: Tank) -> np.ndarray:
    """The table before: relaxation of a ``(cells, cells)`` array by numpy, as it was."""
    raster = tank.raster
    shape = raster.shape
    free = ~raster.obstructed
    n = raster.n_cells
    big = np.int32(10 * n)
    dist = np.full((n,) + shape, big, dtype=np.int32)
    dist.reshape(n, n)[np.arange(n), np.arange(n)] = 0
    moves = [(axis, step) for axis in range(3) for step in (-1, 1)]

    def neighbour_min(d: np.ndarray) -> np.ndarray:
        best = np.full_like(d, big)
        for axis, step in moves:
            src = [slice(None)] * 4
            dst = [slice(None)] * 4
            src[axis + 1] = slice(max(0, -step), shape[axis] - max(0, step))
            dst[axis + 1] = slice(max(0, step), shape[axis] - max(0, -step))
            best[tuple(dst)] = np.minimum(best[tuple(dst)], d[tuple(src)])
        return best

    for _ in range(4 * sum(shape)):
        new = np.where(free[None], np.minimum(dist, neighbour_min(dist) + 1), dist)
        if np.array_equal(new, dist):
            break
        dist = new
    dist = np.where(free[None], dist, np.minimum(dist, neighbour_min(dist) + 1))
    flat = dist.reshape(n, n)
    flat = np.minimum(flat, flat.T)
    finite = flat[flat < big]
    return np.where(flat < big, flat, (finite.max() + 1) if finite.size else 0).astype(np.int32)


def _seconds(fn, *args, **kwargs) -> tuple[float, object]:  # noqa: ANN001
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - start, out


def tank_costs(spec: str) -> dict[str, float]:
    """Seconds of each part for one tank built here for the first time."""
    row: dict[str, float] = {}
    row["generate"], tank = _seconds(load_tank, spec)
    row["cells"] = float(tank.raster.n_cells)
    row["state"], env = _seconds(ArmFTLVectorEnv, num_envs=4, tank=tank)
    env.close()
    row["guide"], env = _seconds(ArmFTLVectorEnv, num_envs=4, tank=tank, guide=True)
    env.reset(seed=0)  # the first target's field
    row["guide"] += _seconds(env.step, np.zeros((4, 3), np.float32))[0]
    env.close()
    row["table"], table = _seconds(raster_distance_table, tank)
    row["detour"], _ = _seconds(raster_detour_table, tank)
    row["table before"], before = _seconds(previous_distance_table, load_tank(spec))
    if not np.array_equal(table, before):
        raise SystemExit(f"{spec}: the compiled table differs from the relaxation's")
    return row


def steps_per_second(rows: int, **kwargs: object) -> float:
    """Random-action steps per second of ``rows`` rows of the batched env on a built tank."""
    env = ArmFTLVectorEnv(num_envs=rows, **kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (300, rows, 3)).astype(np.float32)
    for a in actions[:20]:  # the first targets' fields, compiled kernels
        env.step(a)
    start = time.perf_counter()
    for a in actions[20:]:
        env.step(a)
    env.close()
    return rows * (len(actions) - 20) / (time.perf_counter() - start)


def training_rate(steps: int, rows: int, tank: str, **stream: int) -> tuple[float, int]:
    """SB3 PPO's steps/s on ``rows`` rows (the wings recipe's settings), and the wings it met.

    In a process of its own: no tank, grid or guide field of an earlier measurement is cached.
    """
    return in_new_process(_training_rate, steps, rows, tank, stream)


def _training_rate(steps: int, rows: int, tank: str, stream: dict[str, int]) -> tuple[float, int]:
    import torch
    from stable_baselines3 import PPO

    from aftir_rl.rl.sb3.vec_adapter import make_batched_vec_env

    torch.set_num_threads(1)
    warm = make_batched_vec_env("AFTIR-ArmFTL-v0", 4, 0, {"guide": True})  # torch's first steps
    PPO("MultiInputPolicy", warm, n_steps=32, batch_size=128, device="cpu").learn(256)
    warm.close()  # type: ignore[union-attr]
    kwargs = {"tank": tank, "guide": True, "shaping": "field", "steer": "target", **stream}
    venv = make_batched_vec_env("AFTIR-ArmFTL-v0", rows, 0, kwargs)
    assert venv is not None
    model = PPO("MultiInputPolicy", venv, n_steps=128, batch_size=4096, n_epochs=5, seed=0,
                policy_kwargs={"net_arch": [256, 256]}, device="cpu")  # fmt: skip
    batched = venv.venv.venv  # type: ignore[attr-defined]  (VecMonitor, SB3VectorEnv)
    start = time.perf_counter()
    model.learn(steps)
    seconds = time.perf_counter() - start
    used = getattr(batched, "tanks_met", 1)  # (one tank: the plain batched env)
    venv.close()
    return model.num_timesteps / seconds, used


def in_new_process(fn, *args):  # noqa: ANN001, ANN201
    """``fn(*args)`` in a process of its own: no tank, grid or field of earlier ones cached."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
        return pool.submit(fn, *args).result()


def _route_rate(routes: int, tank: str, stream: dict[str, int]) -> tuple[float, int]:
    """Teacher-labelled routes/s on ``tank`` (its first wing's building included), wings met."""
    import torch

    from aftir_rl.envs.ftl.route_env import ArmRouteEnv
    from aftir_rl.rl.route_policy import RouteTeacher, collect

    torch.set_num_threads(1)
    warm = ArmRouteEnv(tank="wing:2:899999", leads=(0.0,))  # the kernels, compiled or loaded
    collect(warm, 0, RouteTeacher(), None)
    start = time.perf_counter()
    env, teacher = ArmRouteEnv(tank=tank, **stream), RouteTeacher()
    for i in range(routes):
        collect(env, 20_000_000 + i, teacher, None)
    return routes / (time.perf_counter() - start), env.tanks_met or 1


def route_table(args: argparse.Namespace) -> None:
    """Print the route teacher's routes/s in one new wing and on the stream moving on."""
    print(f"\n| route policy's teaching, {args.routes} routes, 3-bay wings | routes/s | "
          "wings met | share of one wing's |")  # fmt: skip
    print("|---|---:|---:|---:|")
    fixed, _ = in_new_process(_route_rate, args.routes, "wing:3:920000", {})
    print(f"| one new wing (wing:3:920000) | {fixed:.2f} | 1 | 100% |")
    for episodes in (5, 1):
        rate, met = in_new_process(
            _route_rate, args.routes, "wing:3:920000+", {"tank_episodes": episodes}
        )
        print(
            f"| a stream, the next wing every {episodes} route{'s' * (episodes > 1)} | "
            f"{rate:.2f} | {met} | {rate / fixed:.0%} |"
        )


def cost_tables(args: argparse.Namespace) -> None:
    """Print what each part of a new tank costs, and the fixed tank's steps/s."""
    load_tank("wing:2:899999")  # compile (or load) the kernels outside the timings
    ArmFTLVectorEnv(num_envs=2, tank="wing:2:899999", guide=True, shaping=True).close()
    specs = ["b737_center"] + [
        f"wing:{bays}:{900_000 + seed}"
        for bays in (int(b) for b in args.bays.split(","))
        for seed in range(args.seeds)
    ]
    print("| tank | raster cells | generate s | env state s | guide s | raster table s, "
          "before / now | ratio | detour s |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    totals = []
    for spec in specs:
        r = tank_costs(spec)
        totals.append((r["generate"] + r["state"] + r["guide"], r["table"] + r["detour"]))
        print(
            f"| {spec} | {r['cells']:,.0f} | {r['generate']:.2f} | {r['state']:.2f} | "
            f"{r['guide']:.2f} | {r['table before']:.2f} / {r['table']:.2f} | "
            f"{r['table before'] / r['table']:.0f}x | {r['detour']:.2f} |"
        )
    wing = "wing:3:900000"  # (built above when --bays has 3: its fields are kept)
    fixed = {
        "guide, field shaping": steps_per_second(args.rows, tank=wing, guide=True, shaping="field"),
        "guide, raster shaping": steps_per_second(args.rows, tank=wing, guide=True, shaping=True),
    }
    guide_cost = float(np.median([t[0] for t in totals[1:]]))
    raster_cost = guide_cost + float(np.median([t[1] for t in totals[1:]]))
    print(f"\n| {wing}, {args.rows} rows | steps/s | a new wing costs (median) | in steps |")
    print("|---|---:|---:|---:|")
    for (name, rate), cost in zip(fixed.items(), (guide_cost, raster_cost)):
        print(f"| {name} | {rate:,.0f} | {cost:.2f} s | {rate * cost:,.0f} |")


def training_table(args: argparse.Namespace) -> None:
    """Print PPO's steps/s on one new wing, a pool of 8 and the stream moving on."""
    print(
        f"\n| PPO on {args.rows} rows, 3-bay wings, {args.train_steps:,} steps | steps/s | "
        "wings met | share of one wing's |"
    )
    print("|---|---:|---:|---:|")
    # new wings for the baselines too: every target cell's guide field is built on first use
    fixed_rate, _ = training_rate(args.train_steps, args.rows, "wing:3:905000")
    print(f"| one new wing (wing:3:905000) | {fixed_rate:,.0f} | 1 | 100% |")
    rate, _ = training_rate(args.train_steps, args.rows, "wing:3:910000-910007")
    share = rate / fixed_rate
    print(
        f"| the stream's first 8 as a pool, a group of rows each | {rate:,.0f} | 8 | {share:.0%} |"
    )
    for episodes in (8, 32, 128):
        rate, used = training_rate(
            args.train_steps, args.rows, "wing:3:910000+", tank_episodes=episodes
        )
        print(
            f"| a stream, 8 wings at once, the next one per {episodes} episodes of a group | "
            f"{rate:,.0f} | {used} | {rate / fixed_rate:.0%} |"
        )


def main() -> None:
    """Print the table of costs per tank and what they are worth in steps."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="generated wings per bay count")
    parser.add_argument("--bays", default="2,3,5", help="bay counts of the wings (default 2,3,5)")
    parser.add_argument("--rows", type=int, default=128, help="rows of the fixed-tank env")
    parser.add_argument(
        "--train-steps", type=int, default=131072, help="PPO steps per training measurement"
    )
    parser.add_argument("--routes", type=int, default=100, help="routes per route measurement")
    parser.add_argument(
        "--tables", default="costs,training,route", help="which tables: costs, training, route"
    )
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    tables = set(args.tables.split(","))
    if not tables <= {"costs", "training", "route"}:
        parser.error(f"--tables: costs, training and/or route, got {args.tables}")
    if "costs" in tables:
        cost_tables(args)
    if "training" in tables:
        training_table(args)
    if "route" in tables:
        route_table(args)
    print()
    print(machine_facts())


if __name__ == "__main__":
    main()
