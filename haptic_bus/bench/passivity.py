"""Benchmark 1: the passivity check, run time against the error of the boundary it implies.

Parameter points: a seeded set of realistic loops, ``T = 1 ms``, ``m`` log-uniform in
0.02..2 kg, ``c = bT/m`` log-uniform in 1e-4..1, delay ``d`` alternating 0 and 1, ``B`` a
random fraction (5-50 %) of the largest passive ``B`` without a spring and ``K`` a random
fraction of the largest passive ``K`` at that ``B``; 8 points (``--quick``: 3 of them, a flip,
an interior tangency and a low-frequency boundary).  At each point two boundaries: the largest
passive ``K`` at the point's ``B`` and the largest passive ``B`` at its ``K``, each against the
40-digit reference of :mod:`haptic_bus.bench.mp_boundary`.

Methods (a *check* is one verdict on one loop, its time the median of repeats):

* **closed form** -- eq. 23's slack (:func:`haptic_bus.analysis.closed_form.velocity_sampling_slack`);
  its boundary is linear in ``K`` and ``B`` and solved exactly.  ``d = 0`` only.
* **exact criterion** -- :func:`haptic_bus.analysis.criterion.exact_verdict`; its boundaries are what
  the product reports, :func:`haptic_bus.analysis.limits.max_stiffness` / ``max_damping``.
* **grid N** -- :func:`haptic_bus.analysis.poles.is_stable` and the minimum of ``Re z_fund`` on the
  fixed uniform grid ``theta = pi i/N``, ``i = 1..N`` (vectorised, ``pi`` included).
* **python-control** -- the same loop built from ``control.TransferFunction`` blocks: the
  continuous ``G11 = 1/(m s + b)``, the discrete ``G11d = k1/(z - a)`` and
  ``K_d' = ((KT + B) z - B)/((z - 1) z^d)`` (``dt = T``), stability from the poles of
  ``control.feedback(G11d, K_d')``, the responses from ``control.frequency_response`` on a
  uniform grid of 10^4 points.  python-control cannot represent the whole sampled-data loop:
  the hold ``H(j omega)/T = (1 - e^{-j theta})/(j theta)`` is transcendental (neither a
  rational continuous nor a discrete transfer function) and a continuous and a discrete
  system cannot be interconnected (``Systems have incompatible timebases``); so those two
  steps are numpy, and ``T_fund`` is assembled point by point from control's responses.

The boundary of a grid-based method (grids, python-control) is found by Newton's method on
that method's own margin (N s/m) along ``K`` (or ``B``), started at the reference boundary,
with the slope of the exact criterion's margin there: one step when it moves less than 1e-6
relative (the neglected term is then < 1e-6 of the error), else until a step is < 1e-3 of
the accumulated correction.
"""

from __future__ import annotations

import importlib
import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from haptic_bus.analysis.closed_form import region_map, velocity_sampling_factor, velocity_sampling_slack
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.frequency import z_fund
from haptic_bus.analysis.limits import max_damping, max_stiffness
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import phi1
from haptic_bus.analysis.poles import is_stable
from haptic_bus.bench.timing import time_per_call, timed_once

SEED = 20240606
PERIOD = 1e-3
GRID_SIZES_FULL = (100, 1_000, 10_000, 100_000, 1_000_000)
CONTROL_GRID = 10_000
FULL_POINTS = 8
QUICK_POINTS = (0, 1, 5)  # of the full set: a flip (d = 0), an interior tangency and a theta -> 0 boundary (d = 1)
ERROR_FLOOR = 1e-17  # plotted instead of an error of exactly 0
_SLOPE_STEP = 1e-6


def parameter_points(count: int, seed: int = SEED) -> list[WallLoop]:
    """``count`` seeded realistic loops (d alternating 0, 1); see the module docstring."""
    rng = np.random.default_rng(seed)
    points: list[WallLoop] = []
    while len(points) < count:
        d = len(points) % 2
        m = 10 ** rng.uniform(math.log10(0.02), math.log10(2.0))
        c = 10 ** rng.uniform(-4.0, 0.0)
        b = c * m / PERIOD
        b_free = max_damping(WallLoop(m, b, PERIOD, 0.0, 0.0, d))
        if not b_free:
            continue
        B = rng.uniform(0.05, 0.5) * b_free
        k_max = max_stiffness(WallLoop(m, b, PERIOD, 0.0, B, d))
        if not k_max:
            continue
        points.append(WallLoop(m, b, PERIOD, rng.uniform(0.05, 0.5) * k_max, B, d))
    return points


def _with(loop: WallLoop, which: str, x: float) -> WallLoop:
    return loop.with_wall(x, loop.B) if which == "K" else loop.with_wall(loop.K, x)


