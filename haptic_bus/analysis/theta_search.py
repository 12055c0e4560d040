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
"""

from __future__ import annotations

import math
from collections.abc import Callable

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
