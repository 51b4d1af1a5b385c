"""The matplotlib pictures (env frames, GIFs): the baffle reads as a surface with a hole in it,
and the arm's guide below the panel stays inside the frame."""

from __future__ import annotations

import numpy as np
from mpl_toolkits.mplot3d import proj3d

from aftir_rl.core.tank import load_tank
from aftir_rl.viz.plotting import PathRenderer, clip_below, figure_to_rgb, path_figure


def _pixel(fig, ax, point) -> tuple[int, int]:
    """The image row and column where ``point`` (cm) is drawn."""
    x, y, _ = proj3d.proj_transform(*point, ax.get_proj())
    col, row = ax.transData.transform((x, y))
    return int(fig.bbox.height - row), int(col)


def _orange(rgb) -> bool:
    r, g, b = (int(c) for c in rgb)
    return r - b > 50 and r > g > b


def test_the_baffle_is_a_surface_and_the_hatch_a_hole_in_it():
    tank = load_tank("b737_center")  # baffle at y 58-62; hatch x 80-120, z 30-70
    fig = path_figure(tank)
    image = figure_to_rgb(fig)
    ax = fig.axes[0]
    on_baffle = [(30.0, 60.0, 50.0), (100.0, 60.0, 85.0), (170.0, 60.0, 15.0)]
    assert all(_orange(image[_pixel(fig, ax, p)]) for p in on_baffle)
    row, col = _pixel(fig, ax, (100.0, 60.0, 50.0))  # the hatch's centre: nothing drawn there
    assert not any(_orange(image[row + dr, col + dc]) for dr in (-3, 0, 3) for dc in (-3, 0, 3))


def test_the_guide_below_the_panel_is_cut_at_the_frame():
    tank = load_tank("b737_center")
    arm = np.array([[0.0, 0.0, z] for z in np.linspace(-400.0, 60.0, 47)])
    kept = clip_below(arm, -30.0)
    assert kept[0, 2] == -30.0 and np.all(kept[:, 2] >= -30.0) and kept[-1, 2] == 60.0
    assert len(clip_below(arm, 100.0)) == 0 and len(clip_below(arm, -500.0)) == len(arm)
    frame = PathRenderer(tank).render(arms=[arm])
    blue = (frame[..., 2].astype(int) - frame[..., 0] > 80) & (frame[..., 2] > 150)
    rows = np.flatnonzero(blue.any(axis=1))
    assert len(rows) and rows.max() < 0.9 * frame.shape[0]  # not down to the bottom edge


def test_legend_titles_keep_the_parts_that_tell_runs_apart():
    from aftir_rl.viz.figure import legend_titles

    names = ["q__T__1_2_3__0__t1", "q__T__4_5_6__0__t2", "q__T__4_5_6__0__t3"]
    assert legend_titles(names) == ["#1 1_2_3 t1", "#2 4_5_6 t2", "#3 4_5_6 t3"]
    assert legend_titles(names[:2]) == ["#1 1_2_3", "#2 4_5_6"]
    assert legend_titles(["only__one"]) == ["#1 only__one"]
