"""Frequency responses of the sampled wall loop on ``theta = omega T`` in (0, pi], every velocity model and delay.

Two responses, both admittances from operator force to handle velocity in m/(N s):

* :func:`seed_t_zw` -- the seed's ``T_zw = G11 / (1 + G_md K_d)`` (eq. 10, with the loop's
  sampled map ``G_md`` from force to measured velocity); it reproduces the seed's Fig. 5.
* :func:`t_fund` -- the exact fundamental-harmonic response of the sampled-data loop (DESIGN 3.5),

      T_fund = G11 [1 - (H/T) e^{-j omega D T} K_d M G11 / (1 + G_md K_d)],

  whose real part is the exact mean power a sinusoidal operator force below Nyquist puts in
  (per ``|W|^2 / 2``).  ``M`` is the velocity model's continuous response
  (:func:`~haptic_bus.analysis.sampled_loop.measurement_response`), ``H = (1 - e^{-j omega T})/(j omega)``
  the hold, ``D = d + delta`` the delay, ``G_md = z^{-d} G`` with ``G`` the exact pulse transfer
  function of the period map (:mod:`haptic_bus.analysis.sampled_loop`).

**The form evaluated.**  Split ``G_md`` into the fundamental path ``(H/T) e^{-j omega D T} M G11``
and its aliases ``z^{-d} (1 - z^{-1}) g(theta)`` (:mod:`haptic_bus.analysis.alias_sum`).  Then the
impedance the operator feels, ``Z = 1/T_fund``, is exactly the handle plus the wall as the
sampled loop presents it,

    Z T/m = s + L E / (j theta U),   s = c + j theta,  L = kappa + q (1 - z^{-1}),
                                     E = e^{-j theta D} M(j theta),  U = 1 + L P,  P = z^{-d} g(theta),

(scaled units: ``c = bT/m``, ``kappa = K T^2/m``, ``q = B T/m``).  Its real part is
``c + Im(L E conj(U)) / (theta |U|^2)``: carried as ``(Re, Im/theta)``
(:class:`~haptic_bus.analysis.theta_complex.ThetaComplex`), every factor known in closed form
or by a series, it has no ``1/theta`` loss at all: ``Re Z`` is accurate to a few ulps of the
terms that make it (returned as ``scale``), even where ``|Z|`` is ``1e20`` times larger.
``Re T_fund = Re Z / |Z|^2`` inherits that.

Because ``L`` is affine in ``K`` and in ``B``, ``|U|^2 Re Z`` is a real quadratic in either at
each ``theta`` (:func:`impedance_quadratic`): the passivity limits come from its roots.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.alias_sum import AliasDevice as AliasKey
from haptic_bus.analysis.alias_sum import alias_function, device_alias_function
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import period_map, pulse_transfer, window_fraction
from haptic_bus.analysis.theta_complex import ThetaComplex
from haptic_bus.analysis.theta_search import grid_parts
from haptic_bus.analysis.trig import HalfAngle, cospi, half_angle, sincpi, sinpi, unit_point
from haptic_bus.analysis.velocity import VelocityModel


@dataclass(frozen=True)
class LoopTerms:
    """The wall-independent factors of ``Z`` on a ``theta`` array (rad): device, velocity model, delay.

    ``hold = 1 - z^{-1}``, ``P = z^{-d} g(theta)``, ``E = e^{-j theta D} M(j theta)``; ``c = bT/m``;
    ``scale = m/T`` (N s/m per scaled impedance unit).
    """

    theta: np.ndarray
    c: float
    scale: float
    hold: ThetaComplex
    P: ThetaComplex
    E: ThetaComplex

    def merged(self, other: LoopTerms) -> LoopTerms:
        """These terms and ``other``'s (same loop) on the sorted union of their ``theta`` (repeats once)."""
        def join(a: ThetaComplex, b: ThetaComplex) -> ThetaComplex:
            return ThetaComplex(theta, *(np.concatenate([x, y]) for x, y in
                                         ((a.re, b.re), (a.im, b.im), (a.mag_re, b.mag_re), (a.mag_im, b.mag_im))))

        theta = np.concatenate([self.theta, other.theta])
        whole = LoopTerms(theta, self.c, self.scale, join(self.hold, other.hold), join(self.P, other.P),
                          join(self.E, other.E))
        order = np.argsort(theta, kind="stable")
        ordered = theta[order]
        first = np.concatenate([[True], ordered[1:] != ordered[:-1]])
        return whole.take(order[first])

    def take(self, where: np.ndarray | slice) -> LoopTerms:
        """These terms at ``theta[where]`` only (``where``: a boolean mask, indices or a slice)."""

        def part(x: ThetaComplex) -> ThetaComplex:
            return ThetaComplex(x.theta[where], x.re[where], x.im[where], x.mag_re[where], x.mag_im[where])

        return LoopTerms(self.theta[where], self.c, self.scale, part(self.hold), part(self.P), part(self.E))


