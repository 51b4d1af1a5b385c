"""Pictures of a tank, tip paths and arm postures (matplotlib, no global pyplot state).

Figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas, so rendering works
headless, in subprocess vector envs and in tests, and never touches pyplot's global figure list.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from aftir_rl.tank import Box, Cylinder, Sphere, Tank

__all__ = ["draw_tank", "path_figure", "figure_to_rgb", "render_path"]

_EDGES = [
    (0, 1),
    (1, 3),
    (3, 2),
    (2, 0),
    (4, 5),
    (5, 7),
    (7, 6),
    (6, 4),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
]


def _box_lines(ax, lo: Sequence[float], hi: Sequence[float], **style) -> None:  # noqa: ANN001
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    for i, j in _EDGES:
        ax.plot(*corners[[i, j]].T, **style)


def draw_tank(ax, tank: Tank) -> None:  # noqa: ANN001
    """Draw the tank's box, panel and solids on a 3D axes (wireframes, cm)."""
    _box_lines(ax, tank.box_min, tank.box_max, color="0.6", lw=0.6)
    t = np.linspace(0, 2 * np.pi, 40)
    c, r = tank.panel.center, tank.panel.radius
    ax.plot(c[0] + r * np.cos(t), c[1] + r * np.sin(t), np.full_like(t, c[2]), color="k", lw=1.0)
    for solid in tank.solids:
        if isinstance(solid, Box):
            _box_lines(ax, solid.min, solid.max, color="tab:brown", lw=0.8)
        elif isinstance(solid, Cylinder):
            k = solid.axis
            others = [i for i in range(3) if i != k]
            for ang in np.linspace(0, 2 * np.pi, 6, endpoint=False):
                p0, p1 = np.array(solid.p0, float), np.array(solid.p1, float)
                off = np.zeros(3)
                off[others[0]], off[others[1]] = (
                    solid.radius * np.cos(ang),
                    solid.radius * np.sin(ang),
                )
                ax.plot(*np.stack([p0 + off, p1 + off]).T, color="tab:gray", lw=0.8)
        elif isinstance(solid, Sphere):
            u, v = np.mgrid[0 : 2 * np.pi : 12j, 0 : np.pi : 7j]
            ax.plot_wireframe(
                solid.center[0] + solid.radius * np.cos(u) * np.sin(v),
                solid.center[1] + solid.radius * np.sin(u) * np.sin(v),
                solid.center[2] + solid.radius * np.cos(v),
                color="tab:red",
                lw=0.5,
            )
    ax.set_xlim(tank.box_min[0], tank.box_max[0])
    ax.set_ylim(tank.box_min[1], tank.box_max[1])
    ax.set_zlim(min(tank.box_min[2], -10), tank.box_max[2])
    ax.set_box_aspect(np.array(tank.box_max) - np.array(tank.box_min) + [0, 0, 10])
    ax.set_xlabel("x [cm]")
    ax.set_ylabel("y [cm]")
    ax.set_zlabel("z [cm]")


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
        arm = np.asarray(arm)
        shade = 0.35 + 0.65 * (i + 1) / len(arms)
        ax.plot(*arm.T, color=(0.1, 0.3, shade), lw=2.0)
    if points is not None and len(np.asarray(points)):
        pts = np.asarray(points, dtype=float)
        ax.plot(*pts.T, color="tab:blue", marker="o", ms=3, lw=1.5, label="tip path")
        ax.scatter(*pts[0], color="tab:green", s=40, label="start")
    if target is not None:
        ax.scatter(*np.asarray(target, float), color="tab:red", marker="*", s=120, label="target")
    if title:
        ax.set_title(title, fontsize=9)
    ax.view_init(elev=28, azim=-62)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    return fig


def figure_to_rgb(fig: Figure) -> NDArray[np.uint8]:
    """Rasterise a figure to an ``(H, W, 3)`` uint8 array."""
    canvas = fig.canvas
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
