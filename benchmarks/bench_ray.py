"""The benchmark serially and on a local Ray with 2 workers: wall time, speed-up, same table.

    python benchmarks/bench_ray.py [--sets jace filomat2018 bay1] [--n-random 3] [--workers 2]

Runs ``python -m aftir_rl.bench`` twice with the same arguments, once serially and once with
``--ray local --workers N``, and prints one markdown table. Rows are compared cell by cell but for
the seconds column; the clearance and path of ``rrt_connect`` and ``q_table+postures`` come from
OMPL's path simplifier, which runs for a time budget, so they are compared apart (two serial runs
can differ there too). Needs the ray extra (``pip install "aftir_rl[ray]"``).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time

TIMED = ("rrt_connect", "q_table+postures")


def run(args: list[str]) -> tuple[float, str]:
    start = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "aftir_rl.experiments.bench", *args],
        capture_output=True,
        text=True,
        check=False,
    )
    seconds = time.perf_counter() - start
    if out.returncode != 0:
        sys.exit(f"bench {' '.join(args)} failed (exit {out.returncode}):\n{out.stderr[-3000:]}")
    return seconds, out.stdout


def rows(table: str) -> list[list[str]]:
    """The table's data rows as cells, less the seconds column."""
    out = []
    for line in table.splitlines():
        if line.startswith("| ") and not line.startswith("| set |"):
            cells = [c.strip() for c in line.strip("|").split(" | ")]
            del cells[-2]
            out.append(cells)
    return out


def compare(a: list[list[str]], b: list[list[str]]) -> tuple[int, int, int]:
    """(rows equal in every compared cell, rows equal but for timed cells, rows that differ)."""
    same = timed = differ = 0
    for x, y in zip(a, b):
        if x == y:
            same += 1
        elif x[1] in TIMED and [c for i, c in enumerate(x) if i not in (5, 7)] == [
            c for i, c in enumerate(y) if i not in (5, 7)
        ]:
            timed += 1
        else:
            differ += 1
    return same, timed, differ + abs(len(a) - len(b))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", default=["jace", "filomat2018", "bay1"])
    parser.add_argument("--n-random", default="3")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--show-table", action="store_true", help="print the bench table too")
    args = parser.parse_args()
    common = ["--sets", *args.sets, "--n-random", args.n_random, "--quiet"]
    load = os.getloadavg()[0]
    serial_s, serial = run(common)
    ray_s, on_ray = run([*common, "--ray", "local", "--workers", str(args.workers)])
    a, b = rows(serial), rows(on_ray)
    same, timed, differ = compare(a, b)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}; load average before the runs {load:.2f}; "
        f"bench {' '.join(common)}"
    )
    print()
    print("| run | wall time (s) | speed-up | rows | same as serial |")
    print("|---|---:|---:|---:|---|")
    print(f"| serial | {serial_s:.1f} | 1.00x | {len(a)} | – |")
    verdict = f"{same} identical, {timed} identical but for OMPL-timed cells, {differ} differ"
    print(
        f"| --ray local --workers {args.workers} | {ray_s:.1f} | {serial_s / ray_s:.2f}x | "
        f"{len(b)} | {verdict} |"
    )
    if args.show_table:
        print()
        print(on_ray.split("\n\n", 1)[-1].rstrip())


if __name__ == "__main__":
    main()
