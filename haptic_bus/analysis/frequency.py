"""Frequency responses of the velocity-sampled wall loop on ``theta = omega T`` in (0, pi].

Two responses, both admittances from operator force to handle velocity in m/(N s):

* :func:`seed_t_zw` -- the seed's ``T_zw = G11 / (1 - G22d K_d)`` (eq. 10), a continuous
  ``G11`` mixed with the discrete loop; it reproduces the seed's Fig. 5.
* :func:`t_fund` -- the exact fundamental-harmonic response of the sampled-data loop
  (DESIGN 3.2), ``G11 [1 - (H/T) K_d' G11 / (1 + G11d K_d')]``, whose real part is the exact
  mean power a sinusoidal operator force below Nyquist puts in.

Everything is evaluated in the dimensionless variables ``c = bT/m``, ``p = j theta``,
``s = c + p``, ``kappa = K T^2/m``, ``q = B T/m`` and then scaled by ``T/m``, in a form with no
catastrophic cancellation (DESIGN 3.1):

* ``z - 1 = 2j sin(theta/2) e^{j theta/2}`` and ``z - a = (z - 1) - expm1(-c)``;
* the wall's pole is cleared, ``(z - 1) K_d T/m = kappa z + q (z - 1)``;
* the alias sum ``G11d - (H/T) G11``, which is a difference of two nearly equal terms as
  ``theta, c -> 0``, is carried as ``-p s R(p, s) / (z - a)`` where
  ``R = int_0^1 int_0^1 e^{p t} e^{-s tau} min(t, tau) (1 - max(t, tau)) dt dtau`` is smooth
  (``R(0, 0) = 1/12``): a double Taylor series where ``|p|, c < 1``, the closed form elsewhere.

With ``P(z) = (z - a)(z - 1) + phi1(c) (kappa z + q (z - 1)) z^{-d}`` (the closed-loop
characteristic polynomial over ``z^d``) and ``E = (z - 1)/p``:

    T_zw  (T/m)^-1 = (z - a)(z - 1) / (s P)
    T_fund (T/m)^-1 = p [(z - a) E - W s R] / (s P),     W = (kappa z + q (z - 1)) z^{-d}

The relative error of ``Re`` of either is about ``eps / theta`` (the imaginary part grows as
``1/theta`` near 0 while the real part stays finite), i.e. 1e-4 at ``theta = 1e-12``.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import phi1

_SERIES_TERMS = 16
_SERIES_BELOW = 1.0


def _alias_moment_coefficients(terms: int) -> np.ndarray:
    """Coefficients ``M_kn / (k! n!)`` of the double series of R (exact rationals, as floats)."""
    table = np.empty((terms, terms))
    for k in range(terms):
        for n in range(terms):
            moment = (Fraction(1, n + 2) + Fraction(1, k + 2)) / ((k + n + 3) * (k + n + 4))
            table[k, n] = float(moment / (math.factorial(k) * math.factorial(n)))
    return table


_R_COEFFICIENTS = _alias_moment_coefficients(_SERIES_TERMS)


# phi2(x) = sum_n (-x)^n / (n + 2)!, highest power first for np.polyval; error < 1/18! at |x| < 1
_PHI2_SERIES = np.array([(-1.0) ** n / math.factorial(n + 2) for n in range(_SERIES_TERMS)][::-1])


def _phi2_complex(x: np.ndarray) -> np.ndarray:
    """``(x - 1 + e^{-x}) / x^2`` for complex ``x``: its Taylor series where ``|x| < 1``."""
    small = np.abs(x) < 1.0
    if not small.any():
        return (x + np.expm1(-x)) / (x * x)
    out = np.polyval(_PHI2_SERIES, x)
    if not small.all():
        xl = x[~small]
        out[~small] = (xl + np.expm1(-xl)) / (xl * xl)
    return out


def _alias_kernel(c: float, theta: np.ndarray) -> np.ndarray:
    """``R(p, s)`` with ``p = j theta``, ``s = c + p`` (dimensionless, R(0, 0) = 1/12)."""
    p = 1j * theta
    s = c + p
    out = np.empty(theta.shape, dtype=complex)
    near = (theta < _SERIES_BELOW) & (c < _SERIES_BELOW)
    if near.any():
        powers = np.arange(_SERIES_TERMS)
        p_pow = p[near, None] ** powers
        s_pow = (-s[near, None]) ** powers
        out[near] = np.einsum("ik,kn,in->i", p_pow, _R_COEFFICIENTS, s_pow)
    far = ~near
    if far.any():
        pf, sf = p[far], s[far]
        # Q = phi1(c) - phi2(-p) - e^{-c} phi2(p) = -s^2 R; direct where |p| >= 1 or c >= 1.
        q = phi1(c) - _phi2_complex(-pf) - math.exp(-c) * _phi2_complex(pf)
        out[far] = -q / (sf * sf)
    return out


class _LoopTerms:
    """The stable building blocks shared by both responses at one ``theta`` array."""

    def __init__(self, loop: WallLoop, theta: np.ndarray) -> None:
        c = loop.c
        half = 0.5 * theta
        rotor = np.exp(1j * half)
        self.p = 1j * theta
        self.s = c + self.p
        self.z_minus_1 = 2j * np.sin(half) * rotor
        self.z_minus_a = self.z_minus_1 - math.expm1(-c)
        self.e = rotor * np.sinc(theta / (2 * np.pi))  # (z - 1)/p, = 1 at theta = 0
        z = np.exp(1j * theta)
        kappa = loop.K * loop.T * loop.T / loop.m
        q = loop.B * loop.T / loop.m
        wall = kappa * z + q * self.z_minus_1
        if loop.delay:
            wall = wall * np.exp(-1j * loop.delay * theta)
        self.wall = wall
        self.char = self.z_minus_a * self.z_minus_1 + phi1(c) * wall
        self.c = c
        self.theta = theta
        self.scale = loop.T / loop.m


def _theta_array(theta: ArrayLike) -> np.ndarray:
    return np.atleast_1d(np.asarray(theta, dtype=float))


def seed_t_zw(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """The seed's ``T_zw(theta)`` (eq. 10, with the loop delay in ``K_d``), in m/(N s)."""
    t = _LoopTerms(loop, _theta_array(theta))
    return t.scale * t.z_minus_a * t.z_minus_1 / (t.s * t.char)


def t_fund(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """Exact fundamental-harmonic admittance ``T_fund(theta)`` of the sampled loop, m/(N s)."""
    t = _LoopTerms(loop, _theta_array(theta))
    return t.scale * t.p * _fund_bracket(t) / (t.s * t.char)


def z_fund(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """``1 / T_fund``: the impedance the operator feels at ``theta``, in N s/m."""
    t = _LoopTerms(loop, _theta_array(theta))
    return t.s * t.char / (t.scale * t.p * _fund_bracket(t))


def _fund_bracket(t: _LoopTerms) -> np.ndarray:
    return t.z_minus_a * t.e - t.wall * t.s * _alias_kernel(t.c, t.theta)
