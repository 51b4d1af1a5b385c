"""An interactive 3D view of run directories: one self-contained HTML page (plotly, offline).

:func:`write_view` draws the tank (box outline, access panel, baffle pieces and boxes as solid
blocks, pipes as cylinders, spheres) and, for each run directory, what it holds:

- ``path.json`` (tabular runs): the greedy cell path through the cell centres and the target;
- ``trajectory.json``: the tip route and the arm moving along it, as plotly animation frames
  with a slider and play/pause buttons. The contract is ``{"complete", "margin_cm",
  "section_length", "method", "motion": [{"dis", "theta", "phi"}, ...], "waypoint_index"}``
  (cm, rad; design.md §1 for the kinematics). The older form (``postures`` and ``moves``, as
  :meth:`aftir_rl.posture.trajectory.Trajectory.to_json` writes it) is read too, in the same
  order as ``Trajectory.motion()``.
- anything else (an SB3 run with only ``config.json`` and ``summary.json``) is listed with a note
  saying there is no path to draw.

Several runs are overlaid; the legend groups each run's traces under its directory name. A
motion of any length becomes at most ``max_frames`` frames (evenly spaced, the first and the last
posture always among them, and the waypoints' postures where they fit); with several motions,
frame ``k`` shows each arm at the same fraction of its own motion. The axes span the tank's box
and 30 % of its height below the floor; the arm still inside the guide further down is clipped.
Postures with fewer sections than the longest are padded with straight sections at the base and
``dis`` lowered by their length, which is the same arm.

Only JSON is read from a run directory (nothing is unpickled or imported). A directory that is
missing, holds none of the files above, or holds one that is not valid JSON of the expected shape
raises :class:`~aftir_rl.errors.CheckpointError` (a saved training output cannot be read) with
a one-line message naming the file. The page embeds plotly.js (about 4.7 MB), so it opens with no
network; it is written atomically.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.atomic import atomic_open
from aftir_rl.errors import CheckpointError
from aftir_rl.robot import body_points
from aftir_rl.tank import Box, Cylinder, Sphere, Tank, load_tank

if TYPE_CHECKING:
    import plotly.graph_objects as go

__all__ = ["RunData", "read_run", "build_figure", "write_view", "DEFAULT_MAX_FRAMES"]

DEFAULT_MAX_FRAMES = 120
#: The files a run directory is recognised by.
RUN_FILES = ("path.json", "trajectory.json", "summary.json", "config.json")
_POINTS_PER_SECTION = 6
_MAX_ROUTE_POINTS = 2000
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#e377c2", "#8c564b")


@dataclass
class RunData:
    """What a run directory holds, read from its JSON files only.

    Attributes:
        name: the label in the legend (the directory name, made unique).
        path: the run directory.
        cells_cm: cell centres of the greedy path [cm], shape ``(P, 3)``, or None.
        cells: the path's cells ``(a, b, c)`` when ``path.json`` has no ``points_cm``.
        target: the target [cm], or None.
        dis: the motion's ``dis`` [cm], shape ``(M,)``, or None without a motion.
        theta: bending angles [rad], shape ``(M, N)``, or None.
        phi: bending-plane angles [rad], shape ``(M, N)``, or None.
        section_length: ``l`` [cm] of the motion.
        waypoint_index: motion entries that are waypoints' postures.
        facts: short ``key: value`` lines shown beside the plot (complete, margin, method...).
        notes: what could not be shown, and why.
        tank: the tank named by the run's files, if any.

    """

    name: str
    path: Path
    cells_cm: NDArray[np.float64] | None = None
    cells: NDArray[np.int64] | None = None
    target: NDArray[np.float64] | None = None
    dis: NDArray[np.float64] | None = None
    theta: NDArray[np.float64] | None = None
    phi: NDArray[np.float64] | None = None
    section_length: float = 0.0
    waypoint_index: list[int] = field(default_factory=list)
    facts: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    tank: str | None = None

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

    def tips(self) -> NDArray[np.float64]:
        """Tip of every motion entry [cm], shape ``(M, 3)``."""
        return self.backbones(np.arange(self.n_motion))[:, -1, :]


# --------------------------------------------------------------------------------------------
# Reading run directories (JSON only)


def _read_json(path: Path) -> Any:
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise CheckpointError(f"{path}: cannot read it as JSON: {why}") from None


def _bad(path: Path, what: str) -> CheckpointError:
    return CheckpointError(f"{path}: {what}")


def _points(value: Any, path: Path, key: str) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise _bad(path, f"{key}: expected a list of [x, y, z] in cm") from None
    if arr.ndim == 1 and arr.size == 3:
        return arr
    if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.isfinite(arr)):
        raise _bad(path, f"{key}: expected a list of finite [x, y, z] in cm")
    return arr


def _posture(entry: Any, path: Path, where: str) -> tuple[float, list[float], list[float]]:
    if not isinstance(entry, dict) or not {"dis", "theta", "phi"} <= set(entry):
        raise _bad(path, f"{where}: expected {{'dis', 'theta', 'phi'}}, got {str(entry)[:60]}")
    try:
        dis = float(entry["dis"])
        theta = [float(v) for v in entry["theta"]]
        phi = [float(v) for v in entry["phi"]]
    except (TypeError, ValueError):
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
    except (TypeError, ValueError):
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
        if isinstance(move, dict) and isinstance(move.get("via"), list):
            vias[int(move.get("from", -1))] = move["via"]
    motion, waypoints = [], []
    for i, posture in enumerate(postures):
        if posture is not None:
            waypoints.append(len(motion))
            motion += [posture, *vias.get(i, [])]
    return motion, waypoints


def _read_trajectory(run: RunData, path: Path) -> None:
    data = _read_json(path)
    if not isinstance(data, dict):
        raise _bad(path, "expected a JSON object")
    for key in ("complete", "method", "margin_cm", "inserting"):
        if key in data and not isinstance(data[key], (dict, list)):
            run.facts[key] = str(data[key])
    entries, waypoints = _motion_entries(data, path)
    if not entries:
        run.notes.append("trajectory.json has no postures: no arm to show")
        return
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


def read_run(run_dir: str | Path) -> RunData:
    """Read a run directory's JSON files (``path.json``, ``trajectory.json``, ``summary.json``...).

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
            data = _read_json(path / name)
            if not isinstance(data, dict):
                raise _bad(path / name, "expected a JSON object")
            if isinstance(data.get("tank"), str):
                run.tank = data["tank"]
            for key in ("algo", "env_id", "timesteps", "success_rate", "tip_error_cm"):
                if key in data and isinstance(data[key], (str, int, float)):
                    run.facts[key] = (
                        f"{data[key]:.4g}" if isinstance(data[key], float) else str(data[key])
                    )
    if "path.json" in present:
        file = path / "path.json"
        data = _read_json(file)
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
    if "trajectory.json" in present:
        _read_trajectory(run, path / "trajectory.json")
    if run.cells_cm is None and run.cells is None and run.dis is None:
        run.notes.append(
            f"no path.json or trajectory.json (found {', '.join(present)}): no path to draw"
        )
    return run


