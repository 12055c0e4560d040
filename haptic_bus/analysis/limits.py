"""The passive walls: every passive ``K`` at the loop's ``B``, every passive ``B`` at its ``K``.

The passive values of one wall parameter, the other fixed, form a set of intervals that need not
start at 0 (with a delay, too little damping is active as well as too much): :class:`PassiveSet`
carries them with their ends **open or closed** as they are, ``lowest`` and ``largest`` its ends
(None: nothing passive), and whether the last end is only the input ceiling.

**Per-theta quadratic** (DESIGN 3.5, issue 14).  At a fixed ``theta`` the impedance is a
linear-fractional function of ``K`` (and of ``B``), so ``|U|^2 Re Z`` is a real quadratic
``Q_theta(x)`` in the scaled parameter ``x`` (``kappa = K T^2/m`` or ``q = B T/m``;
:func:`~haptic_bus.analysis.frequency.impedance_quadratic`).  At each grid ``theta`` the values
with ``Q_theta(x) < 0`` (beyond the sign tolerance) are forbidden: at most two intervals, read off
the roots.  Their union over the grid leaves candidate intervals.

**Where the stability changes.**  A pole crossing the unit circle at ``theta*`` makes
``Z(theta*) = 0``, so generically it is a root of ``Q_theta*`` and an end of a candidate.  Not at
``theta = pi`` without friction: there ``Re Z(pi) = b = 0`` for *every* wall (point velocity,
whole delay), ``Q_pi`` vanishes identically, and the flip -- a pole through ``z = -1`` -- is no
root of anything.  So the value where a pole sits at ``z = -1`` is solved for directly (the
characteristic function is affine in each wall parameter:
:func:`~haptic_bus.analysis.characteristic.flip_value`) and splits the candidates.  Stability is
then constant inside each candidate: one pole test at an interior point keeps or drops it.

**The ends.**  ``0`` (closed if the loop without that parameter is stable, or the free mass),
the input ceiling (closed; the largest passive value is then *at least* the ceiling), the flip
(open: a pole on the circle), or an envelope: an upper end ``e`` of the interval around ``s``
is ``min_theta r+(theta)`` of the first root above ``s``, a lower end ``max_theta r-(theta)`` of
the last root below it, located by the joint zoom of
:func:`~haptic_bus.analysis.theta_search.refine_lanes` (one evaluation of the loop's terms per
round for every end of ``K`` and ``B`` together; a smooth envelope minimum is exact to
round-off in ``x``), never beyond the candidate's own end.  An envelope end is open when
``Z = 0`` there (``|Z| < 1e-6 |c + j theta|``: a pole on the circle, the stability boundary),
closed when only ``Re Z = 0`` (a tangency: the wall there is passive with margin 0).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.characteristic import characteristic, flip_value
from haptic_bus.analysis.criterion import SIGN_TOLERANCE
from haptic_bus.analysis.frequency import (
    LoopTerms,
    grid_terms,
    impedance_quadratic,
    loop_terms,
    quadratic_coefficients,
    scaled_impedance,
)
from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE, WallLoop
from haptic_bus.analysis.poles import closed_loop_poles, stable_all
from haptic_bus.analysis.theta_complex import ThetaComplex
from haptic_bus.analysis.theta_search import Group, Lane, LaneMinimum, refine_lanes, sorted_unique, theta_grid
from haptic_bus.errors import ParameterError

_NO_ROOT = 1e300  # stands in for "no root on that side" (finite, so the zoom's differences stay finite)
_ZOOM_COUNT = 3  # minima refined per end, as the criterion's zoom does
_SAME = 1e-12  # relative: a candidate's end this close to the flip is the flip
_POLE_ON_CIRCLE = 1e-6  # |Z T/m| / |c + j theta| at an envelope end below which a pole sits on the circle there

RELATIVE_TOLERANCE = 1e-12
"""Relative accuracy of every limit: an envelope minimum located by the zoom, in double precision."""


@dataclass(frozen=True)
class PassiveSet:
    """The passive values of ``parameter`` ("K" in N/m, "B" in N s/m, or the "scale" of the wall).

    ``intervals``: disjoint intervals ``(low, high)``, ascending (``low == high``: that one value);
    ``closed``: for each, whether ``(low, high)`` belong to it (a missing tuple: both do);
    ``ceiling``: the input ceiling when the last interval reaches it (the largest passive value is
    then at least that, not that).  Empty ``intervals``: nothing is passive.
    """

    parameter: str
    intervals: tuple[tuple[float, float], ...]
    closed: tuple[tuple[bool, bool], ...] = ()
    ceiling: float | None = None

    @property
    def lowest(self) -> float | None:
        """The least passive value (the infimum, if its end is open), None if none is passive."""
        return self.intervals[0][0] if self.intervals else None

    @property
    def largest(self) -> float | None:
        """The largest passive value (the supremum, if its end is open; at least it, if ``capped``), None if none."""
        return self.intervals[-1][1] if self.intervals else None

    @property
    def capped(self) -> bool:
        """The last interval reaches the input ceiling: the largest passive value is at least :attr:`largest`."""
        return self.ceiling is not None

    def ends(self) -> tuple[tuple[bool, bool], ...]:
        """``(low included, high included)`` of every interval."""
        return self.closed or tuple((True, True) for _ in self.intervals)

    def contains(self, value: float) -> bool:
        """Whether ``value`` is in the set, open ends respected."""
        for (low, high), (low_in, high_in) in zip(self.intervals, self.ends()):
            if (low < value or (low_in and value == low)) and (value < high or (high_in and value == high)):
                return True
        return False

    def describe(self, unit: str, digits: int = 9) -> str:
        """``[0, 999.95) N s/m``, ``only 0 N/m``, ``none``, ``..., largest at least 1e+15 (the input ceiling)``:
        ``[`` ``]`` a closed end, ``(`` ``)`` an open one, ``{x}`` one value; ``digits`` significant digits."""
        if not self.intervals:
            return "none"
        if self.intervals == ((0.0, 0.0),):
            return f"only 0 {unit}".rstrip()
        parts = []
        for (low, high), (low_in, high_in) in zip(self.intervals, self.ends()):
            if low == high:
                parts.append(f"{{{low:.{digits}g}}}")
            else:
                parts.append(f"{'[' if low_in else '('}{low:.{digits}g}, {high:.{digits}g}{']' if high_in else ')'}")
        text = (" and ".join(parts) + f" {unit}").rstrip()
        if self.ceiling is not None:
            text += f", largest at least {self.ceiling:g} (the input ceiling)"
        return text

    def at_most(self, ceiling: float) -> PassiveSet:
        """The values of this set no larger than ``ceiling`` (a closed end there; ``inf``: the set itself)."""
        if math.isinf(ceiling):
            return self
        intervals, closed = [], []
        for (low, high), (low_in, high_in) in zip(self.intervals, self.ends()):
            if low > ceiling or (low == ceiling and not low_in):
                break
            cut = high >= ceiling
            intervals.append((low, ceiling if cut else high))
            closed.append((low_in, True if cut else high_in))
            if cut:
                break
        whole = bool(self.intervals) and len(intervals) == len(self.intervals) and self.intervals[-1][1] < ceiling
        kept_ceiling = self.ceiling if whole else None  # an empty set (no passive value at all) stays empty
        return PassiveSet(self.parameter, tuple(intervals), tuple(closed), kept_ceiling)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: ``lowest``, ``largest``, the ``intervals`` as ``[low, high]`` pairs, ``closed`` as
        ``[low included, high included]`` pairs, and ``largest_at_least`` (the largest is only the ceiling)."""
        return {"lowest": self.lowest, "largest": self.largest, "intervals": [list(i) for i in self.intervals],
                "closed": [list(c) for c in self.ends()], "largest_at_least": self.capped}


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
        self.top = self.ceiling * self.unit

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

    def probe(self, lo: float, hi: float) -> WallLoop:
        """A loop inside the candidate ``(lo, hi)`` (scaled): the loop itself if its own value is
        inside (its poles are already known), else the midpoint."""
        own = {"K": self.loop.kappa, "B": self.loop.q}.get(self.which, 1.0)
        return self.loop if lo < own < hi else self.at(0.5 * (lo + hi))

    def walls(self, x: float) -> tuple[float, float]:
        """The scaled wall ``(kappa, q)`` at scaled ``x`` (unclipped)."""
        loop = self.loop
        if self.which == "K":
            return x, loop.q
        if self.which == "B":
            return loop.kappa, x
        return x * loop.kappa, x * loop.q

    def quadratic(self, terms: LoopTerms) -> tuple[np.ndarray, np.ndarray]:
        """Coefficients ``(3, n)`` of ``Q_theta(x)``, and the same with the sign tolerance added.

        The tolerant one (passive iff ``>= 0``, as the verdict judges) decides which intervals
        there are; the exact one's roots are their ends.
        """
        coefficients, magnitudes = impedance_quadratic(terms, *self.lines(terms))
        return coefficients, coefficients + SIGN_TOLERANCE * magnitudes

    @functools.cached_property
    def flip(self) -> float | None:
        """The ``x`` in ``(0, top)`` where a closed-loop pole sits at ``z = -1`` (None if there is none)."""
        loop = self.loop
        kappa, q = loop.kappa, loop.q
        if self.which == "K":  # W = x (1 + w) + q w; x > 0 brings the integrator
            base, slope, integrator = np.array([q, 0.0]), np.array([1.0, 1.0]), True
        elif self.which == "B" and loop.K > 0:  # W = kappa (1 + w) + x w
            base, slope, integrator = np.array([kappa, kappa]), np.array([1.0, 0.0]), True
        elif self.which == "B":  # W = x
            base, slope, integrator = np.array([0.0]), np.array([1.0]), False
        elif loop.K > 0:  # W = s (kappa (1 + w) + q w)
            base, slope, integrator = np.zeros(2), np.array([kappa + q, kappa]), True
        else:
            base, slope, integrator = np.zeros(1), np.array([q]), False
        x = flip_value(characteristic(loop), base, slope, integrator)
        return x if x is not None and 0.0 < x < self.top else None


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
    """Open intervals of ``[0, top]`` where some column's quadratic is negative, merged and ascending."""
    r1, r2 = _roots(q)
    a, b, c = q
    none = np.isnan(r1)
    linear = (a == 0) & ~none
    up = (a > 0) & ~none & ~linear
    down = (a < 0) & ~none & ~linear
    inf = np.full(a.shape, math.inf)
    pieces = [
        (-inf[none & (c < 0)], inf[none & (c < 0)]),  # no real root and negative at 0: negative everywhere
        (r1[up], r2[up]),  # between the roots of an upward parabola
        (-inf[down], r1[down]), (r2[down], inf[down]),  # outside those of a downward one
        (-inf[linear & (b > 0)], r1[linear & (b > 0)]), (r1[linear & (b < 0)], inf[linear & (b < 0)]),
        (-inf[linear & (b == 0) & (c < 0)], inf[linear & (b == 0) & (c < 0)]),
    ]
    lo = np.concatenate([p[0] for p in pieces])
    hi = np.concatenate([p[1] for p in pieces])
    keep = (lo < hi) & (hi > 0) & (lo < top)
    lo, hi = np.maximum(lo[keep], -1.0), np.minimum(hi[keep], 2.0 * top)
    if lo.size == 0:
        return []
    order = np.argsort(lo, kind="stable")
    lo, hi = lo[order], hi[order]
    reach = np.maximum.accumulate(hi)
    starts = np.concatenate([[True], lo[1:] > reach[:-1]])  # a new merged interval where nothing before reaches
    first = np.flatnonzero(starts)
    last = np.concatenate([first[1:] - 1, [lo.size - 1]])
    return [(float(lo[i]), float(reach[j])) for i, j in zip(first, last)]


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


