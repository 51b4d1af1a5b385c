"""The tanks page's picture: a generated wing tank and a follow-the-leader motion through it.

Run: ``python scripts/wing_picture.py [-o docs/_static/wing.png] [--tank wing:4:3]``. Plans the
motion to the tank's last reference target (the middle of the farthest bay; :func:`plan_motion`,
1 cm margin) and draws the tank, the arm at the end of the motion and the target with the
renderer the envs' ``rgb_array`` uses (:class:`aftir_rl.viz.plotting.PathRenderer`).
Deterministic: the same tank gives the same picture.
"""

from __future__ import annotations

import argparse

import matplotlib.pyplot as plt
import numpy as np

from aftir_rl.core.robot import body_points
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.plan import plan_motion
from aftir_rl.viz.plotting import PathRenderer


def main() -> None:
    """Plan, draw, write the PNG."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("-o", "--output", default="docs/_static/wing.png")
    parser.add_argument("--tank", default="wing:4:3")
    args = parser.parse_args()
    tank = load_tank(args.tank)
    for target in reversed(tank.targets):
        plan = plan_motion(tank, target)
        if plan.complete:
            break
    else:
        raise SystemExit(f"no motion to any reference target of {args.tank}")
    last = plan.to_json()["motion"][-1]
    body = body_points(np.array([last["dis"]]), np.array([last["theta"]]),
                       np.array([last["phi"]]), plan.section_length)[0]  # fmt: skip
    title = f"{args.tank}: follow-the-leader to {tuple(target)} cm, 1 cm margin"
    image = PathRenderer(tank, title=title).render(None, target, arms=[body])
    plt.imsave(args.output, image)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
