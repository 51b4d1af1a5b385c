"""The scene suite: eight tanks with fixed targets, every applicable planner, results as files.

:data:`SCENES` are the reference 737 tank, that tank read back from its own exported mesh,
generated wing tanks of 2 to 5 bays, a wing whose ribs have only round and oval holes
(the generator's ``round`` family), and a
wing given only as meshes (its walls and its solids). :func:`suite_targets` draws a scene's
targets (seeded, at least :data:`CLEARANCE` from every surface, in a raster cell reachable from
the start);
:func:`run_suite` plans a follow-the-leader motion with the 1 cm margin to each (the planner
that applies to any tank) and writes ``suite.json``, ``suite.csv`` and ``suite.db``, an SQLite
file in OMPL's benchmark-database layout (``experiments``, ``plannerConfigs``, ``runs``) that
Planner Arena reads. More: docs/tanks.md.
"""

from __future__ import annotations

import csv
import sqlite3
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import ConfigError
from aftir_rl.core.files import atomic_open, write_json
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank import Tank, load_tank
from aftir_rl.core.tank.meshes import export_tank_mesh

__all__ = ["SCENES", "CLEARANCE", "SuiteRow", "scene_tanks", "suite_targets", "run_suite"]

#: Scene name -> how to make it: a tank name or spec, or (how, argument) for the built ones.
SCENES: dict[str, Any] = {
    "b737_center": DEFAULT_TANK,
    "b737_center_mesh": ("mesh_of", DEFAULT_TANK),
    "wing_2bay": "wing:2:1",
    "wing_3bay": "wing:3:2",
    "wing_4bay": "wing:4:3",
    "wing_5bay": "wing:5:4",
    "wing_round_holes": "round:3:6",
    "wing_mesh_only": ("mesh_only", "wing:3:5"),
}
#: How far every target lies from every surface [cm].
CLEARANCE = 10.0


@dataclass(frozen=True)
class SuiteRow:
    """One target of one scene: the planner's outcome."""

    scene: str
    index: int
    target: tuple[float, float, float]
    complete: bool
    seconds: float
    min_clearance_cm: float | None
    tip_error_cm: float | None
    reason: str | None