# --------------------------------------------------------------------------------------------
# Tank traces


#: A triangle mesh: vertices ``(V, 3)`` [cm] and faces ``(F, 3)`` (vertex indices).
_Mesh = tuple[NDArray[np.float64], NDArray[np.int64]]


def _box_mesh(lo: Sequence[float], hi: Sequence[float]) -> _Mesh:
    """Vertices and triangles of a box."""
    v = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    faces = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )  # fmt: skip
    return v, faces


def _cylinder_mesh(c: Cylinder, segments: int = 24) -> _Mesh:
    k = c.axis
    others = [i for i in range(3) if i != k]
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.zeros((segments, 3))
    ring[:, others[0]] = c.radius * np.cos(ang)
    ring[:, others[1]] = c.radius * np.sin(ang)
    p0, p1 = np.array(c.p0, float), np.array(c.p1, float)
    v = np.vstack([p0 + ring, p1 + ring, p0, p1])
    j = np.arange(segments)
    nxt = (j + 1) % segments
    side = np.vstack([np.c_[j, nxt, j + segments], np.c_[nxt, nxt + segments, j + segments]])
    caps = np.vstack(
        [np.c_[np.full(segments, 2 * segments), nxt, j],
         np.c_[np.full(segments, 2 * segments + 1), j + segments, nxt + segments]]
    )  # fmt: skip
    return v, np.vstack([side, caps])


def _sphere_mesh(s: Sphere, n_u: int = 16, n_v: int = 9) -> _Mesh:
    u = np.linspace(0, 2 * np.pi, n_u, endpoint=False)
    w = np.linspace(0, np.pi, n_v)
    uu, ww = np.meshgrid(u, w, indexing="ij")
    v = np.array(s.center) + s.radius * np.stack(
        [np.cos(uu) * np.sin(ww), np.sin(uu) * np.sin(ww), np.cos(ww)], axis=-1
    ).reshape(-1, 3)
    faces = []
    for i in range(n_u):
        for j in range(n_v - 1):
            a, b = i * n_v + j, ((i + 1) % n_u) * n_v + j
            faces += [[a, b, b + 1], [a, b + 1, a + 1]]
    return v, np.array(faces)


