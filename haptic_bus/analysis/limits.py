"""The passive walls: every passive ``K`` at the loop's ``B``, every passive ``B`` at its ``K``.

The passive values of one wall parameter, the other fixed, form a set of closed intervals that
need not start at 0 (with a delay, too little damping is active as well as too much):
:class:`PassiveSet` carries them, ``lowest`` and ``largest`` its ends (None: nothing passive).

**Per-theta quadratic** (DESIGN 3.5, issue 14).  At a fixed ``theta`` the impedance is a
linear-fractional function of ``K`` (and of ``B``), so ``|U|^2 Re Z`` is a real quadratic
``Q_theta(x)`` in the scaled parameter ``x`` (``kappa = K T^2/m`` or ``q = B T/m``;
:func:`~haptic_bus.analysis.frequency.impedance_quadratic`).  At each grid ``theta`` the values
with ``Q_theta(x) < 0`` (beyond the sign tolerance) are forbidden: at most two intervals,
read off the roots.  Their union over the grid leaves the candidate intervals.  Each end is
then refined: an upper end ``e`` of the interval around ``s`` is the envelope
``min_theta r+(theta)`` of the first root above ``s``, a lower end ``max_theta r-(theta)`` of
the last root below it, located by the vectorised zoom of :mod:`haptic_bus.analysis.theta_search`
(a smooth envelope minimum is exact to round-off in ``x``).  A closed-loop pole crossing the
unit circle at ``theta*`` makes ``Re Z(theta*) = 0``, so every change of stability is a root
of some ``Q_theta`` and, generically, an end of an interval: stability is constant inside each
candidate interval, and one eigenvalue test at an interior point keeps or drops it.

One evaluation of the wall-independent terms on the grid serves ``K`` and ``B`` alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drives.errors import ParameterError
from haptic_bus.analysis.criterion import SIGN_TOLERANCE
from haptic_bus.analysis.frequency import LoopTerms, impedance_quadratic, loop_terms
from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE, WallLoop
from haptic_bus.analysis.poles import closed_loop_poles, is_stable
from haptic_bus.analysis.theta_complex import ThetaComplex
from haptic_bus.analysis.theta_search import refine_minima, theta_grid

_NO_ROOT = 1e300  # stands in for "no root on that side" (finite, so the zoom's differences stay finite)

RELATIVE_TOLERANCE = 1e-12
"""Relative accuracy of every limit: an envelope minimum located by the zoom, in double precision."""


@dataclass(frozen=True)
class PassiveSet:
    """The passive values of ``parameter`` ("K" in N/m or "B" in N s/m), the other held fixed.

    ``intervals``: disjoint closed intervals ``(low, high)``, ascending; empty when nothing is passive.
    """

    parameter: str
    intervals: tuple[tuple[float, float], ...]

    @property
    def lowest(self) -> float | None:
        """The least passive value, None if none is passive."""
        return self.intervals[0][0] if self.intervals else None

    @property
    def largest(self) -> float | None:
        """The largest passive value, None if none is passive."""
        return self.intervals[-1][1] if self.intervals else None

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: ``lowest``, ``largest`` and the ``intervals`` as ``[low, high]`` pairs."""
        return {"lowest": self.lowest, "largest": self.largest, "intervals": [list(i) for i in self.intervals]}


FAMILIES = ("K", "B", "scale")
"""The one-parameter families of walls: ``K`` at the loop's ``B``, ``B`` at its ``K``, and the
whole wall scaled, ``(s K, s B)`` for ``s`` in ``[0, 1]`` (a start ramp)."""


