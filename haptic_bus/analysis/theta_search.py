"""Where on (0, pi] a frequency function is smallest: the grid and the vectorised zoom.

The grid (:func:`theta_grid`): uniform points (more for a long delay, whose responses wind
``D`` times round the circle: 24 points per turn), a logarithmic fan towards 0 down to
``1e-9`` rad (the ``theta -> 0`` limit to ``O(1e-18)`` relative, the functions being even in
``theta``), a fan at the low-pass corner ``T/TAU`` and a fan of points at the angle of every
lightly damped closed-loop pole with spacing scaled by ``1 - |pole|``.

The zoom (:func:`refine_lanes`): several functions of ``theta`` on one grid (*lanes*: the
margin, the seed's test, every end of every passive interval) are refined at once.  The three
lowest interior local minima of each lane's grid values are bracketed by their neighbours; each
round evaluates 41 points inside every bracket and keeps the neighbours of the best (the bracket
shrinks 20x a round); after 3 rounds (8000x) the parabola through the best point and its two
neighbours gives the vertex, evaluated once more.  A smooth minimum is then located to
``~1e-8`` of the grid step and its value is exact to round-off.  Each round evaluates the costly
shared part (the loop's terms) once, on the points of every lane together: 4 evaluations refine
everything a check asks for.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.analysis.loop import WallLoop

LOWEST_THETA = 1e-9
UNIFORM_POINTS = 192
POINTS_PER_TURN = 24
_FAN = np.array([-16.0, -8.0, -4.0, -2.0, -1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
_LOG_POINTS = 16
_LIGHT_DAMPING = 0.2  # poles within this of the unit circle get a fan
_MAX_POLE_FANS = 64
_ZOOM_POINTS = 25
_ZOOM_ROUNDS = 2
_MINIMA_POINTS = 11  # refine_minima's zoom (the coupled axes' criterion): 5 rounds to about 1e-10 in theta
_MINIMA_ROUNDS = 5


def uniform_points(loop: WallLoop) -> int:
    """Uniform grid size for ``loop``: 192, or 24 per turn of ``e^{-j theta D}`` on (0, pi] if more."""
    return max(UNIFORM_POINTS, POINTS_PER_TURN * math.ceil(loop.delay + 1))


def theta_grid(loop: WallLoop, poles: np.ndarray) -> np.ndarray:
    """The search grid on [1e-9, pi] (rad), sorted, ``pi`` included (see the module docstring)."""
    base, fans = grid_parts(loop, poles)
    return sorted_unique(np.concatenate([base, fans])) if fans.size else base


def grid_parts(loop: WallLoop, poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the wall-independent part of :func:`theta_grid`, sorted and shared: uniform points, the log
    fan, the low-pass corner's fan; the fans at ``poles``' angles, unsorted)."""
    base = _base_grid(uniform_points(loop), loop.T / loop.velocity.time if loop.velocity.kind == "lowpass" else 0.0)
    light = poles[np.abs(1.0 - np.abs(poles)) < _LIGHT_DAMPING][:_MAX_POLE_FANS]
    if not light.size:
        return base, np.empty(0)
    width = np.maximum(np.abs(1.0 - np.abs(light)), 1e-9)
    fans = (np.abs(np.angle(light))[:, None] + width[:, None] * _FAN).ravel()
    return base, fans[(fans >= LOWEST_THETA) & (fans <= math.pi)]


@functools.lru_cache(maxsize=256)
def _base_grid(n: int, corner: float) -> np.ndarray:
    """The wall-independent part of the grid: ``n`` uniform points, the log fan, the low-pass corner's fan."""
    pieces = [np.linspace(math.pi / n, math.pi, n), np.geomspace(LOWEST_THETA, math.pi / n, _LOG_POINTS)]
    if corner:
        pieces.append(corner * np.exp2(np.arange(-4.0, 5.0)))
    grid = np.concatenate(pieces)
    grid = sorted_unique(np.append(grid[(grid >= LOWEST_THETA) & (grid <= math.pi)], math.pi))
    grid.setflags(write=False)
    return grid


