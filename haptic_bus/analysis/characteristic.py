"""The closed loop's characteristic function in ``w = z - 1``: the delay line as a shift, the plant's order kept.

The closed loop ``xi_{k+1} = M xi_k`` (:mod:`haptic_bus.analysis.sampled_loop`) has a delay line of
``L`` held forces behind a plant of order ``n`` (1 or 2) and the controller's integrator.  Its poles
are the zeros of one scalar function: from ``1 + c (zI - Phi)^{-1} (gamma_now + gamma_before/z)
z^{-d} K_d(z) = 0`` times ``z^L (z - 1) det(zI - Phi)``,

    f(z) = z^L A(w) + N(w) W(w),          w = z - 1,

* ``A(w) = w det(wI - E)`` with the integrator (``K > 0``), ``det(wI - E)`` without it;
  ``E = Phi - I`` (lower triangular, entries without cancellation), so ``A`` is a product of
  ``w - E_ii``;
* ``N(w) = c adj(wI - E) gamma(w)``: ``gamma = gamma_now + gamma_before + gamma_now w`` when the
  delay has a fraction (``L = d + 1``), ``gamma_now`` when it is whole (``L = d``);
* ``W(w) = kappa + (kappa + q) w`` with the integrator (``K_d (z - 1)``), ``q`` without.

Every coefficient of ``A`` and ``N`` (in powers of ``w``) is a sum of non-negative terms (the
force columns are positive, ``-E_ii >= 0``): nothing cancels, so a loop that barely moves in a
period (``bT/m`` of ``1e-18``) keeps its poles' offsets from 1 to full relative precision -- which
no polynomial in ``z`` (``1 - e^{-c}`` rounds to 0) and no dense eigenvalue solver (its error is
``eps`` times the delay line's unit entries) can.  ``z^L = (1 + w)^L`` is evaluated as
``exp(L log1p(w))`` near ``z = 1``.  ``f`` has degree ``L + deg A``, the size of ``M``.

:func:`flip_value` solves ``f(-1) = 0`` for the one wall parameter that moves (``f`` is affine in
each): where a pole sits at ``z = -1``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import period_map
from haptic_bus.analysis.velocity import VelocityModel

EPS = float(np.finfo(float).eps)
SCHUR_COHN_TRUST = 1e-8  # |1 - max |k_j|| below this: the double-precision recursion decides nothing


@dataclass(frozen=True)
class Characteristic:
    """The wall-independent parts of ``f`` (coefficients in powers of ``w``, highest first).

    ``lag`` is ``L``; ``plant`` the coefficients of ``det(wI - E)``; ``numerator`` those of ``N``.
    """

    lag: int
    plant: np.ndarray
    numerator: np.ndarray

    def wall(self, kappa: float, q: float, integrator: bool) -> np.ndarray:
        """Coefficients of ``W`` (highest first) for the scaled wall ``kappa``, ``q``."""
        return np.array([kappa + q, kappa]) if integrator else np.array([q])

    def denominator(self, integrator: bool) -> np.ndarray:
        """Coefficients of ``A``: ``w det(wI - E)`` with the integrator, ``det(wI - E)`` without."""
        return np.append(self.plant, 0.0) if integrator else self.plant

    def degree(self, integrator: bool) -> int:
        """The number of closed-loop poles: ``L + deg A``."""
        return self.lag + self.denominator(integrator).size - 1


def log_one_plus(w: np.ndarray) -> np.ndarray:
    """``log(1 + w)`` (principal) for complex ``w``, to relative precision also where ``|w|`` is tiny."""
    w = np.asarray(w, dtype=complex)
    near = np.abs(w) < 0.5
    safe = np.where(near, w, 0.0)
    # 0.5 log1p(2 Re w + |w|^2) + j atan2(Im w, 1 + Re w): no 1 + tiny rounding
    small = 0.5 * np.log1p(2.0 * safe.real + np.abs(safe) ** 2) + 1j * np.arctan2(safe.imag, 1.0 + safe.real)
    with np.errstate(divide="ignore"):
        return np.where(near, small, np.log(np.where(near, 1.0, 1.0 + w)))


def characteristic(loop: WallLoop) -> Characteristic:
    """:class:`Characteristic` of ``loop``'s device, velocity model and delay (its wall ignored); cached."""
    return _characteristic(loop.m, loop.b, loop.T, loop.delay, loop.velocity)


