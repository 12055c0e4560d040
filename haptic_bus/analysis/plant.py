"""The handle's plant ``m dv/dt + b v = f`` and its exact zero-order-hold solution.

Units: mass ``m`` in kg, viscous friction ``b`` in N s/m, time in s, force in N,
velocity in m/s, position in m.  Over an interval ``h`` with the force held constant the
solution is exact (no integration error), evaluated with ``expm1`` so that ``b -> 0`` and
``b h / m`` huge are both accurate to round-off.

With ``c = b h / m``:

    v(h) = a v0 + k1 f,                     a = exp(-c),  k1 = (h/m) phi1(c) = (1 - a)/b
    x(h) = x0 + h phi1(c) v0 + (h^2/m) phi2(c) f

where ``phi1(c) = (1 - e^-c)/c`` and ``phi2(c) = (c - 1 + e^-c)/c^2`` (limits 1 and 1/2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

_PHI2_SERIES_BELOW = 0.1
_PHI2_TERMS = 9


def phi1(c: float) -> float:
    """``(1 - exp(-c)) / c`` for ``c >= 0`` (dimensionless), exact limit 1 at ``c = 0``."""
    if c == 0.0:
        return 1.0
    return -math.expm1(-c) / c


def phi2(c: float) -> float:
    """``(c - 1 + exp(-c)) / c^2`` for ``c >= 0`` (dimensionless), exact limit 1/2 at 0."""
    if c < _PHI2_SERIES_BELOW:
        # sum_{n>=0} (-c)^n / (n + 2)!, alternating, truncation error < c^9 / 11!
        term, total = 0.5, 0.5
        for n in range(1, _PHI2_TERMS):
            term *= -c / (n + 2)
            total += term
        return total
    return (c + math.expm1(-c)) / (c * c)


def phi1_array(c: ArrayLike) -> np.ndarray:
    """Vectorised :func:`phi1` over an array of ``c >= 0``."""
    c = np.asarray(c, dtype=float)
    safe = np.where(c == 0.0, 1.0, c)
    return np.where(c == 0.0, 1.0, -np.expm1(-safe) / safe)


def phi2_array(c: ArrayLike) -> np.ndarray:
    """Vectorised :func:`phi2` over an array of ``c >= 0`` (same series below 0.1)."""
    c = np.asarray(c, dtype=float)
    small = c < _PHI2_SERIES_BELOW
    term = np.full_like(c, 0.5)
    series = term.copy()
    for n in range(1, _PHI2_TERMS):
        term = term * (-c) / (n + 2)
        series += term
    safe = np.where(small, 1.0, c)
    return np.where(small, series, (safe + np.expm1(-safe)) / (safe * safe))


@dataclass(frozen=True)
class ZohCoefficients:
    """Exact ZOH step of the plant over ``h`` seconds.

    ``a`` (dimensionless) and ``k1`` (m/(N s)) give ``v+ = a v + k1 f``; ``p_v`` (s) and
    ``p_f`` (s^2/kg) give ``x+ = x + p_v v + p_f f``.
    """

    a: float
    k1: float
    p_v: float
    p_f: float


def zoh_coefficients(m: float, b: float, h: float) -> ZohCoefficients:
    """Exact ZOH coefficients of ``1/(m s + b)`` over ``h`` s (m in kg, b in N s/m)."""
    c = b * h / m
    return ZohCoefficients(
        a=math.exp(-c),
        k1=h / m * phi1(c),
        p_v=h * phi1(c),
        p_f=h * h / m * phi2(c),
    )


class ExactPlant:
    """The handle's state (velocity m/s, position m) advanced exactly under held forces."""

    __slots__ = ("m", "b", "step", "velocity", "position", "_co")

    def __init__(self, m: float, b: float, step: float, velocity: float = 0.0, position: float = 0.0) -> None:
        self.m = m
        self.b = b
        self.step = step
        self.velocity = velocity
        self.position = position
        self._co = zoh_coefficients(m, b, step)

    def advance(self, force: float) -> float:
        """Advance one ``step`` with ``force`` (N) held; return the displacement (m).

        The work ``force * displacement`` (J) done on the handle over the step is exact.
        """
        co = self._co
        v0 = self.velocity
        displacement = co.p_v * v0 + co.p_f * force
        self.velocity = co.a * v0 + co.k1 * force
        self.position += displacement
        return displacement