def _split(pieces: list[tuple[float, float]], flip: float | None) -> list[tuple[float, float]]:
    """``pieces`` cut at the flip (an end within :data:`_SAME` of it is moved onto it)."""
    if flip is None:
        return pieces
    out = []
    for lo, hi in pieces:
        lo = flip if abs(lo - flip) <= _SAME * flip else lo
        hi = flip if abs(hi - flip) <= _SAME * flip else hi
        out += [(lo, flip), (flip, hi)] if lo < flip < hi else [(lo, hi)]
    return out


@dataclass(frozen=True)
class _End:
    """One end to refine: of ``family``'s candidate ``(low, high)`` around ``inside``, its upper end
    (``upper``) or its lower; the envelope never passes the candidate's own end."""

    family: _Family
    inside: float
    upper: bool
    low: float
    high: float

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

    def clamp(self, value: float) -> float:
        """The refined end (scaled ``x``), kept within the candidate."""
        return min(value, self.high) if self.upper else max(-value, self.low)


End = float | int | str  # a plan's end: a fixed value, the index of an end to refine, or "flip" (open)


class LimitsPlan:
    """The passive sets of ``which`` families of ``loop`` up to the refinement of their ends.

    ``lanes`` and ``groups`` go to :func:`~haptic_bus.analysis.theta_search.refine_lanes` (with
    other lanes, if the caller zooms more); :meth:`finish` turns their minima (in ``lanes``' order)
    into the :class:`PassiveSet` s.
    """

    def __init__(self, loop: WallLoop, which: tuple[str, ...], terms: LoopTerms) -> None:
        for name in which:
            if name not in FAMILIES:
                raise ParameterError("which", name, " or ".join(repr(f) for f in FAMILIES), "passive set")
        self.loop = loop
        self.ends: list[_End] = []
        self.plans: list[tuple[_Family, list[tuple[End, End]], bool]] = []
        self.groups: dict[str, Group] = {}
        lanes: list[Lane] = []
        drafts = []
        for name in which:
            family = _Family(loop, name)
            q, tolerant = family.quadratic(terms)
            pieces = [(lo, hi) for lo, hi in _split(_allowed(_forbidden(tolerant, family.top), family.top), family.flip)]
            drafts.append((family, q, pieces))
        # one batch of pole tests: each family's start (x = 0) and one interior point of every candidate
        probes = [family.at(0.0) for family, _, _ in drafts]
        probes += [family.probe(lo, hi) for family, _, pieces in drafts for lo, hi in pieces if lo < hi]
        verdicts = iter(stable_all(probes))
        starts = [next(verdicts) for _ in drafts]
        for (family, q, pieces), start_stable in zip(drafts, starts):
            start = family.at(0.0)
            start_ok = bool(pieces and pieces[0][0] == 0.0 and (start.lossless or start_stable))
            plan: list[tuple[End, End]] = []
            for lo, hi in pieces:
                if lo == hi or not next(verdicts):
                    continue
                low: End = "flip" if lo == family.flip else 0.0 if lo == 0.0 else len(self.ends)
                if isinstance(low, int):
                    self.ends.append(_End(family, 0.5 * (lo + hi), False, lo, hi))
                high: End = "flip" if hi == family.flip else float(family.top) if hi >= family.top else len(self.ends)
                if isinstance(high, int):
                    self.ends.append(_End(family, 0.5 * (lo + hi), True, lo, hi))
                plan.append((low, high))
            self.plans.append((family, plan, start_ok))
            self.groups[family.which] = Group(_quadratic_of(family))
            lanes += [Lane(end.branch(q), family.which, end.branch) for end in self.ends[len(lanes):]]
        self.lanes = lanes

    def finish(self, minima: list[LaneMinimum]) -> tuple[PassiveSet, ...]:
        """The passive sets, from the zoomed minima of :attr:`lanes` (same order)."""
        values = [end.clamp(m.value) for end, m in zip(self.ends, minima)]
        open_end = self._poles_on_circle(values, [m.theta for m in minima])
        out = []
        for family, plan, start_ok in self.plans:
            intervals: list[tuple[float, float]] = []
            closed: list[tuple[bool, bool]] = []
            ceiling = None
            for low, high in plan:
                lo, lo_in = self._end(family, low, values, open_end, start_ok)
                hi, hi_in = self._end(family, high, values, open_end, start_ok)
                if lo > hi or (lo == hi and not (lo_in and hi_in)):
                    continue
                intervals.append((lo, hi))
                closed.append((lo_in, hi_in))
                if high == float(family.top) and family.which != "scale":  # s = 1 is the wall itself, no cap
                    ceiling = family.ceiling
            if start_ok and not (intervals and intervals[0][0] == 0.0 and closed[0][0]):
                intervals.insert(0, (0.0, 0.0))  # the wall without this parameter alone (e.g. the free mass)
                closed.insert(0, (True, True))
            out.append(PassiveSet(family.which, tuple(intervals), tuple(closed), ceiling))
        return tuple(out)

    def _end(self, family: _Family, end: End, values: list[float], open_end: list[bool], start_ok: bool
             ) -> tuple[float, bool]:
        """(physical value, included) of one end of a plan."""
        if end == "flip":
            assert family.flip is not None
            return family.value(family.flip), False
        if isinstance(end, int):
            return family.value(values[end]), not open_end[end]
        assert isinstance(end, float)
        return family.value(end), start_ok if end == 0.0 else True

    def _poles_on_circle(self, values: list[float], thetas: list[float]) -> list[bool]:
        """For each refined end: ``Z = 0`` there (a pole on the circle: the end is open)."""
        if not values:
            return []
        terms = loop_terms(self.loop, np.array(thetas))
        walls = np.array([end.family.walls(x) for end, x in zip(self.ends, values)])
        z = scaled_impedance(terms, walls[:, 0], walls[:, 1])  # one wall per end, element-wise
        return [bool(v) for v in np.hypot(z.re, z.im) < _POLE_ON_CIRCLE * np.hypot(terms.c, terms.theta)]


