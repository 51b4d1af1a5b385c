"""Region division against blind search in the single cabin tank (st2014 Tables 1 and 2).

Run: ``python benchmarks/bench_st2014.py``. Prints markdown tables measured in this one run:

1. st2014 Table 1: blind search (planar, 1° grid over the bending angles, the jace baseline,
   ``Planner.plan(method="blind")``) against region division for the paper's three targets, our
   speed-up beside the paper's (Matlab, 2014).
2. st2014 Table 2: region division to the eight tank vertices (pulled 3 cm inside, the arm's
   radius + 0.5) and one arbitrary point, ours beside the paper's, with the tip error by forward
   kinematics and the clearance from python-fcl.
3. The geometric reading on the paper's exact targets (no tank, no collision check): what the
   closed-form methods give for the printed vertices, beside the paper's numbers.
"""

from __future__ import annotations

import argparse
import math
import os
import platform

import numpy as np
from bench_posture import best_time  # benchmarks/ is the script's own folder
from quick_mode import parse_args, print_header

from aftir_rl.core.errors import PlanningError
from aftir_rl.core.papers import ST2014_TABLE1, ST2014_TABLE2
from aftir_rl.core.tank.raster import format_point
from aftir_rl.planning.posture import Planner
from aftir_rl.planning.posture.region_division import bearing, geometric_solution, region_division

QUICK = {"repeats": 1}


def table1(planner: Planner, repeats: int) -> None:
    print("st2014 Table 1: blind search against region division, single_cabin (l = 25 cm)")
    print()
    print(
        "| target (cm) | blind search (s) | region division (s) | ratio, ours | "
        "blind, paper (s) | region division, paper (s) | ratio, paper |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    planner.plan(ST2014_TABLE1[-1][0], method="blind")  # loads the compiled kernels: not timed
    for target, paper_blind, paper_rd in ST2014_TABLE1:
        t_blind, _ = best_time(lambda t=target: planner.plan(t, method="blind"), 1)
        t_rd, _ = best_time(lambda t=target: region_division(planner, t), repeats)
        print(
            f"| {format_point(target)} | {t_blind:.3f} | {t_rd * 1e3:.2f} ms | "
            f"{t_blind / t_rd:.0f}x | {paper_blind} | {paper_rd} | "
            f"{paper_blind / paper_rd:.0f}x |"
        )
    print()
    print(f"Blind search: one run each; region division: best of {repeats}.")
    print()


def table2(planner: Planner) -> None:
    print(
        "st2014 Table 2: region division in single_cabin, ours / paper (paper targets are "
        "tank vertices, ours 3 cm inside)"
    )
    print()
    print(
        "| No. | paper target → our target (cm) | method | ϕ (deg) | Θ (deg) | descending (cm) "
        "| joints | sections (base) | tip error (cm) | clearance (cm) |"
    )
    print("|---:|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for i, row in enumerate(ST2014_TABLE2, start=1):
        where = f"{format_point(row.paper_target)} → {format_point(row.target)}"
        try:
            r = region_division(planner, row.target)
        except PlanningError as exc:
            print(f"| {i} | {where} | {exc} | | | | | | | |")
            continue
        d = r.details
        print(
            f"| {i} | {where} | {d['numerical_method']} / {row.method} | "
            f"{d['rotation_deg']:.1f} / {row.rotation_deg:g} | "
            f"{d['bend_deg']:.1f} / {row.bend_deg:g} | "
            f"{d['descending_cm']:.1f} / {row.descending_cm:g} | {d['joints']} / {row.joints} | "
            f"{r.posture.n_sections} ({d['base_sections']}) | {r.error_cm:.1e} | "
            f"{r.clearance_cm:.2f} |"
        )
    print()
    print(
        "sections (base): sections of the returned posture (straight sections added at the base "
        "where the paper raises it, so that dis <= 0)."
    )
    print()


def table2_exact() -> None:
    print("The geometric reading on the paper's exact targets (no tank), ours / paper")
    print()
    print(
        "| No. | paper target (cm) | region | method | ϕ (deg) | Θ (deg) | descending (cm) | "
        "joints |"
    )
    print("|---:|---|---:|---|---:|---:|---:|---:|")
    for i, row in enumerate(ST2014_TABLE2, start=1):
        c = geometric_solution(row.paper_target)
        phi = math.degrees(bearing(row.paper_target)) % 360
        bend = math.degrees(c.bend)
        print(
            f"| {i} | {format_point(row.paper_target)} | {c.region} | {c.method} / {row.method} | "
            f"{phi:.2f} / {row.rotation_deg:g} | {bend:.2f} / {row.bend_deg:g} | "
            f"{c.descending:.2f} / {row.descending_cm:g} | "
            f"{c.joints} / {row.joints} |"
        )
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="best of this many runs")
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    print(
        f"Machine: {platform.machine()}, {platform.processor() or platform.system()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}"
    )
    print()
    planner = Planner("single_cabin")
    table1(planner, args.repeats)
    table2(planner)
    table2_exact()


if __name__ == "__main__":
    main()