@functools.lru_cache(maxsize=512)
def _characteristic(m: float, b: float, T: float, delay: float, velocity: VelocityModel) -> Characteristic:
    device = WallLoop(m, b, T, 0.0, 0.0, delay, velocity)
    pmap = period_map(device)
    whole, fraction = device.whole_delay, device.fractional_delay > 0.0
    E = pmap.phi_minus_identity
    n = E.shape[0]
    if fraction:  # gamma(w) rows: [coefficient of w, constant]
        gamma = np.stack([pmap.gamma_now, pmap.gamma_now + pmap.gamma_before], axis=1)
    else:
        gamma = pmap.gamma_now[:, None]
    c = pmap.c
    if n == 1:
        numerator = c[0] * gamma[0]
        plant = np.array([1.0, -E[0, 0]])
    else:  # adj(wI - E) = [[w - E11, 0], [E10, w - E00]] for lower-triangular E
        numerator = (c[0] * np.convolve([1.0, -E[1, 1]], gamma[0])
                     + c[1] * (np.convolve([0.0, E[1, 0]], gamma[0]) + np.convolve([1.0, -E[0, 0]], gamma[1])))
        plant = np.convolve([1.0, -E[0, 0]], [1.0, -E[1, 1]])
    numerator = np.trim_zeros(numerator, "f")
    if numerator.size == 0:
        numerator = np.zeros(1)
    for array in (plant, numerator):
        array.setflags(write=False)
    return Characteristic(whole + (1 if fraction else 0), plant, numerator)