def sorted_unique(values: np.ndarray) -> np.ndarray:
    """``values`` sorted, repeats dropped (``np.unique`` without its import of ``numpy.ma``: 0.1 s at start-up)."""
    ordered = np.sort(values)
    return ordered[np.concatenate([[True], ordered[1:] != ordered[:-1]])] if ordered.size else ordered


@dataclass(frozen=True)
class Lane:
    """One function of ``theta`` for :func:`refine_lanes`: its ``values`` on the shared grid,
    the ``group`` whose evaluation it reads, ``pick`` (that evaluation at its points -> its values)
    and, optionally, ``check`` (-> values that must stay >= 0: the least over every point it
    evaluated is returned too); ``rounds`` of zoom before the parabola (2: an envelope to 1e-12
    in ``x``; 1: a minimum's value to about 1e-10 relative, what a margin needs)."""

    values: np.ndarray
    group: str
    pick: Callable[[np.ndarray], np.ndarray]
    check: Callable[[np.ndarray], np.ndarray] | None = None
    grid_check: np.ndarray | None = None
    rounds: int = 2


@dataclass(frozen=True)
class LaneMinimum:
    """A lane's least value (over its grid and refined points), the ``theta`` there (rad), and the
    least of its ``check`` over every point it evaluated (inf without one)."""

    value: float
    theta: float
    check: float


@dataclass(frozen=True)
class Group:
    """How a group of lanes is evaluated at ``theta``: ``evaluate`` gets the shared terms there
    (``shared(theta)``, computed once a round for every group with ``shared = True``) or, without,
    ``theta`` itself; it returns data whose last axis runs over the points."""

    evaluate: Callable[[Any], np.ndarray]
    shared: bool = True