def _quadratic_of(family: _Family) -> Callable[[LoopTerms], np.ndarray]:
    def evaluate(terms: LoopTerms) -> np.ndarray:
        return quadratic_coefficients(terms, *family.lines(terms))

    return evaluate


def _scale_grid(loop: WallLoop) -> np.ndarray:
    """The search grid for the scaled walls: the union of the grids of five walls along the way,
    so every lightly damped pole the ramp passes near has its fan of points."""
    grids = [theta_grid(scaled, closed_loop_poles(scaled))
             for scaled in (loop.with_wall(s * loop.K, s * loop.B) for s in (0.0, 0.25, 0.5, 0.75, 1.0))]
    return sorted_unique(np.concatenate(grids))


def passive_sets(loop: WallLoop, which: tuple[str, ...], terms: LoopTerms | None = None) -> tuple[PassiveSet, ...]:
    """:func:`passive_set` of each family in ``which``, from one grid evaluation and one joint zoom."""
    if terms is None:
        terms = loop_terms(loop, _scale_grid(loop)) if "scale" in which else grid_terms(loop, closed_loop_poles(loop))
    plan = LimitsPlan(loop, which, terms)
    minima = refine_lanes(terms.theta, plan.lanes, plan.groups, lambda theta: loop_terms(loop, theta),
                          count=_ZOOM_COUNT)
    return plan.finish(minima)


