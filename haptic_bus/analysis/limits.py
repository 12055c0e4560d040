"""The largest passive wall: ``K`` for a given ``B``, and ``B`` for a given ``K``.

Eq. (23)'s flip boundary ``P(-1) = 0`` bounds every passive wall from above for ``d = 0``
(beyond it a closed-loop pole leaves the unit circle through ``z = -1``); for ``d >= 1`` it is
used as the upper end of the search, an assumption (no passive wall beyond the ``d = 0`` flip
value, and the passive set starting at 0) that grid maps agree with but that is not proven:

    K_flip = 2 (b / tanh(c/2) - B) / T,     B_flip = b / tanh(c/2) - K T / 2,     c = bT/m.

Where the exact criterion confirms it (it does for ``d = 0`` and ``c`` up to about 3, i.e.
every realistic handle), the flip value *is* the limit, exact to round-off.  Otherwise (delay,
or a plant that settles within a sample) the limit is the root of the exact criterion's
margin (N s/m) in the parameter, found with Brent's method to a relative tolerance of
:data:`RELATIVE_TOLERANCE`.  Both return None when no non-negative value is passive.
"""

from __future__ import annotations

import math
from typing import Callable

from scipy.optimize import brentq

from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE, WallLoop

RELATIVE_TOLERANCE = 1e-9
_CONFIRM = 1e-12  # relative step either side of the flip value that confirms it as the limit
_DAMPING_PROBES = (0.0, 0.5, 0.25, 0.125, 0.75, 1 / 16, 1 / 64, 1 / 256)


def flip_damping_budget(loop: WallLoop) -> float:
    """``b / tanh(c/2)`` in N s/m: the ``KT/2 + B`` eq. (23) allows (``2m/T`` as b -> 0).

    Formed as ``(2m/T) x / tanh(x)`` with ``x = c/2``, so a tiny or subnormal ``b`` (where
    ``tanh(x)`` rounds to 0) gives the limit instead of a division by zero.
    """
    x = 0.5 * loop.c
    ratio = 1.0 if x < 1e-8 else x / math.tanh(x)  # x/tanh(x) = 1 + x^2/3 + ...
    return 2.0 * loop.m / loop.T * ratio


def max_stiffness(loop: WallLoop) -> float | None:
    """Largest passive ``K`` (N/m) with the loop's ``B``, or None if even ``K = 0`` is not passive."""
    flip = 2.0 * (flip_damping_budget(loop) - loop.B) / loop.T
    return _largest_passive(lambda k: loop.with_wall(k, loop.B), STIFFNESS_RANGE[1], flip, 0.0)


def max_damping(loop: WallLoop) -> float | None:
    """Largest passive ``B`` (N s/m) with the loop's ``K``, or None if no ``B >= 0`` is passive.

    With a loop delay, too little ``B`` can be active as well; the search starts from the
    smallest passive ``B`` among a few probes below the flip value.
    """
    flip = flip_damping_budget(loop) - 0.5 * loop.K * loop.T
    if flip < 0:
        return None
    make = lambda b: loop.with_wall(loop.K, b)  # noqa: E731
    for fraction in _DAMPING_PROBES:
        if _margin(make(fraction * flip)) >= 0:
            return _largest_passive(make, DAMPING_RANGE[1], flip, fraction * flip)
    return None


def _margin(candidate: WallLoop) -> float:
    return exact_verdict(candidate).margin


def _largest_passive(
    make: Callable[[float], WallLoop], ceiling: float, flip: float, passive_at: float
) -> float | None:
    """The root of the margin along ``make(x)`` above ``passive_at``, or the confirmed flip value."""
    if flip < passive_at or _margin(make(passive_at)) < 0:
        return None
    flip = min(flip, ceiling)
    if _margin(make(flip * (1 - _CONFIRM))) >= 0:
        return flip  # the flip boundary itself is the limit
    return brentq(lambda x: _margin(make(x)), passive_at, flip, rtol=RELATIVE_TOLERANCE, xtol=1e-300)
