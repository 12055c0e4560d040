"""The alias function ``g(theta)``: what sampling adds to the continuous loop, free of cancellation.

With ``G(z)`` the pulse transfer function from the held, ``delta``-shifted wall force to the
measured velocity (:func:`haptic_bus.analysis.sampled_loop.pulse_transfer`, scaled units) and
``F(theta) = M(j theta) e^{-j theta delta} / (j theta (c + j theta))`` the continuous path
divided by the hold's ``1 - z^{-1}``, Poisson's formula gives

    G(z) = (1 - z^{-1}) sum_k F(theta + 2 pi k),       z = e^{j theta},

so the aliases alone are ``(1 - z^{-1}) g(theta)`` with

    g(theta) = sum_{k != 0} F(theta + 2 pi k) = G(z) / (1 - z^{-1}) - F(theta).

``g`` is analytic for ``|theta| < 2 pi`` (``F``'s poles, ``theta = 0``, ``j c`` and ``j T/TAU``,
are excluded with ``k = 0``), but the difference on the right cancels as ``theta -> 0`` (both
terms grow like ``1/theta^2``).  So: for ``theta >= 0.5`` the difference itself (it loses at
most ``log10(12/theta^2)`` ~ 2 digits there); below, the Taylor series of ``g`` at 0, whose
coefficients come from the same difference on a circle ``|theta| = rho`` (``rho`` in 1..2.5,
chosen at least 0.25 away from ``j c`` and ``j T/TAU``, where nothing cancels) by a 64-point FFT:
the Cauchy integral, exact to ``(rho/2 pi)^64`` plus round-off ``~ eps max|terms|``.  Since
``g(-theta) = conj g(theta)``, ``g = sum_n gamma_n (j theta)^n`` with real ``gamma_n``, and the
series gives ``Re g`` and ``Im g/theta`` directly (:class:`~haptic_bus.analysis.theta_complex.ThetaComplex`).

**Other plants** (:class:`AliasDevice`: a two-mass device, :mod:`haptic_bus.analysis.two_mass`):
the same with their own ``G(z)`` and ``F(theta) = M e^{-j theta delta} G_p(j theta)/(j theta)``,
``G_p`` the plant's mobility from the held force to the measured state.  Its poles ``theta_p``
(``-j`` times the scaled plant's eigenvalues: complex for a resonance) are ``F``'s, and
``theta_p - 2 pi k`` (``k != 0``) are ``g``'s own: a resonance above Nyquist aliases towards 0.
So the circle keeps ``|rho - |theta_p|| >= 0.25 rho`` from the first and stays within half the
distance to the nearest of the second (the 64-point Cauchy sum then errs by ``2^-64`` relative),
from the same radii as the rigid handle or, if none is allowed, smaller ones down to 0.1 and then
half the distance to that nearest aliased pole (a resonance near a multiple of the sampling
frequency); the series is used below ``min(0.5, rho/2)``.  With no allowed radius (one below
1e-6 rad) ``g`` is the difference at every ``theta``.
"""

from __future__ import annotations

import functools
import math
from typing import Protocol

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import measurement_response, period_map, pulse_transfer
from haptic_bus.analysis.theta_complex import ThetaComplex
from haptic_bus.analysis.trig import HalfAngle, cospi, sinpi, unit_point
from haptic_bus.analysis.velocity import VelocityModel

SERIES_BELOW = 0.5  # rad: below, g from its Taylor series
_CIRCLE_POINTS = 64
_SERIES_TERMS = 32  # (0.5/2 pi)^32 < 1e-35
_RADII = (1.0, 1.5, 2.0, 2.5)
_SMALL_RADII = (0.75, 0.5, 0.35, 0.25, 0.15, 0.1)  # another plant's aliased poles may forbid the others
_POLE_CLEARANCE = 0.25
_LEAST_RADIUS = 1e-6  # rad: a smaller circle's terms (~1/rho^2) would drown g in their round-off