def scene_tanks(folder: Path, names: list[str] | None = None) -> dict[str, Tank]:
    """The suite's tanks; the built ones (meshes) are written under ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for name in names or list(SCENES):
        how = SCENES[name]
        if isinstance(how, str):
            out[name] = load_tank(how)
        else:
            walls = folder / f"{name}_walls.stl" if how[0] == "mesh_only" else None
            export_tank_mesh(
                load_tank(how[1]), folder / f"{name}.stl", folder / f"{name}.yaml", walls
            )
            out[name] = load_tank(folder / f"{name}.yaml")
    return out


def suite_targets(
    tank: Tank,
    n: int,
    seed: int,
    region: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """``n`` targets ``(n, 3)`` [cm]: uniform in ``region`` (default the box), clear, reachable.

    Each is at least :data:`CLEARANCE` from every surface, in a raster cell reachable from the
    start (not the start's), drawn with ``seed``.

    Raises:
        ConfigError: fewer than ``n`` such points in 256,000 draws.

    """
    rng = np.random.default_rng(seed)
    lo, hi = region if region is not None else (np.array(tank.box_min), np.array(tank.box_max))
    lo, hi = np.asarray(lo) + CLEARANCE, np.asarray(hi) - CLEARANCE
    if np.any(hi <= lo):
        raise ConfigError(
            f"{tank.name}: the region is too small for targets {CLEARANCE:g} cm clear"
        )
    found: list[NDArray[np.float64]] = []
    for _ in range(1000):
        cand = rng.uniform(lo, hi, (256, 3))
        cand = cand[tank.distance(cand) >= CLEARANCE]
        cells = [tank.raster.point_to_cell(p) for p in cand]
        keep = [p for p, c in zip(cand, cells) if tank.reachable[c] > 0]
        found.extend(keep[: n - len(found)])
        if len(found) >= n:
            out: NDArray[np.float64] = np.asarray(found[:n], dtype=np.float64).round(2)
            return out
    raise ConfigError(f"{tank.name}: found {len(found)} of {n} clear, reachable targets")


def run_suite(
    folder: str | Path,
    n_targets: int = 100,
    scenes: list[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[SuiteRow]:
    """Plan every scene's targets and write ``suite.json``, ``.csv`` and ``.db`` in ``folder``."""
    from aftir_rl.planning.ftl.plan import plan_motion

    folder = Path(folder)
    tanks = scene_tanks(folder / "scenes", scenes)
    rows: list[SuiteRow] = []
    start = time.perf_counter()
    for s, (name, tank) in enumerate(tanks.items()):
        for i, target in enumerate(suite_targets(tank, n_targets, seed=s)):
            plan = plan_motion(tank, target)
            rows.append(SuiteRow(name, i, tuple(map(float, target)), plan.complete,  # type: ignore[arg-type]
                                 plan.seconds, plan.min_clearance_cm, plan.tip_error_cm,
                                 plan.reason))  # fmt: skip
            if progress:
                progress(f"{name} {i + 1}/{n_targets}: {'ok' if plan.complete else plan.reason}")
    write_suite(folder, rows, time.perf_counter() - start)
    return rows


def write_suite(folder: Path, rows: list[SuiteRow], seconds: float) -> None:
    """``suite.json``, ``suite.csv`` and the OMPL-layout ``suite.db``."""
    from aftir_rl.experiments.bench import machine_facts

    facts = machine_facts()
    write_json(folder / "suite.json", {"machine": facts, "seconds": seconds,
                                       "rows": [asdict(r) for r in rows]})  # fmt: skip
    with atomic_open(folder / "suite.csv", "w") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(asdict(rows[0])) if rows else ["scene"])
        writer.writeheader()
        writer.writerows(asdict(r) for r in rows)
    db = folder / "suite.db"
    db.unlink(missing_ok=True)
    with sqlite3.connect(db) as con:
        _ompl_tables(con)
        con.execute("INSERT INTO plannerConfigs (name, settings) VALUES (?, ?)",
                    ("geometric_FTL", '{"margin_cm": 1.0}'))  # fmt: skip
        for scene in dict.fromkeys(r.scene for r in rows):
            mine = [r for r in rows if r.scene == scene]
            cur = con.execute(
                "INSERT INTO experiments (name, totaltime, timelimit, memorylimit, runcount, "
                "version, hostname, cpuinfo, date, seed, setup) VALUES "
                "(?, ?, 0, 0, ?, ?, '', ?, datetime('now'), 0, '')",
                (scene, sum(r.seconds for r in mine), len(mine), facts["aftir_rl"], facts["cpu"]),
            )
            for r in mine:
                con.execute(
                    "INSERT INTO runs (experimentid, plannerid, time, solved, clearance, "
                    "tip_error, status) VALUES (?, 1, ?, ?, ?, ?, ?)",
                    (cur.lastrowid, r.seconds, int(r.complete), r.min_clearance_cm,
                     r.tip_error_cm, int(not r.complete)),
                )  # fmt: skip


def _ompl_tables(con: sqlite3.Connection) -> None:
    """The tables of OMPL's benchmark database that Planner Arena reads."""
    con.executescript(
        """
        CREATE TABLE experiments (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512),
            totaltime REAL, timelimit REAL, memorylimit REAL, runcount INTEGER,
            version VARCHAR(128), hostname VARCHAR(1024), cpuinfo TEXT, date DATETIME,
            seed INTEGER, setup TEXT);
        CREATE TABLE plannerConfigs (id INTEGER PRIMARY KEY AUTOINCREMENT,
            name VARCHAR(512) NOT NULL, settings TEXT);
        CREATE TABLE enums (name VARCHAR(512), value INTEGER, description TEXT,
            PRIMARY KEY (name, value));
        INSERT INTO enums VALUES ('status', 0, 'Exact solution'), ('status', 1, 'Unknown status');
        CREATE TABLE runs (id INTEGER PRIMARY KEY AUTOINCREMENT, experimentid INTEGER,
            plannerid INTEGER, time REAL, solved BOOLEAN, clearance REAL, tip_error REAL,
            status ENUM, FOREIGN KEY (experimentid) REFERENCES experiments(id) ON DELETE CASCADE,
            FOREIGN KEY (plannerid) REFERENCES plannerConfigs(id) ON DELETE CASCADE);
        """
    )