def grid_terms(loop: WallLoop, poles: np.ndarray) -> LoopTerms:
    """:func:`loop_terms` on :func:`~haptic_bus.analysis.theta_search.theta_grid`: the grid's
    wall-independent part evaluated once per device (cached: a gate judges many walls on one
    device), the fans at ``poles``' angles for this wall."""
    base, fans = grid_parts(loop, poles)
    terms = _device_terms(loop.m, loop.b, loop.T, loop.delay, loop.velocity, base.size)
    return terms.merged(loop_terms(loop, fans)) if fans.size else terms


@functools.lru_cache(maxsize=256)
def _device_terms(m: float, b: float, T: float, delay: float, velocity: VelocityModel, size: int) -> LoopTerms:
    device = WallLoop(m, b, T, 0.0, 0.0, delay, velocity)
    terms = loop_terms(device, grid_parts(device, np.empty(0))[0])
    assert terms.theta.size == size
    return terms


def delay_rotation(theta: np.ndarray, delay: float) -> ThetaComplex:
    """``e^{-j theta delay}``: ``Re = cos``, ``Im/theta = -delay sinc``."""
    x = theta * (delay / np.pi)
    return ThetaComplex.exact(theta, cospi(x), -delay * sincpi(x))


def measurement_terms(loop: WallLoop, theta: np.ndarray) -> ThetaComplex:
    """``M(j theta)`` as ``(Re, Im/theta)`` in closed form (exact at ``theta -> 0``)."""
    kind = loop.velocity.kind
    if kind == "point":
        return ThetaComplex.exact(theta, 1.0, 0.0)
    if kind == "lowpass":
        tau = loop.velocity.time / loop.T
        den = 1.0 + (theta * tau) ** 2
        return ThetaComplex.exact(theta, 1.0 / den, -tau / den)
    half = 0.5 * window_fraction(loop)
    envelope = sincpi(theta * (half / np.pi))  # (1 - e^{-j theta w})/(j theta w) = e^{-j theta w/2} sinc
    return delay_rotation(theta, half) * ThetaComplex.exact(theta, envelope, 0.0)


def hold_and_aliases(loop: WallLoop, circle: HalfAngle, aliases: AliasKey | None = None
                     ) -> tuple[ThetaComplex, ThetaComplex, ThetaComplex]:
    """``(1 - z^{-1}, z^{-d}, P = z^{-d} g(theta))`` of ``loop`` on the half angles ``circle`` of
    ``theta`` (rad, in ``(0, pi]``): the part of :func:`loop_terms` that the coupled criterion
    needs (``aliases``: as there)."""
    theta = circle.theta
    sinc = circle.sinc()
    hold = ThetaComplex.exact(theta, 2.0 * circle.s * circle.s, sinc)
    if loop.whole_delay == 1:  # z^-1 = cos - j sin
        whole = ThetaComplex.exact(theta, circle.c * circle.c - circle.s * circle.s, -sinc)
    else:
        whole = delay_rotation(theta, loop.whole_delay)
    P = whole * (alias_function(loop, theta, circle) if aliases is None else device_alias_function(aliases, theta, circle))
    return hold, whole, P