class AliasDevice(Protocol):
    """A plant other than the rigid handle, as ``g`` needs it (hashable: its series are cached).

    ``T`` s, the ``velocity`` model, ``fractional_delay`` ``delta`` in [0, 1); ``sampled_over_hold``
    is ``G(z)/(1 - z^{-1})`` (scaled), ``path_over_hold`` ``G_p(j theta)/(j theta)`` (no ``M``, no
    delay), both at complex arguments; ``theta_poles`` the plant's poles in the ``theta`` plane.
    """

    @property
    def T(self) -> float: ...

    @property
    def velocity(self) -> VelocityModel: ...

    @property
    def fractional_delay(self) -> float: ...

    def sampled_over_hold(self, z: np.ndarray, z_minus_1: np.ndarray) -> np.ndarray: ...

    def path_over_hold(self, theta: np.ndarray) -> np.ndarray: ...

    def theta_poles(self) -> tuple[complex, ...]: ...

    def __hash__(self) -> int: ...


Key = WallLoop | AliasDevice


@functools.lru_cache(maxsize=4096)
def device_key(loop: WallLoop) -> WallLoop:
    """The part of ``loop`` that ``g`` depends on: device, velocity model and ``delta`` (no wall, no ``d``)."""
    return WallLoop(loop.m, loop.b, loop.T, 0.0, 0.0, loop.fractional_delay, loop.velocity)


