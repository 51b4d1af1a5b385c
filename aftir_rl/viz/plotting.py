"""Pictures of a tank, tip paths and arm postures (matplotlib, no global pyplot state).

Figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas, so rendering works
headless, in subprocess vector envs and in tests, and never touches pyplot's global figure list.

:func:`render_path` draws a whole figure (about 120-250 ms). The envs' ``rgb_array`` frames use a
:class:`PathRenderer` instead: it draws the tank, axes, title and legend once, keeps that as a
background, and per frame only restores it and draws the path, start, target and arms on top
(blitting; a few ms). The picture is the same as :func:`render_path`'s, except that the moving
artists are drawn after the tank's spheres rather than depth-sorted with them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from aftir_rl.core.tank import Box, Solid, Tank
from aftir_rl.core.tank.meshes import is_walls

if TYPE_CHECKING:
    from mpl_toolkits.mplot3d.art3d import Path3DCollection
    from mpl_toolkits.mplot3d.axes3d import Axes3D

__all__ = [
    "solid_group",
    "floor_view",
    "clip_below",
    "draw_tank",
    "path_figure",
    "figure_to_rgb",
    "render_path",
    "PathRenderer",
    "save_gif",
]

#: Wireframe style of each kind of solid.
_SOLID_STYLE: dict[str, dict[str, Any]] = {
    "box": {"color": "tab:brown", "lw": 0.8},
    "cylinder": {"color": "tab:gray", "lw": 0.8},
    "sphere": {"color": "tab:red", "lw": 0.5},
    "plate": {"color": "tab:olive", "lw": 0.8},
    "wedge": {"color": "tab:blue", "lw": 0.5},
    "mesh": {"color": "tab:green", "lw": 0.8},
}


#: The baffle: a translucent surface, so that the hatch reads as the hole in it.
_BAFFLE_STYLE: dict[str, Any] = {"facecolor": (0.85, 0.55, 0.25, 0.28), "edgecolor": "none"}
_BAFFLE_EDGES: dict[str, Any] = {"color": (0.55, 0.3, 0.1), "lw": 0.7}


def solid_group(solid: Solid) -> str:
    """What a solid is drawn as: ``walls``, ``baffle`` (a plate, a box named baffle*), its kind."""
    if is_walls(solid):
        return "walls"
    if solid.kind == "plate" or (solid.kind == "box" and solid.name.startswith("baffle")):
        return "baffle"
    return solid.kind


def floor_view(tank: Tank) -> float:
    """The lowest z drawn: a little of the guide below the panel (30 % of the tank's height)."""
    return float(tank.box_min[2] - 0.3 * (tank.box_max[2] - tank.box_min[2]))


def clip_below(points: ArrayLike, z_lo: float) -> NDArray[np.float64]:
    """``points`` from where the polyline first rises to ``z_lo`` (the guide below is cut)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    above = np.flatnonzero(pts[:, 2] >= z_lo)
    if not len(above) or above[0] == 0:
        return pts[above[0] if len(above) else len(pts) :]
    i = above[0]
    a, b = pts[i - 1], pts[i]
    cut = a + (b - a) * (z_lo - a[2]) / (b[2] - a[2])
    return np.vstack([cut, pts[i:]])


def draw_tank(ax: Axes3D, tank: Tank) -> None:
    """Draw the tank's box, panel and solids on a 3D axes (cm).

    Solids are wireframes, but the baffle is a translucent surface, its hatch cut out; the axes
    reach 30 % of the tank's height below its floor (:func:`floor_view`).
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    for edge in Box(tank.box_min, tank.box_max).wireframe():
        ax.plot(*edge.T, color="0.6", lw=0.6)
    t = np.linspace(0, 2 * np.pi, 40)
    c, r = tank.panel.center, tank.panel.radius
    ax.plot(c[0] + r * np.cos(t), c[1] + r * np.sin(t), np.full_like(t, c[2]), color="k", lw=1.0)
    for solid in tank.solids:
        if solid_group(solid) == "baffle":
            verts, faces = solid.mesh()
            ax.add_collection3d(Poly3DCollection(verts[faces], **_BAFFLE_STYLE))
        style = _BAFFLE_EDGES if solid_group(solid) == "baffle" else _SOLID_STYLE[solid.kind]
        for line in solid.wireframe():
            ax.plot(*line.T, **style)
    z_lo = floor_view(tank)
    ax.set_xlim(tank.box_min[0], tank.box_max[0])
    ax.set_ylim(tank.box_min[1], tank.box_max[1])
    ax.set_zlim(z_lo, tank.box_max[2])
    below = [0.0, 0.0, tank.box_min[2] - z_lo]
    ax.set_box_aspect(np.array(tank.box_max) - np.array(tank.box_min) + below)
    ax.set_xlabel("x [cm]")
    ax.set_ylabel("y [cm]")
    ax.set_zlabel("z [cm]")


def _arm_color(i: int, n: int) -> tuple[float, float, float]:
    return (0.1, 0.3, 0.35 + 0.65 * (i + 1) / n)


def path_figure(
    tank: Tank,
    points: ArrayLike | None = None,
    target: ArrayLike | None = None,
    arms: Sequence[ArrayLike] = (),
    title: str = "",
    size: tuple[float, float] = (6.4, 4.8),
) -> Figure:
    """A figure of the tank with a tip path, a target and arm body polylines (all cm)."""
    fig = Figure(figsize=size, dpi=80)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    draw_tank(ax, tank)
    for i, arm in enumerate(arms):
        arm = clip_below(arm, floor_view(tank))
        ax.plot(*arm.T, color=_arm_color(i, len(arms)), lw=2.0)
    if points is not None and len(np.asarray(points)):
        pts = np.asarray(points, dtype=float)
        ax.plot(*pts.T, color="tab:blue", marker="o", ms=3, lw=1.5, label="tip path")
        ax.scatter(*pts[0], color="tab:green", s=40, label="start")
    if target is not None:
        ax.scatter(*np.asarray(target, float), color="tab:red", marker="*", s=120, label="target")
    if title:
        ax.set_title(title, fontsize=10)
    ax.view_init(elev=28, azim=-62)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", fontsize=9)
    fig.tight_layout()
    return fig


def figure_to_rgb(fig: Figure) -> NDArray[np.uint8]:
    """Rasterise a figure to an ``(H, W, 3)`` uint8 array."""
    canvas = cast(FigureCanvasAgg, fig.canvas)  # path_figure attaches an Agg canvas
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def render_path(
    tank: Tank,
    points: ArrayLike | None = None,
    target: ArrayLike | None = None,
    arms: Sequence[ArrayLike] = (),
    title: str = "",
) -> NDArray[np.uint8]:
    """:func:`path_figure` rasterised to an RGB array."""
    return figure_to_rgb(path_figure(tank, points, target, arms, title))


class PathRenderer:
    """:func:`render_path`'s picture, fast enough for every env step (blitting).

    The figure with the tank, the axes and the title is drawn once per kind of frame (with or
    without a path, with or without a target) and kept as a background, and the legend once as an
    RGBA overlay; a frame restores the background, draws only the arms, the path, the start and
    the target markers, and blends the legend on top.
    The view and the axis limits never change (:func:`draw_tank` fixes them), which is what makes
    the background reusable. Pickling keeps only the tank, title and size; the figure is rebuilt
    on the next frame.
    """

    def __init__(self, tank: Tank, title: str = "", size: tuple[float, float] = (6.4, 4.8)):
        self.tank, self.title, self.size = tank, title, size
        self._kind: tuple[bool, bool] | None = None

    def __getstate__(self) -> dict[str, object]:
        return {"tank": self.tank, "title": self.title, "size": self.size, "_kind": None}

    def _setup(self, has_points: bool, has_target: bool) -> None:
        fig = Figure(figsize=self.size, dpi=80)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_subplot(projection="3d")
        draw_tank(ax, self.tank)
        anchor = np.array(self.tank.box_min, dtype=float)  # placeholder data; limits are fixed
        self._path = self._start = self._target = None
        if has_points:
            (self._path,) = ax.plot(
                *anchor[:, None], color="tab:blue", marker="o", ms=3, lw=1.5, label="tip path"
            )
            self._start = ax.scatter(*anchor, color="tab:green", s=40, label="start")
        if has_target:
            self._target = ax.scatter(*anchor, color="tab:red", marker="*", s=120, label="target")
        if self.title:
            ax.set_title(self.title, fontsize=10)
        ax.view_init(elev=28, azim=-62)
        self._legend = None
        if ax.get_legend_handles_labels()[0]:
            self._legend = ax.legend(loc="upper left", fontsize=9)
        fig.tight_layout()
        moving = [a for a in (self._path, self._start, self._target, self._legend) if a]
        for artist in moving:
            artist.set_animated(True)
        canvas.draw()  # also sets the projection (ax.M) the moving artists use
        self._background = canvas.copy_from_bbox(fig.bbox)
        self._fig, self._ax, self._canvas = fig, ax, canvas
        self._overlay = None
        if self._legend is not None:  # drawing its text costs more than the rest of a frame
            renderer = canvas.get_renderer()
            renderer.clear()  # transparent
            self._legend.draw(renderer)
            rgba = np.asarray(renderer.buffer_rgba())
            rows, cols = np.nonzero(rgba[..., 3])
            where = np.s_[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
            alpha = rgba[where][..., 3:].astype(np.float32) / 255.0
            self._overlay = (where, rgba[where][..., :3] * alpha, 1.0 - alpha)
            canvas.restore_region(self._background)
        self._arms: list[Any] = []  # the arms' Line3D artists
        self._z_lo = floor_view(self.tank)
        self._kind = (has_points, has_target)

    def render(
        self,
        points: ArrayLike | None = None,
        target: ArrayLike | None = None,
        arms: Sequence[ArrayLike] = (),
    ) -> NDArray[np.uint8]:
        """The picture of :func:`render_path` with these arguments, as an ``(H, W, 3)`` array."""
        pts = None if points is None else np.asarray(points, dtype=float).reshape(-1, 3)
        has_points = pts is not None and len(pts) > 0
        kind = (has_points, target is not None)
        if kind != self._kind:
            self._setup(*kind)
        ax, canvas = self._ax, self._canvas
        canvas.restore_region(self._background)
        while len(self._arms) < len(arms):
            (line,) = ax.plot(*np.array(self.tank.box_min, float)[:, None], lw=2.0)
            line.set_animated(True)
            self._arms.append(line)
        for i, arm in enumerate(arms):
            line = self._arms[i]
            line.set_data_3d(*clip_below(arm, self._z_lo).T)
            line.set_color(_arm_color(i, len(arms)))
            ax.draw_artist(line)
        if has_points:
            assert pts is not None and self._path is not None  # has_points: both are there
            self._path.set_data_3d(*pts.T)
            ax.draw_artist(self._path)
            self._draw_marker(self._start, pts[0])
        if target is not None:
            self._draw_marker(self._target, np.asarray(target, dtype=float))
        image = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        if self._overlay is not None:  # the legend on top, as Agg blends it ("over")
            where, premultiplied, keep = self._overlay
            image[where] = (premultiplied + image[where] * keep + 0.5).astype(np.uint8)
        return image

    def _draw_marker(self, marker: Path3DCollection, point: NDArray[np.float64]) -> None:
        marker.set_offsets(point[None, :2])
        marker.set_3d_properties(point[2:3], "z")
        marker.do_3d_projection()
        self._ax.draw_artist(marker)


def save_gif(path: str | os.PathLike[str], frames: Sequence[NDArray[np.uint8]], fps: int) -> int:
    """Write RGB ``frames`` as a looping animated GIF (Pillow), atomically; the frame count."""
    from PIL import Image

    from aftir_rl.core.files import atomic_open

    images = [Image.fromarray(np.asarray(f)) for f in frames]
    if not images:
        raise ValueError("no frames to write")
    with atomic_open(path, "wb") as fh:
        images[0].save(
            fh,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=round(1000 / fps),
            loop=0,
            optimize=True,
        )
    return len(images)
