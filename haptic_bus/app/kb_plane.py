"""A run's ``region.png``: the K-B plane (N/m, N s/m) of the loop the gate judged, with every scene.

The loop is ``run.json``'s ``gate_loop``: the profile's ``m``, ``b``, ``T``, its velocity model and
its loop delay (the measured one on Modbus).  For each ``B`` of a grid the passive ``K`` are exact
closed intervals (:func:`haptic_bus.analysis.limits.passive_set`, the gate's own criterion); the
plane is shaded where a wall is passive and the largest passive ``K`` drawn as the boundary.  Every
contact wall of every scene in effect is marked and labelled with its scene: the profile's design
(scene 0, a star), each upload (a circle), each derate (a triangle), with the gate's margin.  The
seed's ``alpha = B/(KT) = 6`` rule is the dash-dotted line.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from haptic_bus.analysis.design import BANDWIDTH_ALPHA
from haptic_bus.analysis.limits import passive_set
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.app.run_folder import RunFolder
from haptic_bus.app.run_plots import title_of

_B_ROWS = 60  # B values the passive K intervals are computed for (about 10 ms each)
_K_COLUMNS = 500
_KEPT_PLANES = 16  # K-B planes' passive K kept (one is _B_ROWS passive sets, 0.25 s of CPU for cia402-handle)
_MARKERS = {"profile": "*", "upload": "o"}  # by the scene's origin; a derate (origin "derate ...") gets "^"


@dataclass(frozen=True)
class MarkedWall:
    """One contact wall of one scene: ``K`` N/m, ``B`` N s/m, the gate's ``margin`` N s/m."""

    scene_id: int
    origin: str
    objects: tuple[str, ...]
    K: float
    B: float
    margin: float | None

    @property
    def label(self) -> str:
        """Which scene, which objects, the values."""
        margin = "" if self.margin is None else f", margin {self.margin:+.3g} N s/m"
        return f"scene {self.scene_id} ({self.origin}): {'+'.join(self.objects)} K {self.K:g} N/m, B {self.B:g} N s/m{margin}"

    @property
    def marker(self) -> str:
        """Star: the profile's design; circle: an upload; triangle: a derate."""
        return _MARKERS.get(self.origin, "^" if self.origin.startswith("derate") else "D")


def marked_walls(document: dict[str, Any]) -> list[MarkedWall]:
    """Every contact wall of every scene ``run.json`` lists, in order."""
    return [MarkedWall(int(scene["scene_id"]), str(scene["origin"]), tuple(wall["objects"]), float(wall["K"]),
                       float(wall["B"]), None if wall.get("margin") is None else float(wall["margin"]))
            for scene in document.get("scenes") or [] for wall in scene.get("walls", [])]


def gate_wall_loop(document: dict[str, Any]) -> WallLoop:
    """The gate's loop of ``run.json`` with no wall (``K = B = 0``)."""
    loop = document["gate_loop"]
    return WallLoop(float(loop["m"]), float(loop["b"]), float(loop["T"]), 0.0, 0.0, float(loop["delay"]),
                    VelocityModel.parse(str(loop["velocity"])))


def passive_stiffness(loop: WallLoop, damping: np.ndarray) -> list[tuple[tuple[float, float], ...]]:
    """For each ``B`` (N s/m): the passive ``K`` (N/m) as closed intervals (empty: none)."""
    return list(_kept_stiffness(loop, tuple(float(B) for B in damping)))


@functools.lru_cache(maxsize=_KEPT_PLANES)
def _kept_stiffness(loop: WallLoop, damping: tuple[float, ...]) -> tuple[tuple[tuple[float, float], ...], ...]:
    """:func:`passive_stiffness`, kept per gate loop and ``B`` grid (a function of them alone, tuples of floats):
    every run of a profile with the same walls has the same grid, and ``haptic-bus plot`` draws the plane again."""
    return tuple(passive_set(loop.with_wall(0.0, B), "K").intervals for B in damping)


def kb_plane_figure(run: RunFolder) -> Figure:
    """The K-B plane of the run's gate loop with every scene marked (module docstring)."""
    document = run.document
    loop = gate_wall_loop(document)
    walls = marked_walls(document)
    b_top = passive_set(loop, "B").largest or 0.0  # the largest passive B without a spring
    shown_b = [w.B for w in walls if w.B > 0] + ([b_top] if b_top > 0 else [])
    b_low, b_high = (min(shown_b) / 30, max(shown_b) * 3) if shown_b else (1e-2, 1e3)
    damping = np.unique(np.concatenate([np.geomspace(b_low, b_high, _B_ROWS),
                                        [b for b in (b_top * (1 - 1e-6),) if b_low < b < b_high]]))
    intervals = passive_stiffness(loop, damping)
    k_top = max((iv[-1][1] for iv in intervals if iv), default=0.0)
    shown_k = [w.K for w in walls if w.K > 0] + ([k_top] if k_top > 0 else [])
    k_low, k_high = (min(shown_k) / 100, max(shown_k) * 3) if shown_k else (1.0, 1e6)
    stiffness = np.geomspace(k_low, k_high, _K_COLUMNS)
    passive = np.array([[any(lo <= k <= hi for lo, hi in row) for k in stiffness] for row in intervals], dtype=float)

    fig, ax = plt.subplots(figsize=(11, 6.5))
    if passive.any():
        ax.contourf(stiffness, damping, passive, levels=[0.5, 1.5], colors=["tab:green"], alpha=0.18)
    largest = np.array([row[-1][1] if row else math.nan for row in intervals])
    ax.plot(largest, damping, color="tab:green", lw=2.5, alpha=0.7,
            label="largest passive K at each B (exact criterion; shaded: passive)")
    ax.plot(stiffness, BANDWIDTH_ALPHA * stiffness * loop.T, "-.", color="0.45", lw=1,
            label=rf"$\alpha = B/(KT) = {BANDWIDTH_ALPHA:g}$ (seed eq. 25): above it $\alpha > {BANDWIDTH_ALPHA:g}$")
    palette = plt.get_cmap("tab10")
    for wall in walls:
        shade = palette(wall.scene_id % 10)
        at = (max(wall.K, k_low), max(wall.B, b_low))  # K = 0 or B = 0 at the plane's edge
        ax.plot(*at, marker=wall.marker, ms=15 if wall.marker == "*" else 10, color=shade, mec="black", ls="none",
                label=wall.label)
        ax.annotate(f"scene {wall.scene_id}: {'+'.join(wall.objects)}", at, xytext=(7, 5), textcoords="offset points",
                    fontsize=7, color=shade)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(k_low, k_high)
    ax.set_ylim(b_low, b_high)
    ax.set_xlabel("wall stiffness K (N/m)")
    ax.set_ylabel("wall damping B (N s/m)")
    ax.grid(True, which="major", color="0.88", lw=0.6)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, borderaxespad=0.0)
    text, color = title_of(run, "K-B plane")
    fig.suptitle(f"{text}\nthe gate's loop: m = {loop.m:g} kg, b = {loop.b:g} N s/m, T = {loop.T * 1e3:g} ms, "
                 f"D = {loop.delay:g} samples, {loop.velocity} velocity", color=color, fontsize=10)
    fig.tight_layout()
    return fig