def _alias_terms(key: Key, theta: np.ndarray, circle: HalfAngle | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The two terms of ``g(theta) = G(z)/(1 - z^{-1}) - F(theta)`` at real or complex ``theta``
    (dimensionless, scaled units), ``G(z)/(1 - z^{-1})`` and ``F(theta)`` (``circle``: the
    half angles of real ``theta``, if already known)."""
    z, z_minus_1 = unit_point(theta) if circle is None else (circle.z, circle.z_minus_1)
    if isinstance(key, WallLoop):
        sampled = pulse_transfer(period_map(key), z, z_minus_1) * z / z_minus_1
        continuous = 1.0 / (1j * theta * (key.c + 1j * theta))
    else:
        sampled = key.sampled_over_hold(z, z_minus_1)
        continuous = key.path_over_hold(theta)
    delta = key.fractional_delay
    shift: np.ndarray | float
    if np.iscomplexobj(theta):
        shift = np.exp(-1j * theta * delta)
    elif delta:
        x = theta * (delta / np.pi)
        shift = cospi(x) - 1j * sinpi(x)
    else:
        shift = 1.0
    if key.velocity.kind != "point":
        continuous = continuous * measurement_response(key, theta)
    return sampled, continuous * shift


@functools.lru_cache(maxsize=256)
def _circle_radius(key: Key) -> float | None:
    """The Cauchy circle's radius (rad), None if no radius is allowed (see the module docstring)."""
    lowpass = [key.T / key.velocity.time] if key.velocity.kind == "lowpass" else []
    if isinstance(key, WallLoop):
        poles = [key.c, *lowpass]
        for radius in _RADII:
            if all(abs(radius - p) >= _POLE_CLEARANCE for p in poles):
                return radius
        raise AssertionError("two poles cannot exclude four radii 0.5 apart")  # pragma: no cover
    own = key.theta_poles()
    sizes = [abs(p) for p in own] + lowpass
    aliased = [abs(p - 2 * math.pi * k) for p in own for k in (math.floor(p.real / (2 * math.pi)),
                                                             math.ceil(p.real / (2 * math.pi))) if k]
    aliased += [abs(p - 2 * math.pi * k) for p in own for k in (-1, 1)]
    nearest = min(aliased)
    for radius in _RADII + _SMALL_RADII + tuple(0.5 * nearest * f for f in (1.0, 0.75, 0.5, 0.35)):
        if (radius >= _LEAST_RADIUS and all(abs(radius - p) >= _POLE_CLEARANCE * min(radius, 1.0) for p in sizes)
                and 2 * radius <= nearest):
            return radius
    return None


def series_below(key: Key) -> float:
    """Below this ``theta`` (rad) ``g`` comes from its Taylor series (0: never)."""
    radius = _circle_radius(key)
    return 0.0 if radius is None else min(SERIES_BELOW, 0.5 * radius)


@functools.lru_cache(maxsize=256)
def taylor_coefficients(key: Key) -> tuple[np.ndarray, float]:
    """Real ``gamma_n`` with ``g(theta) = sum_n gamma_n (j theta)^n``, ``n < 32`` (Cauchy integral by
    FFT), and the magnitude of the terms cancelled on the circle (their round-off bounds the series')."""
    radius = _circle_radius(key)
    if radius is None:
        raise ValueError(f"{key}: no Cauchy circle avoids its poles")
    nodes = radius * np.exp(2j * np.pi * np.arange(_CIRCLE_POINTS) / _CIRCLE_POINTS)
    sampled, continuous = _alias_terms(key, nodes)
    coefficients = np.fft.fft(sampled - continuous) / _CIRCLE_POINTS
    n = np.arange(_SERIES_TERMS)
    gamma = (coefficients[:_SERIES_TERMS] / (radius**n * 1j**n)).real
    gamma.setflags(write=False)
    # coefficient n errs by ~eps max|terms| / radius^n: summed at theta <= radius/2, twice that
    return gamma, 2.0 * float(np.max(np.maximum(np.abs(sampled), np.abs(continuous))))


@functools.lru_cache(maxsize=256)
def _series(key: Key) -> tuple[np.ndarray, float]:
    """Columns ``Re g``, ``Im g/theta`` and their magnitudes as polynomials in ``theta^2`` (powers
    ascending, ``(16, 4)``), and the cancelled magnitude of :func:`taylor_coefficients`."""
    gamma, cancelled = taylor_coefficients(key)
    signs = (-1.0) ** np.arange(_SERIES_TERMS // 2)
    even, odd = gamma[0::2] * signs, gamma[1::2] * signs
    table = np.stack([even, odd, np.abs(even), np.abs(odd)], axis=1)
    table.setflags(write=False)
    return table, cancelled


def alias_function(loop: WallLoop, theta: np.ndarray, circle: HalfAngle | None = None) -> ThetaComplex:
    """``g(theta)`` on real ``theta >= 0`` (rad) as ``(Re g, Im g/theta)``, scaled units (``circle``:
    the half angles of ``theta``, if already known)."""
    return device_alias_function(device_key(loop), theta, circle)


def device_alias_function(key: Key, theta: np.ndarray, circle: HalfAngle | None = None) -> ThetaComplex:
    """:func:`alias_function` of a device ``key`` (a rigid handle's :func:`device_key`, or an :class:`AliasDevice`)."""
    theta = np.asarray(theta, dtype=float)
    small = theta < (SERIES_BELOW if isinstance(key, WallLoop) else series_below(key))
    if small.all():
        return _series_part(key, theta)
    if not small.any():
        return _direct_part(key, theta, circle)
    low, high = _series_part(key, theta[small]), _direct_part(key, theta[~small], None if circle is None else circle.take(~small))
    parts = []
    for a, b in ((low.re, high.re), (low.im, high.im), (low.mag_re, high.mag_re), (low.mag_im, high.mag_im)):
        out = np.empty(theta.shape)
        out[small], out[~small] = a, b
        parts.append(out)
    return ThetaComplex(theta, *parts)


def _series_part(key: Key, theta: np.ndarray) -> ThetaComplex:
    """``g`` below :data:`SERIES_BELOW` from its Taylor series."""
    table, cancelled = _series(key)
    # powers of theta^2 times the table; einsum's own loop, no BLAS call (a threaded one spins on a busy machine)
    values = np.einsum("ij,jk->ik", np.vander(theta * theta, table.shape[0], increasing=True), table)
    return ThetaComplex(theta, values[:, 0], values[:, 1], np.maximum(values[:, 2], cancelled),
                        np.maximum(values[:, 3], cancelled / min(_RADII[0], _circle_radius(key) or 1.0)))


def _direct_part(key: Key, theta: np.ndarray, circle: HalfAngle | None) -> ThetaComplex:
    """``g`` from and above :data:`SERIES_BELOW` as the difference itself."""
    sampled, continuous = _alias_terms(key, theta, circle)
    value = sampled - continuous
    re, im = value.real, value.imag / theta
    # each part errs by ~eps times the terms that cancel; at z = -1 the sampled term is real
    # and the imaginary part is the continuous term's own, exact to its ulps
    size = np.maximum(np.abs(sampled), np.abs(continuous))
    return ThetaComplex(theta, re, im, np.maximum(np.abs(re), size),
                        np.maximum(np.abs(im), np.where(theta == np.pi, 0.0, size / theta)))
