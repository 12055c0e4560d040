"""``trajectory.png``, the picture of motion in space (a run of several axes): the trajectory in its plane of
motion against the objects, and time plots; its title says how the run ended, in red unless it completed
(:func:`~haptic_bus.app.run_plots.title_of`, the one-axis pictures' rule: a killed run never looks healthy).

The plane of motion: for two axes the plane of the axes; for three or more, the plane through the
trajectory's mean spanned by its two principal directions (an SVD of the positions), the plane
that holds most of the motion.  Each object is drawn as its section with that plane (where the
plane cuts its solid), found on a grid of the plane by the object's own penetration test, so a
plane, a box and a sphere are drawn by one rule.  Beside it: every axis' position over time, and
every axis' wall force with the whole port's energy ``E = sum E_i``.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import transforms
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from haptic_bus.app.run_folder import RunFolder
from haptic_bus.app.run_plots import title_of
from haptic_bus.app.space_records import space_objects
from haptic_bus.control.space_scene import SpaceObject

_GRID = 240  # points per side of the grid the sections are found on
_MARGIN = 0.25  # the view's margin around the trajectory and the objects near it, as a fraction of its span


def motion_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(origin, basis)``: the plane of motion of ``points`` (rows, m) -- its mean and two unit
    directions (rows of ``basis``); for two coordinates the plane of the axes."""
    origin = points.mean(axis=0)
    size = points.shape[1]
    if size <= 2:
        return origin, np.eye(size)[:2] if size == 2 else np.array([[1.0], [0.0]])
    if points.shape[0] < 2:  # one position (a one-cycle run) spans no direction: the first two axes' plane
        return origin, np.eye(size)[:2]
    _, _, directions = np.linalg.svd(points - origin, full_matrices=False)
    return origin, directions[:2]


def trajectory_figure(run: RunFolder) -> Figure:
    """The figure (module docstring) of a multi-axis run folder ``run`` (its records and the objects
    of its last scene); the caller saves and closes it."""
    names = list(run.axes)
    tables = [run.axes[name] for name in names]
    cycles = min(table.cycles for table in tables)
    time_s = tables[0]["time_s"][:cycles]
    q = np.column_stack([table["position_m"][:cycles] for table in tables])
    x = q  # Cartesian: axis i along coordinate i (the profile's kinematics)
    forces = np.column_stack([table["force_n"][:cycles] for table in tables])
    energy = np.sum([table["energy_j"][:cycles] for table in tables], axis=0)
    fig = plt.figure(figsize=(13, 6.2))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.1, 1))
    section = fig.add_subplot(grid[:, 0])
    _draw_sections(section, names, space_objects(run.document), x)
    positions = fig.add_subplot(grid[0, 1])
    for i, name in enumerate(names):
        positions.plot(time_s, q[:, i] * 1e3, label=f"{name}")
    positions.set_ylabel("joint position (mm)")
    positions.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)  # beside: on no data
    positions.grid(alpha=0.3)
    force_axes = fig.add_subplot(grid[1, 1], sharex=positions)
    for i, name in enumerate(names):
        force_axes.plot(time_s, forces[:, i], label=f"u along {name} (the handle feels -u)" if i == 0 else f"u along {name}")
    force_axes.set_xlabel("time (s)")
    force_axes.set_ylabel("wall force u (N)")  # along each axis; the handle feels -u (the legend says so)
    force_axes.grid(alpha=0.3)
    twin = force_axes.twinx()
    twin.plot(time_s, energy * 1e3, color="black", linewidth=0.8, linestyle="--", label="port energy E = sum E_i")
    twin.set_ylabel("port energy (mJ)")
    lines = force_axes.get_legend_handles_labels()
    more = twin.get_legend_handles_labels()
    force_axes.legend(lines[0] + more[0], lines[1] + more[1], loc="upper center",
                      bbox_to_anchor=(0.5, -0.2), ncol=4, fontsize=8)  # below: on no data
    loop = run.document.get("loop", {})
    title, colour = title_of(run, f"{len(names)} axes, T = {loop.get('period', float('nan')) * 1e3:g} ms")
    fig.suptitle(title, color=colour)  # how the run ended, red unless it completed, as the one-axis pictures say it
    fig.tight_layout()
    return fig


def _draw_sections(axes: Axes, names: list[str], objects: list[SpaceObject], x: np.ndarray) -> None:
    """The trajectory in its plane of motion, and each object's section with that plane."""
    origin, basis = motion_plane(x)
    plane = (x - origin) @ basis.T  # (a, b) of each point, m
    low, high = plane.min(axis=0), plane.max(axis=0)
    span = max(float(np.max(high - low)), 1e-3)
    low, high = low - _MARGIN * span, high + _MARGIN * span
    a, b = np.meshgrid(np.linspace(low[0], high[0], _GRID), np.linspace(low[1], high[1], _GRID))
    points = origin + a[..., None] * basis[0] + b[..., None] * basis[1]
    flat = points.reshape(-1, points.shape[-1]).tolist()
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, obj in enumerate(objects):
        inside = np.array([obj.penetration(p) is not None for p in flat]).reshape(a.shape)
        if not inside.any():
            continue
        colour = colours[(k + 3) % len(colours)]
        axes.contourf(a * 1e3, b * 1e3, inside.astype(float), levels=[0.5, 1.5], colors=[colour], alpha=0.3)
        axes.contour(a * 1e3, b * 1e3, inside.astype(float), levels=[0.5], colors=[colour], linewidths=1.2)
        row, col = np.argwhere(inside)[len(np.argwhere(inside)) // 2]
        axes.annotate(f"{obj.name} (K {obj.stiffness:g} N/m)", (a[row, col] * 1e3, b[row, col] * 1e3), fontsize=8,
                      ha="center")
    axes.plot(plane[:, 0] * 1e3, plane[:, 1] * 1e3, color="black", linewidth=1.0, label="handle")
    axes.plot(*(plane[0] * 1e3), "o", color="green", label="start")
    axes.plot(*(plane[-1] * 1e3), "s", color="red", label="end")
    axes.set_aspect("equal")
    axes.set_xlim(low[0] * 1e3, high[0] * 1e3)
    axes.set_ylim(low[1] * 1e3, high[1] * 1e3)
    first, second = ("(" + ", ".join(f"{c:+.2f}" for c in row) + ")" for row in basis)
    axes.set_xlabel(f"mm along {first} in ({', '.join(names)})")
    axes.set_ylabel(f"mm along {second}")
    axes.set_title("trajectory in its plane of motion, objects cut by that plane", fontsize=10)
    # below the axis label, on no object: 36 pt under the axes (the tick labels and the label take ~28 pt at any
    # height; at -0.12 of an equal-aspect section only 0.3 of the figure high it covered the label)
    below = axes.transAxes + transforms.ScaledTranslation(0, -36 / 72, axes.figure.dpi_scale_trans)
    axes.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below, ncol=3, fontsize=8)
    axes.grid(alpha=0.3)
