"""Trigonometry of ``theta = omega T`` that is exact at the Nyquist frequency.

``np.sin(np.pi)`` is ``1.2e-16``, not 0: at ``theta = pi`` the unit-circle point ``z = -1`` would
pick up an imaginary part, and a sampled quantity that is real there (every pulse transfer
function at ``z = -1``) an error of ``1e-16`` of its size -- enough to move a flip boundary
whose net damping is ``1e-15`` of the terms.  Here every function takes the argument in units
of ``pi`` (``x = theta/pi``, exact for ``theta = np.pi``) and reduces it by symmetry, so whole
and half multiples of ``pi`` give exact 0 and +-1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


def sinpi(x: ArrayLike) -> np.ndarray:
    """``sin(pi x)``, exact at whole and half ``x``."""
    r = np.mod(np.asarray(x, dtype=float), 2.0)
    sign = np.where(r > 1.0, -1.0, 1.0)
    r = np.where(r > 1.0, r - 1.0, r)  # exact (Sterbenz)
    return sign * np.sin(np.pi * np.minimum(r, 1.0 - r))


def cospi(x: ArrayLike) -> np.ndarray:
    """``cos(pi x)``, exact at whole and half ``x``."""
    r = np.mod(np.asarray(x, dtype=float), 2.0)
    r = np.where(r > 1.0, 2.0 - r, r)  # cos is even about 1
    near = r < 0.25
    return np.where(near, np.cos(np.pi * r), sinpi(0.5 - np.where(near, 0.5, r)))


def sincpi(x: ArrayLike) -> np.ndarray:
    """``sin(pi x) / (pi x)`` (1 at 0), exact zeros at whole ``x``."""
    x = np.asarray(x, dtype=float)
    safe = np.where(x == 0.0, 1.0, x)
    return np.where(x == 0.0, 1.0, sinpi(safe) / (np.pi * safe))


@dataclass(frozen=True)
class HalfAngle:
    """``s = sin(theta/2)``, ``c = cos(theta/2)`` on real ``theta`` in ``[0, pi]``, exact at ``pi``
    (``s = 1``, ``c = 0``; ``c`` is taken as ``sin((pi - theta)/2)``, and ``pi - theta`` is exact
    there), and what follows from them without cancellation."""

    theta: np.ndarray
    s: np.ndarray
    c: np.ndarray

    @property
    def z(self) -> np.ndarray:
        """``e^{j theta} = (c^2 - s^2) + 2j s c``."""
        return (self.c * self.c - self.s * self.s) + 2j * self.s * self.c

    @property
    def z_minus_1(self) -> np.ndarray:
        """``z - 1 = 2j s (c + j s)``."""
        return 2j * self.s * (self.c + 1j * self.s)

    def sinc(self) -> np.ndarray:
        """``sin(theta)/theta`` (``theta > 0``)."""
        return 2.0 * self.s * self.c / self.theta

    def take(self, where: np.ndarray) -> HalfAngle:
        """These values at ``theta[where]`` only."""
        return HalfAngle(self.theta[where], self.s[where], self.c[where])


def half_angle(theta: np.ndarray) -> HalfAngle:
    """:class:`HalfAngle` of real ``theta`` in ``[0, pi]`` (rad)."""
    return HalfAngle(theta, np.sin(0.5 * theta), np.sin(0.5 * (np.pi - theta)))


def unit_point(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(z, z - 1)`` for ``z = e^{j theta}``; real ``theta`` exact at multiples of ``pi``, complex by ``np.exp``.

    ``z - 1 = 2j sin(theta/2) e^{j theta/2}``: no cancellation as ``theta -> 0``.
    """
    if np.iscomplexobj(theta):
        half = 0.5 * theta
        return np.exp(1j * theta), 2j * np.sin(half) * np.exp(1j * half)
    if theta.size and 0.0 <= float(np.min(theta)) and float(np.max(theta)) <= np.pi:
        circle = half_angle(theta)
        return circle.z, circle.z_minus_1
    x = theta / np.pi
    z = cospi(x) + 1j * sinpi(x)
    s = sinpi(0.5 * x)
    return z, 2j * s * (cospi(0.5 * x) + 1j * s)
