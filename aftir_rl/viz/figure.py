"""The plotly figure of the view: the tank, each run's paths, and its arm as animation frames.

:func:`tank_traces` draws the box outline, the access panel and the solids from their own
:meth:`~aftir_rl.core.tank.solids.Box.mesh` and :meth:`~aftir_rl.core.tank.solids.Box.wireframe`,
grouped in the legend (baffles, boxes, pipes, spheres, taper, meshes). :func:`build_figure` adds,
per run, the cell path, the target, the tip route and the arm, the arm animated over at most
``max_frames`` frames (evenly spaced, the first and the last posture always among them, and the
waypoints' postures where they fit); with several motions, frame ``k`` shows each arm at the same
fraction of its own motion. The axes span the tank's box and 30 % of its height below the floor;
the arm still inside the guide further down is clipped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aftir_rl.core.tank import Box, Tank
from aftir_rl.core.tank.solids import Mesh
from aftir_rl.viz.plotting import floor_view, solid_group
from aftir_rl.viz.runs import RunData

if TYPE_CHECKING:
    import plotly.graph_objects as go

__all__ = ["DEFAULT_MAX_FRAMES", "tank_traces", "build_figure"]

DEFAULT_MAX_FRAMES = 120
_MAX_ROUTE_POINTS = 2000
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#e377c2", "#8c564b")
#: The simulated body of physics.json (aftir simulate), in every run: an amber beside the arms.
_SIMULATED = "#f0a202"
#: The legend groups of the tank's solids, in order: (label, colour, opacity), by kind.
_SOLID_GROUPS = {
    "baffle": ("baffle", "#c8a165", 0.35),
    "box": ("boxes (stringers)", "#8c564b", 0.6),
    "cylinder": ("pipes", "#7f7f7f", 0.6),
    "sphere": ("spheres", "#e45756", 0.5),
    "wedge": ("taper", "#9fb4c7", 0.3),
    "mesh": ("meshes", "#6b8e23", 0.5),
    "walls": ("walls (mesh)", "#b0b0b0", 0.12),
}


def _mesh_trace(parts: list[Mesh], name: str, color: str, opacity: float) -> go.Mesh3d:
    import plotly.graph_objects as go

    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    v, f = np.vstack(verts), np.vstack(faces)
    return go.Mesh3d(
        x=v[:, 0],
        y=v[:, 1],
        z=v[:, 2],
        i=f[:, 0],
        j=f[:, 1],
        k=f[:, 2],
        color=color,
        opacity=opacity,
        name=name,
        legendgroup="tank",
        showlegend=True,
        flatshading=True,
        hoverinfo="name",
    )


def _polyline(lines: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Polylines joined into one with a NaN row after each (plotly breaks the line there)."""
    gap = np.full((1, 3), np.nan)
    return np.vstack([part for line in lines for part in (line, gap)])


def _line(points: NDArray[np.float64], **kwargs: Any) -> go.Scatter3d:
    import plotly.graph_objects as go

    p = np.round(np.asarray(points, dtype=np.float64), 2)
    return go.Scatter3d(x=p[:, 0], y=p[:, 1], z=p[:, 2], **kwargs)


def tank_traces(tank: Tank) -> list[Any]:
    """Plotly traces of the tank: box outline, panel, and its solids grouped by kind."""
    outline = _polyline(Box(tank.box_min, tank.box_max).wireframe())
    t = np.linspace(0, 2 * np.pi, 49)
    c, r = tank.panel.center, tank.panel.radius
    circle = np.c_[c[0] + r * np.cos(t), c[1] + r * np.sin(t), np.full_like(t, c[2])]
    traces = [
        _line(
            outline,
            mode="lines",
            name=f"tank {tank.name}",
            line={"color": "#888888", "width": 2},
            legendgroup="tank",
            hoverinfo="skip",
            legendgrouptitle_text="tank",
        ),
        _line(
            circle,
            mode="lines",
            name="access panel",
            line={"color": "black", "width": 4},
            legendgroup="tank",
            hoverinfo="name",
        ),
    ]
    for group, (name, color, opacity) in _SOLID_GROUPS.items():
        parts = [s.mesh() for s in tank.solids if solid_group(s) == group]
        if parts:
            traces.append(_mesh_trace(parts, name, color, opacity))
    return traces


