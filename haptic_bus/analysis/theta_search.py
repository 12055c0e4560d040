"""Where on (0, pi] a frequency function is smallest: the grid and the vectorised zoom.

The grid (:func:`theta_grid`): uniform points (more for a long delay, whose responses wind
``D`` times round the circle: 24 points per turn), a logarithmic fan towards 0 down to
``1e-9`` rad (the ``theta -> 0`` limit to ``O(1e-18)`` relative, the functions being even in
``theta``), a fan at the low-pass corner ``T/TAU`` and a fan of points at the angle of every
lightly damped closed-loop pole with spacing scaled by ``1 - |pole|``.

The zoom (:func:`refine_minima`): the lowest interior local minima of the grid values are
refined together, vectorised: each round evaluates 11 points inside every bracket and keeps
the neighbours of the best (the bracket shrinks 5x a round); after 5 rounds a parabola through
the last three points ends it.  A smooth minimum is then located to ``~1e-6`` of the grid step
and its value is exact to round-off.

The joint zoom (:func:`refine_lanes`): several functions of ``theta`` on one grid (the margin,
the seed's test, every end of every passive interval) zoomed at once, each round's points of
all of them evaluated by one call of the costly shared part (the loop's terms).
"""

from __future__ import annotations

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
_ZOOM_POINTS = 11
_ZOOM_ROUNDS = 5

Objective = Callable[[np.ndarray], np.ndarray]


def uniform_points(loop: WallLoop) -> int:
    """Uniform grid size for ``loop``: 192, or 24 per turn of ``e^{-j theta D}`` on (0, pi] if more."""
    return max(UNIFORM_POINTS, POINTS_PER_TURN * math.ceil(loop.delay + 1))


def theta_grid(loop: WallLoop, poles: np.ndarray) -> np.ndarray:
    """The search grid on [1e-9, pi] (rad), sorted, ``pi`` included (see the module docstring)."""
    n = uniform_points(loop)
    pieces = [np.linspace(math.pi / n, math.pi, n), np.geomspace(LOWEST_THETA, math.pi / n, _LOG_POINTS)]
    if loop.velocity.kind == "lowpass":
        pieces.append(loop.T / loop.velocity.time * np.exp2(np.arange(-4.0, 5.0)))
    light = poles[np.abs(1.0 - np.abs(poles)) < _LIGHT_DAMPING][:_MAX_POLE_FANS]
    for pole in light:
        width = max(abs(1.0 - abs(pole)), 1e-9)
        pieces.append(abs(np.angle(pole)) + width * _FAN)
    grid = np.concatenate(pieces)
    grid = grid[(grid >= LOWEST_THETA) & (grid <= math.pi)]
    return np.unique(np.append(grid, math.pi))