def _mesh_trace(parts: list[_Mesh], name: str, color: str, opacity: float) -> go.Mesh3d:
    import plotly.graph_objects as go

    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    v, f = np.vstack(verts), np.vstack(faces)
    return go.Mesh3d(
        x=v[:, 0], y=v[:, 1], z=v[:, 2], i=f[:, 0], j=f[:, 1], k=f[:, 2],
        color=color, opacity=opacity, name=name, legendgroup="tank", showlegend=True,
        flatshading=True, hoverinfo="name",
    )  # fmt: skip


def _edges(lo: Sequence[float], hi: Sequence[float]) -> NDArray[np.float64]:
    """The 12 edges of a box as one polyline with NaN breaks, shape ``(36, 3)``."""
    c = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    pairs = [(0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4),
             (0, 4), (1, 5), (2, 6), (3, 7)]  # fmt: skip
    out = np.full((3 * len(pairs), 3), np.nan)
    for n, (i, j) in enumerate(pairs):
        out[3 * n], out[3 * n + 1] = c[i], c[j]
    return out


def _line(points: NDArray[np.float64], **kwargs: Any) -> go.Scatter3d:
    import plotly.graph_objects as go

    p = np.round(np.asarray(points, dtype=np.float64), 2)
    return go.Scatter3d(x=p[:, 0], y=p[:, 1], z=p[:, 2], **kwargs)


def tank_traces(tank: Tank) -> list[Any]:
    """Plotly traces of the tank: box outline, panel, and its solids grouped by kind."""
    traces = [
        _line(_edges(tank.box_min, tank.box_max), mode="lines", name=f"tank {tank.name}",
              line={"color": "#888888", "width": 2}, legendgroup="tank", hoverinfo="skip",
              legendgrouptitle_text="tank"),
    ]  # fmt: skip
    t = np.linspace(0, 2 * np.pi, 49)
    c, r = tank.panel.center, tank.panel.radius
    circle = np.c_[c[0] + r * np.cos(t), c[1] + r * np.sin(t), np.full_like(t, c[2])]
    traces.append(
        _line(
            circle,
            mode="lines",
            name="access panel",
            line={"color": "black", "width": 4},
            legendgroup="tank",
            hoverinfo="name",
        )  # fmt: skip
    )
    baffle = [s for s in tank.solids if isinstance(s, Box) and s.name.startswith("baffle")]
    boxes = [s for s in tank.solids if isinstance(s, Box) and s not in baffle]
    cylinders = [s for s in tank.solids if isinstance(s, Cylinder)]
    spheres = [s for s in tank.solids if isinstance(s, Sphere)]
    groups = (
        ("baffle", [_box_mesh(b.min, b.max) for b in baffle], "#c8a165", 0.35),
        ("boxes (stringers)", [_box_mesh(b.min, b.max) for b in boxes], "#8c564b", 0.6),
        ("pipes", [_cylinder_mesh(cyl) for cyl in cylinders], "#7f7f7f", 0.6),
        ("spheres", [_sphere_mesh(s) for s in spheres], "#e45756", 0.5),
    )
    for name, parts, color, opacity in groups:
        if parts:
            traces.append(_mesh_trace(parts, name, color, opacity))
    return traces


# --------------------------------------------------------------------------------------------
# The figure


def _frame_indices(run: RunData, max_frames: int) -> NDArray[np.int64]:
    """Motion entries shown as frames: evenly spaced, ends included, waypoints where they fit."""
    m = run.n_motion
    if m <= max_frames:
        return np.arange(m)
    wp = np.unique([i for i in run.waypoint_index if 0 < i < m - 1]).astype(np.int64)
    if len(wp) > max_frames // 2:
        wp = wp[:0]
    best = np.union1d(np.linspace(0, m - 1, max_frames - len(wp)).round().astype(np.int64), wp)
    for n_even in range(max_frames - len(wp) + 1, max_frames + 1):  # fill up where they coincide
        out = np.union1d(np.linspace(0, m - 1, n_even).round().astype(np.int64), wp)
        if len(out) > max_frames:
            break
        best = out
    return best


def _unique_names(runs: list[RunData]) -> None:
    seen: dict[str, int] = {}
    for run in runs:
        base = run.name
        if base in seen:
            seen[base] += 1
            run.name = f"{base} ({seen[base]})"
        else:
            seen[base] = 1