class _Family:
    """The loops along one parameter (``K``, ``B`` or the ``scale`` s), in scaled units ``x``."""

    def __init__(self, loop: WallLoop, which: str) -> None:
        self.loop = loop
        self.which = which
        if which == "K":
            self.unit = loop.T * loop.T / loop.m  # kappa per N/m
            self.ceiling = STIFFNESS_RANGE[1]
        elif which == "B":
            self.unit = loop.T / loop.m  # q per N s/m
            self.ceiling = DAMPING_RANGE[1]
        else:
            self.unit, self.ceiling = 1.0, 1.0  # x = s itself

    def lines(self, terms: LoopTerms) -> tuple[ThetaComplex | float, ThetaComplex | float]:
        """``L = base + x slope`` on ``terms``' grid."""
        if self.which == "K":
            return terms.hold * self.loop.q, 1.0
        if self.which == "B":
            return self.loop.kappa, terms.hold
        return 0.0, terms.hold * self.loop.q + self.loop.kappa

    def value(self, x: float) -> float:
        """The physical parameter (N/m, N s/m or the scale) at scaled ``x``, clipped to its range."""
        return min(max(x / self.unit, 0.0), self.ceiling)

    def at(self, x: float) -> WallLoop:
        value, loop = self.value(x), self.loop
        if self.which == "K":
            return loop.with_wall(value, loop.B)
        if self.which == "B":
            return loop.with_wall(loop.K, value)
        return loop.with_wall(value * loop.K, value * loop.B)

    def quadratic(self, terms: LoopTerms) -> tuple[np.ndarray, np.ndarray]:
        """Coefficients ``(3, n)`` of ``Q_theta(x)``, and the same with the sign tolerance added.

        The tolerant one (passive iff ``>= 0``, as the verdict judges) decides which intervals
        there are; the exact one's roots are their ends.
        """
        coefficients, magnitudes = impedance_quadratic(terms, *self.lines(terms))
        return coefficients, coefficients + SIGN_TOLERANCE * magnitudes


