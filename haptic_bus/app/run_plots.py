"""A run's pictures, drawn from its folder (``record.csv`` and ``run.json``) and nothing else:
``haptic-bus run`` and ``haptic-bus demo`` draw them when they end, ``haptic-bus plot RUN_DIR``
draws them again (:func:`haptic_bus.app.run_pictures.render_run`).

* ``timeline.png`` (:func:`timeline_figure`): position with every scene object's extent, wall
  force, the observer's interface energy and each cycle's lateness over the run's time; every
  event (uploads, refusals, alarms, derates, faults, stops) a vertical line with its label; the
  way the run ended in the title (red unless it completed).
* ``force_position.png`` (:func:`force_position_figure`): wall force against position, each step
  coloured by whether the wall took energy (``u dx > 0``) or gave it back, over each object's
  spring law; the title sums both (the loop's area is what the wall kept), and adds what its springs
  got with no ``u dx`` (:func:`springs_energy_in_place`: held at the first cycle, or gained in place as a
  start ramp or a derate scaled them, or an upload changed them, while the handle was inside).
* ``region.png`` (:mod:`~haptic_bus.app.kb_plane`): the K-B plane of the gate's loop with every
  scene's contact walls.

Each ``*_figure`` returns the matplotlib figure (tests read its texts); ``render_run`` saves
and closes them.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from haptic_bus.app.run_folder import RunFolder
from haptic_bus.app.run_options import ended_line
from haptic_bus.control.record import RecordTable
from haptic_bus.control.scene import CompiledScene, SceneObject, compile_scene, object_from_dict

EVENT_COLORS = {"upload": "tab:green", "refused": "tab:gray", "alarm": "tab:orange", "derate": "tab:purple",
                "fault": "tab:red", "stop": "black"}
OTHER_EVENT_COLOR = "tab:brown"
_TITLE_WIDTH = 110  # characters a title line holds before it wraps
_ENERGY_WIDTH = 150  # characters a line of force_position.png's energy sentence (fontsize 10 across the figure)
_EVENT_LABEL_WIDTH = 40  # characters of an event's label beside its line (the whole message is in run.json)


# --------------------------------------------------------------------------- what every picture shares

def ending(run: RunFolder) -> tuple[str, bool]:
    """How the run ended, one phrase for a title, and whether it is a clean completion."""
    document = run.document
    if not run.ended_cleanly:  # a run still writing its folder was drawn (plot --out elsewhere) as killed or crashed
        writer = run.writer
        if writer is not None:
            return f"still running (process {writer}): drawn from the cycles written so far", False
        return "did NOT end cleanly: run.json still says 'running' (the process was killed or crashed)", False
    reason = str(document.get("exit_reason", document.get("status", "ended")))
    error = document.get("error")
    text = "ended: " + (ended_line(reason, str(error)) if error else reason)
    return text, reason in ("completed", "stopped")


def title_of(run: RunFolder, picture: str) -> tuple[str, str]:
    """The figure title (wrapped) and its colour: the profile, the picture, how the run ended."""
    profile = run.document.get("profile", {}).get("name", "?")
    how, clean = ending(run)
    text = "\n".join(textwrap.wrap(f"{profile}: {picture}; {how}", _TITLE_WIDTH))
    return text, "black" if clean else "tab:red"


def scene_objects(document: dict[str, Any], scene_id: int = 0) -> list[SceneObject]:
    """The objects of scene ``scene_id`` as ``run.json`` keeps them (geometry, K, B)."""
    scenes = document.get("scenes") or []
    entry = next((s for s in scenes if s.get("scene_id") == scene_id), None)
    if entry is None:
        return []
    return [object_from_dict(table) for table in entry["objects"] if "kind" in table]


def _object_colors(objects: list[SceneObject]) -> dict[str, Any]:
    palette = plt.get_cmap("tab10")
    return {obj.name: palette(i % 10) for i, obj in enumerate(objects)}


def _draw_extents(ax: Axes, objects: list[SceneObject], colors: dict[str, Any]) -> None:
    """Each object on the position axis (mm): a wall's surface and its solid side, a slot's two
    walls, a detent's centre and reach; one legend entry each."""
    for obj in objects:
        color, label = colors[obj.name], f"{obj.name} ({type(obj).__name__.lower()})"
        for start, end, _, anchor, _ in obj.pieces():
            low, high = (start * 1e3 if math.isfinite(start) else None), (end * 1e3 if math.isfinite(end) else None)
            if low is not None and high is not None:  # a bounded support: a detent
                ax.axhspan(low, high, color=color, alpha=0.12, lw=0)
                ax.axhline(anchor * 1e3, color=color, ls=":", lw=1.2, label=label)
            else:
                ax.axhline(anchor * 1e3, color=color, ls="--", lw=1.2, label=label)
            label = "_"  # one legend entry an object