def passive_set(loop: WallLoop, which: str, terms: LoopTerms | None = None) -> PassiveSet:
    """The passive ``K`` (``which = "K"``, at the loop's ``B``), ``B`` (at its ``K``) or scales
    ``s`` of the whole wall (``which = "scale"``: ``(s K, s B)``, ``s`` in ``[0, 1]``).

    ``terms``: the wall-independent terms on the search grid, if already evaluated.
    """
    return passive_sets(loop, (which,), terms)[0]


def passive_scales(loop: WallLoop) -> PassiveSet:
    """The scales ``s`` in ``[0, 1]`` at which the wall ``(s K, s B)`` is passive: a start ramp
    from no wall to the loop's wall is passive all the way iff this is the one closed interval ``[0, 1]``."""
    return passive_set(loop, "scale")


def passive_limits(loop: WallLoop) -> tuple[PassiveSet, PassiveSet]:
    """(passive ``K`` at the loop's ``B``, passive ``B`` at its ``K``), from one grid evaluation."""
    stiffness, damping = passive_sets(loop, ("K", "B"))
    return stiffness, damping


def max_stiffness(loop: WallLoop) -> float | None:
    """Largest passive ``K`` (N/m) with the loop's ``B`` (the supremum), or None if no ``K >= 0`` is passive."""
    return passive_set(loop, "K").largest


def max_damping(loop: WallLoop) -> float | None:
    """Largest passive ``B`` (N s/m) with the loop's ``K`` (the supremum), or None if no ``B >= 0`` is passive."""
    return passive_set(loop, "B").largest
