"""Closed-loop characteristic polynomial of the wall loop, its poles and its stability.

With ``a = exp(-bT/m)`` and ``k1 = (T/m) phi1(bT/m)`` the loop ``K_d(z) z^-d`` closed around
``G22d(z) = -k1/(z - a)`` has the characteristic polynomial

    (z - a)(z - 1) z^d + k1 (K T z + B (z - 1))          (K > 0)
    (z - a) z^d + k1 B                                    (K = 0: no wall integrator)

The seed's design gives poles 0.998 and 0.8014.
"""

from __future__ import annotations

import math

import numpy as np

from haptic_bus.loop import WallLoop
from haptic_bus.plant import phi1


def characteristic_polynomial(loop: WallLoop) -> np.ndarray:
    """Coefficients (highest power first, dimensionless) of the closed-loop polynomial in z."""
    c = loop.c
    decay = -math.expm1(-c)  # 1 - a, exact for tiny c
    a = 1.0 - decay
    k1_scaled = phi1(c)  # k1 m / T
    stiffness = k1_scaled * loop.K * loop.T * loop.T / loop.m  # k1 K T
    damping = k1_scaled * loop.B * loop.T / loop.m  # k1 B
    d = loop.delay
    if loop.K > 0:
        poly = np.zeros(d + 3)
        poly[0], poly[1], poly[2] = 1.0, -(2.0 - decay), a
        poly[-2] += stiffness + damping
        poly[-1] -= damping
    else:
        poly = np.zeros(d + 2)
        poly[0], poly[1] = 1.0, -a
        poly[-1] += damping
    return poly


def closed_loop_poles(loop: WallLoop) -> np.ndarray:
    """The closed-loop poles in the z-plane (complex, sorted by decreasing magnitude)."""
    roots = np.roots(characteristic_polynomial(loop))
    return roots[np.argsort(-np.abs(roots))]


def spectral_radius(loop: WallLoop) -> float:
    """Largest closed-loop pole magnitude (dimensionless); < 1 means stable."""
    if loop.delay == 0:
        return float(np.max(np.abs(_quadratic_roots(characteristic_polynomial(loop)))))
    return float(np.abs(closed_loop_poles(loop)[0]))


def _quadratic_roots(poly: np.ndarray) -> np.ndarray:
    """Roots of a monic polynomial of degree 1 or 2, without cancellation."""
    if poly.size == 2:
        return np.array([-poly[1]])
    _, p1, p0 = poly
    disc = p1 * p1 - 4.0 * p0
    if disc >= 0:
        big = -0.5 * (p1 + math.copysign(math.sqrt(disc), p1))
        return np.array([big, p0 / big if big != 0 else 0.0])
    root = complex(-0.5 * p1, 0.5 * math.sqrt(-disc))
    return np.array([root, root.conjugate()])


def is_stable(loop: WallLoop) -> bool:
    """True if every closed-loop pole is strictly inside the unit circle.

    For ``d = 0`` this is the exact Jury test with its terms formed without cancellation:
    ``P(1) = k1 K T > 0``, ``P(-1) = 2(1 + a) - k1 (K T + 2B) > 0`` (eq. 23) and
    ``|a - k1 B| < 1``.  For ``d >= 1`` the pole magnitudes decide.
    """
    if loop.delay:
        return spectral_radius(loop) < 1.0
    c = loop.c
    decay = -math.expm1(-c)  # 1 - a, exact where a rounds to 1
    k1_scaled = phi1(c)
    stiffness = k1_scaled * loop.K * loop.T * loop.T / loop.m
    damping = k1_scaled * loop.B * loop.T / loop.m
    # |a - k1 B| < 1  <=>  k1 B + (1 - a) > 0  and  k1 B < 2 - (1 - a)
    constant_inside = damping + decay > 0 and damping < 2.0 - decay
    if loop.K == 0:
        return constant_inside
    flip = 2.0 * (2.0 - decay) - stiffness - 2.0 * damping
    return stiffness > 0 and flip > 0 and constant_inside
