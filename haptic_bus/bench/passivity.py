"""Benchmark 1: the passivity check, run time against the error of the boundary it implies.

Parameter points: a seeded set of realistic loops, ``T = 1 ms``, ``m`` log-uniform in
0.02..2 kg, ``c = bT/m`` log-uniform in 1e-4..1, delay ``d`` alternating 0 and 1, ``B`` a
random fraction (5-50 %) of the largest passive ``B`` without a spring and ``K`` a random
fraction of the largest passive ``K`` at that ``B``; 8 points (``--quick``: 3 of them, a flip,
an interior tangency and a low-frequency boundary, and grids up to 10^5; ``--smoke``: 2, grids
10^2 and 10^3).  At each point two boundaries: the largest passive ``K`` at the point's ``B`` and
the largest passive ``B`` at its ``K``, each against the 40-digit reference of
:mod:`haptic_bus.bench.mp_boundary`.

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

Every time is a median over the points of each point's median of at least 5 repeats, with the
medians of the repeats' minima and maxima beside it.

**Against numpy's floor** (issues 14 and 19): at each delay-1 point, side by side, the gate's
verdict (:func:`gate_verdict`, target <= 2 x), the full check with its limits (:func:`full_check`,
``check_passivity`` without the out-of-band search, <= 5 x) and the out-of-band exposure
(:func:`exposure`, <= 20 x), each against one evaluation of ``T_fund`` on 10^4 uniform points in
plain numpy (:func:`numpy_t_fund`, DESIGN 3.2's formula as written), timed pairwise, each call a new
wall; the boundaries within 1e-12 of the reference.

The boundary of a grid-based method (grids, python-control) is found by Newton's method on
that method's own margin (N s/m) along ``K`` (or ``B``), started at the reference boundary,
with the slope of the exact criterion's margin there: one step when it moves less than 1e-6
relative (the neglected term is then < 1e-6 of the error), else until a step is < 1e-3 of
the accumulated correction.
"""

from __future__ import annotations

import functools
import importlib
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.analysis.check import check_loop
from haptic_bus.analysis.closed_form import region_map, velocity_sampling_factor, velocity_sampling_slack
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.frequency import t_fund, z_fund
from haptic_bus.analysis.limits import max_damping, max_stiffness
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.out_of_band import worst_force
from haptic_bus.analysis.plant import phi1
from haptic_bus.analysis.poles import forget_walls, is_stable
from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import Spread, paired_calls, time_per_call

SEED = 20240606
PERIOD = 1e-3
GRID_SIZES_FULL = (100, 1_000, 10_000, 100_000, 1_000_000)
CONTROL_GRID = 10_000
FULL_POINTS = 8
QUICK_POINTS = (0, 1, 5)  # of the full set: a flip (d = 0), an interior tangency and a theta -> 0 boundary (d = 1)
SMOKE_POINTS = (0, 5)  # one with d = 0 (the closed form applies), one with d = 1 (the full check)
ERROR_FLOOR = 1e-17  # plotted instead of an error of exactly 0
FULL_CHECK_RATIO_TARGET = 5.0  # issue 14: a full check at delay 1 within 5 x one 10^4-point numpy T_fund
FULL_CHECK_ERROR_TARGET = 1e-12  # issue 14: its boundaries within 1e-12 of the 40-digit reference
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
    import control  # type: ignore[import-untyped]  # no stubs

    m, b, T, K, B, d = loop.m, loop.b, loop.T, loop.K, loop.B, loop.delay
    c = loop.c
    k1 = T / m * phi1(c)
    g11 = control.tf([1.0], [m, b])
    g11d = control.tf([k1], [1.0, -math.exp(-c)], T)
    wall = control.tf([K * T + B, -B], [1.0, -1.0] + [0.0] * round(d), T)
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
                    slope: float, max_steps: int = 8) -> float:
    """Root of ``margin`` along ``which`` from ``start`` with a fixed ``slope``."""
    x = start
    for i in range(max_steps):
        value = margin(_with(loop, which, x))
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
    check: Callable[[WallLoop], float]  # margin-like, timed per check
    applies: Callable[[WallLoop], bool]
    large: bool = False  # slow: each timed batch is one call