def _roots(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real roots ``r1 <= r2`` of ``q[0] x^2 + q[1] x + q[2]`` per column (NaN where none; a linear one in both)."""
    a, b, c = q
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - 4.0 * a * c
        root = np.sqrt(np.where(disc >= 0, disc, np.nan))
        t = -0.5 * (b + np.copysign(root, b))
        r_a, r_b = t / a, c / t
        linear = a == 0
        single = -c / b
        r_a = np.where(linear, single, r_a)
        r_b = np.where(linear, single, r_b)
    return np.fmin(r_a, r_b), np.fmax(r_a, r_b)


def _forbidden(q: np.ndarray, top: float) -> list[tuple[float, float]]:
    """Open intervals of ``[0, top]`` where some column's quadratic is negative."""
    r1, r2 = _roots(q)
    a, b, c = q
    out: list[tuple[float, float]] = []
    none = np.isnan(r1)
    # no real root: negative everywhere iff the value at 0 is negative
    for _ in np.flatnonzero(none & (c < 0))[:1]:
        out.append((-math.inf, math.inf))
    linear = (a == 0) & ~none
    up = (a > 0) & ~none & ~linear
    down = (a < 0) & ~none & ~linear
    out += [(lo, hi) for lo, hi in zip(r1[up], r2[up]) if lo < hi]
    out += [(-math.inf, lo) for lo in r1[down]] + [(hi, math.inf) for hi in r2[down]]
    out += [(-math.inf, r) if s > 0 else (r, math.inf) for r, s in zip(r1[linear], b[linear]) if s != 0]
    out += [(-math.inf, math.inf) for _ in np.flatnonzero(linear & (b == 0) & (c < 0))[:1]]
    merged: list[tuple[float, float]] = []
    for lo, hi in sorted((max(lo, -1.0), min(hi, 2.0 * top)) for lo, hi in out if hi > 0 and lo < top):
        if merged and lo <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
        else:
            merged.append((lo, hi))
    return merged


def _allowed(forbidden: list[tuple[float, float]], top: float) -> list[tuple[float, float]]:
    """The closed complement of ``forbidden`` in ``[0, top]``."""
    out, start = [], 0.0
    for lo, hi in forbidden:  # disjoint, ascending
        if lo >= start:
            out.append((start, min(lo, top)))
        start = max(start, hi)
    if start <= top:
        out.append((start, top))
    return [(lo, hi) for lo, hi in out if lo <= hi]


def _envelope(family: _Family, grid: np.ndarray, q: np.ndarray, inside: float, upper: bool) -> float:
    """``min_theta`` of the first root above ``inside`` (``upper``) or ``max_theta`` of the last below, refined."""

    def branch(coefficients: np.ndarray) -> np.ndarray:
        r1, r2 = _roots(coefficients)
        if upper:
            return np.where(r1 > inside, r1, np.where(r2 > inside, r2, np.inf))
        return -np.where(r2 < inside, r2, np.where(r1 < inside, r1, -np.inf))

    def objective(theta: np.ndarray) -> np.ndarray:
        return np.fmin(branch(family.quadratic(loop_terms(family.loop, theta))[0]), _NO_ROOT)

    values = np.fmin(branch(q), _NO_ROOT)
    _, refined = refine_minima(objective, grid, values)
    best = float(np.min(np.concatenate([values, refined])))
    return best if upper else -best


def _scale_grid(loop: WallLoop) -> np.ndarray:
    """The search grid for the scaled walls: the union of the grids of five walls along the way,
    so every lightly damped pole the ramp passes near has its fan of points."""
    grids = [theta_grid(scaled, closed_loop_poles(scaled))
             for scaled in (loop.with_wall(s * loop.K, s * loop.B) for s in (0.0, 0.25, 0.5, 0.75, 1.0))]
    return np.unique(np.concatenate(grids))


def passive_set(loop: WallLoop, which: str, terms: LoopTerms | None = None) -> PassiveSet:
    """The passive ``K`` (``which = "K"``, at the loop's ``B``), ``B`` (at its ``K``) or scales
    ``s`` of the whole wall (``which = "scale"``: ``(s K, s B)``, ``s`` in ``[0, 1]``): closed intervals.

    ``terms``: the wall-independent terms on the search grid, if already evaluated.
    """
    if which not in FAMILIES:
        raise ParameterError("which", which, " or ".join(repr(f) for f in FAMILIES), "passive set")
    family = _Family(loop, which)
    if terms is None:
        grid = _scale_grid(loop) if which == "scale" else theta_grid(loop, closed_loop_poles(loop))
        terms = loop_terms(loop, grid)
    top = family.ceiling * family.unit
    q, tolerant = family.quadratic(terms)
    intervals: list[tuple[float, float]] = []
    for lo, hi in _allowed(_forbidden(tolerant, top), top):
        inside = 0.5 * (lo + hi) if hi > lo else lo
        candidate = family.at(inside)
        if not (candidate.lossless or is_stable(candidate)):
            continue
        low = 0.0 if lo == 0.0 else _envelope(family, terms.theta, q, inside, upper=False)
        high = top if hi >= top else _envelope(family, terms.theta, q, inside, upper=True)
        intervals.append((family.value(low), family.value(high)))
    if family.at(0.0).lossless and not (intervals and intervals[0][0] == 0.0):
        intervals.insert(0, (0.0, 0.0))  # the free mass itself: lossless, so passive
    return PassiveSet(which, tuple(intervals))


def passive_scales(loop: WallLoop) -> PassiveSet:
    """The scales ``s`` in ``[0, 1]`` at which the wall ``(s K, s B)`` is passive: a start ramp
    from no wall to the loop's wall is passive all the way iff this is the one interval ``[0, 1]``."""
    return passive_set(loop, "scale")


def passive_limits(loop: WallLoop) -> tuple[PassiveSet, PassiveSet]:
    """(passive ``K`` at the loop's ``B``, passive ``B`` at its ``K``), from one grid evaluation."""
    terms = loop_terms(loop, theta_grid(loop, closed_loop_poles(loop)))
    return passive_set(loop, "K", terms), passive_set(loop, "B", terms)


def max_stiffness(loop: WallLoop) -> float | None:
    """Largest passive ``K`` (N/m) with the loop's ``B``, or None if no ``K >= 0`` is passive."""
    return passive_set(loop, "K").largest


def max_damping(loop: WallLoop) -> float | None:
    """Largest passive ``B`` (N s/m) with the loop's ``K``, or None if no ``B >= 0`` is passive."""
    return passive_set(loop, "B").largest