def _run_lines(
    run: RunData, tank: Tank, color: str, frames: NDArray[np.int64] | None
) -> list[tuple[NDArray[np.float64], dict[str, Any]]]:
    """One run's polylines and styles: cell path (its start green), target, tip route, arm."""
    lines: list[tuple[NDArray[np.float64], dict[str, Any]]] = []
    cells_cm = run.cells_cm
    if cells_cm is None and run.cells is not None and len(run.cells):
        if tank.cell_size is None:
            run.notes.append(
                f"path.json has cells but no points_cm, and {tank.name} has no raster: "
                "cell path not drawn"
            )
        else:
            cells_cm = np.array([tank.raster.cell_center(c) for c in run.cells])
    if cells_cm is not None and len(cells_cm):
        path = {"color": color, "width": 3, "dash": "dash"}
        rest = len(cells_cm) - 1  # the start cell green and larger: one legend entry, not two
        marker = {"size": [6] + [3] * rest, "color": ["green"] + [color] * rest}
        style: dict[str, object] = {"mode": "lines+markers", "name": "cell path"}
        lines.append((cells_cm, {**style, "line": path, "marker": marker}))
    if run.target is not None:
        marker = {"size": 6, "color": color, "symbol": "diamond"}
        style = {"mode": "markers", "name": "target", "showlegend": False}  # a diamond: no row
        lines.append((run.target[None], {**style, "marker": marker}))
    if run.targets is not None and len(run.targets):
        marker = {"size": 5, "color": color, "symbol": "diamond-open"}
        style = {"mode": "markers", "name": "targets", "showlegend": False}
        lines.append((run.targets, {**style, "marker": marker}))
    if frames is not None:
        tips = run.tips()
        stride = max(1, math.ceil(len(tips) / _MAX_ROUTE_POINTS))
        route = np.vstack([tips[::stride], tips[-1:]])
        line = {"color": color, "width": 4}
        lines.append((route, {"mode": "lines", "name": "tip route", "line": line}))
        arm = run.backbones(frames[-1:])[0]  # the page opens on the deployed arm
        line = {"color": color, "width": 9}
        lines.append((arm, {"mode": "lines", "name": "arm", "line": line, "hoverinfo": "name"}))
        body = run.simulated_body(int(frames[-1]))
        if body is not None:  # aftir simulate's rod under gravity, beside the kinematic arm
            line = {"color": _SIMULATED, "width": 6}
            style = {"mode": "lines", "name": "simulated body", "hoverinfo": "name"}
            lines.append((body, {**style, "line": line}))
    return lines


def legend_titles(names: Sequence[str]) -> list[str]:
    """Short legend titles for runs: ``#k`` and the parts of their names that tell them apart.

    Names are split at ``__``; parts all runs share are left out, and so are the parts after
    those that already tell the runs apart (the time stamp, say). The page's run list below the
    scene has the whole names.
    """
    parts = [name.split("__") for name in names]
    if len(names) < 2 or len({len(p) for p in parts}) != 1:
        return [f"#{k + 1} {name}" for k, name in enumerate(names)]
    kept: list[int] = []
    for j in range(len(parts[0])):  # the first parts that differ, until they tell runs apart
        if len({p[j] for p in parts}) > 1:
            kept.append(j)
            if len({tuple(p[k] for k in kept) for p in parts}) == len(names):
                break
    return [f"#{k + 1} " + " ".join(p[j] for j in kept) for k, p in enumerate(parts)]


