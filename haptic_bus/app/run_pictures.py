"""A run's pictures written as PNGs: what ``haptic-bus run`` and ``demo`` do when they end, and
``haptic-bus plot RUN_DIR`` does again (:mod:`~haptic_bus.app.run_plots`, :mod:`~haptic_bus.app.kb_plane`)."""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
from matplotlib.figure import Figure

from haptic_bus.app.figure_file import save_figure
from haptic_bus.app.kb_plane import kb_plane_figure
from haptic_bus.app.run_folder import FORCE_POSITION, REGION, TIMELINE, TRAJECTORY, RunFolder
from haptic_bus.app.run_plots import force_position_figure, timeline_figure

DPI = 110


def render_run(run: RunFolder, out: pathlib.Path | None = None) -> list[pathlib.Path]:
    """Draw a run's pictures (``timeline.png``, ``force_position.png``, ``region.png``; for several
    axes ``trajectory.png``) into ``out`` (default: its folder); the paths.  A run that never
    cycled (no ``record.csv``) gets the K-B plane only."""
    target = out if out is not None else run.path
    figures: list[tuple[str, Figure]] = []
    # made at the dpi they are saved at: their tight_layout measures each text (a tick's mathtext parsed) at
    # the dpi the save draws it, and the save finds it measured (at matplotlib's 100 dpi it was done twice)
    with matplotlib.rc_context({"figure.dpi": DPI}):
        if run.axes:
            from haptic_bus.app.trajectory_plot import trajectory_figure

            figures.append((TRAJECTORY, trajectory_figure(run)))
        elif run.record is not None and run.record.cycles:
            figures += [(TIMELINE, timeline_figure(run)), (FORCE_POSITION, force_position_figure(run))]
        if "gate_loop" in run.document:
            figures.append((REGION, kb_plane_figure(run)))
    written = []
    for name, figure in figures:
        written.append(save_figure(figure, target / name, dpi=DPI, bbox_inches="tight"))  # the legends beside the axes too
    return written
