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
from numpy.polynomial import polynomial as P

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import phi1


def characteristic_polynomial(loop: WallLoop) -> np.ndarray:
    """Coefficients (highest power first, dimensionless) of the closed-loop polynomial in z."""
    shifted = np.poly1d(_shifted_polynomial(loop))
    return np.asarray(shifted(np.poly1d([1.0, -1.0])).coeffs)  # substitute w = z - 1


def _shifted_polynomial(loop: WallLoop) -> np.ndarray:
    """The characteristic polynomial in ``w = z - 1`` (coefficients, highest power first).

    Poles near ``z = 1`` (slow plants, soft walls) are ill-conditioned as roots in ``z`` (a
    double root moves by ``sqrt(eps)``) but small, well-conditioned roots in ``w``; every
    coefficient here is formed from ``1 - a = -expm1(-c)`` without cancellation.
    """
    c = loop.c
    decay = -math.expm1(-c)
    k1_scaled = phi1(c)
    stiffness = k1_scaled * loop.K * loop.T * loop.T / loop.m  # k1 K T
    damping = k1_scaled * loop.B * loop.T / loop.m  # k1 B
    delay_factor = P.polypow([1.0, 1.0], loop.delay)  # (1 + w)^d, lowest power first
    if loop.K > 0:
        # (w + 1 - a) w (1 + w)^d + k1 K T (1 + w) + k1 B w
        poly = P.polymul(P.polymul([decay, 1.0], [0.0, 1.0]), delay_factor)
        poly = P.polyadd(poly, [stiffness, stiffness + damping])
    else:
        # (w + 1 - a)(1 + w)^d + k1 B
        poly = P.polyadd(P.polymul([decay, 1.0], delay_factor), [damping])
    return np.asarray(poly)[::-1]


def shifted_poles(loop: WallLoop) -> np.ndarray:
    """Closed-loop poles minus one, ``w = z - 1`` (complex), accurate near ``z = 1``."""
    return np.roots(_shifted_polynomial(loop))


def radius_excess(w: np.ndarray) -> np.ndarray:
    """``|1 + w| - 1`` without cancellation: ``(2 Re w + |w|^2) / (|1 + w| + 1)``."""
    w = np.asarray(w, dtype=complex)
    return (2.0 * w.real + np.abs(w) ** 2) / (np.abs(1.0 + w) + 1.0)


def closed_loop_poles(loop: WallLoop) -> np.ndarray:
    """The closed-loop poles in the z-plane (complex, sorted by decreasing magnitude)."""
    w = shifted_poles(loop)
    order = np.argsort(-radius_excess(w))
    return 1.0 + w[order]


def spectral_radius(loop: WallLoop) -> float:
    """Largest closed-loop pole magnitude (dimensionless); < 1 means stable."""
    return 1.0 + float(np.max(radius_excess(shifted_poles(loop))))


def is_stable(loop: WallLoop) -> bool:
    """True if every closed-loop pole is strictly inside the unit circle.

    For ``d = 0`` this is the exact Jury test with its terms formed without cancellation:
    ``P(1) = k1 K T > 0``, ``P(-1) = 2(1 + a) - k1 (K T + 2B) > 0`` (eq. 23) and
    ``|a - k1 B| < 1``.  For ``d >= 1`` the pole magnitudes decide.
    """
    if loop.delay:
        return bool(np.all(radius_excess(shifted_poles(loop)) < 0.0))
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
