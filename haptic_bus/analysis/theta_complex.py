"""Complex functions of the frequency carried as ``(Re, Im/theta)``, with a running error bound.

The impedance's real part near ``theta = 0`` is ``Im(X)/theta`` of a complex ``X`` whose real
part is ``O(1)`` and imaginary part ``O(theta)``: formed from a complex ``X`` it would carry an
absolute error ``eps |X|``, i.e. ``eps/theta`` relative.  Carried as ``(Re X, Im X/theta)``
from quantities whose ``Im/theta`` is known in closed form (``sin(theta)/theta``, a series),
products and sums never divide by ``theta``:

    Re(AB) = Re A Re B - theta^2 (Im A/theta)(Im B/theta),   Im(AB)/theta = Re A (Im B/theta) + (Im A/theta) Re B.

Beside each part the magnitudes of the terms it was summed from are carried (``mag_re``,
``mag_im``; for an exact input, the absolute values): a round-off of a few ``eps`` times them
bounds the error of the part -- the scale of "the quantities that cancel" a sign test needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


def _filled(value: ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a float array of ``shape`` (an array of that shape as it is, a scalar repeated)."""
    if isinstance(value, np.ndarray) and value.shape == shape and value.dtype == float:
        return value
    return np.broadcast_to(np.asarray(value, dtype=float), shape)


@dataclass(frozen=True)
class ThetaComplex:
    """``re = Re X``, ``im = Im X / theta`` on a ``theta`` array (rad), with term magnitudes."""

    theta: np.ndarray
    re: np.ndarray
    im: np.ndarray
    mag_re: np.ndarray
    mag_im: np.ndarray

    @classmethod
    def exact(cls, theta: np.ndarray, re: ArrayLike, im_over_theta: ArrayLike) -> ThetaComplex:
        """A value known to round-off in both parts (its magnitudes are its absolute values)."""
        re, im = _filled(re, theta.shape), _filled(im_over_theta, theta.shape)
        return cls(theta, re, im, np.abs(re), np.abs(im))

    def __add__(self, other: ThetaComplex | float | np.ndarray) -> ThetaComplex:
        if isinstance(other, ThetaComplex):
            return ThetaComplex(self.theta, self.re + other.re, self.im + other.im,
                                self.mag_re + other.mag_re, self.mag_im + other.mag_im)
        return ThetaComplex(self.theta, self.re + other, self.im, self.mag_re + np.abs(other), self.mag_im)

    __radd__ = __add__

    def __mul__(self, other: ThetaComplex | float | np.ndarray) -> ThetaComplex:
        if isinstance(other, ThetaComplex):
            t2 = self.theta * self.theta
            return ThetaComplex(
                self.theta,
                self.re * other.re - t2 * self.im * other.im,
                self.re * other.im + self.im * other.re,
                self.mag_re * other.mag_re + t2 * self.mag_im * other.mag_im,
                self.mag_re * other.mag_im + self.mag_im * other.mag_re,
            )
        return ThetaComplex(self.theta, self.re * other, self.im * other, self.mag_re * np.abs(other),
                            self.mag_im * np.abs(other))

    __rmul__ = __mul__

    def conj(self) -> ThetaComplex:
        """The complex conjugate."""
        return ThetaComplex(self.theta, self.re, -self.im, self.mag_re, self.mag_im)

    def abs2(self) -> np.ndarray:
        """``|X|^2`` (a sum of squares: no cancellation)."""
        return self.re * self.re + (self.theta * self.im) ** 2