# --------------------------------------------------------------------------- methods


def grid_margin(loop: WallLoop, grid: np.ndarray) -> float:
    """Grid method: ``min Re z_fund`` (N s/m) on ``grid``, or -inf for an unstable loop."""
    if not is_stable(loop):
        return -math.inf
    return float(np.min(z_fund(loop, grid).real))


def uniform_grid(n: int) -> np.ndarray:
    """``theta = pi i / n``, ``i = 1..n`` (rad): uniform, ``pi`` included, 0 excluded."""
    return np.pi * np.arange(1, n + 1) / n


def control_margin(loop: WallLoop, grid: np.ndarray) -> float:
    """python-control method: ``min Re 1/T_fund`` (N s/m) on ``grid`` from control's responses."""
    import control

    m, b, T, K, B, d = loop.m, loop.b, loop.T, loop.K, loop.B, loop.delay
    c = loop.c
    k1 = T / m * phi1(c)
    g11 = control.tf([1.0], [m, b])
    g11d = control.tf([k1], [1.0, -math.exp(-c)], T)
    wall = control.tf([K * T + B, -B], [1.0, -1.0] + [0.0] * d, T)
    closed = control.feedback(g11d, wall)
    if not np.all(np.abs(control.poles(closed)) < 1.0):
        return -math.inf
    omega = grid / T
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # theta = pi is the Nyquist frequency itself
        g = control.frequency_response(g11, omega).complex
        kd = control.frequency_response(wall, omega).complex
        loop_gain = control.frequency_response(g11d * wall, omega).complex
    hold = (1.0 - np.exp(-1j * grid)) / (1j * grid)  # H(j omega)/T, not a transfer function
    t_fund = g * (1.0 - hold * kd * g / (1.0 + loop_gain))
    return float(np.min((1.0 / t_fund).real))


def closed_form_boundary(loop: WallLoop, which: str) -> float:
    """Eq. 23 solved for ``K`` (N/m) or ``B`` (N s/m): its slack is linear in both."""
    slack = velocity_sampling_slack(loop)
    factor = velocity_sampling_factor(loop.c)
    if which == "K":
        return loop.K + 2.0 * slack / (factor * loop.T)
    return loop.B + slack / factor


def exact_slope(loop: WallLoop, which: str, x: float) -> float:
    """d(margin)/dX of the exact criterion just inside the boundary ``x`` (one-sided, N s/m per unit)."""
    h = _SLOPE_STEP * x
    m1 = exact_verdict(_with(loop, which, x - h)).margin
    m2 = exact_verdict(_with(loop, which, x - 2 * h)).margin
    return (m1 - m2) / h


def newton_boundary(margin: Callable[[WallLoop], float], loop: WallLoop, which: str, start: float,
                    slope: float, times: list[float], max_steps: int = 8) -> float:
    """Root of ``margin`` along ``which`` from ``start`` with a fixed ``slope``; call times appended."""
    x = start
    for i in range(max_steps):
        seconds, value = timed_once(lambda: margin(_with(loop, which, x)))
        times.append(seconds)
        if value == 0.0:
            return x
        if not math.isfinite(value):  # unstable by this method's test: the boundary is further inside
            x -= max(2.0 * abs(x - start), 4e-16 * abs(start))
            continue
        step = -value / slope
        x += step
        total = abs(x - start)
        if (i == 0 and total <= 1e-6 * start) or abs(step) <= 1e-3 * total:
            return x
    return x


# --------------------------------------------------------------------------- the benchmark


@dataclass
class _Method:
    name: str
    key: str
    check: Callable[[WallLoop], float] | None  # margin-like, timed per check
    applies: Callable[[WallLoop], bool]
    newton: bool  # boundary by Newton on ``check``; else a dedicated boundary function
    large: bool = False  # too slow to time separately: time the Newton evaluations instead


def _methods(grid_sizes: tuple[int, ...], with_control: bool) -> list[_Method]:
    methods = [
        _Method("closed form (eq. 23)", "closed_form", velocity_sampling_slack, lambda l: l.delay == 0, False),
        _Method("exact criterion", "exact", lambda l: exact_verdict(l).margin, lambda l: True, False),
    ]
    for n in grid_sizes:
        grid = uniform_grid(n)
        methods.append(_Method(f"grid 10^{round(math.log10(n))}", f"grid_{n}",
                               lambda l, g=grid: grid_margin(l, g), lambda l: True, True, large=n >= 100_000))
    if with_control:
        grid = uniform_grid(CONTROL_GRID)
        methods.append(_Method(f"python-control (grid 10^{round(math.log10(CONTROL_GRID))})", "control",
                               lambda l, g=grid: control_margin(l, g), lambda l: True, True))
    return methods


