"""Compile the package's numba kernels once, into numba's cache beside the sources.

    python scripts/warm_kernels.py

Run by ``make install``: the follow-the-leader planner's kernels, the camera's line of sight,
the ``AFTIR-ArmFTL-v0`` step (with and without the guide; the raster's distance table), the
posture planners' planar search, the posture collision pre-check, the posture chain's tip
Jacobian, the mesh tanks' distance kernels, the goal-conditioned Q-learning sweep and (with the
physics extra) PyElastica's rod otherwise compile on first use (about a minute in all on 2
cores). Nothing is written but numba's cache files (and a mesh in a temporary folder, removed).
"""

from __future__ import annotations

import importlib.util
import tempfile
import threading
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import aftir_rl  # noqa: F401  (registers the envs)
from aftir_rl.core.collision import CollisionScene
from aftir_rl.core.kernel.clearance import kernel_grid
from aftir_rl.core.kernel.sections import joint_tip_jacobian
from aftir_rl.core.kernel.visibility import seen_by_groups
from aftir_rl.core.robot import Posture
from aftir_rl.core.tank import load_tank
from aftir_rl.core.tank.meshes import export_tank_mesh
from aftir_rl.planning.ftl.plan import warm_up
from aftir_rl.planning.posture.planner import Planner
from aftir_rl.rl.tabular.q_table_goal import train_all_targets


def main() -> None:
    """Compile (or load) each family of kernels by running it once, saying which."""
    start = time.perf_counter()
    now = ["starting"]

    def say(family: str) -> None:
        now[0] = family
        print(f"  [{time.perf_counter() - start:5.0f} s] {family}", flush=True)

    def still() -> None:  # a line every 10 s: no family takes that long without one
        while not done.wait(10.0):
            print(f"  [{time.perf_counter() - start:5.0f} s]   ...still on {now[0]}", flush=True)

    done = threading.Event()
    threading.Thread(target=still, daemon=True).start()

    print("compiling numba's kernels once, into their cache (1-2 minutes on 2 cores):", flush=True)
    tank = load_tank("b737_center")
    say("the follow-the-leader planner")
    warm_up(tank)
    say("the camera, the collision pre-check, the tip Jacobian")
    seen = np.zeros((1, 1), dtype=np.bool_)
    one = np.array([[0.0, 0.0, 50.0]])
    seen_by_groups(one, one / 50.0, np.array([0, 1]), one + 10.0, one / 50.0,
                   tank.arm.camera.cosines(), kernel_grid(tank), seen)  # fmt: skip
    CollisionScene(tank).collides_fast(Posture(-60.0, (0.0, 0.0), (0.0, 0.0)))
    joint_tip_jacobian(np.zeros(5), 25.0, 1e-6, np.empty(3), np.empty((3, 5)))
    say("the AFTIR-ArmFTL-v0 step")
    for kwargs in ({"shaping": True}, {"guide": True, "shaping": "field", "steer": "target"}):
        env = gym.make("AFTIR-ArmFTL-v0", **kwargs)
        env.reset(seed=0)
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        env.close()
    say("the posture planners")
    planner = Planner("b737_center")
    for target in ((100.0, 50.0, 50.0), (230.0, 140.0, 90.0)):  # bay 1 (TGA), bay 2 (TSM)
        planner.plan(target)
    say("the mesh tanks' distance kernels")
    with tempfile.TemporaryDirectory() as folder:
        export_tank_mesh(tank, Path(folder) / "t.stl", Path(folder) / "t.yaml")
        load_tank(str(Path(folder) / "t.yaml")).raster  # noqa: B018  (builds the mesh grids)
    say("goal-conditioned Q-learning")
    train_all_targets(tank="b737_center", episodes=1, seed=0)
    if importlib.util.find_spec("elastica") is not None:  # the physics extra: PyElastica's own
        say("the physics check's Cosserat rod (PyElastica)")
        from aftir_rl.core.rod import RodProperties
        from aftir_rl.experiments.rod_model import RodModel, kinematic_rod

        model = RodModel(2, 50.0, 2.5, RodProperties())
        model.set_posture(*kinematic_rod(-20.0, np.array([0.3, 0.0]), np.zeros(2), 50.0, model.k))
        model.relax()
    done.set()
    print(f"numba kernels compiled or loaded in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