def _methods(grid_sizes: tuple[int, ...], with_control: bool) -> list[_Method]:
    methods = [
        _Method("closed form (eq. 23)", "closed_form", velocity_sampling_slack, lambda lp: lp.delay == 0),
        _Method("exact criterion", "exact", lambda lp: exact_verdict(lp).margin, lambda lp: True),
    ]
    for n in grid_sizes:
        grid = uniform_grid(n)
        methods.append(_Method(f"grid 10^{round(math.log10(n))}", f"grid_{n}", functools.partial(grid_margin, grid=grid),
                               lambda lp: True, large=n >= 100_000))
    if with_control:
        grid = uniform_grid(CONTROL_GRID)
        methods.append(_Method(f"python-control (grid 10^{round(math.log10(CONTROL_GRID))})", "control",
                               functools.partial(control_margin, grid=grid), lambda lp: True))
    return methods


def _region_map_time(loop: WallLoop) -> Spread:
    """Seconds for one eq. (24) passive-region map over 10^6 (alpha, beta) points."""
    alpha, beta = np.meshgrid(np.logspace(-2, 3, 1000), np.logspace(-3, 2, 1000))
    return time_per_call(lambda: region_map(alpha, beta, loop.c), min_ns=0)


def median_of(spreads: list[Spread]) -> Spread:
    """A figure over several parameter points: the median of their medians, of their mins and of their maxes."""
    return Spread(float(np.median([s.median for s in spreads])), float(np.median([s.low for s in spreads])),
                  float(np.median([s.high for s in spreads])), min(s.repeats for s in spreads))


# --------------------------------------------------------------------------- the full check against numpy's floor


def numpy_t_fund(loop: WallLoop, theta: np.ndarray) -> np.ndarray:
    """The floor: DESIGN 3.2's ``T_fund`` for point sampling and a whole delay, written as plain numpy
    complex arithmetic (no care for cancellation), m/(N s)."""
    m, b, T, d = loop.m, loop.b, loop.T, round(loop.delay)
    z = np.exp(1j * theta)
    g11 = 1.0 / (m * 1j * theta / T + b)
    g11d = T / m * phi1(loop.c) / (z - math.exp(-loop.c))
    wall = (loop.K * T * z / (z - 1.0) + loop.B) * z ** (-d)
    hold = (1.0 - np.exp(-1j * theta)) / (1j * theta)
    return g11 * (1.0 - hold * wall * g11 / (1.0 + g11d * wall))


def _new_wall(func: Callable[[], object]) -> Callable[[], object]:
    """``func`` as for a wall not judged before: the poles' cache emptied first (the device's own
    caches -- period map, alias series -- stay warm, as they are for a gate on one device)."""

    def call() -> object:
        forget_walls()
        return func()

    return call


def gate_verdict(loop: WallLoop) -> bool:
    """What the gate decides on an upload or a profile load: the exact verdict alone."""
    return exact_verdict(loop).passive


def full_check(loop: WallLoop) -> tuple[bool, float | None, float | None]:
    """``check_passivity`` with its limits (no out-of-band search): verdict, seed's test, every passive ``K`` and ``B``."""
    report = check_loop(loop, out_of_band=False)
    return report.passive, report.max_stiffness, report.max_damping


def exposure(loop: WallLoop) -> tuple[float, float]:
    """The out-of-band exposure as ``haptic-bus check`` shows it: the worst pair and the worst force of 16 aliases."""
    return worst_force(loop, pair=True).power, worst_force(loop).power


RATIO_TARGETS = {"verdict": 2.0, "full_check": 5.0, "exposure": 20.0}
"""Issue 19: each against one 10^4-point numpy ``T_fund`` at delay 1."""