def build_figure(runs: Sequence[RunData], tank: Tank, max_frames: int = DEFAULT_MAX_FRAMES) -> Any:
    """A ``plotly.graph_objects.Figure`` of the tank and the runs, animated where there is motion.

    Args:
        runs: read by :func:`~aftir_rl.viz.runs.read_run`.
        tank: the tank to draw.
        max_frames: the most animation frames (at least 2).

    """
    import plotly.graph_objects as go

    if max_frames < 2:
        raise ValueError(f"max_frames must be at least 2, got {max_frames}")
    traces = tank_traces(tank)
    animated: list[tuple[int, RunData, NDArray[np.int64]]] = []  # (trace index, run, entries)
    titles = legend_titles([run.name for run in runs])
    for n, run in enumerate(runs):
        frames = _frame_indices(run, max_frames) if run.n_motion else None
        lines = _run_lines(run, tank, _COLORS[n % len(_COLORS)], frames)
        for i, (points, style) in enumerate(lines):
            title = {} if i else {"legendgrouptitle_text": titles[n]}  # on the group's first
            traces.append(_line(points, legendgroup=f"run{n}", **title, **style))
        if frames is not None:  # the arm, then the simulated body if there is one
            arm = len(traces) - 1 - (run.physics is not None)
            animated.append((arm, run, frames))
    fig = go.Figure(data=traces)
    if animated:
        _add_frames(fig, animated)
    z_lo = floor_view(tank)  # the rest of the arm below is clipped away
    ranges = [
        [tank.box_min[0], tank.box_max[0]],
        [tank.box_min[1], tank.box_max[1]],
        [z_lo, tank.box_max[2]],
    ]
    sizes = np.array([r[1] - r[0] for r in ranges])
    aspect = sizes / sizes.max()
    fig.update_layout(
        scene={
            "xaxis": {"title": {"text": "x [cm]"}, "range": ranges[0]},
            "yaxis": {"title": {"text": "y [cm]"}, "range": ranges[1]},
            "zaxis": {"title": {"text": "z [cm]"}, "range": ranges[2]},
            "aspectmode": "manual",
            "aspectratio": {"x": aspect[0], "y": aspect[1], "z": aspect[2]},
            "camera": {"eye": {"x": -0.85, "y": -1.25, "z": 0.7}},
        },
        legend={
            "groupclick": "toggleitem",
            "itemsizing": "constant",
            "font": {"size": 10},
            "tracegroupgap": 2,
        },
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        uirevision="keep",  # keep the camera while the animation plays
    )
    return fig


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


def _add_frames(fig: Any, animated: list[tuple[int, RunData, NDArray[np.int64]]]) -> None:
    """Animate the arms of ``animated`` (trace index, run, motion entries): frames and slider."""
    import plotly.graph_objects as go

    n_frames = max(len(idx) for _, _, idx in animated)
    arms = [run.backbones(idx) for _, run, idx in animated]
    frames, steps = [], []
    for k in range(n_frames):
        data, label, moved = [], [], []
        for (trace, run, idx), pts in zip(animated, arms):
            j = round(k * (len(idx) - 1) / max(1, n_frames - 1))
            arm = np.round(pts[j], 2)
            data.append(go.Scatter3d(x=arm[:, 0], y=arm[:, 1], z=arm[:, 2]))
            moved.append(trace)
            body = run.simulated_body(int(idx[j]))
            if body is not None:
                body = np.round(body, 2)
                data.append(go.Scatter3d(x=body[:, 0], y=body[:, 1], z=body[:, 2]))
                moved.append(trace + 1)
            label.append(str(int(idx[j])))
        name = str(k)
        frames.append(go.Frame(data=data, traces=moved, name=name))
        steps.append(_slider_step(name, "/".join(label)))
    fig.frames = frames
    _add_animation_controls(fig, steps)


def _slider_step(name: str, label: str) -> dict[str, Any]:
    """The slider step that shows frame ``name``, labelled with the runs' motion entries."""
    return {
        "method": "animate",
        "label": label,
        "args": [
            [name],
            {
                "mode": "immediate",
                "frame": {"duration": 0, "redraw": True},
                "transition": {"duration": 0},
            },
        ],
    }


def _add_animation_controls(fig: Any, steps: list[dict[str, Any]]) -> None:
    """Add the play and pause buttons and the slider over ``steps`` to ``fig``'s layout."""
    play = {  # from the first frame: the page opens on the last
        "frame": {"duration": 60, "redraw": True},
        "fromcurrent": False,
        "transition": {"duration": 0},
        "mode": "immediate",
    }
    pause = {"frame": {"duration": 0, "redraw": False}, "mode": "immediate"}
    fig.update_layout(
        updatemenus=[
            {
                "type": "buttons",
                "direction": "left",
                "x": 0.0,
                "y": 0.0,
                "xanchor": "left",
                "yanchor": "top",
                "pad": {"t": 30, "r": 10},
                "showactive": False,
                "buttons": [
                    {"label": "▶ play from the panel", "method": "animate", "args": [None, play]},
                    {"label": "❚❚ pause", "method": "animate", "args": [[None], pause]},
                ],
            }
        ],
        sliders=[
            {
                "active": len(steps) - 1,
                "x": 0.22,
                "len": 0.78,
                "y": 0.0,
                "yanchor": "top",
                "pad": {"t": 20},
                "steps": steps,
                "currentvalue": {
                    "prefix": "motion entry: ",
                    "font": {"size": 12},
                    "xanchor": "right",
                },
            }
        ],
    )