def refine_minima(objective: Objective, grid: np.ndarray, values: np.ndarray, count: int = 3
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
    fractions = np.linspace(0.0, 1.0, _ZOOM_POINTS)
    rows = np.arange(chosen.size)
    for _ in range(_ZOOM_ROUNDS):
        points = lo[:, None] + (hi - lo)[:, None] * fractions
        f = objective(points.ravel()).reshape(points.shape)
        k = np.clip(np.argmin(f, axis=1), 1, _ZOOM_POINTS - 2)
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


@dataclass(frozen=True)
class Lane:
    """One function of ``theta`` for :func:`refine_lanes`: its ``values`` on the shared grid,
    the ``group`` whose evaluation it reads, ``pick`` (that evaluation at its points -> its values)
    and, optionally, ``check`` (-> values that must stay >= 0: the least over every point it
    evaluated is returned too)."""

    values: np.ndarray
    group: str
    pick: Callable[[np.ndarray], np.ndarray]
    check: Callable[[np.ndarray], np.ndarray] | None = None
    grid_check: np.ndarray | None = None


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
    """:func:`refine_minima` for every lane at once (``count`` minima each); each round computes
    ``shared`` once, on the points of every lane whose group uses it (``shared(theta).take(mask)``
    splits it), and each group once."""
    fractions = np.linspace(0.0, 1.0, _ZOOM_POINTS)
    brackets: list[tuple[np.ndarray, np.ndarray]] = []
    best = []
    for lane in lanes:
        on_grid = lane.values
        interior = np.flatnonzero((on_grid[1:-1] <= on_grid[:-2]) & (on_grid[1:-1] <= on_grid[2:])) + 1
        chosen = interior[np.argsort(on_grid[interior], kind="stable")][:count]
        brackets.append((grid[chosen - 1], grid[chosen + 1]))
        i = int(np.argmin(on_grid))
        least = float(np.min(lane.grid_check)) if lane.grid_check is not None else math.inf
        best.append([float(on_grid[i]), float(grid[i]), least])

    def evaluate(points: list[np.ndarray]) -> list[np.ndarray]:
        """Every lane's values at its ``points`` (flat): ``shared`` once, each group once."""
        out: list[np.ndarray] = [np.empty(0)] * len(lanes)
        users = [k for k, lane in enumerate(lanes) if groups[lane.group].shared and points[k].size]
        owner = np.concatenate([np.full(points[k].size, k) for k in users]) if users else np.empty(0, dtype=int)
        terms = shared(np.concatenate([points[k] for k in users])) if users else None
        for name, group in groups.items():
            members = [k for k, lane in enumerate(lanes) if lane.group == name and points[k].size]
            if not members:
                continue
            if group.shared:
                assert terms is not None
                data = group.evaluate(terms.take(np.isin(owner, members)))
                sizes = [int(np.count_nonzero(owner == k)) for k in members]
            else:
                data = group.evaluate(np.concatenate([points[k] for k in members]))
                sizes = [points[k].size for k in members]
            for k, part in zip(members, np.split(data, np.cumsum(sizes)[:-1], axis=-1)):
                lane = lanes[k]
                out[k] = lane.pick(part)
                if lane.check is not None:
                    best[k][2] = min(best[k][2], float(np.min(lane.check(part))))
        return out

    for _ in range(_ZOOM_ROUNDS):
        points = [lo[:, None] + (hi - lo)[:, None] * fractions for lo, hi in brackets]
        values = evaluate([p.ravel() for p in points])
        for k, (p, v) in enumerate(zip(points, values)):
            if not p.size:
                continue
            f = v.reshape(p.shape)
            j = np.clip(np.argmin(f, axis=1), 1, _ZOOM_POINTS - 2)
            rows = np.arange(p.shape[0])
            brackets[k] = (p[rows, j - 1], p[rows, j + 1])
    triples = [np.stack([lo, 0.5 * (lo + hi), hi], axis=1) for lo, hi in brackets]
    values = evaluate([t.ravel() for t in triples])
    vertices = []
    for (lo, hi), t, v in zip(brackets, triples, values):
        f = v.reshape(t.shape) if t.size else np.empty((0, 3))
        curvature = f[:, 0] - 2 * f[:, 1] + f[:, 2]
        safe = np.where(curvature > 0, curvature, 1.0)
        step = np.where(curvature > 0, 0.25 * (hi - lo) * (f[:, 0] - f[:, 2]) / safe, 0.0)
        vertices.append(np.clip(t[:, 1] + step, lo, hi) if t.size else np.empty(0))
    at_vertices = evaluate(vertices)
    out = []
    for k, (t, v, vertex, at_vertex) in enumerate(zip(triples, values, vertices, at_vertices)):
        thetas = np.concatenate([t[:, 1], vertex]) if t.size else np.empty(0)
        refined = np.concatenate([v.reshape(t.shape)[:, 1], at_vertex]) if t.size else np.empty(0)
        value, theta, least = best[k]
        if refined.size and float(np.min(refined)) < value:
            i = int(np.argmin(refined))
            value, theta = float(refined[i]), float(thetas[i])
        out.append(LaneMinimum(value, theta, least))
    return out
