"""Run directories for the view: :func:`read_run` reads their JSON files into a :class:`RunData`.

- ``path.json`` (tabular runs): the greedy cell path (``points_cm`` or ``cells``) and the target;
- ``trajectory.json``: the motion, ``{"complete", "margin_cm", "section_length", "method",
  "motion": [{"dis", "theta", "phi"}, ...], "waypoint_index"}`` (cm, rad; docs/design.md §2 for
  the kinematics, §9 for the files). The older form (``postures`` and ``moves``, as
  :meth:`aftir_rl.planning.posture.trajectory.Trajectory.to_json` writes it) is read too, in the
  same order as ``Trajectory.motion()``. Postures with fewer sections than the longest are padded
  with straight sections at the base and ``dis`` lowered by their length, which is the same arm;
- ``config.json`` and ``summary.json``: the tank's name and a few facts.

Only JSON is read (nothing is unpickled or imported). A directory that is missing, holds none of
:data:`RUN_FILES`, or holds one that is not valid JSON of the expected shape raises
:class:`~aftir_rl.core.errors.CheckpointError` with a one-line message naming the file.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.files import read_json, run_file
from aftir_rl.core.robot import body_points
from aftir_rl.core.tank.parts import MAX_SECTIONS

__all__ = ["PHYSICS_FILE", "RUN_FILES", "RunData", "read_run", "unique_names"]

#: The files a run directory is recognised by.
RUN_FILES = ("path.json", "trajectory.json", "summary.json", "config.json")
_POINTS_PER_SECTION = 6


@dataclass
class RunData:
    """What a run directory holds, read from its JSON files only.

    Attributes:
        name: the label in the legend (the directory name, made unique).
        path: the run directory.
        cells_cm: cell centres of the greedy path [cm], shape ``(P, 3)``, or None.
        cells: the path's cells ``(a, b, c)`` when ``path.json`` has no ``points_cm``.
        target: the target [cm], or None.
        targets: a tour's targets [cm], shape ``(K, 3)``, or None.
        dis: the motion's ``dis`` [cm], shape ``(M,)``, or None without a motion.
        theta: bending angles [rad], shape ``(M, N)``, or None.
        phi: bending-plane angles [rad], shape ``(M, N)``, or None.
        section_length: ``l`` [cm] of the motion.
        waypoint_index: motion entries that are waypoints' postures.
        facts: short ``key: value`` lines shown beside the plot (complete, margin, method...).
        notes: what could not be shown, and why.
        tank: the tank named by the run's files, if any.
        kept: the top-level values of ``trajectory.json`` asked for by :func:`read_run`'s
            ``keep``, as read (unchecked).
        physics: the bodies simulated by ``aftir simulate`` (``physics.json``): the motion
            entries and, for each, the rod's nodes [cm] ``(P, 3)``; None without the file.

    """

    name: str
    path: Path
    cells_cm: NDArray[np.float64] | None = None
    cells: NDArray[np.int64] | None = None
    target: NDArray[np.float64] | None = None
    targets: NDArray[np.float64] | None = None
    dis: NDArray[np.float64] | None = None
    theta: NDArray[np.float64] | None = None
    phi: NDArray[np.float64] | None = None
    section_length: float = 0.0
    waypoint_index: list[int] = field(default_factory=list)
    facts: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    tank: str | None = None
    kept: dict[str, Any] = field(default_factory=dict)
    physics: tuple[list[int], list[NDArray[np.float64]]] | None = None

    @property
    def n_motion(self) -> int:
        """Number of postures in the motion (0 without one)."""
        return 0 if self.dis is None else len(self.dis)

    def backbones(self, index: Sequence[int] | NDArray[np.int64]) -> NDArray[np.float64]:
        """Arm backbone points [cm] of the given motion entries, shape ``(len, N·K + 1, 3)``."""
        idx = np.asarray(index, dtype=np.int64)
        assert self.dis is not None and self.theta is not None and self.phi is not None
        return body_points(
            self.dis[idx], self.theta[idx], self.phi[idx], self.section_length, _POINTS_PER_SECTION
        )

    def simulated_body(self, entry: int) -> NDArray[np.float64] | None:
        """The simulated body shown at motion entry ``entry``, or None without ``physics.json``.

        The body of the last instant simulated at or before ``entry`` (the first if none is).
        """
        if self.physics is None:
            return None
        entries, bodies = self.physics
        k = max(0, int(np.searchsorted(entries, entry, side="right")) - 1)
        return bodies[k]

    def tips(self) -> NDArray[np.float64]:
        """Tip of every motion entry [cm], shape ``(M, 3)``."""
        return self.backbones(np.arange(self.n_motion))[:, -1, :]


def _bad(path: Path, what: str) -> CheckpointError:
    return CheckpointError(f"{path}: {what}")


#: The most simulated instants read from a ``physics.json`` (a 40-minute motion at 1 s: 2,400).
MAX_SNAPSHOTS = 20_000
#: The most points of one simulated body (12 sections of 20 elements, and more).
MAX_BODY_POINTS = 1_000
#: The file ``aftir simulate`` writes beside ``trajectory.json``.
PHYSICS_FILE = "physics.json"

#: The most targets of a tour drawn from its ``trajectory.json``.
MAX_TARGETS = 10_000
#: The most joint values (postures × sections) a motion read from a file may hold: about 8 times
#: a 20-target tour's, and 128 MB as arrays. A file that says more is refused before any array.
MAX_MOTION_VALUES = 8_000_000


def _points(value: Any, path: Path, key: str) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise _bad(path, f"{key}: expected a list of [x, y, z] in cm") from None
    if arr.ndim == 1 and arr.size == 3:
        return arr
    if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr)):
        raise _bad(path, f"{key}: expected a list of finite [x, y, z] in cm")
    return arr


def _posture(entry: Any, path: Path, where: str) -> tuple[float, list[float], list[float]]:
    if not isinstance(entry, dict) or not {"dis", "theta", "phi"} <= set(entry):
        raise _bad(path, f"{where}: expected {{'dis', 'theta', 'phi'}}, got {str(entry)[:60]}")
    for key in ("theta", "phi"):
        if not isinstance(entry[key], list) or len(entry[key]) > MAX_SECTIONS:
            raise _bad(
                path, f"{where}: {key} must list one angle per section, at most {MAX_SECTIONS}"
            )
    try:
        dis = float(entry["dis"])
        theta = [float(v) for v in entry["theta"]]
        phi = [float(v) for v in entry["phi"]]
    except (TypeError, ValueError, OverflowError):
        raise _bad(path, f"{where}: dis, theta and phi must be numbers (cm, rad)") from None
    if len(theta) != len(phi) or not theta:
        raise _bad(path, f"{where}: theta and phi need one value per section, equal in number")
    if not all(math.isfinite(v) for v in [dis, *theta, *phi]):
        raise _bad(path, f"{where}: dis, theta and phi must be finite")
    return dis, theta, phi


def _section_length(data: dict[str, Any], path: Path) -> float:
    value = data.get("section_length")
    if value is None:
        postures = [p for p in data.get("postures") or [] if isinstance(p, dict)]
        value = postures[0].get("section_length") if postures else None
    try:
        length = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        raise _bad(path, "section_length: expected a positive length in cm") from None
    if not length > 0 or not math.isfinite(length):
        raise _bad(path, f"section_length: expected a positive length in cm, got {value!r}")
    return length


def _motion_entries(data: dict[str, Any], path: Path) -> tuple[list[Any], list[int]]:
    """The motion's posture dicts and the waypoints' entries, from either form of the file."""
    if "motion" in data:
        motion = data["motion"]
        if not isinstance(motion, list):
            raise _bad(path, "motion: expected a list of {dis, theta, phi}")
        wp = data.get("waypoint_index") or []
        if not isinstance(wp, list) or not all(isinstance(i, int) for i in wp):
            raise _bad(path, "waypoint_index: expected a list of integers")
        return motion, [i for i in wp if 0 <= i < len(motion)]
    postures = data.get("postures")
    if not isinstance(postures, list):
        raise _bad(path, "expected a 'motion' list (or the older 'postures' and 'moves')")
    vias: dict[int, list[Any]] = {}
    for move in data.get("moves") or []:
        if (
            isinstance(move, dict)
            and isinstance(move.get("via"), list)
            and isinstance(move.get("from"), int)
        ):
            vias[move["from"]] = move["via"]
    motion, waypoints = [], []
    for i, posture in enumerate(postures):
        if posture is not None:
            waypoints.append(len(motion))
            motion += [posture, *vias.get(i, [])]
    return motion, waypoints


def _read_trajectory(run: RunData, path: Path, keep: Sequence[str] = ()) -> None:
    data = read_json(path, path.name)
    if not isinstance(data, dict):
        raise _bad(path, "expected a JSON object")
    run.kept = {key: data[key] for key in keep if key in data}
    if data.get("target") is not None and run.target is None:  # a plan's or a rollout's
        run.target = _points(data["target"], path, "target").reshape(3)
    if isinstance(data.get("targets"), list) and len(data["targets"]) <= MAX_TARGETS:  # a tour's
        run.targets = _points(data["targets"], path, "targets").reshape(-1, 3)
    for key in ("complete", "method", "margin_cm", "inserting"):
        if key in data and not isinstance(data[key], (dict, list)):
            run.facts[key] = str(data[key])
    entries, waypoints = _motion_entries(data, path)
    if not entries:
        run.notes.append("trajectory.json has no postures: no arm to show")
        return
    if len(entries) > MAX_MOTION_VALUES // MAX_SECTIONS:
        # at most MAX_SECTIONS each: only a longer motion needs its entries counted
        values = sum(len(e["theta"]) if isinstance(e, dict) and isinstance(e.get("theta"), list)
                     else 1 for e in entries)  # fmt: skip
        if values > MAX_MOTION_VALUES:
            raise _bad(path, f"the motion holds {values:,} joint values, more than "
                       f"{MAX_MOTION_VALUES:,}")  # fmt: skip
    parsed = [_posture(e, path, f"motion[{i}]") for i, e in enumerate(entries)]
    l = _section_length(data, path)
    n = max(len(t) for _, t, _ in parsed)
    dis = np.empty(len(parsed))
    theta = np.zeros((len(parsed), n))
    phi = np.zeros((len(parsed), n))
    for i, (d, t, p) in enumerate(parsed):
        pad = n - len(t)  # straight sections at the base: the same arm (see the docstring)
        dis[i] = d - pad * l
        theta[i, pad:], phi[i, pad:] = t, p
    run.dis, run.theta, run.phi, run.section_length = dis, theta, phi, l
    run.waypoint_index = waypoints
    run.facts["motion"] = f"{len(parsed)} postures, {n} sections of {l:g} cm"


def read_run(run_dir: str | Path, keep: Sequence[str] = ()) -> RunData:
    """Read a run directory's JSON files (``path.json``, ``trajectory.json``, ``summary.json``...).

    ``keep``: top-level keys of ``trajectory.json`` to keep in :attr:`RunData.kept` (each file
    is read once).

    Raises:
        CheckpointError: the directory is missing, holds none of :data:`RUN_FILES`, or one of
            them is not valid JSON of the expected shape.

    """
    path = Path(run_dir)
    if not path.is_dir():
        raise CheckpointError(f"{path}: not a run directory (no such directory)")
    present = [name for name in RUN_FILES if (path / name).is_file()]
    if not present:
        raise CheckpointError(
            f"{path}: not a run directory: none of {', '.join(RUN_FILES)} is in it"
        )
    run = RunData(name=path.name or str(path), path=path)
    for name in ("config.json", "summary.json"):
        if name in present:
            _read_facts(run, run_file(path, name))
    if "path.json" in present:
        _read_path(run, run_file(path, "path.json"))
    if "trajectory.json" in present:
        _read_trajectory(run, run_file(path, "trajectory.json"), keep)
        if run.dis is not None and (path / PHYSICS_FILE).is_file():
            _read_physics(run, run_file(path, PHYSICS_FILE))
    if run.cells_cm is None and run.cells is None and run.dis is None:
        run.notes.append(
            f"no path.json or trajectory.json (found {', '.join(present)}): no path to draw"
        )
    return run


def _read_physics(run: RunData, path: Path) -> None:
    """The simulated bodies of ``physics.json`` and its verdict (``aftir simulate``)."""
    data = read_json(path, path.name)
    snapshots = data.get("snapshots") if isinstance(data, dict) else None
    if not isinstance(snapshots, list) or not 0 < len(snapshots) <= MAX_SNAPSHOTS:
        raise _bad(path, f"expected 1 to {MAX_SNAPSHOTS:,} snapshots")
    entries: list[int] = []
    bodies: list[NDArray[np.float64]] = []
    for i, snap in enumerate(snapshots):
        entry = snap.get("entry") if isinstance(snap, dict) else None
        body = snap.get("body") if isinstance(snap, dict) else None
        if not isinstance(entry, int) or isinstance(entry, bool) or not isinstance(body, list):
            raise _bad(path, f"snapshots[{i}]: expected an integer entry and a body")
        if not 2 <= len(body) <= MAX_BODY_POINTS or (entries and entry < entries[-1]):
            raise _bad(path, f"snapshots[{i}]: a body of 2 to {MAX_BODY_POINTS} points, entries "
                       "in order")  # fmt: skip
        entries.append(entry)
        bodies.append(_points(body, path, f"snapshots[{i}].body").reshape(-1, 3))
    run.physics = (entries, bodies)
    summary = data.get("summary")
    if isinstance(summary, dict) and isinstance(summary.get("least_clearance_cm"), int | float):
        held = "held" if summary.get("margin_held") is True else "lost"
        run.facts["physics"] = (
            f"margin {held} on the simulated body ({float(summary['least_clearance_cm']):.2f} cm)"
        )


def _read_facts(run: RunData, file: Path) -> None:
    """Read the tank and the facts shown beside the run from ``config.json`` or ``summary.json``.

    Raises:
        CheckpointError: the file is not a JSON object.

    """
    data = read_json(file, file.name)
    if not isinstance(data, dict):
        raise _bad(file, "expected a JSON object")
    if isinstance(data.get("tank"), str):
        run.tank = data["tank"]
    for key in ("algo", "env_id", "timesteps", "success_rate", "tip_error_cm"):
        if key in data and isinstance(data[key], (str, int, float)):
            run.facts[key] = f"{data[key]:.4g}" if isinstance(data[key], float) else str(data[key])


def _read_path(run: RunData, file: Path) -> None:
    """Read a Q-learning run's ``path.json``: tank, cell path (cm or cells), target and length.

    Raises:
        CheckpointError: the file is not a JSON object, or a point list is malformed.

    """
    data = read_json(file, file.name)
    if not isinstance(data, dict):
        raise _bad(file, "expected a JSON object")
    if isinstance(data.get("tank"), str):
        run.tank = data["tank"]
    if data.get("points_cm") is not None:
        run.cells_cm = _points(data["points_cm"], file, "points_cm").reshape(-1, 3)
    elif data.get("cells") is not None:
        run.cells = _points(data["cells"], file, "cells").reshape(-1, 3).astype(np.int64)
    if data.get("target") is not None:
        run.target = _points(data["target"], file, "target").reshape(3)
    if "length_steps" in data:
        run.facts["path"] = f"{data['length_steps']} steps"


def unique_names(runs: Sequence[RunData]) -> None:
    """Make the runs' legend names unique: a repeated name gets `` (2)``, `` (3)``..."""
    seen: dict[str, int] = {}
    for run in runs:
        base = run.name
        if base in seen:
            seen[base] += 1
            run.name = f"{base} ({seen[base]})"
        else:
            seen[base] = 1