def loop_terms(loop: WallLoop, theta: ArrayLike, aliases: AliasKey | None = None) -> LoopTerms:
    """:class:`LoopTerms` of ``loop`` (its wall ignored) at ``theta`` (rad, in ``(0, pi]``); ``aliases``:
    another plant whose alias function ``g`` goes into ``P`` (None: ``loop``'s rigid handle)."""
    theta = np.atleast_1d(np.asarray(theta, dtype=float))
    hold, whole, P = hold_and_aliases(loop, half_angle(theta), aliases)
    rotation = whole if loop.delay == loop.whole_delay else delay_rotation(theta, loop.delay)
    E = rotation if loop.velocity.kind == "point" else rotation * measurement_terms(loop, theta)  # M = 1 exactly
    return LoopTerms(theta, loop.c, loop.m / loop.T, hold, P, E)


@dataclass(frozen=True)
class ScaledImpedance:
    """``Z T/m`` on ``theta``: ``re`` (accurate to ``~eps * scale``), ``im``, and ``scale``, the
    magnitude of the terms ``re`` is summed from (the yardstick of its sign)."""

    re: np.ndarray
    im: np.ndarray
    scale: np.ndarray


def _wall(terms: LoopTerms, kappa: float | np.ndarray, q: float | np.ndarray) -> ThetaComplex:
    """``L = kappa + q (1 - z^{-1})`` (``kappa``, ``q`` scalars, or arrays: one wall per point)."""
    return terms.hold * q + kappa


def scaled_impedance(terms: LoopTerms, kappa: float | np.ndarray, q: float | np.ndarray) -> ScaledImpedance:
    """``Z T/m = s + L E/(j theta U)`` for the scaled wall ``kappa``, ``q`` (see the module docstring;
    arrays of walls: one per point)."""
    L = _wall(terms, kappa, q)
    U = L * terms.P + 1.0
    Y = L * terms.E * U.conj()
    size = U.abs2()
    wall_re = Y.im / size
    u_spread = (U.mag_re**2 + (terms.theta * U.mag_im) ** 2) / size
    scale = terms.c + Y.mag_im / size + np.abs(wall_re) * u_spread
    return ScaledImpedance(terms.c + wall_re, terms.theta - Y.re / (terms.theta * size), scale)


