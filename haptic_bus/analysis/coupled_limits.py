"""Limits along a direction: every passive ``K`` (and ``B``) of a plane wall with normal ``n`` on coupled axes.

A plane wall ``K n n^T``, ``B n n^T`` adds a rank-two Hermitian term to ``Herm Z``
(:mod:`haptic_bus.analysis.coupled`): with ``ell = K T + B h`` (N s/m, ``h = 1 - z^{-1}``),
``p = sum n_i^2 P_i T/m_i``, ``U = 1 + ell p`` and ``gamma = ell / (j theta U)``,

    Herm Z = diag(b) + Herm(gamma a b^T),     a_i = n_i eps_i,  b_i = n_i mu_i.

For ``diag(b) > 0`` this is positive semidefinite iff the ``2 x 2`` matrix ``C (X^H diag(b)^{-1} X)``
(``X = [gamma a, conj b]``, ``C = [[0, 1/2], [1/2, 0]]``) has no eigenvalue below ``-1``,
which works out to ``|2 + gamma sigma|^2 >= |gamma|^2 A Bmu`` with ``A = sum n_i^2/b_i``,
``Bmu = sum n_i^2 |mu_i|^2/b_i``, ``sigma = sum n_i^2 eps_i mu_i / b_i``.  Multiplied by
``|theta U|^2 / 4``:

    F(theta) = |U|^2 - Im(U conj(ell sigma))/theta - |ell|^2 Gamma >= 0,
    Gamma = (A Bmu - |sigma|^2)/(4 theta^2) = (1/8) sum_{i,k} (n_i n_k)^2/(b_i b_k) |Psi_ik|^2,

(Lagrange's identity; ``E_i - E_k = j theta Psi_ik`` for ``E_i = eps_i mu_i``, formed without
cancellation as in :mod:`haptic_bus.analysis.coupled`).  With every axis on one timing
``Gamma = 0`` and ``F >= 0`` is the 1-D condition of the mobility projection (see
:mod:`haptic_bus.analysis.coupled`).  ``ell`` is affine in ``K`` and in ``B``, so at each
``theta`` ``F`` is a real quadratic in either (:func:`plane_quadratic`).

**The passive set** (:func:`passive_along`): on the search grid every root of every ``F_theta``
in ``[0, top]`` is a breakpoint; the middle of each stretch between consecutive breakpoints is
allowed when every ``F_theta`` is ``>= 0`` there (within the sign tolerance) and the coupled
loop there is stable; allowed stretches merge into closed intervals.  Each end that is not 0
or the range's top is the envelope of a root branch, ``min_theta`` (upper end) or ``max_theta``
(lower end) of the root nearest the interval, refined by the vectorised zoom of
:mod:`haptic_bus.analysis.theta_search`.  An axis-aligned normal is the 1-D loop of that axis
(:func:`~haptic_bus.analysis.limits.passive_set`, exactly); axes the normal does not touch
take no part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.coupled import measurement_lag
from haptic_bus.analysis.coupled_loop import coupled_poles, plane_wall, unit_normal
from haptic_bus.analysis.criterion import SIGN_TOLERANCE
from haptic_bus.analysis.frequency import delay_rotation, loop_terms, measurement_terms
from haptic_bus.analysis.limits import PassiveSet, passive_set
from haptic_bus.analysis.loop import DAMPING_RANGE, STIFFNESS_RANGE, WallLoop
from haptic_bus.analysis.poles import radius_excess
from haptic_bus.analysis.theta_complex import ThetaComplex
from haptic_bus.analysis.theta_search import refine_minima, theta_grid
from haptic_bus.analysis.trig import cospi, sincpi
from haptic_bus.errors import ParameterError

FAMILIES = ("K", "B", "scale")


@dataclass(frozen=True)
class PlaneWall:
    """A plane wall on coupled axes: the axes (walls 0), unit ``normal``, ``K`` N/m, ``B`` N s/m."""

    axes: tuple[WallLoop, ...]
    normal: np.ndarray
    K: float
    B: float

    def with_value(self, which: str, value: float) -> PlaneWall:
        """The same wall with ``K`` (``which = "K"``) or ``B`` set to ``value``, or both scaled by it (``"scale"``)."""
        if which == "scale":
            return PlaneWall(self.axes, self.normal, value * self.K, value * self.B)
        return PlaneWall(self.axes, self.normal, value, self.B) if which == "K" else PlaneWall(self.axes, self.normal,
                                                                                                self.K, value)

    def stable(self) -> bool:
        """Every closed-loop pole of the coupled loop strictly inside the unit circle."""
        poles = coupled_poles(plane_wall(self.axes, self.normal, self.K, self.B))
        return bool(radius_excess(poles[:1] - 1.0)[0] < 0.0)


def _pair_terms(wall: PlaneWall, theta: np.ndarray) -> tuple[ThetaComplex, ThetaComplex, ThetaComplex, np.ndarray]:
    """``(p, sigma, h, Gamma)`` on ``theta``: aliases along ``n``, the weighted lag sum, the hold, the spread."""
    n, T = wall.normal, wall.axes[0].T
    terms = [loop_terms(axis, theta) for axis in wall.axes]
    eps = [delay_rotation(theta, axis.delay) for axis in wall.axes]
    mu = [measurement_terms(axis, theta) for axis in wall.axes]
    nu = [measurement_lag(axis, theta) for axis in wall.axes]
    weights = [ni * ni / axis.b for ni, axis in zip(n, wall.axes)]
    p = sum((t.P * (ni * ni * T / axis.m) for t, ni, axis in zip(terms, n, wall.axes)), ThetaComplex.exact(theta, 0, 0))
    sigma = sum((e * m * w for e, m, w in zip(eps, mu, weights)), ThetaComplex.exact(theta, 0, 0))
    spread = np.zeros(theta.shape)
    for i, axis_i in enumerate(wall.axes):
        for k in range(i + 1, len(wall.axes)):
            half_diff, half_sum = 0.5 * (axis_i.delay - wall.axes[k].delay), 0.5 * (axis_i.delay + wall.axes[k].delay)
            x = theta * (half_sum / np.pi)
            gap = -2.0 * half_diff * sincpi(theta * (abs(half_diff) / np.pi))  # sinc is even; trig wants x >= 0
            rho = ThetaComplex.exact(theta, gap * cospi(x), -gap * half_sum * sincpi(x))  # (eps_i - eps_k)/(j theta)
            psi = rho * mu[i] + eps[k] * (nu[k] + nu[i] * -1.0)
            spread += 0.25 * weights[i] * weights[k] * psi.abs2()  # i < k: each pair once, (1/8) * 2
    return p, sigma, terms[0].hold, spread


def plane_quadratic(wall: PlaneWall, which: str, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``F_theta(x) = Q2 x^2 + Q1 x + Q0`` with ``x`` = ``K`` (N/m) or ``B`` (N s/m), the other held,
    or the scale ``s`` of the wall ``(s K, s B)`` (``which = "scale"``: ``ell = s (K T + B h)``):
    coefficients ``(3, n)`` highest power first, and the same with every term's magnitude."""
    T = wall.axes[0].T
    p, sigma, hold, spread = _pair_terms(wall, theta)
    if which == "K":
        base, slope = hold * wall.B, ThetaComplex.exact(theta, T, 0.0)
    elif which == "scale":
        base, slope = ThetaComplex.exact(theta, 0.0, 0.0), hold * wall.B + wall.K * T
    else:
        base, slope = ThetaComplex.exact(theta, wall.K * T, 0.0), hold
    U, V = p * base + 1.0, p * slope
    base_s, slope_s = base * sigma, slope * sigma
    uv, bs = U * V.conj(), base * slope.conj()
    q2 = V * slope_s.conj()
    q1 = U * slope_s.conj() + V * base_s.conj()
    q0 = U * base_s.conj()
    t2 = theta * theta
    coefficients = np.stack([V.abs2() - q2.im - spread * slope.abs2(), 2.0 * uv.re - q1.im - 2.0 * spread * bs.re,
                             U.abs2() - q0.im - spread * base.abs2()])
    magnitudes = np.stack([
        V.mag_re**2 + t2 * V.mag_im**2 + q2.mag_im + spread * slope.abs2(),
        2.0 * uv.mag_re + q1.mag_im + 2.0 * spread * bs.mag_re,
        U.mag_re**2 + t2 * U.mag_im**2 + q0.mag_im + spread * base.abs2(),
    ])
    return coefficients, magnitudes


