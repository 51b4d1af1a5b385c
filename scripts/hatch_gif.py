"""The README's picture: the arm going through the hatch, as an animated GIF.

Run: ``python scripts/hatch_gif.py [-o docs/_static/hatch.gif] [--target X Y Z]``. Plans a
follow-the-leader motion from the access panel to a bay-2 target (:func:`plan_motion`, 1 cm
margin, checked densely) and draws every kept entry with the renderer the envs' ``rgb_array``
uses (:class:`aftir_rl.viz.plotting.PathRenderer`): the tank, the arm and
the target. Deterministic: the same tank and target give the same frames.
"""

from __future__ import annotations

import argparse

import numpy as np

from aftir_rl.core.robot import body_points
from aftir_rl.core.tank import load_tank
from aftir_rl.planning.ftl.plan import plan_motion
from aftir_rl.viz.plotting import PathRenderer, save_gif


def frames(target: list[float], count: int) -> list[np.ndarray]:
    """``count`` frames of the planned motion to ``target``, the last held."""
    tank = load_tank("b737_center")
    plan = plan_motion(tank, target)
    if not plan.complete:
        raise SystemExit(f"no motion to {target}: {plan.reason}")
    motion = plan.to_json()["motion"]
    length = plan.section_length
    dis = np.array([m["dis"] for m in motion])
    theta = np.array([m["theta"] for m in motion])
    phi = np.array([m["phi"] for m in motion])
    bodies = body_points(dis, theta, phi, length)
    renderer = PathRenderer(tank, title=f"follow-the-leader to {tuple(target)} cm, 1 cm margin")
    keep = np.unique(np.linspace(0, len(motion) - 1, count).round().astype(int))
    out = [renderer.render(None, target, arms=[bodies[i]]) for i in keep]
    return out + [out[-1]] * 12


def main() -> None:
    """Write the GIF."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("-o", "--output", default="docs/_static/hatch.gif")
    parser.add_argument("--target", nargs=3, type=float, default=[230.0, 140.0, 90.0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--fps", type=int, default=12)
    args = parser.parse_args()
    count = save_gif(args.output, frames(args.target, args.frames), args.fps)
    print(f"wrote {args.output} ({count} frames)")


if __name__ == "__main__":
    main()
