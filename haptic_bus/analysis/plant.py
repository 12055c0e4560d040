"""The handle's plant ``m dv/dt + b v = f`` and its exact zero-order-hold solution.

Units: mass ``m`` in kg, viscous friction ``b`` in N s/m, time in s, force in N,
velocity in m/s, position in m.  Over an interval ``h`` with the force held constant the
solution is exact (no integration error), evaluated with ``expm1`` so that ``b -> 0`` and
``b h / m`` huge are both accurate to round-off.

With ``c = b h / m``:

    v(h) = a v0 + k1 f,                     a = exp(-c),  k1 = (h/m) phi1(c) = (1 - a)/b
    x(h) = x0 + h phi1(c) v0 + (h^2/m) phi2(c) f

where ``phi1(c) = (1 - e^-c)/c`` and ``phi2(c) = (c - 1 + e^-c)/c^2`` (limits 1 and 1/2).
A first-order filter on the velocity (the low-pass velocity model) adds divided differences of
``exp`` at the plant's and the filter's rates (:func:`exp_divided_difference`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_PHI2_SERIES_BELOW = 0.1
_PHI2_TERMS = 9
_DIVIDED_TERMS = 22  # (n + 1) beta^n / (n + 2)! < 1e-20 for beta < 1


def phi1(c: float) -> float:
    """``(1 - exp(-c)) / c`` (dimensionless), exact limit 1 at ``c = 0``; any real ``c`` that does not overflow."""
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


def exp_divided_difference(*nodes: float) -> float:
    """The divided difference ``exp[x0, ..., xn]`` of ``exp`` at 1 to 3 real nodes (dimensionless).

    ``exp[x] = e^x``, ``exp[x, y] = (e^x - e^y)/(x - y)``, ``exp[x, y, z] = (exp[x, y] - exp[y, z])/(x - z)``,
    with their confluent limits; ``exp[x0, .., xn] = int over the simplex of e^{sum t_i x_i}``, so
    it is positive and never cancels.  Evaluated from the largest node ``x0`` down, as
    ``e^{x0} exp[0, x1 - x0, ...]``: no overflow for nodes far below 0 and none of the
    differences of nearly equal exponentials (series where the nodes lie within 1 of each other).
    """
    top, *rest = sorted(nodes, reverse=True)
    shifted = [top - x for x in rest]  # alpha <= beta, both >= 0
    if not shifted:
        return math.exp(top)
    if len(shifted) == 1:
        return math.exp(top) * phi1(shifted[0])
    if len(shifted) != 2:
        raise ValueError(f"{len(nodes)} nodes; allowed: 1 to 3")
    alpha, beta = shifted
    if beta < 1.0:
        # sum_n h_n(-alpha, -beta) / (n + 2)!, h_n the complete homogeneous polynomial of degree n
        total, h, y_power, factorial = 0.5, 1.0, 1.0, 2.0
        for n in range(1, _DIVIDED_TERMS):
            y_power *= -alpha
            h = -beta * h + y_power
            factorial *= n + 2
            total += h / factorial
        return math.exp(top) * total
    return math.exp(top) * (phi1(alpha) - math.exp(-alpha) * phi1(beta - alpha)) / beta


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


def stop_time(m: float, b: float, speed: float, deceleration: float) -> float:
    """Seconds until a handle moving at ``speed`` m/s (> 0) stops under a held net braking force ``deceleration`` N (> 0).

    ``m du/dt = -b u - g`` gives ``t* = (m/b) log1p(b u/g) = (m u/g) log1p(y)/y``, ``y = b u/g`` (exact as ``b -> 0``).
    """
    y = b * speed / deceleration
    return m * speed / deceleration * (math.log1p(y) / y if y else 1.0)


class ExactPlant:
    """The handle's state (velocity m/s, position m) advanced exactly under held forces."""

    __slots__ = ("_co", "b", "m", "position", "step", "velocity")

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