def full_check_against_floor(loops: list[WallLoop]) -> dict:
    """Issues 14 and 19's yardstick, side by side at each delay-1 point: the gate's verdict
    (:func:`gate_verdict`), the full check with limits (:func:`full_check`) and the out-of-band
    exposure (:func:`exposure`), each timed pairwise against one 10^4-point :func:`numpy_t_fund`
    (each call a new wall: :func:`_new_wall`); the product's cancellation-free ``t_fund`` beside."""
    grid = uniform_grid(CONTROL_GRID)
    rows = []
    ratios: dict[str, list[Spread]] = {key: [] for key in RATIO_TARGETS}
    for loop in loops:
        agreement = float(np.max(np.abs(numpy_t_fund(loop, grid) / t_fund(loop, grid) - 1.0)))
        floor_call = functools.partial(numpy_t_fund, loop, grid)
        row: dict[str, Any] = {"m": loop.m, "b": loop.b, "K": loop.K, "B": loop.B, "delay": loop.delay}
        for key, func in (("verdict", gate_verdict), ("full_check", full_check), ("exposure", exposure)):
            own, floor, ratio = paired_calls(_new_wall(functools.partial(func, loop)), floor_call)
            ratios[key].append(ratio)
            row[f"{key}_s"], row[f"{key}_ratio"] = own.to_dict(), ratio.to_dict()
            if key == "full_check":
                row["numpy_t_fund_1e4_s"], row["ratio"] = floor.to_dict(), ratio.to_dict()
        row["product_t_fund_1e4_s"] = time_per_call(functools.partial(t_fund, loop, grid)).to_dict()
        row["numpy_vs_product_max_relative"] = agreement
        rows.append(row)
    summary = {}
    for key, spreads in ratios.items():
        worst = max(spreads, key=lambda r: r.median)
        summary[key] = {"median": float(np.median([r.median for r in spreads])), "max": worst.median,
                        "worst_point": worst.to_dict(), "target": RATIO_TARGETS[key]}
    return {"points": rows, "ratio": summary["full_check"], "ratios": summary,
            "ratio_target": FULL_CHECK_RATIO_TARGET,
            "note": "verdict = the gate's exact verdict alone; full check = check_passivity without the out-of-band "
                    "search (exact verdict + seed's test + every passive K and B); exposure = worst pair + worst "
                    "force of 16 aliases; each call a new wall (poles' cache emptied); the floor is T_fund on 10^4 "
                    "uniform theta points in plain numpy (DESIGN 3.2, point sampling, whole delay)"}


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 1; returns its section of ``bench.json``."""
    from haptic_bus.bench.mp_boundary import reference_boundary

    try:  # seconds to import: not for the smoke
        with_control, control_note = size.pick(False, True, True), size.pick("python-control: not in the smoke run", None, None)
        if with_control:
            importlib.import_module("control")
    except ImportError as exc:
        with_control, control_note = False, f"python-control not installed ({exc}); pip install 'haptic_bus[bench]'"
    points = parameter_points(FULL_POINTS)
    points = [points[i] for i in size.pick(SMOKE_POINTS, QUICK_POINTS, range(FULL_POINTS))]
    grid_sizes = size.pick(GRID_SIZES_FULL[:2], GRID_SIZES_FULL[:4], GRID_SIZES_FULL)
    methods = _methods(grid_sizes, with_control)
    per_point: list[dict[str, Any]] = []
    times: dict[str, list[Spread]] = {m.key: [] for m in methods}
    errors: dict[str, dict[str, list[float]]] = {m.key: {"K": [], "B": []} for m in methods}
    boundary_times: dict[str, list[Spread]] = {"exact": [], "closed_form": []}
    for p_index, loop in enumerate(points):
        record: dict[str, Any] = {"m": loop.m, "b": loop.b, "T": loop.T, "K": loop.K, "B": loop.B, "delay": loop.delay,
                                  "c": loop.c, "boundaries": {}}
        for which, exact_limit in (("K", max_stiffness), ("B", max_damping)):
            estimate = exact_limit(loop)
            if estimate is None:
                raise RuntimeError(f"no passive {which} at a benchmark point: {loop}")
            boundary_times["exact"].append(time_per_call(functools.partial(exact_limit, loop), min_ns=0))
            ref = reference_boundary(loop, which, estimate)
            slope = exact_slope(loop, which, ref.value)
            entry: dict[str, Any] = {"reference": ref.value, "reference_theta": ref.theta, "reference_kind": ref.kind,
                     "reference_verified": ref.verified, "methods": {}}
            for method in methods:
                if not method.applies(loop):
                    continue
                if method.key == "exact":
                    value = estimate
                elif method.key == "closed_form":
                    value = closed_form_boundary(loop, which)
                    boundary_times["closed_form"].append(time_per_call(functools.partial(closed_form_boundary, loop, which)))
                else:
                    value = newton_boundary(method.check, loop, which, ref.value, slope)
                error = abs(value - ref.value) / ref.value
                errors[method.key][which].append(error)
                entry["methods"][method.key] = {"boundary": value, "relative_error": error}
            record["boundaries"][which] = entry
            tick(f"passivity: point {p_index + 1}/{len(points)} {which}")
        for method in methods:
            if method.applies(loop):
                times[method.key].append(time_per_call(functools.partial(method.check, loop),
                                                       min_ns=0 if method.large else 2_000_000))
        per_point.append(record)
    exact_time = median_of(times["exact"]).median
    region = _region_map_time(points[0])
    summary = []
    for method in methods:
        errs = errors[method.key]["K"] + errors[method.key]["B"]
        if not errs:
            continue
        t = median_of(times[method.key])
        summary.append({
            "method": method.name, "key": method.key,
            "time_per_check_s": t.median, "time_per_check": t.to_dict(), "time_ratio_to_exact": t.median / exact_time,
            "error_K_median": float(np.median(errors[method.key]["K"])), "error_K_max": float(np.max(errors[method.key]["K"])),
            "error_B_median": float(np.median(errors[method.key]["B"])), "error_B_max": float(np.max(errors[method.key]["B"])),
            "error_max": float(np.max(errs)), "points": len(errs) // 2,
        })
    delayed = [i for i, loop in enumerate(points) if loop.delay == 1]
    full = full_check_against_floor([points[i] for i in delayed])
    full["boundary_error_max"] = max(max(p["boundaries"][w]["methods"]["exact"]["relative_error"] for w in ("K", "B"))
                                     for p in (per_point[i] for i in delayed))
    full["boundary_error_target"] = FULL_CHECK_ERROR_TARGET
    full["met"] = full["ratio"]["max"] <= FULL_CHECK_RATIO_TARGET and full["boundary_error_max"] <= FULL_CHECK_ERROR_TARGET
    tick("passivity: full check against the numpy floor")
    return {
        "description": "time per passivity check vs relative error of the boundary (largest passive K at the "
                       "point's B, largest passive B at its K) against a 40-digit mpmath reference",
        "points": per_point,
        "methods": summary,
        "full_check": full,
        "boundary_time_s": {k: median_of(v).median for k, v in boundary_times.items() if v},
        "boundary_time": {k: median_of(v).to_dict() for k, v in boundary_times.items() if v},
        "control_note": control_note or (
            "python-control builds G11 (continuous), G11d and K_d z^-d (discrete, dt = T) and evaluates their "
            "frequency responses; the hold H/T is numpy (transcendental) and T_fund is assembled pointwise "
            "(continuous and discrete systems cannot be interconnected in python-control)"),
        "grid_note": "uniform theta = pi i/N, i = 1..N, pi included; boundary by Newton on the method's own margin "
                     "from the reference, slope of the exact margin",
        "region_map_1e6_s": region.median,
        "region_map_1e6": region.to_dict(),
        "region_map_note": "closed_form.region_map on a 1000 x 1000 (alpha, beta) mesh (eq. 24 at the point's c)",
        "all_references_verified": all(e["reference_verified"] for p in per_point for e in p["boundaries"].values()),
    }