def _resolve_tank(tank: str | Path | Tank | None, runs: list[RunData]) -> Tank:
    if tank is not None:
        return load_tank(tank)
    named = [r.tank for r in runs if r.tank]
    return load_tank(named[0] if named else "b737_center")


def build_figure(runs: Sequence[RunData], tank: Tank, max_frames: int = DEFAULT_MAX_FRAMES) -> Any:
    """A ``plotly.graph_objects.Figure`` of the tank and the runs, animated where there is motion.

    Args:
        runs: read by :func:`read_run`.
        tank: the tank to draw.
        max_frames: the most animation frames (at least 2).

    """
    import plotly.graph_objects as go

    if max_frames < 2:
        raise ValueError(f"max_frames must be at least 2, got {max_frames}")
    traces = tank_traces(tank)
    animated: list[tuple[int, RunData, NDArray[np.int64]]] = []  # (trace index, run, entries)
    for n, run in enumerate(runs):
        color = _COLORS[n % len(_COLORS)]
        group = {"legendgroup": f"run{n}", "legendgrouptitle_text": run.name}
        first = True

        def style(first_in_group: bool, group: dict[str, Any] = group) -> dict[str, Any]:
            return group if first_in_group else {"legendgroup": group["legendgroup"]}

        cells_cm = run.cells_cm
        if cells_cm is None and run.cells is not None and len(run.cells):
            if tank.cell_size is None:
                run.notes.append(f"path.json has cells but no points_cm, and {tank.name} has no "
                                 "raster: cell path not drawn")  # fmt: skip
            else:
                cells_cm = np.array([tank.raster.cell_center(c) for c in run.cells])
        if cells_cm is not None and len(cells_cm):
            traces.append(
                _line(
                    cells_cm,
                    mode="lines+markers",
                    name="cell path",
                    line={"color": color, "width": 3, "dash": "dash"},
                    marker={"size": 3, "color": color},
                    **style(first),
                )  # fmt: skip
            )
            first = False
            traces.append(
                _line(
                    cells_cm[:1],
                    mode="markers",
                    name="start",
                    marker={"size": 5, "color": "green", "symbol": "circle"},
                    **style(first),
                )  # fmt: skip
            )
        if run.target is not None:
            traces.append(
                _line(
                    run.target[None],
                    mode="markers",
                    name="target",
                    marker={"size": 6, "color": color, "symbol": "diamond"},
                    **style(first),
                )  # fmt: skip
            )
            first = False
        if run.n_motion:
            tips = run.tips()
            stride = max(1, math.ceil(len(tips) / _MAX_ROUTE_POINTS))
            route = np.vstack([tips[::stride], tips[-1:]])
            traces.append(
                _line(
                    route,
                    mode="lines",
                    name="tip route",
                    line={"color": color, "width": 4},
                    **style(first),
                )  # fmt: skip
            )
            first = False
            idx = _frame_indices(run, max_frames)
            arm = run.backbones(idx[:1])[0]
            traces.append(
                _line(
                    arm,
                    mode="lines",
                    name="arm",
                    line={"color": color, "width": 9},
                    hoverinfo="name",
                    **style(first),
                )  # fmt: skip
            )
            animated.append((len(traces) - 1, run, idx))
    fig = go.Figure(data=traces)
    if animated:
        _add_frames(fig, animated)
    span = np.array(tank.box_max) - np.array(tank.box_min)
    # a little of the guide below the panel; the rest of the arm down there is clipped away
    z_lo = tank.box_min[2] - 0.3 * span[2]
    ranges = [[tank.box_min[0], tank.box_max[0]], [tank.box_min[1], tank.box_max[1]],
              [z_lo, tank.box_max[2]]]  # fmt: skip
    sizes = np.array([r[1] - r[0] for r in ranges])
    aspect = sizes / sizes.max()
    fig.update_layout(
        scene={
            "xaxis": {"title": {"text": "x [cm]"}, "range": ranges[0]},
            "yaxis": {"title": {"text": "y [cm]"}, "range": ranges[1]},
            "zaxis": {"title": {"text": "z [cm]"}, "range": ranges[2]},
            "aspectmode": "manual",
            "aspectratio": {"x": aspect[0], "y": aspect[1], "z": aspect[2]},
            "camera": {"eye": {"x": -1.1, "y": -1.6, "z": 0.9}},
        },
        legend={"groupclick": "toggleitem", "itemsizing": "constant"},
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        height=720,
        uirevision="keep",  # keep the camera while the animation plays
    )
    return fig


