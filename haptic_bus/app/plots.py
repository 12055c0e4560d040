"""PNG figures of the seed's Figs. 4-6 for a given device and loop (matplotlib, Agg backend).

* :func:`plot_region` -- Fig. 4 for this device: eq. (24) for three periods (the given ``T``,
  ``5T``, ``10T``), Colgate's eq. (3), Liu 2011's eq. (5), the ``alpha > 6`` rule and the exact
  criterion's boundary for the loop as it runs (delay included).
* :func:`plot_nyquist` -- Fig. 5: the seed's ``T_zw`` and the exact ``T_fund``.
* :func:`plot_step` -- Fig. 6: the wall force after a unit operator-force step.

Each writes one PNG to ``path`` and returns the path.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.design import (
    BANDWIDTH_ALPHA,
    SETTLING_BAND,
    NyquistData,
    exact_region_boundary,
    exact_region_floor,
    force_step_response,
    nyquist_data,
    passive_region_curves,
)
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.velocity import POINT, VelocityModel
from haptic_bus.app.figure_file import save_figure

_DPI = 110  # each figure is made at the dpi it is saved at: tight_layout's text measures serve the save
_BOUNDARY_POINTS = 120
PathLike = str | os.PathLike[str]
WallPoint = WallLoop | tuple[float, float] | None  # a wall to mark: its loop, or (alpha, beta)

_TITLE_POLES = 4  # the step figure's title names the poles of largest magnitude, at most this many


def _save(fig: Figure, path: PathLike) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, path, dpi=_DPI)


def _point_coordinates(point: WallPoint, m: float, b: float, T: float) -> tuple[float, float] | None:
    if point is None:
        return None
    if isinstance(point, WallLoop):
        return point.alpha, point.beta
    alpha, beta = point
    return float(alpha), float(beta)


def plot_region(path: PathLike, m: float, b: float, T: float, delay: float = 0, point: WallPoint = None,
                velocity: VelocityModel | str = POINT, label: str = "profile", marks: Sequence[WallLoop] = ()) -> Path:
    """Fig. 4 for the device (``m`` kg, ``b`` N s/m) at period ``T`` s, loop delay ``delay``
    (samples, real) and the drive's ``velocity`` model (the exact boundary's; the seed's
    closed forms are for a point velocity).

    ``point`` (optional) is a :class:`WallLoop` or an ``(alpha, beta)`` pair to mark, named
    ``label``; each of ``marks`` (walls ``K``, ``B`` > 0 on this device) is marked with its ``K``
    and ``B``.  Axes are ``alpha = B/(KT)`` and ``beta = b/B`` (log-log); above a boundary is
    passive by it.
    """
    loop = WallLoop(m, b, T, 0.0, 0.0, delay, VelocityModel.parse(velocity))  # validates the device
    shown = [(point, label)] if point is not None else []
    shown += [(mark, f"K = {mark.K:g} N/m, B = {mark.B:g} N s/m") for mark in marks]
    points = [(coordinates, text, wall) for wall, text in shown
              if (coordinates := _point_coordinates(wall, m, b, T)) is not None]
    periods = (T, 5 * T, 10 * T)
    lo_a, hi_a = 1e-2, 1e3
    for (a, _), _, _ in points:
        if math.isfinite(a) and a > 0:
            lo_a, hi_a = min(lo_a, a / 3), max(hi_a, a * 3)
    alpha = np.geomspace(lo_a, hi_a, 400)
    curves = passive_region_curves(alpha, loop.m, loop.b, periods)
    lo_b = max(float(np.min(curves.velocity)) / 5, 1e-12)
    hi_b = float(np.max(curves.colgate)) * 3
    for (_, beta), _, _ in points:
        if math.isfinite(beta) and beta > 0:
            lo_b, hi_b = min(lo_b, beta / 3), max(hi_b, beta * 3)

    fig, ax = plt.subplots(figsize=(11.5, 5.8), dpi=_DPI)
    ax.axvspan(BANDWIDTH_ALPHA, hi_a, color="0.93", zorder=0)
    ax.axvline(BANDWIDTH_ALPHA, color="0.45", lw=1, ls="-.", label=r"$\alpha = 6$ (eq. 25); shaded: $\alpha > 6$")
    styles = ("-", "-", "-")
    colors = ("tab:blue", "tab:cyan", "tab:purple")
    for row, period, style, color in zip(curves.velocity, periods, styles, colors):
        ax.plot(alpha, row, style, color=color, lw=1.6, zorder=3, label=f"velocity sampling, eq. 24, T = {period * 1e3:g} ms")
    ax.plot(alpha, curves.colgate, "--", color="k", lw=1.4, label="position sampling, Colgate, eq. 3")
    ax.plot(alpha, curves.liu2011, ":", color="k", lw=1.8, label="position sampling, Liu 2011, eq. 5")

    beta_grid = np.geomspace(lo_b, hi_b, _BOUNDARY_POINTS)
    floor = exact_region_floor(loop.m, loop.b, loop.T, loop.delay, loop.velocity)
    if floor is not None:  # resolve the approach to the asymptote beta -> floor as alpha -> inf
        beta_grid = np.union1d(beta_grid, floor * (1.0 + np.geomspace(1e-7, 1.0, 40)))
    exact_alpha = exact_region_boundary(loop.m, loop.b, loop.T, loop.delay, beta_grid, loop.velocity)
    shown = np.isfinite(exact_alpha)
    label = f"exact criterion, T = {T * 1e3:g} ms, D = {loop.delay:g}, {loop.velocity} velocity: boundary, passive shaded"
    if shown.any():
        ea, eb = exact_alpha[shown], beta_grid[shown]
        ax.fill_betweenx(eb, np.minimum(ea, hi_a), hi_a, color="tab:green", alpha=0.13, lw=0, zorder=0)
        ax.plot(ea, eb, color="tab:green", lw=5, alpha=0.45, zorder=1, label=label)
    else:
        ax.plot([], [], color="tab:green", lw=5, alpha=0.45,
                label=f"exact criterion, D = {loop.delay:g}, {loop.velocity} velocity: no passive wall in view")

    for number, (marked, text, wall) in enumerate(points):
        verdict = exact_verdict(wall) if isinstance(wall, WallLoop) else None
        judged = "" if verdict is None else (" (passive)" if verdict.passive else " (NOT passive)")
        ax.plot(*marked, marker="*" if number == 0 and point is not None else "o", ms=15 if number == 0 else 10,
                color=plt.get_cmap("tab10")((3 + number) % 10), mec="k", ls="none",
                label=rf"{text}: $\alpha$ = {marked[0]:.3g}, $\beta$ = {marked[1]:.3g}{judged}")

    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo_a, hi_a)
    ax.set_ylim(lo_b, hi_b)
    ax.set_xlabel(r"$\alpha = B/(KT)$  (dimensionless)")
    ax.set_ylabel(r"$\beta = b/B$  (dimensionless)")
    ax.set_title(f"Passive regions (above each curve), m = {loop.m:g} kg, b = {loop.b:g} N s/m\n"
                 r"device fixed: a point is the wall $B = b/\beta$, $K = B/(\alpha T)$", fontsize=10)
    ax.grid(True, which="major", color="0.85", lw=0.6)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0.0)
    fig.tight_layout()
    return _save(fig, path)


def plot_nyquist(path: PathLike, loop: WallLoop) -> Path:
    """Fig. 5: ``T_zw`` (seed, eq. 10) and the exact ``T_fund`` in m/(N s), Nyquist and real part."""
    data = nyquist_data(loop, 4000)
    verdict = exact_verdict(loop)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11.5, 4.8), dpi=_DPI)
    ax.plot(data.t_zw.real, data.t_zw.imag, color="tab:blue", lw=1.6, label=r"seed $T_{zw}$ (eq. 10)")
    ax.plot(data.t_fund.real, data.t_fund.imag, "--", color="tab:orange", lw=1.6, label=r"exact $T_{fund}$")
    ax.axvline(0.0, color="k", lw=0.8)
    ax.axhline(0.0, color="k", lw=0.4)
    ax.set_xlabel("Re  (m/(N s))")
    ax.set_ylabel("Im  (m/(N s))")
    ax.set_title(r"Nyquist plot, $\theta = \omega T \in (0, \pi]$", fontsize=10)
    ax.grid(True, color="0.9")
    ax.legend(fontsize=8, loc="upper left")

    ax2.plot(data.theta, data.t_zw.real, color="tab:blue", lw=1.6, label=r"Re $T_{zw}$ (seed)")
    ax2.plot(data.theta, data.t_fund.real, "--", color="tab:orange", lw=1.6, label=r"Re $T_{fund}$ (exact)")
    if math.isfinite(verdict.critical_theta):
        ax2.axvline(verdict.critical_theta, color="tab:red", lw=0.8, ls=":",
                    label=rf"exact criterion's critical $\theta$ = {verdict.critical_theta:.3g}")
    both = np.concatenate([data.t_zw.real, data.t_fund.real])
    ax2.set_xscale("log")
    if np.all(both > 0):
        ax2.set_yscale("log")
        ax2.set_ylabel("Re  (m/(N s)), log")
        ax2.set_title(r"Real part: > 0 on $(0, \pi]$", fontsize=10)
    else:
        negative = np.abs(both[both < 0])
        ax2.set_yscale("symlog", linthresh=1e-3 * float(np.max(negative)))
        ax2.set_ylabel("Re  (m/(N s)), symmetric log")
        ax2.set_title(r"Real part: negative somewhere (active)", fontsize=10)
        ax2.axhline(0.0, color="k", lw=0.8)
    ax2.set_xlabel(r"$\theta = \omega T$  (rad)")
    ax2.grid(True, color="0.9")
    ax2.legend(fontsize=8, loc="lower center")  # a fixed place: loc="best" searches the data, slowly
    _nyquist_inset(ax, data)
    state = "passive" if verdict.passive else "NOT passive"
    fig.suptitle(f"m = {loop.m:g} kg, b = {loop.b:g} N s/m, T = {loop.T * 1e3:g} ms, K = {loop.K:g} N/m, "
                 f"B = {loop.B:g} N s/m, D = {loop.delay:g}, {loop.velocity} velocity: "
                 f"exact criterion {state}, margin {verdict.margin:.3g} N s/m",
                 fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def _nyquist_inset(ax: Axes, data: NyquistData, theta_from: float = 1.0) -> None:
    """Zoom on the high-frequency end (``theta >= theta_from``), where the two responses part."""
    keep = data.theta >= theta_from
    if keep.sum() < 2:
        return
    inset = ax.inset_axes((0.64, 0.06, 0.34, 0.34))
    inset.plot(data.t_zw.real[keep], data.t_zw.imag[keep], color="tab:blue", lw=1.3)
    inset.plot(data.t_fund.real[keep], data.t_fund.imag[keep], "--", color="tab:orange", lw=1.3)
    inset.axvline(0.0, color="k", lw=0.7)
    inset.set_title(rf"zoom: $\theta \in [{theta_from:g}, \pi]$", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.ticklabel_format(style="sci", scilimits=(-2, 2))
    inset.xaxis.get_offset_text().set_fontsize(6)
    inset.yaxis.get_offset_text().set_fontsize(6)
    inset.grid(True, color="0.9")


def plot_step(path: PathLike, loop: WallLoop) -> Path:
    """Fig. 6: wall force (N) after a unit operator-force step (N), start and whole horizon."""
    step = force_step_response(loop)
    rep = step.report
    n_zoom = int(min(step.time.size, max(60, 4 * (rep.settling_time / loop.T if math.isfinite(rep.settling_time) else 60))))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11.5, 4.6), dpi=_DPI)
    t_ms = step.time[:n_zoom] * 1e3
    ax.step(t_ms, step.applied[:n_zoom], where="post", color="tab:blue", lw=1.4, label=r"applied wall force $u_{k-d}$ (ZOH)")
    if loop.delay:
        ax.plot(t_ms, step.force[:n_zoom], ".", color="tab:orange", ms=4, label=r"computed $u_k$ at $kT$")
    ax.axhline(rep.final_value, color="k", lw=0.8, label=f"final value {rep.final_value:.4g} N")
    band = SETTLING_BAND * abs(rep.final_value)
    ax.axhspan(rep.final_value - band, rep.final_value + band, color="0.88", label="2 % band")
    ax.set_xlabel("time  (ms)")
    ax.set_ylabel("wall force  (N)")
    ax.set_title(f"Fig. 6: first {n_zoom} samples", fontsize=10)
    ax.grid(True, color="0.9")
    ax.legend(fontsize=8, loc="lower right")

    deviation = (step.force - rep.final_value) / abs(rep.final_value) * 100.0
    ax2.plot(step.time, deviation, color="tab:blue", lw=1.2, label=r"$(u_k - u_\infty)/u_\infty$")
    ax2.axhline(0.0, color="k", lw=0.8)
    if rep.overshoot > 0:
        ax2.plot(rep.peak_time, rep.overshoot, "v", color="tab:red",
                 label=f"peak: {rep.overshoot:.3g} % at {rep.peak_time * 1e3:.3g} ms")
    top = max(2.0 * max(rep.overshoot, 0.0), 0.5)
    ax2.set_ylim(-2.0 * top, top)
    ax2.set_xlabel("time  (s)")
    ax2.set_ylabel("deviation from final value  (%)")
    ax2.set_title("whole run, zoomed on the final value", fontsize=10)
    ax2.grid(True, color="0.9")
    ax2.legend(fontsize=8, loc="lower right")
    poles = sorted(rep.poles, key=abs, reverse=True)
    more = len(poles) - _TITLE_POLES
    shown = ", ".join(f"{p:.4g}" for p in poles[:_TITLE_POLES]) + (f" and {more} more" if more > 0 else "")
    fig.suptitle(f"Unit step of operator force: overshoot {rep.overshoot:.3g} %, 2 % settling {rep.settling_time * 1e3:.3g} ms, "
                 f"poles {shown}  (D = {loop.delay:g}, {loop.velocity} velocity)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