def _mark_events(axes: list[Axes], events: list[dict[str, Any]]) -> None:
    """Every event: a vertical line on every axis, its kind and message at the top axis."""
    seen: set[str] = set()
    top = axes[0]
    for event in events:
        kind = str(event.get("kind", "?"))
        color = EVENT_COLORS.get(kind, OTHER_EVENT_COLOR)
        t = float(event.get("time_s", 0.0))
        for ax in axes:
            ax.axvline(t, color=color, lw=1.4, alpha=0.85, label=None if kind in seen or ax is not top else f"event: {kind}")
        seen.add(kind)
        label = textwrap.shorten(f"{kind}: {event.get('message', '')}", _EVENT_LABEL_WIDTH, placeholder=" ...")
        top.annotate(label, xy=(t, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -4), textcoords="offset points",
                     rotation=90, va="top", ha="left", fontsize=7, color=color)


# --------------------------------------------------------------------------- timeline

def timeline_figure(run: RunFolder) -> Figure:
    """Position, force, interface energy and lateness over the run's time, events marked (module docstring)."""
    record = _record(run)
    objects = scene_objects(run.document)
    colors = _object_colors(objects)
    t = record["time_s"]
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(10, 9.5), gridspec_kw={"height_ratios": (3, 2, 2, 1.3)})
    ax_x, ax_f, ax_e, ax_l = axes
    _draw_extents(ax_x, objects, colors)
    ax_x.plot(t, record["position_m"] * 1e3, color="tab:blue", lw=1.2, label="handle position")
    _keep_in_view(ax_x, record["position_m"] * 1e3)
    ax_x.set_ylabel("position (mm)")
    ax_f.plot(t, record["force_n"], color="tab:red", lw=1.0, label="wall force u")
    ax_f.set_ylabel("force (N)")
    ax_e.plot(t, record["energy_j"] * 1e3, color="tab:green", lw=1.0,
              label="interface energy (observer: stored at start + wall + b v² + kinetic)")
    ax_e.axhline(0.0, color="black", lw=0.8)
    ax_e.set_ylabel("energy (mJ)")
    lateness = record.columns.get("lateness_s", np.zeros_like(t)) * 1e3
    ax_l.plot(t, lateness, color="0.3", lw=0.8, label="cycle start lateness")
    late = record.columns.get("late")
    if late is not None and np.any(late > 0):
        ax_l.plot(t[late > 0], lateness[late > 0], "x", color="tab:orange", ms=4, label="late (supervisor)")
    ax_l.set_ylabel("lateness (ms)")
    ax_l.set_xlabel("run time (s)")
    _mark_events(list(axes), run.document.get("events", []))
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, borderaxespad=0.0)
        ax.grid(True, color="0.92")
    text, color = title_of(run, "timeline")
    fig.suptitle(text, color=color, fontsize=10)
    fig.tight_layout()
    return fig


def _keep_in_view(ax: Axes, values: np.ndarray) -> None:
    """Limit the axis to the data plus a margin (objects far away would flatten the trace)."""
    low, high = float(np.min(values)), float(np.max(values))
    span = max(high - low, 1.0)
    ax.set_ylim(low - 0.25 * span, high + 0.25 * span)


def _record(run: RunFolder) -> RecordTable:
    if run.record is None:
        raise ValueError(f"{run.path}: no record.csv")
    return run.record


# --------------------------------------------------------------------------- force against position

def wall_energy_taken_and_returned(position: np.ndarray, force: np.ndarray) -> tuple[float, float]:
    """Energy (J) the wall took from the handle and gave back: the sums of ``u_k dx_k`` over the
    steps where it is positive and negative (``dx_k = x_{k+1} - x_k``, ``u_k`` held over the step)."""
    work = force[:-1] * np.diff(position)
    return float(work[work > 0].sum()), float(-work[work < 0].sum())