def refine_lanes(grid: np.ndarray, lanes: list[Lane], groups: dict[str, Group], shared: Callable[[np.ndarray], Any],
                 count: int = 3) -> list[LaneMinimum]:
    """Every lane's least value: its ``count`` lowest interior grid minima zoomed (see the module
    docstring).  Each round computes ``shared`` once, on the points of every lane whose group uses
    it, and each group once; the brackets of all lanes are refined as one array."""
    names = sorted(groups, key=lambda name: not groups[name].shared)  # the shared groups' points first
    order = [k for name in names for k, lane in enumerate(lanes) if lane.group == name]  # lanes by group
    best = []
    lows, highs, owners = [], [], []
    for k, lane in enumerate(lanes):
        on_grid = lane.values
        interior = np.flatnonzero((on_grid[1:-1] <= on_grid[:-2]) & (on_grid[1:-1] <= on_grid[2:])) + 1
        chosen = interior[np.argsort(on_grid[interior], kind="stable")][:count]
        lows.append(grid[chosen - 1])
        highs.append(grid[chosen + 1])
        owners.append(np.full(chosen.size, k))
        i = int(np.argmin(on_grid))
        least = float(np.min(lane.grid_check)) if lane.grid_check is not None else math.inf
        best.append([float(on_grid[i]), float(grid[i]), least])
    if not order or sum(o.size for o in owners) == 0:
        return [LaneMinimum(*b) for b in best]
    lo = np.concatenate([lows[k] for k in order])
    hi = np.concatenate([highs[k] for k in order])
    owner = np.concatenate([owners[k] for k in order])
    rounds = np.array([lanes[k].rounds for k in owner])

    def evaluate(points: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Values at the ``active`` rows of ``points`` (one row per bracket, in ``order``; inf elsewhere):
        ``shared`` once, each group once."""
        width = points.shape[1]
        rows_of = np.bincount(owner[active], minlength=len(lanes))
        flat = points[active].ravel()
        values = np.empty(flat.size)
        shared_rows = sum(int(rows_of[k]) for k in order if groups[lanes[k].group].shared)
        terms = shared(flat[: shared_rows * width]) if shared_rows else None
        start = 0
        for name in names:
            ks = [k for k in order if lanes[k].group == name and rows_of[k]]
            size = sum(int(rows_of[k]) for k in ks) * width
            if not size:
                continue
            if groups[name].shared:
                assert terms is not None
                data = groups[name].evaluate(terms.take(slice(start, start + size)))
            else:
                data = groups[name].evaluate(flat[start:start + size])
            offset = 0
            for k in ks:
                part = data[..., offset:offset + int(rows_of[k]) * width]
                lane = lanes[k]
                values[start + offset:start + offset + part.shape[-1]] = lane.pick(part)
                if lane.check is not None:
                    best[k][2] = min(best[k][2], float(np.min(lane.check(part))))
                offset += part.shape[-1]
            start += size
        out = np.full(points.shape, np.inf)
        out[active] = values.reshape(-1, width)
        return out

    fractions = np.linspace(0.0, 1.0, _ZOOM_POINTS)
    rows = np.arange(lo.size)
    middle = f_lo = f_mid = f_hi = np.zeros(lo.size)
    for r in range(int(np.max(rounds))):
        active = rounds > r
        points = lo[:, None] + (hi - lo)[:, None] * fractions
        f = evaluate(points, active)
        j = np.clip(np.argmin(f, axis=1), 1, _ZOOM_POINTS - 2)
        new = (points[rows, j - 1], points[rows, j + 1], points[rows, j], f[rows, j - 1], f[rows, j], f[rows, j + 1])
        lo, hi, middle, f_lo, f_mid, f_hi = (np.where(active, a, b) for a, b in zip(new, (lo, hi, middle, f_lo, f_mid, f_hi)))
    # the parabola through the best point and its equally spaced neighbours
    curvature = f_lo - 2 * f_mid + f_hi
    safe = np.where(curvature > 0, curvature, 1.0)
    step = np.where(curvature > 0, 0.25 * (hi - lo) * (f_lo - f_hi) / safe, 0.0)
    vertex = np.clip(middle + step, lo, hi)
    at_vertex = evaluate(vertex[:, None], np.ones(lo.size, dtype=bool))[:, 0]
    thetas = np.concatenate([middle, vertex])
    refined = np.concatenate([f_mid, at_vertex])
    owners_twice = np.concatenate([owner, owner])
    out = []
    for k in range(len(lanes)):
        value, theta, least = best[k]
        mine = np.flatnonzero(owners_twice == k)
        if mine.size and float(np.min(refined[mine])) < value:
            i = mine[int(np.argmin(refined[mine]))]
            value, theta = float(refined[i]), float(thetas[i])
        out.append(LaneMinimum(value, theta, least))
    return out


def refine_minima(objective: Callable[[np.ndarray], np.ndarray], grid: np.ndarray, values: np.ndarray, count: int = 3
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Refine the ``count`` lowest interior local minima of ``values = objective(grid)``.

    Returns ``(theta, value)`` arrays of the refined points (and the zoom's last midpoints),
    to be compared with the grid's own minimum by the caller.
    """
    interior = np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:])) + 1
    chosen = interior[np.argsort(values[interior], kind="stable")][:count]
    if chosen.size == 0:
        return np.empty(0), np.empty(0)
    lo, hi = grid[chosen - 1], grid[chosen + 1]
    fractions = np.linspace(0.0, 1.0, _MINIMA_POINTS)
    rows = np.arange(chosen.size)
    for _ in range(_MINIMA_ROUNDS):
        points = lo[:, None] + (hi - lo)[:, None] * fractions
        f = objective(points.ravel()).reshape(points.shape)
        k = np.clip(np.argmin(f, axis=1), 1, _MINIMA_POINTS - 2)
        lo, hi = points[rows, k - 1], points[rows, k + 1]
    mid = 0.5 * (lo + hi)
    triple = np.stack([lo, mid, hi], axis=1)
    f = objective(triple.ravel()).reshape(triple.shape)
    curvature = f[:, 0] - 2 * f[:, 1] + f[:, 2]
    safe = np.where(curvature > 0, curvature, 1.0)
    step = np.where(curvature > 0, 0.25 * (hi - lo) * (f[:, 0] - f[:, 2]) / safe, 0.0)
    vertex = np.clip(mid + step, lo, hi)
    thetas = np.concatenate([vertex, mid])
    return thetas, np.concatenate([objective(vertex), f[:, 1]])
