"""The guide's fields: Dijkstra and next steps, this tree against the previous kernels, one run.

    python benchmarks/bench_fields.py [--targets N] [--seed S]

Per tank, N random targets (seeded); each field is built twice, one implementation after the
other: ``relax_field`` (the shortest distances) and ``descend_field`` (each grid point's next
step) of :mod:`aftir_rl.core.kernel.guide`, and the previous ones, transcribed below (Dijkstra on
a ``heapq`` of ``(distance, point)`` pairs, stale pairs skipped; the next steps point by point).
Both must give the same arrays bit for bit. Printed: milliseconds per field (median), the ratio,
and the machine. The ``AFTIR-ArmFTL-v0`` guide builds one field per new target cell: in a
generated wing most training episodes build one.
"""

from __future__ import annotations

import argparse
import heapq
import math
import time

import numpy as np
from numba import njit
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder

from aftir_rl.core.kernel.guide import descend_field, relax_field
from aftir_rl.core.tank import load_tank
from aftir_rl.experiments.bench import machine_facts
from aftir_rl.planning.ftl.guide import NEIGHBOURS, GuideField

TANKS = ("b737_center", "wing:3:5", "wing:5:2")
QUICK = {"targets": 10}


@njit(cache=True)
def previous_relax(dist, free, edges, weights, neighbours, shape):  # noqa: ANN001, ANN201
    """``relax_field`` before: ``heapq`` of tuples, a point pushed again when it gets nearer."""
    s1, s2 = shape[1], shape[2]
    offset = (neighbours[:, 0] * s1 + neighbours[:, 1]) * s2 + neighbours[:, 2]
    n = dist.shape[0]
    heap = [(0.0, 0)]
    heap.pop()
    for x in range(n):
        if math.isfinite(dist[x]):
            heapq.heappush(heap, (dist[x], x))
    while heap:
        dy, y = heapq.heappop(heap)
        if dy > dist[y]:
            continue
        for e in range(offset.shape[0]):
            x = y - offset[e]
            if not (0 <= x < n and edges[e, x] and free[x]):
                continue
            v = dy + weights[e, x]
            if v < dist[x]:
                dist[x] = v
                heapq.heappush(heap, (v, x))


@njit(cache=True)
def previous_descend(dist, edges, weights, neighbours, shape, out):  # noqa: ANN001, ANN201
    """``descend_field`` before: point by point, every direction of each."""
    s1, s2 = shape[1], shape[2]
    for x in range(dist.shape[0]):
        x0, rem = x // (s1 * s2), x % (s1 * s2)
        x1, x2 = rem // s2, rem % s2
        best, nxt = np.inf, x
        for e in range(neighbours.shape[0]):
            y0, y1, y2 = x0 + neighbours[e, 0], x1 + neighbours[e, 1], x2 + neighbours[e, 2]
            if not (edges[e, x] and 0 <= y0 < shape[0] and 0 <= y1 < s1 and 0 <= y2 < s2):
                continue
            y = (y0 * s1 + y1) * s2 + y2
            via = dist[y] + weights[e, x]
            if via < best:
                best, nxt = via, y
        out[x] = x if dist[x] < best - 1e-9 else nxt


def _timed(fn, *args) -> float:  # noqa: ANN001
    start = time.perf_counter()
    fn(*args)
    return time.perf_counter() - start


def measure(name: str, targets: int, rng: np.random.Generator) -> dict[str, float]:
    """Median milliseconds per field of both implementations in one tank (equal outputs)."""
    tank = load_tank(name)
    lo, hi = np.asarray(tank.box_min, float), np.asarray(tank.box_max, float)
    probe = GuideField(tank, (lo + hi) / 2, clearance_cost=1.0)
    free, edges, table = (
        probe.free.reshape(-1),
        np.ascontiguousarray(probe.edges.reshape(len(NEIGHBOURS), -1)),
        probe.weight_table,
    )
    shape, n = probe.shape, probe.free.size
    centres = probe.origin + (np.indices(tuple(shape)).reshape(3, -1).T + 0.5) * probe.size
    times: dict[str, list[float]] = {"relax now": [], "relax before": []}
    times |= {"next now": [], "next before": []}
    for i in range(targets + 1):
        target = rng.uniform(lo, hi)
        near = np.linalg.norm(centres - target, axis=-1)
        start = np.where(free & (near <= 1.75 * probe.size), near, np.inf)
        a, b = start.copy(), start.copy()
        t_now = _timed(relax_field, a, free, edges, table, NEIGHBOURS, shape)
        t_before = _timed(previous_relax, b, free, edges, table, NEIGHBOURS, shape)
        na, nb = np.empty(n, np.int32), np.empty(n, np.int32)
        d_now = _timed(descend_field, a, edges, table, NEIGHBOURS, shape, na)
        d_before = _timed(previous_descend, a, edges, table, NEIGHBOURS, shape, nb)
        if not (np.array_equal(a, b) and np.array_equal(na, nb)):
            raise SystemExit(f"{name}: the implementations disagree on target {target}")
        if i:  # the first field compiled them
            for key, t in zip(times, (t_now, t_before, d_now, d_before)):
                times[key].append(1000 * t)
    return {key: float(np.median(v)) for key, v in times.items()} | {"points": float(n)}


def main() -> None:
    """Print the table: per tank, ms per field of each step, now and before, and the ratio."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--targets", type=int, default=30, help="fields per tank (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the targets (default 0)")
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    rng = np.random.default_rng(args.seed)
    print("| tank | grid points | Dijkstra ms, before / now | next steps ms, before / now | "
          "field ms, before / now | ratio |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|")
    for name in TANKS:
        m = measure(name, args.targets, rng)
        before, now = m["relax before"] + m["next before"], m["relax now"] + m["next now"]
        print(
            f"| {name} | {m['points']:,.0f} | {m['relax before']:.2f} / {m['relax now']:.2f} | "
            f"{m['next before']:.2f} / {m['next now']:.2f} | {before:.2f} / {now:.2f} | "
            f"{before / now:.2f}x |"
        )
    print(machine_facts())


if __name__ == "__main__":
    main()