def evaluate(char: Characteristic, wall: np.ndarray, integrator: bool, w: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(f(w), f'(w), size)`` up to one common positive factor per point (``|z|^-L`` where
    ``|z| > 1``, so nothing overflows): ``f``, its derivative in ``w``, and the sum of the
    magnitudes of the terms ``f`` is formed from (its round-off is a few ``eps`` times ``size``)."""
    w = np.asarray(w, dtype=complex)
    a = char.denominator(integrator)
    if char.lag:
        log_z = log_one_plus(w)
        grow = np.maximum(char.lag * log_z.real, 0.0)  # -inf at z = 0: no growth there
        with np.errstate(over="ignore", invalid="ignore"):
            zl = np.exp(char.lag * log_z - grow)  # z^L |z|^-L where |z| > 1 (0 at z = 0)
        zl = np.where(np.isfinite(zl), zl, 0.0)
    else:
        grow, zl = np.zeros(w.shape), np.ones(w.shape, dtype=complex)
    scale = np.exp(-grow)
    av = np.polyval(a, w)
    ad = np.polyval(np.polyder(a), w) if a.size > 1 else np.zeros_like(w)
    nv, wv = np.polyval(char.numerator, w), np.polyval(wall, w)
    nd = np.polyval(np.polyder(char.numerator), w) if char.numerator.size > 1 else np.zeros_like(w)
    wd = np.polyval(np.polyder(wall), w) if wall.size > 1 else np.zeros_like(w)
    f = zl * av + scale * nv * wv
    with np.errstate(divide="ignore", invalid="ignore"):
        lead = np.where(w == -1.0, 0.0, char.lag * zl / (1.0 + w)) if char.lag else np.zeros_like(w)
    derivative = lead * av + zl * ad + scale * (nd * wv + nv * wd)
    r = np.abs(w)
    size = (np.abs(zl) * np.polyval(np.abs(a), r)
            + scale * np.polyval(np.abs(char.numerator), r) * np.polyval(np.abs(wall), r))
    return f, derivative, size


def flip_value(char: Characteristic, base: np.ndarray, slope: np.ndarray, integrator: bool) -> float | None:
    """The ``x`` with ``f(-1) = 0`` when ``W = base + x slope`` (coefficient arrays), or None if
    ``f(-1)`` does not depend on ``x``: where a pole crosses the unit circle at ``z = -1``."""
    w = np.array([-2.0 + 0j])
    a = char.denominator(integrator)
    lead = (-1.0) ** char.lag * np.polyval(a, w.real)[0]
    n = np.polyval(char.numerator, w.real)[0]
    b0, b1 = np.polyval(base, w.real)[0], np.polyval(slope, w.real)[0]
    gain = n * b1
    if gain == 0.0:
        return None
    return float(-(lead + n * b0) / gain)


def _in_z(coefficients: np.ndarray) -> np.ndarray:
    """A polynomial in ``w`` (highest first) as one in ``z = 1 + w`` (highest first): Horner with ``z - 1``."""
    out = np.zeros(1)
    for a in coefficients:
        out = np.append(out, 0.0) - np.append(0.0, out)  # times (z - 1)
        out[-1] += a
    return np.trim_zeros(out, "f") if np.any(out) else np.zeros(1)


def schur_cohn(char: Characteristic, wall: np.ndarray, integrator: bool) -> float:
    """``1 - max |k_j|`` over the Schur-Cohn (Jury) reflection coefficients of ``f`` in powers of ``z``:
    positive iff every zero lies strictly inside the unit circle.  ``O(L^2)`` flops on one array
    (normalised each step); in double precision, so a result within :data:`SCHUR_COHN_TRUST` of 0
    decides nothing (poles that close to the circle, or ``z``-coefficients that lost them: the caller asks
    :mod:`haptic_bus.analysis.poles`).  Stops at the first ``|k_j| > 1``."""
    top = _in_z(char.denominator(integrator))[::-1]  # ascending
    bottom = _in_z(np.convolve(char.numerator, wall))[::-1]
    m = max(top.size, bottom.size) - 1
    degree = char.lag + top.size - 1
    least = 1.0
    if degree > 2 * m + 2:  # z^L A + B: two blocks of m + 1 coefficients, a gap between; the gap shrinks by one a step
        low = [float(x) for x in np.pad(bottom, (0, m + 1 - bottom.size))]
        high = [float(x) for x in np.pad(top, (m + 1 - top.size, 0))]
        while degree > 2 * m + 2:
            if high[m] == 0.0:
                return -math.inf
            k = low[0] / high[m]
            least = min(least, 1.0 - abs(k))
            if least < -SCHUR_COHN_TRUST:
                return least
            low, high = ([(low[j + 1] if j < m else 0.0) - k * (high[m - 1 - j] if j < m else 0.0) for j in range(m + 1)],
                         [high[t] - k * low[m - t] for t in range(m + 1)])
            scale = abs(high[m]) or 1.0
            low, high = [x / scale for x in low], [x / scale for x in high]
            degree -= 1
        a = np.zeros(degree + 1)
        a[:m + 1] += low
        a[degree - m:] += high
    else:
        a = np.zeros(char.lag + top.size)
        a[char.lag:] += top
        a[:bottom.size] += bottom
        a = np.trim_zeros(a, "b")
    for _ in range(a.size - 1):
        lead, constant = a[-1], a[0]
        if lead == 0.0:
            return -math.inf
        k = constant / lead
        least = min(least, 1.0 - abs(float(k)))
        if least < -SCHUR_COHN_TRUST:
            return least
        a = (a - k * a[::-1])[1:]  # (p - k p*)/z, p* the reversed polynomial
        a = a / abs(a[-1]) if a[-1] != 0.0 else a
    return least
