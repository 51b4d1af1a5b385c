"""Milliseconds per ``rgb_array`` frame: a whole matplotlib figure per frame against blitting.

Run: ``python benchmarks/bench_render.py [--frames N]``. Prints one markdown table measured in this
one run on this machine. "old" is :func:`aftir_rl.viz.plotting.render_path` (a new figure per frame,
what the envs did before); "new" is :class:`aftir_rl.viz.plotting.PathRenderer` (background drawn
once, then only the moving artists), called the way each env's ``render()`` calls it, on a path
that grows frame by frame. "env" is ``env.render()`` after ``env.step`` (the step excluded). The
last column is the largest difference of any pixel channel between the old and the new picture of
the last frame (0-255; the legend is blended in numpy, which rounds differently from Agg by 1).
"""

from __future__ import annotations

import argparse
import platform
import time
from functools import partial

import gymnasium as gym
import numpy as np
from quick_mode import parse_args, print_header  # benchmarks/ is the script's own folder

import aftir_rl  # noqa: F401
from aftir_rl.core.robot import body_points
from aftir_rl.core.tank import load_tank
from aftir_rl.viz.plotting import PathRenderer, render_path

QUICK = {"frames": 20}


def frames(kind: str, n: int):
    """Arguments of ``n`` frames like the env's: a growing tip path, the target, maybe an arm."""
    tank = load_tank("b737_center")
    cells = [(3, 2, c) for c in range(5)] + [(a, 2, 4) for a in range(4, 15)]
    pts = np.array([tank.raster.cell_center(c) for c in cells])
    target = np.array([230.0, 140.0, 90.0])
    out = []
    for i in range(n):
        path = pts[: 1 + i % len(pts)]
        if kind == "AFTIR-Tank-v0":
            out.append({"points": path, "target": target})
        else:
            arm = body_points(-60.0, [0.0, 0.02 * i, 0.8], [0.3, 0.3, 0.3], 50.0, 10)
            out.append({"points": path, "target": target, "arms": [arm]})
    return tank, out


def ms_per_frame(fn, args, repeats: int = 1) -> float:
    fn(**args[0])  # warm up (imports, the renderer's background)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for a in args:
            fn(**a)
        best = min(best, (time.perf_counter() - start) / len(args) * 1e3)
    return best


def env_ms(env_id: str, n: int) -> float:
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    total = 0.0
    for _ in range(n):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        start = time.perf_counter()
        env.render()
        total += time.perf_counter() - start
        if term or trunc:
            env.reset()
    return total / n * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="frames per measurement")
    args = parse_args(parser, QUICK)
    print_header(args, QUICK)
    print(f"{platform.python_version()} on {platform.machine()}, {args.frames} frames, one run\n")
    print("| frame | old ms/frame | new ms/frame | ratio | env.render() ms | max pixel diff |")
    print("|---|---:|---:|---:|---:|---|")
    for kind, title in (("AFTIR-Tank-v0", "AFTIR-Tank-v0"), ("AFTIR-ArmReach-v0", "AFTIR-Arm")):
        tank, calls = frames(kind, args.frames)
        old_n = max(5, args.frames // 4)  # the old way is slow: fewer frames
        old = ms_per_frame(partial(render_path, tank, title=title), calls[:old_n])
        renderer = PathRenderer(tank, title=title)
        new = ms_per_frame(renderer.render, calls, repeats=3)
        old_img = render_path(tank, title=title, **calls[-1]).astype(int)
        diff = int(np.abs(old_img - renderer.render(**calls[-1])).max())
        env = env_ms(kind, args.frames)
        print(f"| {kind} | {old:.1f} | {new:.2f} | {old / new:.0f}x | {env:.2f} | {diff} |")


if __name__ == "__main__":
    main()