def _add_frames(fig: Any, animated: list[tuple[int, RunData, NDArray[np.int64]]]) -> None:
    import plotly.graph_objects as go

    n_frames = max(len(idx) for _, _, idx in animated)
    arms = [run.backbones(idx) for _, run, idx in animated]
    frames, steps = [], []
    for k in range(n_frames):
        data, label = [], []
        for (_, _, idx), pts in zip(animated, arms):
            j = round(k * (len(idx) - 1) / max(1, n_frames - 1))
            arm = np.round(pts[j], 2)
            data.append(go.Scatter3d(x=arm[:, 0], y=arm[:, 1], z=arm[:, 2]))
            label.append(str(int(idx[j])))
        name = str(k)
        frames.append(go.Frame(data=data, traces=[i for i, _, _ in animated], name=name))
        steps.append(
            {"method": "animate", "label": "/".join(label),
             "args": [[name], {"mode": "immediate", "frame": {"duration": 0, "redraw": True},
                              "transition": {"duration": 0}}]}
        )  # fmt: skip
    fig.frames = frames
    play = {"frame": {"duration": 60, "redraw": True}, "fromcurrent": True,
            "transition": {"duration": 0}, "mode": "immediate"}  # fmt: skip
    pause = {"frame": {"duration": 0, "redraw": False}, "mode": "immediate"}
    fig.update_layout(
        updatemenus=[{
            "type": "buttons", "direction": "left", "x": 0.0, "y": 0.0, "xanchor": "left",
            "yanchor": "top", "pad": {"t": 30, "r": 10}, "showactive": False,
            "buttons": [{"label": "▶ play", "method": "animate", "args": [None, play]},
                        {"label": "❚❚ pause", "method": "animate", "args": [[None], pause]}],
        }],
        sliders=[{
            "active": 0, "x": 0.16, "len": 0.84, "y": 0.0, "yanchor": "top",
            "pad": {"t": 20}, "steps": steps,
            "currentvalue": {"prefix": "motion entry: ", "font": {"size": 12}},
        }],
    )  # fmt: skip


def _page(fig: Any, runs: Sequence[RunData], tank: Tank) -> str:
    rows = []
    for run in runs:
        facts = ", ".join(f"{k} {v}" for k, v in run.facts.items())
        notes = "".join(f"<li class='note'>{html.escape(s)}</li>" for s in run.notes)
        rows.append(
            f"<li><b>{html.escape(run.name)}</b> <span class='dir'>{html.escape(str(run.path))}"
            f"</span><br>{html.escape(facts) or 'no facts recorded'}<ul>{notes}</ul></li>"
        )
    plot = fig.to_html(
        full_html=False, include_plotlyjs=True, div_id="aftir-view", auto_play=False,
        config={"displaylogo": False, "responsive": True},
    )  # fmt: skip
    title = f"aftir_rl view: {len(runs)} run{'s' if len(runs) != 1 else ''} in {tank.name}"
    return (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>"
        "body{font-family:sans-serif;margin:8px 16px}h1{font-size:18px;margin:4px 0}"
        "li{margin:4px 0}.dir{color:#777;font-size:12px}.note{color:#a33}"
        "</style></head><body>"
        f"<h1>{html.escape(title)}</h1>{plot}"
        f"<h2 style='font-size:15px'>Runs</h2><ul id='aftir-runs'>{''.join(rows)}</ul>"
        "<p class='dir'>units cm; drag to rotate, scroll to zoom, click a legend entry to hide "
        "it; the slider picks a posture of the motion (label: its entry index per run).</p>"
        "</body></html>\n"
    )


def write_view(
    run_dirs: Sequence[str | Path],
    out: str | Path,
    tank: str | Path | Tank | None = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
) -> Path:
    """Write one self-contained HTML page viewing ``run_dirs`` over their tank; returns its path.

    Args:
        run_dirs: run directories (at least one).
        out: the HTML file to write (atomically; parents are created).
        tank: tank name, YAML path or :class:`Tank`; default the first ``tank`` a run's JSON
            names, else ``b737_center``.
        max_frames: the most animation frames.

    Raises:
        CheckpointError: a run directory cannot be read (see :func:`read_run`).
        ConfigError: the tank is unknown or malformed.

    """
    if not run_dirs:
        raise CheckpointError("no run directory given: name at least one")
    runs = [read_run(d) for d in run_dirs]
    _unique_names(runs)
    the_tank = _resolve_tank(tank, runs)
    page = _page(build_figure(runs, the_tank, max_frames), runs, the_tank)
    out = Path(out)
    with atomic_open(out, "w") as fh:
        fh.write(page)
    return out
