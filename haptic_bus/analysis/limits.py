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

One evaluation of the wall-independent terms on the grid serves ``K`` and ``B`` alike, and the
ends of every interval of both are refined by one joint zoom (:func:`_envelopes`): each zoom
round evaluates the wall-independent terms once, on the points of every end together, so a
check's ``K`` and ``B`` cost the terms' evaluations of one boundary, not of each.
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
_LANE = 4.0  # rad: the joint zoom keeps end k's theta in [k LANE, k LANE + pi] (LANE > pi, a power of 2)
_ZOOM_COUNT = 3  # minima refined per end, as the criterion's zoom does
_NOT_A_MINIMUM, _AN_END = 1e9, 2e9  # zoom selection keys of the points that are not minima, and of the grid's ends

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


@dataclass(frozen=True)
class _End:
    """One end to refine: of ``family``'s interval around ``inside``, its upper end (``upper``) or its lower."""

    family: _Family
    inside: float
    upper: bool

    def branch(self, q: np.ndarray) -> np.ndarray:
        """Per column of ``q``: the first root above ``inside`` (upper), or minus the last below (lower),
        capped at :data:`_NO_ROOT`; the end is the minimum over ``theta`` (of minus it, for a lower)."""
        r1, r2 = _roots(q)
        inside = self.inside
        if self.upper:
            near = np.where(r1 > inside, r1, np.where(r2 > inside, r2, np.inf))
        else:
            near = -np.where(r2 < inside, r2, np.where(r1 < inside, r1, -np.inf))
        return np.fmin(near, _NO_ROOT)


def _selection_keys(values: np.ndarray) -> np.ndarray:
    """Keys with the same interior minima as ``values``, each keyed by its rank among them (0 the
    lowest); every other point above them all and the two ends above everything, never minima."""
    keys = np.full(values.shape, _NOT_A_MINIMUM)
    interior = np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:])) + 1
    keys[interior[np.argsort(values[interior], kind="stable")]] = np.arange(interior.size)
    keys[[0, -1]] = _AN_END
    return keys


def _envelopes(loop: WallLoop, terms: LoopTerms, quadratics: dict[str, np.ndarray], ends: list[_End]) -> list[float]:
    """Every end of ``ends`` (scaled ``x``): ``min_theta`` of its root branch on the grid, refined by one
    joint zoom of :func:`~haptic_bus.analysis.theta_search.refine_minima`.

    End ``k``'s grid is laid in the lane ``theta + k LANE``; its :func:`_selection_keys` make the zoom
    refine the :data:`_ZOOM_COUNT` lowest minima of every end (as separate zooms would), and each
    round's points of all ends are evaluated by one :func:`loop_terms` call.
    """
    if not ends:
        return []
    grid = terms.theta
    values = [end.branch(quadratics[end.family.which]) for end in ends]
    lanes = _LANE * np.arange(len(ends))
    families = {end.family.which: end.family for end in ends}
    lanes_of = {which: [k for k, end in enumerate(ends) if end.family.which == which] for which in families}

    def objective(points: np.ndarray) -> np.ndarray:
        lane = np.floor(points / _LANE).astype(int)
        at = loop_terms(loop, points - _LANE * lane)
        out = np.empty(points.shape)
        for which, family in families.items():  # each family's quadratic on its own ends' points only
            mine = np.isin(lane, lanes_of[which])
            q, own = family.quadratic(at.take(mine))[0], lane[mine]
            part = np.empty(own.shape)
            for k in lanes_of[which]:
                here = own == k
                part[here] = ends[k].branch(q[:, here])
            out[mine] = part
        return out

    stacked = np.concatenate([grid + lane for lane in lanes])
    keys = np.concatenate([_selection_keys(v) for v in values])
    thetas, refined = refine_minima(objective, stacked, keys, count=_ZOOM_COUNT * len(ends))
    lane_of = np.floor(thetas / _LANE)
    out = []
    for k, end in enumerate(ends):
        best = float(np.min(np.concatenate([values[k], refined[lane_of == k]])))
        out.append(best if end.upper else -best)
    return out