def _roots(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The real roots ``r1 <= r2`` of each column's quadratic (NaN without; a linear column's root twice)."""
    a, b, c = q
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - 4.0 * a * c
        half = -0.5 * (b + np.copysign(np.sqrt(np.where(disc >= 0.0, disc, np.nan)), b))
        first = np.where(a == 0.0, -c / b, half / a)
        second = np.where(a == 0.0, -c / b, c / half)
    return np.fmin(first, second), np.fmax(first, second)


def _ends(wall: PlaneWall, which: str, grid: np.ndarray, inside: float, upper: bool) -> float:
    """The interval's end beyond ``inside``: ``min_theta`` (upper) / ``max_theta`` (lower) of the nearest root, zoomed."""

    def branch(theta: np.ndarray) -> np.ndarray:
        r1, r2 = _roots(plane_quadratic(wall, which, theta)[0])
        if upper:
            near = np.where(r1 > inside, r1, np.where(r2 > inside, r2, np.inf))
        else:
            near = -np.where(r2 < inside, r2, np.where(r1 < inside, r1, -np.inf))
        return np.fmin(near, 1e300)

    values = branch(grid)
    _, refined = refine_minima(branch, grid, values)
    best = float(np.min(np.concatenate([values, refined])))
    return best if upper else -best