def seed_impedance(terms: LoopTerms, kappa: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Re, Im)`` of the seed's ``Z_zw T/m = s (1 + G_md K_d) = s U + L E/(j theta)`` from the same terms
    (``G_md = hold (P + E/(j theta s))``, ``K_d = L/hold``): :func:`seed_z_zw` without its own evaluation."""
    L = _wall(terms, kappa, q)
    U = L * terms.P + 1.0
    sU = ThetaComplex.exact(terms.theta, terms.c, 1.0) * U
    LE = L * terms.E
    return sU.re + LE.im, terms.theta * sU.im - LE.re / terms.theta


def impedance_quadratic(terms: LoopTerms, base: ThetaComplex | float, slope: ThetaComplex | float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """``|U|^2 Re(Z T/m)`` as a quadratic in ``x`` where ``L = base + x slope``: coefficients and magnitudes.

    Returns ``(coefficients, magnitudes)``, each of shape ``(3, n)``, highest power first:
    ``Q(x) = Q2 x^2 + Q1 x + Q0`` and the same with every term's magnitude (the yardstick of
    ``Q``'s sign).  With ``U = 1 + base P`` and ``V = slope P``:
    ``Q2 = c|V|^2 + Im(slope E conj V)/theta``, ``Q1 = 2c Re(U conj V) + Im(slope E conj U + base E conj V)/theta``,
    ``Q0 = c|U|^2 + Im(base E conj U)/theta``.
    """
    c = terms.c
    t2 = terms.theta * terms.theta
    U = terms.P * base + 1.0
    V = terms.P * slope
    slope_e = terms.E * slope
    base_e = terms.E * base
    uv = U * V.conj()
    q2 = slope_e * V.conj()
    q1 = slope_e * U.conj() + base_e * V.conj()
    q0 = base_e * U.conj()
    coefficients = np.stack([c * V.abs2() + q2.im, 2.0 * c * uv.re + q1.im, c * U.abs2() + q0.im])
    magnitudes = np.stack([
        c * (V.mag_re**2 + t2 * V.mag_im**2) + q2.mag_im,
        2.0 * c * uv.mag_re + q1.mag_im,
        c * (U.mag_re**2 + t2 * U.mag_im**2) + q0.mag_im,
    ])
    return coefficients, magnitudes


Pair = tuple[np.ndarray, np.ndarray]  # (Re X, Im X / theta), no magnitudes


def _pair(x: ThetaComplex | float, zero: np.ndarray) -> Pair:
    return (x.re, x.im) if isinstance(x, ThetaComplex) else (zero + x, zero)


def _mul(x: Pair, y: Pair, t2: np.ndarray) -> Pair:
    """The product in the ``(Re, Im/theta)`` form (``t2 = theta^2``)."""
    return (x[0] * y[0] - t2 * x[1] * y[1], x[0] * y[1] + x[1] * y[0])


def quadratic_coefficients(terms: LoopTerms, base: ThetaComplex | float, slope: ThetaComplex | float) -> np.ndarray:
    """The coefficients of :func:`impedance_quadratic` alone (no magnitudes), ``(3, n)``: what a zoom needs."""
    c, t2 = terms.c, terms.theta * terms.theta
    zero = np.zeros(t2.shape)
    P, E = (terms.P.re, terms.P.im), (terms.E.re, terms.E.im)
    b, k = _pair(base, zero), _pair(slope, zero)
    bp = _mul(b, P, t2)
    U = (1.0 + bp[0], bp[1])
    V = _mul(k, P, t2)
    ke, be = _mul(k, E, t2), _mul(b, E, t2)
    conj_u, conj_v = (U[0], -U[1]), (V[0], -V[1])
    q2 = c * (V[0] ** 2 + t2 * V[1] ** 2) + _mul(ke, conj_v, t2)[1]
    q1 = 2.0 * c * _mul(U, conj_v, t2)[0] + _mul(ke, conj_u, t2)[1] + _mul(be, conj_v, t2)[1]
    q0 = c * (U[0] ** 2 + t2 * U[1] ** 2) + _mul(be, conj_u, t2)[1]
    return np.stack([q2, q1, q0])


def _theta_array(theta: ArrayLike) -> np.ndarray:
    return np.atleast_1d(np.asarray(theta, dtype=float))


def z_fund(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """``1 / T_fund``: the impedance the operator feels at ``theta``, in N s/m (real part exact to ulps)."""
    terms = loop_terms(loop, _theta_array(theta))
    z = scaled_impedance(terms, loop.kappa, loop.q)
    return terms.scale * (z.re + 1j * z.im)


def t_fund(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """Exact fundamental-harmonic admittance ``T_fund(theta)`` of the sampled loop, m/(N s)."""
    terms = loop_terms(loop, _theta_array(theta))
    z = scaled_impedance(terms, loop.kappa, loop.q)
    size = z.re * z.re + z.im * z.im
    return (z.re - 1j * z.im) / (size * terms.scale)


def seed_z_zw(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """``1 / T_zw`` in N s/m: the impedance of the seed's test, finite at every ``theta`` (zero
    where a closed-loop pole sits on the unit circle, where ``T_zw`` itself is infinite)."""
    theta = _theta_array(theta)
    z, z_minus_1 = unit_point(theta)
    sampled = pulse_transfer(period_map(loop), z, z_minus_1) * (cospi(theta * (loop.whole_delay / np.pi))
                                                                 - 1j * sinpi(theta * (loop.whole_delay / np.pi)))
    wall = loop.kappa * z / z_minus_1 + loop.q  # K_d T/m
    s = loop.c + 1j * theta
    return (loop.m / loop.T) * (s * (1.0 + sampled * wall))


def seed_t_zw(loop: WallLoop, theta: ArrayLike) -> np.ndarray:
    """The seed's ``T_zw = G11 / (1 + G_md K_d)`` (eq. 10, with the loop's sampled map and delay),
    m/(N s); complex infinity where :func:`seed_z_zw` is zero (a pole on the unit circle)."""
    impedance = seed_z_zw(loop, theta)
    zero = impedance == 0
    with np.errstate(divide="ignore", invalid="ignore"):
        admittance = 1.0 / np.where(zero, 1.0, impedance)
    return np.where(zero, complex(math.inf, 0.0), admittance)