def _region_map_time(loop: WallLoop) -> float:
    """Seconds for one eq. (24) passive-region map over 10^6 (alpha, beta) points."""
    alpha, beta = np.meshgrid(np.logspace(-2, 3, 1000), np.logspace(-3, 2, 1000))
    return time_per_call(lambda: region_map(alpha, beta, loop.c), repeats=3)


def run(quick: bool, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 1; returns its section of ``bench.json``."""
    from haptic_bus.bench.mp_boundary import reference_boundary

    try:
        importlib.import_module("control")
        with_control, control_note = True, None
    except ImportError as exc:
        with_control, control_note = False, f"python-control not installed ({exc}); pip install 'haptic_bus[bench]'"
    points = parameter_points(FULL_POINTS)
    if quick:
        points = [points[i] for i in QUICK_POINTS]
    grid_sizes = GRID_SIZES_FULL
    methods = _methods(grid_sizes, with_control)
    per_point = []
    times: dict[str, list[float]] = {m.key: [] for m in methods}
    errors: dict[str, dict[str, list[float]]] = {m.key: {"K": [], "B": []} for m in methods}
    boundary_times: dict[str, list[float]] = {"exact": [], "closed_form": []}
    for p_index, loop in enumerate(points):
        record = {"m": loop.m, "b": loop.b, "T": loop.T, "K": loop.K, "B": loop.B, "delay": loop.delay, "c": loop.c,
                  "boundaries": {}}
        for which, exact_limit in (("K", max_stiffness), ("B", max_damping)):
            seconds, estimate = timed_once(lambda: exact_limit(loop))
            boundary_times["exact"].append(seconds)
            ref = reference_boundary(loop, which, estimate)
            slope = exact_slope(loop, which, ref.value)
            entry = {"reference": ref.value, "reference_theta": ref.theta, "reference_kind": ref.kind,
                     "reference_verified": ref.verified, "methods": {}}
            for method in methods:
                if not method.applies(loop):
                    continue
                if method.key == "exact":
                    value = estimate
                elif method.key == "closed_form":
                    seconds, value = timed_once(lambda: closed_form_boundary(loop, which))
                    boundary_times["closed_form"].append(seconds)
                else:
                    sink = times[method.key] if method.large else []
                    value = newton_boundary(method.check, loop, which, ref.value, slope, sink)
                error = abs(value - ref.value) / ref.value
                errors[method.key][which].append(error)
                entry["methods"][method.key] = {"boundary": value, "relative_error": error}
            record["boundaries"][which] = entry
            tick(f"passivity: point {p_index + 1}/{len(points)} {which}")
        for method in methods:
            if method.applies(loop) and not method.large:
                times[method.key].append(time_per_call(lambda: method.check(loop), repeats=5))
        per_point.append(record)
    exact_time = float(np.median(times["exact"]))
    region = _region_map_time(points[0])
    summary = []
    for method in methods:
        errs = errors[method.key]["K"] + errors[method.key]["B"]
        if not errs:
            continue
        t = float(np.median(times[method.key]))
        summary.append({
            "method": method.name, "key": method.key,
            "time_per_check_s": t, "time_ratio_to_exact": t / exact_time,
            "error_K_median": float(np.median(errors[method.key]["K"])), "error_K_max": float(np.max(errors[method.key]["K"])),
            "error_B_median": float(np.median(errors[method.key]["B"])), "error_B_max": float(np.max(errors[method.key]["B"])),
            "error_max": float(np.max(errs)), "points": len(errs) // 2,
        })
    return {
        "description": "time per passivity check vs relative error of the boundary (largest passive K at the "
                       "point's B, largest passive B at its K) against a 40-digit mpmath reference",
        "points": per_point,
        "methods": summary,
        "boundary_time_s": {k: float(np.median(v)) for k, v in boundary_times.items() if v},
        "control_note": control_note or (
            "python-control builds G11 (continuous), G11d and K_d z^-d (discrete, dt = T) and evaluates their "
            "frequency responses; the hold H/T is numpy (transcendental) and T_fund is assembled pointwise "
            "(continuous and discrete systems cannot be interconnected in python-control)"),
        "grid_note": "uniform theta = pi i/N, i = 1..N, pi included; boundary by Newton on the method's own margin "
                     "from the reference, slope of the exact margin",
        "region_map_1e6_s": region,
        "region_map_note": "closed_form.region_map on a 1000 x 1000 (alpha, beta) mesh (eq. 24 at the point's c)",
        "all_references_verified": all(e["reference_verified"] for p in per_point for e in p["boundaries"].values()),
    }