def springs_energy_in_place(document: dict[str, Any], record: RecordTable) -> float:
    """The energy (J) the walls' springs got with no ``u dx`` bringing it: what they held at the first cycle,
    ``s_0 V_0(x_0)``, and at each cycle ``k`` whose scale ``s`` (a start ramp, a derate) or scene ``sigma`` (an
    upload) changed, ``s_k V_k(x_k) - s_(k-1) V_(k-1)(x_k)``, ``V`` a scene's spring energy at full scale
    (``stored_energy``).  With the wall's ``sum u dx`` it is what its springs hold at the end plus what its
    damping spent.  A ramp from 0 with the handle inside gives its springs ``K x^2 / 2`` that the operator then
    takes back: the wall's ``sum u dx`` is below zero by as much, while the port, the handle's damping counted,
    may stay passive (the observer's sum, the timeline's)."""
    position, scale, scene = record["position_m"], record["scale"], record["scene_id"].astype(int)
    changed = np.flatnonzero((np.diff(scale) != 0.0) | (np.diff(scene) != 0)) + 1
    scenes: dict[int, CompiledScene] = {}

    def held(sigma: int, x: float) -> float:
        if sigma not in scenes:
            scenes[sigma] = compile_scene(scene_objects(document, sigma))
        return scenes[sigma].stored_energy(x)

    if position.size == 0:
        return 0.0
    start = float(scale[0]) * held(int(scene[0]), float(position[0]))
    return math.fsum([start, *(float(scale[k]) * held(int(scene[k]), float(position[k]))
                               - float(scale[k - 1]) * held(int(scene[k - 1]), float(position[k])) for k in changed.tolist())])


def force_position_figure(run: RunFolder) -> Figure:
    """Wall force against position, taking and giving back told apart, each object's law (module docstring)."""
    record = _record(run)
    x_mm, force = record["position_m"] * 1e3, record["force_n"]
    taken, returned = wall_energy_taken_and_returned(record["position_m"], force)
    fig, ax = plt.subplots(figsize=(10, 6.5))
    objects = scene_objects(run.document)
    colors = _object_colors(objects)
    low, high = float(np.min(x_mm)), float(np.max(x_mm))
    span = max(high - low, 1.0)
    view = (low - 0.15 * span, high + 0.15 * span)
    for obj in objects:
        _draw_law(ax, obj, view, colors[obj.name])
    segments = np.stack([np.column_stack([x_mm[:-1], force[:-1]]), np.column_stack([x_mm[1:], force[1:]])], axis=1)
    work = force[:-1] * np.diff(record["position_m"])
    for mask, color, label in ((work >= 0, "tab:blue", "wall takes energy (u dx > 0)"),
                               (work < 0, "tab:orange", "wall gives energy back (u dx < 0)")):
        ax.add_collection(LineCollection(list(segments[mask]), colors=color, linewidths=1.3, label=label))
    ax.plot(x_mm[0], force[0], "o", color="black", ms=5, label="start")
    ax.plot(x_mm[-1], force[-1], "s", color="black", ms=5, label="end")
    ax.set_xlim(*view)
    f_low, f_high = float(np.min(force)), float(np.max(force))
    f_span = max(f_high - f_low, 0.1)
    ax.set_ylim(f_low - 0.15 * f_span, f_high + 0.15 * f_span)
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xlabel("handle position (mm)")
    ax.set_ylabel("wall force u (N)")
    ax.grid(True, color="0.92")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
    text, color = title_of(run, "wall force against position")
    net, in_place = taken - returned, springs_energy_in_place(run.document, record)
    balance = (f"net {net * 1e3:.4g} mJ into it" if abs(in_place) <= 1e-9 else
               f"net {net * 1e3:.4g} mJ, and its springs got {in_place * 1e3:.4g} mJ with no u dx (held at the start, "
               f"or gained in place by a ramp, derate or upload with the handle inside): {(net + in_place) * 1e3:.4g} mJ")
    energy = textwrap.fill(f"the wall took {taken * 1e3:.4g} mJ and gave back {returned * 1e3:.4g} mJ: {balance} (held in "
                           "its springs at the end or spent in its damping: a loop's area; below zero the wall would "
                           "have made energy)", _ENERGY_WIDTH)
    fig.suptitle(f"{text}\n{energy}", color=color, fontsize=10)
    fig.tight_layout()
    return fig


def _draw_law(ax: Axes, obj: SceneObject, view: tuple[float, float], color: Any) -> None:
    """The object's spring law ``K (x - anchor)`` (N) over its support within ``view`` (mm), dashed."""
    label = f"{obj.name}: K {obj.stiffness:g} N/m, B {obj.damping:g} N s/m (spring part)"
    for start, end, K, anchor, _ in obj.pieces():
        lo, hi = max(start * 1e3, view[0]), min(end * 1e3, view[1])
        if lo >= hi:
            continue
        x = np.array([lo, hi])
        ax.plot(x, K * (x * 1e-3 - anchor), "--", color=color, lw=1.2, label=label)
        label = "_"
    if label != "_":  # nowhere near the travel: named all the same
        ax.plot([], [], "--", color=color, lw=1.2, label=f"{label}, beyond the travel shown")
