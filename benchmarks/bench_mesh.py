"""How long a mesh tank takes to load, and how much memory: the 737 tank's solids, refined.

Run: ``python benchmarks/bench_mesh.py --triangles 200000``. Exports the reference tank's
solids as a mesh (``aftir tank export``), splits its triangles until there are at least
``--triangles`` (trimesh's ``subdivide_to_size``), then, in a fresh process each, loads the
primitive tank and the mesh tank and builds their raster and signed-distance grids. Printed:
triangles, seconds and peak memory of each load side by side with their ratio, the raster's
agreement and the largest signed-distance gap within 4 cm of a surface and anywhere in the
box, and the machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from aftir_rl.core.tank import load_tank
from aftir_rl.core.tank.meshes import export_tank_mesh
from aftir_rl.experiments.bench import machine_facts

_LOAD = """
import json, resource, sys, time
import numpy as np
t0 = time.perf_counter()
from aftir_rl.core.tank import load_tank
tank = load_tank(sys.argv[1])
obstructed = tank.raster.obstructed
for s in tank.solids:
    getattr(s, "grid", None)
rng = np.random.default_rng(0)
pts = rng.uniform(tank.box_min, tank.box_max, (100_000, 3))
d = tank.distance(pts)
seconds = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
np.save(sys.argv[2], np.concatenate([d, obstructed.ravel().astype(float)]))
print(json.dumps({"seconds": seconds, "peak_mb": peak}))
"""


def _load(tank: str, out: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", _LOAD, tank, str(out)], capture_output=True,
                          text=True, check=True)  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    """Export, refine, load both tanks in fresh processes; print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--triangles", type=int, default=200_000, help="at least this many")
    parser.add_argument("--json", help="write the row here too")
    args = parser.parse_args()
    import trimesh

    folder = Path(tempfile.mkdtemp())
    tank = load_tank("b737_center")
    export_tank_mesh(tank, folder / "coarse.stl")
    mesh = trimesh.load_mesh(folder / "coarse.stl", process=False)
    verts, faces, edge = mesh.vertices, mesh.faces, 50.0
    while len(faces) < args.triangles:
        edge *= 0.93
        verts, faces = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=edge)
    trimesh.Trimesh(verts, faces, process=False).export(folder / "fine.stl")
    export_tank_mesh(tank, folder / "unused.stl", folder / "fine.yaml")
    text = (folder / "fine.yaml").read_text().replace("unused.stl", "fine.stl")
    (folder / "fine.yaml").write_text(text)
    prim = _load("b737_center", folder / "prim.npy")
    meshed = _load(str(folder / "fine.yaml"), folder / "mesh.npy")
    a, b = np.load(folder / "prim.npy"), np.load(folder / "mesh.npy")
    n = 100_000
    gap = np.abs(a[:n] - b[:n])
    near = np.abs(a[:n]) < 4.0
    row = {
        "triangles": int(len(faces)),
        "primitive_s": prim["seconds"], "mesh_s": meshed["seconds"],
        "ratio": meshed["seconds"] / prim["seconds"],
        "primitive_peak_mb": prim["peak_mb"], "mesh_peak_mb": meshed["peak_mb"],
        "raster_equal": bool(np.array_equal(a[n:], b[n:])),
        "max_gap_near_cm": float(gap[near].max()), "max_gap_cm": float(gap.max()),
        "machine": machine_facts(),
    }  # fmt: skip
    print(f"machine: {row['machine']}")
    print("triangles | load primitive [s] | load mesh [s] | ratio | peak MB (prim / mesh) | "
          "raster equal | max |Δd| ≤4 cm / anywhere [cm]")  # fmt: skip
    print(f"{row['triangles']:,} | {row['primitive_s']:.2f} | {row['mesh_s']:.2f} | "
          f"{row['ratio']:.1f} | {row['primitive_peak_mb']:.0f} / {row['mesh_peak_mb']:.0f} | "
          f"{row['raster_equal']} | {row['max_gap_near_cm']:.2f} / "
          f"{row['max_gap_cm']:.2f}")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(row, indent=1))


if __name__ == "__main__":
    main()
