"""The exact passivity criterion of the sampled-data wall loop, and the seed's verdict beside it.

Passive (for operator forces band-limited below the Nyquist frequency ``pi/T``) iff

1. every closed-loop pole lies strictly inside the unit circle, and
2. ``Re T_fund(theta) >= 0`` on ``(0, pi]``.

Condition 2 is judged on the impedance ``Z = 1/T_fund``: ``Re Z = Re T / |T|^2`` has the same
sign, stays finite as ``theta -> 0`` (where ``Re T -> 0``), and its minimum is the least net
damping the operator feels at any frequency, in N s/m.  That minimum is the **margin** of a
stable loop.  For an unstable loop the margin is ``-(rho - 1) m / T`` (N s/m), ``rho`` the
largest pole magnitude: to first order the physical damping that would have to be added to
pull that pole back onto the unit circle.  Either way ``margin >= 0`` iff passive.

How the minimum is found (it cannot slip between grid points): ``Re Z`` is smooth except near
the closed-loop poles (a pole at radius ``r`` and angle ``phi`` makes a feature of width
``1 - r`` at ``phi``) and near the plant corner ``theta = c``.  The grid is 192 uniform points
plus a logarithmic fan towards 0 plus a fan of points at each pole angle with spacing scaled
by ``1 - r`` and a fan at ``c``; the three lowest grid local minima are refined
between their neighbours by a vectorised zoom and a final parabola.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.frequency import seed_t_zw, z_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import closed_loop_poles, is_stable

_UNIFORM_POINTS = 192
_FAN = np.array([-16.0, -8.0, -4.0, -2.0, -1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
_LOWEST_THETA = 1e-6
_LOG_FAN = np.logspace(math.log10(_LOWEST_THETA), math.log10(math.pi / _UNIFORM_POINTS), 12)
_REFINED_MINIMA = 3
_ZOOM_POINTS = 11
_ZOOM_ROUNDS = 5
_SIGN_TOLERANCE = 1e-14  # relative to |Z| at the minimum: Re Z is accurate to ~1e-15 |Z|

EXACT = "exact: closed-loop stability and Re T_fund >= 0 on (0, pi]"
SEED = "seed: Re T_zw >= 0 on (0, pi] (eq. 11)"


@dataclass(frozen=True)
class Verdict:
    """The outcome of one passivity criterion.

    ``margin`` in N s/m (``>= 0`` iff passive), ``critical_theta`` the ``omega T`` where the
    margin is attained (rad), ``method`` how the minimum was located.
    """

    criterion: str
    passive: bool
    stable: bool
    margin: float
    critical_theta: float
    spectral_radius: float
    method: str


def _theta_grid(loop: WallLoop, poles: np.ndarray) -> np.ndarray:
    uniform = np.linspace(math.pi / _UNIFORM_POINTS, math.pi, _UNIFORM_POINTS)
    pieces = [uniform, _LOG_FAN]
    for pole in poles:
        radius, angle = abs(pole), abs(np.angle(pole))
        width = max(abs(1.0 - radius), 1e-9)
        pieces.append(angle + width * _FAN)
    if loop.c < math.pi:
        pieces.append(loop.c * np.abs(_FAN[_FAN > 0]) / 4.0)
    grid = np.concatenate(pieces)
    grid = grid[(grid >= _LOWEST_THETA) & (grid <= math.pi)]
    return np.unique(np.append(grid, math.pi))


def minimum_real_part(impedance, loop: WallLoop, poles: np.ndarray | None = None) -> tuple[float, float, float]:
    """Minimum over ``(0, pi]`` of ``Re impedance(loop, theta)``: (value, theta, |Z| there).

    The three lowest grid minima are refined together, vectorised: each round evaluates
    ``_ZOOM_POINTS`` points inside every bracket and keeps the neighbours of the best
    (the bracket shrinks 5x a round); a parabola through the final three points ends it.
    """
    grid = _theta_grid(loop, closed_loop_poles(loop) if poles is None else poles)
    values = impedance(loop, grid)
    real = values.real
    best_i = int(np.argmin(real))
    best = (float(real[best_i]), float(grid[best_i]), float(abs(values[best_i])))
    interior = np.flatnonzero((real[1:-1] <= real[:-2]) & (real[1:-1] <= real[2:])) + 1
    chosen = interior[np.argsort(real[interior])][:_REFINED_MINIMA]
    if chosen.size == 0:
        return best
    lo, hi = grid[chosen - 1], grid[chosen + 1]
    fractions = np.linspace(0.0, 1.0, _ZOOM_POINTS)
    for _ in range(_ZOOM_ROUNDS):
        points = lo[:, None] + (hi - lo)[:, None] * fractions
        re = impedance(loop, points.ravel()).real.reshape(points.shape)
        k = np.clip(np.argmin(re, axis=1), 1, _ZOOM_POINTS - 2)
        rows = np.arange(points.shape[0])
        lo, hi = points[rows, k - 1], points[rows, k + 1]
    mid = 0.5 * (lo + hi)
    triple = np.stack([lo, mid, hi], axis=1)
    f = impedance(loop, triple.ravel()).real.reshape(triple.shape)
    curvature = f[:, 0] - 2 * f[:, 1] + f[:, 2]
    step = np.where(curvature > 0, 0.25 * (hi - lo) * (f[:, 0] - f[:, 2]) / np.where(curvature > 0, curvature, 1.0), 0.0)
    vertex = np.clip(mid + step, lo, hi)
    final = impedance(loop, vertex)
    candidates = [
        (float(final.real[i]), float(vertex[i]), float(abs(final[i]))) for i in range(vertex.size)
    ] + [(float(f[i, 1]), float(mid[i]), float("nan")) for i in range(mid.size)]
    for value, theta, magnitude in candidates:
        if value < best[0]:
            best = (value, theta, magnitude if math.isfinite(magnitude) else float(abs(impedance(loop, theta)[0])))
    return best


def _verdict(loop: WallLoop, impedance, criterion: str, require_stability: bool) -> Verdict:
    poles = closed_loop_poles(loop)
    radius = float(np.abs(poles[0]))
    stable = is_stable(loop)
    value, theta, magnitude = minimum_real_part(impedance, loop, poles)
    method = f"grid ({_UNIFORM_POINTS} uniform + pole/corner fans) + vectorised zoom + parabola"
    if require_stability and not stable:
        margin = -max((radius - 1.0) * loop.m / loop.T, math.ulp(1.0))
        return Verdict(criterion, False, False, margin, theta, radius, "closed-loop poles (unstable)")
    scale = loop.m / loop.T
    margin = value * scale
    passive = value >= -_SIGN_TOLERANCE * magnitude
    if passive and margin < 0:
        margin = 0.0  # within the evaluation's round-off of the boundary
    return Verdict(criterion, passive, stable, margin, theta, radius, method)


def _scaled_fund_impedance(loop: WallLoop, theta) -> np.ndarray:
    return z_fund(loop, theta) * (loop.T / loop.m)


def _scaled_seed_impedance(loop: WallLoop, theta) -> np.ndarray:
    return (loop.T / loop.m) / seed_t_zw(loop, theta)


def exact_verdict(loop: WallLoop) -> Verdict:
    """The exact criterion (stability and ``Re T_fund >= 0``): what the passivity gate uses."""
    return _verdict(loop, _scaled_fund_impedance, EXACT, require_stability=True)


def seed_verdict(loop: WallLoop) -> Verdict:
    """The seed's frequency test ``Re T_zw >= 0`` alone (no stability test, as in the seed)."""
    return _verdict(loop, _scaled_seed_impedance, SEED, require_stability=False)
