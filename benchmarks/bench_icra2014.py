"""Collision-free region clipping among spherical obstacles (icra2014 Table II).

Run: ``python benchmarks/bench_icra2014.py [--rows abcd]``. Prints one markdown table measured in
this run: target [30, 18, 51], l = 25 cm, r0 = 2, r_b = 2 (so r_oba = 4), NUM = 10, Δθ = 0.1°,
the three obstacles added one by one (``configs/tanks/open_space_obstacles{1,2,3}.yaml``). For
each row, ours in the paper's mode (stop in the 1 cm target plane zone) and refined (tip within
0.01 cm), beside the paper's posture; "zone distance" is the smallest horizontal distance of the
backbone above the floor to an obstacle's vertical axis, for ours and for the paper's printed
posture.
"""

from __future__ import annotations

import argparse
import math
import os
import platform

import numpy as np
from bench_posture import fmt_theta as fmt
from quick_mode import parse_args, print_header

from aftir_rl.core.papers import ICRA2014_TABLE2, ICRA2014_TANKS, ICRA2014_TARGET
from aftir_rl.core.robot import Posture
from aftir_rl.planning.posture import Planner
from aftir_rl.planning.posture.obstacle_clipping import obstacle_clipping

QUICK = {"rows": "b"}


def zone_distance(posture: Posture, centres: list[tuple[float, float, float]], l: float) -> float:
    pts = posture.points(l, 40)
    pts = pts[pts[:, 2] >= 0]
    if not centres:
        return math.inf
    return min(float(np.min(np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1]))) for c in centres)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--rows", default="abcd", help="the table's rows: a to d, 0 to 3 obstacles (abcd)"
    )
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    print(
        f"machine: {platform.machine()}, {platform.system()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )
    print()
    print(
        "| row | obstacles | mode | N | theta (rad) | phi (rad) | dis (cm) | tip error (cm) | "
        "zone distance (cm) | loops | seconds |"
    )
    print("|---|---:|---|---:|---|---|---:|---:|---:|---:|---:|")
    for k, (tank, paper) in enumerate(zip(ICRA2014_TANKS, ICRA2014_TABLE2)):
        if "abcd"[k] not in args.rows:
            continue
        planner = Planner(tank)
        l = planner.arm.section_length
        centres = [s.center for s in planner.tank.obstacles]
        for mode, refine in (("ours, paper's zone", False), ("ours, refined", True)):
            r = obstacle_clipping(planner, ICRA2014_TARGET, refine=refine)
            p = r.posture
            zone = zone_distance(p, centres, l)
            print(
                f"| ({'abcd'[k]}) | {k} | {mode} | {p.n_sections} | {fmt(p.theta)} | "
                f"{fmt(p.phi)} | {p.dis:.2f} | {r.error_cm:.2g} | {zone:.2f} | "
                f"{r.details['loops']} | {r.seconds:.2f} |"
            )
        pp = Posture(paper.dis, paper.theta, paper.phi)
        err = float(np.linalg.norm(pp.tip(l) - np.array(ICRA2014_TARGET)))
        print(
            f"| ({'abcd'[k]}) | {k} | paper | 3 | {fmt(paper.theta)} | {fmt(paper.phi)} | "
            f"{paper.dis:.2f} | {err:.2g} | {zone_distance(pp, centres, l):.2f} | | |"
        )


if __name__ == "__main__":
    main()