def _scale_grid(loop: WallLoop) -> np.ndarray:
    """The search grid for the scaled walls: the union of the grids of five walls along the way,
    so every lightly damped pole the ramp passes near has its fan of points."""
    grids = [theta_grid(scaled, closed_loop_poles(scaled))
             for scaled in (loop.with_wall(s * loop.K, s * loop.B) for s in (0.0, 0.25, 0.5, 0.75, 1.0))]
    return np.unique(np.concatenate(grids))


def passive_sets(loop: WallLoop, which: tuple[str, ...], terms: LoopTerms | None = None) -> tuple[PassiveSet, ...]:
    """:func:`passive_set` of each family in ``which``, from one grid evaluation and one joint zoom."""
    for name in which:
        if name not in FAMILIES:
            raise ParameterError("which", name, " or ".join(repr(f) for f in FAMILIES), "passive set")
    if terms is None:
        grid = _scale_grid(loop) if "scale" in which else theta_grid(loop, closed_loop_poles(loop))
        terms = loop_terms(loop, grid)
    quadratics: dict[str, np.ndarray] = {}
    ends: list[_End] = []
    plans: list[tuple[_Family, list[tuple[float | int, float | int]]]] = []  # per family: (low, high) or end indices
    for name in which:
        family = _Family(loop, name)
        top = family.ceiling * family.unit
        q, tolerant = family.quadratic(terms)
        quadratics[name] = q
        plan: list[tuple[float | int, float | int]] = []
        for lo, hi in _allowed(_forbidden(tolerant, top), top):
            inside = 0.5 * (lo + hi) if hi > lo else lo
            candidate = family.at(inside)
            if not (candidate.lossless or is_stable(candidate)):
                continue
            low: float | int = 0.0 if lo == 0.0 else len(ends)  # an int: the index of an end to refine
            if isinstance(low, int):
                ends.append(_End(family, inside, upper=False))
            high: float | int = float(top) if hi >= top else len(ends)
            if isinstance(high, int):
                ends.append(_End(family, inside, upper=True))
            plan.append((low, high))
        plans.append((family, plan))
    refined = _envelopes(loop, terms, quadratics, ends)
    out = []
    for family, plan in plans:
        intervals = [(family.value(refined[lo] if isinstance(lo, int) else lo),
                      family.value(refined[hi] if isinstance(hi, int) else hi)) for lo, hi in plan]
        if family.at(0.0).lossless and not (intervals and intervals[0][0] == 0.0):
            intervals.insert(0, (0.0, 0.0))  # the free mass itself: lossless, so passive
        out.append(PassiveSet(family.which, tuple(intervals)))
    return tuple(out)


def passive_set(loop: WallLoop, which: str, terms: LoopTerms | None = None) -> PassiveSet:
    """The passive ``K`` (``which = "K"``, at the loop's ``B``), ``B`` (at its ``K``) or scales
    ``s`` of the whole wall (``which = "scale"``: ``(s K, s B)``, ``s`` in ``[0, 1]``): closed intervals.

    ``terms``: the wall-independent terms on the search grid, if already evaluated.
    """
    return passive_sets(loop, (which,), terms)[0]


def passive_scales(loop: WallLoop) -> PassiveSet:
    """The scales ``s`` in ``[0, 1]`` at which the wall ``(s K, s B)`` is passive: a start ramp
    from no wall to the loop's wall is passive all the way iff this is the one interval ``[0, 1]``."""
    return passive_set(loop, "scale")


def passive_limits(loop: WallLoop) -> tuple[PassiveSet, PassiveSet]:
    """(passive ``K`` at the loop's ``B``, passive ``B`` at its ``K``), from one grid evaluation."""
    stiffness, damping = passive_sets(loop, ("K", "B"))
    return stiffness, damping


def max_stiffness(loop: WallLoop) -> float | None:
    """Largest passive ``K`` (N/m) with the loop's ``B``, or None if no ``K >= 0`` is passive."""
    return passive_set(loop, "K").largest


def max_damping(loop: WallLoop) -> float | None:
    """Largest passive ``B`` (N s/m) with the loop's ``K``, or None if no ``B >= 0`` is passive."""
    return passive_set(loop, "B").largest
