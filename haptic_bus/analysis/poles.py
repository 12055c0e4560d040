"""Closed-loop poles of the wall loop and its stability: eigenvalues of the closed-loop state matrix.

The poles are ``z = 1 + w`` with ``w`` the eigenvalues of ``M - I``
(:func:`~haptic_bus.analysis.sampled_loop.loop_matrix`: every velocity model, every real
delay).  No polynomial is ever expanded: the roots of an expanded characteristic polynomial
go wrong for delays in the thirties, the eigenvalues of the (balanced, LAPACK ``geev``) state
matrix stay right for ``d`` in the thousands.  Working with ``M - I``, whose entries are
formed without cancellation, keeps poles near ``z = 1`` (slow plants, soft walls) as accurate
as the small numbers ``w`` themselves.

For the point model without delay the matrix is the seed's loop and its poles are the roots of
``(z - a)(z - 1) + k1 (K T z + B (z - 1))``; the seed's design gives 0.998 and 0.8014.
"""

from __future__ import annotations

import functools

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import loop_matrix


def radius_excess(w: np.ndarray) -> np.ndarray:
    """``|1 + w| - 1`` without cancellation: ``(2 Re w + |w|^2) / (|1 + w| + 1)``."""
    w = np.asarray(w, dtype=complex)
    return (2.0 * w.real + np.abs(w) ** 2) / (np.abs(1.0 + w) + 1.0)


@functools.lru_cache(maxsize=1024)
def _shifted_poles(loop: WallLoop) -> np.ndarray:
    w = np.linalg.eigvals(loop_matrix(loop))
    w = w[np.argsort(-radius_excess(w), kind="stable")]
    w.setflags(write=False)
    return w


def shifted_poles(loop: WallLoop) -> np.ndarray:
    """Closed-loop poles minus one, ``w = z - 1`` (complex), largest ``|z|`` first; accurate near ``z = 1``."""
    return _shifted_poles(loop)


def closed_loop_poles(loop: WallLoop) -> np.ndarray:
    """The closed-loop poles in the z-plane (complex, sorted by decreasing magnitude)."""
    return 1.0 + _shifted_poles(loop)


def spectral_radius(loop: WallLoop) -> float:
    """Largest closed-loop pole magnitude (dimensionless); < 1 means stable."""
    return 1.0 + float(radius_excess(_shifted_poles(loop)[:1])[0])


def is_stable(loop: WallLoop) -> bool:
    """True if every closed-loop pole is strictly inside the unit circle."""
    return bool(radius_excess(_shifted_poles(loop)[:1])[0] < 0.0)
