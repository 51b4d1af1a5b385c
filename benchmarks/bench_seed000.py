"""Collision-free region clipping among spherical obstacles (seed 000 Table II).

Run: ``python benchmarks/bench_seed000.py``. Prints one markdown table measured in this run:
target [30, 18, 51], l = 25 cm, r0 = 2, r_b = 2 (so r_oba = 4), NUM = 10, Δθ = 0.1°, the three
obstacles added one by one (``configs/tanks/open_space_obstacles{1,2,3}.yaml``). For each row,
ours in the paper's mode (stop in the 1 cm target plane zone) and refined (tip within 0.01 cm),
beside the paper's posture; "zone distance" is the smallest horizontal distance of the backbone
above the floor to an obstacle's vertical axis, for ours and for the paper's printed posture.
"""

from __future__ import annotations

import math
import os
import platform

import numpy as np
from bench_posture import fmt_theta as fmt

from aftir_rl.posture import Planner
from aftir_rl.posture.obstacle_clipping import obstacle_clipping
from aftir_rl.robot import Posture

TARGET = (30.0, 18.0, 51.0)
PAPER = [  # seed 000 Table II: theta, phi (rad), dis (cm), tip (cm)
    ((0.62, -0.15, 0.32), (0.54, 0.54, 0.54), -13.99, (30.01, 18.01, 51.00)),
    ((0.49, 0.65, -0.10), (1.22, 6.00, 6.79), -11.34, (30.03, 17.95, 51.00)),
    ((0.71, 0.96, 0.57), (1.35, 5.41, 1.44), -9.57, (30.02, 17.94, 51.00)),
    ((0.60, 1.07, 1.13), (1.42, 6.24, 3.99), -7.08, (29.95, 17.97, 51.00)),
]
TANKS = ["open_space", "open_space_obstacles1", "open_space_obstacles2", "open_space_obstacles3"]


def zone_distance(posture: Posture, centres: list[tuple[float, float, float]], l: float) -> float:
    pts = posture.points(l, 40)
    pts = pts[pts[:, 2] >= 0]
    if not centres:
        return math.inf
    return min(float(np.min(np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1]))) for c in centres)


def main() -> None:
    print(f"machine: {platform.machine()}, {platform.system()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}")  # fmt: skip
    print()
    print("| row | obstacles | mode | N | theta (rad) | phi (rad) | dis (cm) | tip error (cm) | "
          "zone distance (cm) | loops | seconds |")  # fmt: skip
    print("|---|---:|---|---:|---|---|---:|---:|---:|---:|---:|")
    for k, (tank, paper) in enumerate(zip(TANKS, PAPER)):
        planner = Planner(tank)
        l = planner.arm.section_length
        centres = [s.center for s in planner.tank.obstacles]
        for mode, refine in (("ours, paper's zone", False), ("ours, refined", True)):
            r = obstacle_clipping(planner, TARGET, refine=refine)
            p = r.posture
            zone = zone_distance(p, centres, l)
            print(f"| ({'abcd'[k]}) | {k} | {mode} | {p.n_sections} | {fmt(p.theta)} | "
                  f"{fmt(p.phi)} | {p.dis:.2f} | {r.error_cm:.2g} | {zone:.2f} | "
                  f"{r.details['loops']} | {r.seconds:.2f} |")  # fmt: skip
        theta, phi, dis, _ = paper
        pp = Posture(dis, theta, phi)
        err = float(np.linalg.norm(pp.tip(l) - np.array(TARGET)))
        print(f"| ({'abcd'[k]}) | {k} | paper | 3 | {fmt(theta)} | {fmt(phi)} | {dis:.2f} | "
              f"{err:.2g} | {zone_distance(pp, centres, l):.2f} | | |")  # fmt: skip


if __name__ == "__main__":
    main()