def passive_along(axes: tuple[WallLoop, ...], normal: ArrayLike, K: float, B: float, which: str) -> PassiveSet:
    """Every passive ``K`` (N/m) at this ``B`` (``which = "K"``), or ``B`` (N s/m) at this ``K``, or scale
    ``s`` in [0, 1] of the wall ``(s K, s B)`` (``"scale"``: a start ramp's), of the plane wall with
    ``normal`` on ``axes`` (module docstring): closed intervals, ascending."""
    if which not in FAMILIES:
        raise ParameterError("which", which, "'K', 'B' or 'scale'", "passive set along a direction")
    n = unit_normal(normal, len(axes))
    touched = [i for i in range(len(axes)) if n[i] != 0.0]
    if len(touched) == 1:
        i = touched[0]
        return passive_set(axes[i].with_wall(K, B), which)
    if any(axes[i].b <= 0.0 for i in touched):
        raise ParameterError("b", [axes[i].b for i in touched], "b > 0 N s/m on every axis the wall couples",
                             "limits along a direction")
    wall = PlaneWall(tuple(axes[i] for i in touched), n[touched], K, B)
    top = {"K": STIFFNESS_RANGE[1], "B": DAMPING_RANGE[1], "scale": 1.0}[which]
    poles = coupled_poles(plane_wall(wall.axes, wall.normal, K, B))
    grid = np.unique(np.concatenate([theta_grid(axis, poles) for axis in wall.axes]))
    q, magnitudes = plane_quadratic(wall, which, grid)
    tolerant = q + SIGN_TOLERANCE * magnitudes
    r1, r2 = _roots(q)
    breaks = np.concatenate([r1, r2])
    breaks = np.unique(np.concatenate([[0.0, top], breaks[(breaks > 0.0) & (breaks < top)]]))
    middles = 0.5 * (breaks[:-1] + breaks[1:])
    value = tolerant[0][None, :] * middles[:, None] ** 2 + tolerant[1][None, :] * middles[:, None] + tolerant[2][None, :]
    allowed = np.all(value >= 0.0, axis=1)
    intervals: list[tuple[float, float]] = []
    for k in np.flatnonzero(allowed):
        lo, hi = float(breaks[k]), float(breaks[k + 1])
        if intervals and intervals[-1][1] == lo:
            intervals[-1] = (intervals[-1][0], hi)
        else:
            intervals.append((lo, hi))
    out = []
    for lo, hi in intervals:
        inside = 0.5 * (lo + hi)
        if not wall.with_value(which, inside).stable():
            continue
        low = lo if lo == 0.0 else max(_ends(wall, which, grid, inside, upper=False), 0.0)
        high = hi if hi == top else min(_ends(wall, which, grid, inside, upper=True), top)
        out.append((low, high))
    return PassiveSet(which, tuple(out))
