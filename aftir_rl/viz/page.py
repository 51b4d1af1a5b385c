"""An interactive 3D view of run directories: one self-contained HTML page (plotly, offline).

:func:`write_view` draws the tank (box outline, access panel, solid blocks, pipes, spheres) and,
for each run directory, what it holds (:func:`~aftir_rl.viz.runs.read_run`):

- ``path.json`` (tabular runs): the greedy cell path through the cell centres and the target;
- ``trajectory.json``: the tip route and the arm moving along it, as plotly animation frames
  with a slider and play/pause buttons (:func:`~aftir_rl.viz.figure.build_figure`);
- anything else (an SB3 run with only ``config.json`` and ``summary.json``) is listed with a note
  saying there is no path to draw.

Several runs are overlaid, grouped in the legend by directory name. Only JSON is read from a run
directory (docs/design.md §9); one that cannot be read raises
:class:`~aftir_rl.core.errors.CheckpointError` naming the file. The page embeds plotly.js, so it
opens with no network; it is written atomically.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aftir_rl.core.errors import CheckpointError
from aftir_rl.core.extras import require
from aftir_rl.core.files import atomic_open
from aftir_rl.core.shipped import DEFAULT_TANK
from aftir_rl.core.tank import Tank, load_tank, resolve_run_tank
from aftir_rl.viz.figure import DEFAULT_MAX_FRAMES, build_figure, tank_traces
from aftir_rl.viz.runs import RUN_FILES, RunData, read_run, unique_names

__all__ = [
    "RunData",
    "read_run",
    "build_figure",
    "tank_traces",
    "write_view",
    "DEFAULT_MAX_FRAMES",
    "RUN_FILES",
]


def _resolve_tank(tank: str | Path | Tank | None, runs: list[RunData]) -> Tank:
    if tank is not None:
        return load_tank(tank)
    named = [r for r in runs if r.tank]
    if not named:
        return load_tank(DEFAULT_TANK)
    return load_tank(resolve_run_tank(named[0].tank, named[0].path))


def _page(fig: Any, runs: Sequence[RunData], tank: Tank) -> str:
    rows = []
    for k, run in enumerate(runs):
        facts = ", ".join(f"{k} {v}" for k, v in run.facts.items())
        notes = "".join(f"<li class='note'>{html.escape(s)}</li>" for s in run.notes)
        rows.append(
            f"<li><b>#{k + 1} {html.escape(run.name)}</b> "
            f"<span class='dir'>{html.escape(str(run.path))}"
            f"</span><br>{html.escape(facts) or 'no facts recorded'}<ul>{notes}</ul></li>"
        )
    plot = fig.to_html(
        full_html=False,
        include_plotlyjs=True,
        div_id="aftir-view",
        auto_play=False,
        default_height="85vh",  # most of the window, whatever its size
        config={"displaylogo": False, "responsive": True},
    )
    title = f"aftir_rl view: {len(runs)} run{'s' if len(runs) != 1 else ''} in {tank.name}"
    return (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>"
        "body{font-family:sans-serif;margin:8px 16px}h1{font-size:18px;margin:4px 0}"
        "li{margin:4px 0}.dir{color:#777;font-size:12px}.note{color:#a33}"
        "</style></head><body>"
        f"<h1>{html.escape(title)}</h1>{plot}"
        f"<h2 style='font-size:15px'>Runs</h2><ul id='aftir-runs'>{''.join(rows)}</ul>"
        "<p class='dir'>units cm; diamonds are targets, a cell path starts at its green "
        "marker; drag to rotate, scroll to zoom, click a legend entry to hide it; the page opens "
        "on the last posture of each motion, ▶ plays it from the panel, and the slider picks a "
        "posture (label: its entry index per run).</p>"
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
        MissingExtraError: plotly is not installed (the ``view`` extra).

    """
    require("plotly.graph_objects", "view")
    if not run_dirs:
        raise CheckpointError("no run directory given: name at least one")
    runs = [read_run(d) for d in run_dirs]
    unique_names(runs)
    the_tank = _resolve_tank(tank, runs)
    page = _page(build_figure(runs, the_tank, max_frames), runs, the_tank)
    out = Path(out)
    with atomic_open(out, "w") as fh:
        fh.write(page)
    return out
