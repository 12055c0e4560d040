"""The exact passivity criterion of a wall that couples several axes (issue 22).

The loop: :mod:`haptic_bus.analysis.coupled_loop` (``N`` axes, each its own drive, velocity
model and delay ``D_i``; a wall ``u = K x + B y`` with symmetric ``K``, ``B``).  An operator
force ``W e^{j omega t}`` (a complex ``N``-vector, below Nyquist) meets, at its own frequency,
the matrix admittance ``T_fund(theta)`` (m/(N s)); the mean power it puts in is
``Re(W^H T_fund W)/2``.  So the loop is passive (for operator forces band-limited below
Nyquist, in every direction) iff

1. every closed-loop pole lies strictly inside the unit circle, and
2. the Hermitian part of ``T_fund(theta)`` is positive semidefinite on ``(0, pi]``.

As in 1-D, condition 2 is judged on the impedance ``Z = T_fund^{-1}`` (N s/m): its Hermitian
part is congruent to ``T_fund``'s (``Z + Z^H = Z (T^H + T) Z^H``), so it has the same inertia,
and stays finite as ``theta -> 0``.  **The margin** is the least eigenvalue of ``Herm Z`` over
``(0, pi]``, in N s/m: the least net damping the operator feels in any direction at any
frequency; its eigenvector is the worst velocity direction, and ``W = Z v`` the operator force
that drives it.  For one axis it is ``min Re Z``, the 1-D margin.  An unstable loop's margin
is ``-(rho - 1) max(m_i)/T``.

**The impedance matrix.**  Per axis, from the 1-D terms (:func:`~haptic_bus.analysis.frequency.loop_terms`):
the hold ``h = 1 - z^{-1}``, the aliases ``P_i = z^{-d_i} g_i(theta)``, the delay
``eps_i = e^{-j theta D_i}`` and the measurement ``mu_i = M_i(j theta)``.  With the wall
``L = K T + B h`` (N s/m), ``Dp = diag(P_i T/m_i)``, ``E = diag(eps_i)``, ``Mu = diag(mu_i)``,
Woodbury's identity applied to the sampled-data loop's fundamental response gives

    Z = diag(b_i + j theta m_i/T) + E G Mu / (j theta),      G = L (I + Dp L)^{-1} = (I + L Dp)^{-1} L,

(for one axis: DESIGN 3.5's ``Z T/m = s + L E/(j theta U)``).  ``G`` is complex symmetric, so
``Herm Z = S + j A`` with the real symmetric ``S = diag(b) + sym(Im Y/theta)``, ``Y = E G Mu``,
and the real antisymmetric ``A = -(Re Y - Re Y^T)/(2 theta)``.  Both are formed without a
``1/theta`` loss, as the 1-D code does (values carried as ``(Re, Im/theta)``,
:class:`~haptic_bus.analysis.theta_complex.ThetaComplex`): ``G`` from the real block system
``[[Xr^T, -theta^2 Xi^T], [Xi^T, Xr^T]] [Gr; Gi] = [Lr; Li]`` for ``X = I + Dp L = Xr + j theta Xi``,
and ``Y - Y^T = G o Delta`` (elementwise) with ``Delta_ik = eps_i mu_k - mu_i eps_k = j theta Omega_ik``,
``Omega_ik = rho_ik mu_k + eps_k (nu_i - nu_k)``, ``eps_i - eps_k = j theta rho_ik`` in closed form and
``mu = 1 - j theta nu`` (:func:`measurement_lag`), so ``A = theta Im(G o Omega)/(2 theta)``.
For one axis ``A = 0``, and an axis-aligned wall leaves the axes apart
(:func:`~haptic_bus.analysis.coupled_loop.components`): both are the 1-D criterion itself.

**The sign** of the least eigenvalue is judged against ``SIGN_TOLERANCE`` times the size of
the terms summed (``max b_i`` plus the Frobenius norms of the wall part's term magnitudes).
The search over ``theta``: the union of every axis' 1-D grid with fans at the coupled loop's
lightly damped poles, and the 1-D zoom (:mod:`haptic_bus.analysis.theta_search`).

**Is checking each axis' projection enough?  No** (issue 22; pinned by
tests/test_coupled_projection.py, every number below checked there, the active ones against the
exact time-domain energy of :mod:`haptic_bus.analysis.coupled_energy`).  ``T = 1 ms``, ``B = 0``,
a plane at 45 degrees, ``n = (1, 1)/sqrt 2``.

* *Each axis alone with ``K n_i^2``, ``B n_i^2``* can be optimistic by up to a factor ``N``,
  even for identical axes: the wall's negative damping ``K tau`` acts along ``n`` and the
  operator can move along ``n`` with both axes' friction in series, not one.  Two
  cia402-handle axes (``m = 1 kg``, ``b = 20 N s/m``, ``D = 1``, ``average``): per axis every
  ``K <= 26 667 N/m`` passes, the coupled limit is ``13 333 N/m``; at ``K = 20 000`` each axis
  alone has margin ``+5.0 N s/m`` while the coupled loop is unstable (largest ``|z|``
  ``1.00478``) and the operator's energy from rest falls below ``-2e6 J``.
* *The 1-D loop along ``n`` with ``n^T M n``, ``n^T b n``* is optimistic as soon as the axes
  differ: ``m = (1, 0.25) kg``, ``b = (20, 5) N s/m`` (same timing): the arithmetic
  projection (0.625 kg, 12.5 N s/m) passes ``K <= 8 333``, the coupled limit is ``5 333``; at
  ``K = 7 000`` the projection has margin ``+2.0`` and the coupled loop is unstable.
* *The 1-D loop along ``n`` with the mobility projection* ``m_n = 1/(n^T M^{-1} n)``,
  ``b_n = 1/(n^T diag(b)^{-1} n)`` **is exact when every axis has the same timing (``D``,
  velocity model) and the same ``b_i/m_i``** -- proof: the plant ``dv_i/dt = -(c/T) v_i - (n_i/m_i) f``
  gives ``s = n^T v`` the 1-D plant ``m_n ds/dt = -b_n s - f`` and the other directions the
  decoupled decay ``e^{-c}``; the measurement filters and delays being alike, ``n^T y`` is
  ``s`` measured, so the poles are the 1-D loop's plus ``e^{-c}``'s; and ``Herm Z = diag(b) +
  r(theta) n n^T`` with the 1-D wall term ``r`` of ``(m_n, b_n)``, PSD iff
  ``1 + r n^T diag(b)^{-1} n >= 0``, i.e. iff ``b_n + r = Re Z_1D >= 0`` (the example above:
  both limits ``5 333.33465 N/m``).  Otherwise it is not: the aliasing terms ``P_i`` depend on
  each ``c_i = b_i T/m_i``, and the axes' delays and filters differ.  ``m = (1, 1)``,
  ``b = (20, 2)``, ``point``, ``D = 0`` (the seed's ideal loop): the mobility projection
  (1 kg, 3.64 N s/m) passes ``K <= 4.000e6``, the coupled limit is ``3.078e6`` (the flip
  boundary at ``theta = pi``); at ``K = 3.5e6`` margin ``+1.65`` against ``-1.50 N s/m``,
  and ``-0.709 W`` per (m/s)^2 measured in the time domain.  With different timing there is no
  one projection: ``(1 kg, 20 N s/m, D = 1, point)`` beside ``(0.5 kg, 10 N s/m, D = 0.5,
  average)`` (equal ``b/m``, equal low-frequency lag): the coupled limit ``13 318.5`` lies
  between the mobility projection with the second axis' timing (``13 333.3``, optimistic: at
  ``K = 13 325`` margin ``+0.0083`` against ``-0.0058``, ``-0.0029 W`` in the time domain) and
  with the first axis' (``13 289.1``).

So the gate judges the coupled loop itself.  The mobility projection is what to reason with
(``K`` roughly ``<= b_n / tau_eff`` along ``n``, DESIGN 3.5), never what to gate with.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.coupled_loop import CoupledLoop, components, coupled_poles
from haptic_bus.analysis.criterion import EXACT, SIGN_TOLERANCE, Verdict, exact_verdict
from haptic_bus.analysis.frequency import delay_rotation, hold_and_aliases, measurement_terms
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import radius_excess
from haptic_bus.analysis.sampled_loop import window_fraction
from haptic_bus.analysis.theta_complex import ThetaComplex
from haptic_bus.analysis.theta_search import refine_minima, theta_grid
from haptic_bus.analysis.trig import cospi, half_angle, sincpi
from haptic_bus.errors import ParameterError

COUPLED = "exact, coupled axes: closed-loop stability and Herm T_fund >= 0 on (0, pi] (least eigenvalue)"
_SEARCH = "union of the axes' grids + coupled pole fans + vectorised zoom + parabola"
_LAG_TERMS = 30  # series of phi2(j y), |y| <= pi: pi^60 / 62! < 1e-50
_LAG_EVEN = np.array([(-1.0) ** k / math.factorial(2 * k + 2) for k in range(_LAG_TERMS)])[::-1]
_LAG_ODD = np.array([(-1.0) ** k / math.factorial(2 * k + 3) for k in range(_LAG_TERMS)])[::-1]


def measurement_lag(axis: WallLoop, theta: np.ndarray) -> ThetaComplex:
    """``nu = (1 - M(j theta)) / (j theta)`` (in periods) as ``(Re, Im/theta)``: the measurement's lag, no cancellation.

    ``0`` (point), ``tau/(1 + j theta tau)`` (lowpass, ``tau = TAU/T``), ``w phi2(j theta w)``
    (window ``w = TW/T``, ``phi2(x) = (x - 1 + e^{-x})/x^2 = sum (-x)^n/(n + 2)!``, summed as a
    polynomial in ``(theta w)^2``: its terms are at most ``pi^2/24``, nothing cancels).
    """
    kind = axis.velocity.kind
    if kind == "point":
        return ThetaComplex.exact(theta, 0.0, 0.0)
    if kind == "lowpass":  # 1 - M = j theta tau M
        return measurement_terms(axis, theta) * (axis.velocity.time / axis.T)
    width = window_fraction(axis)
    y2 = (theta * width) ** 2
    return ThetaComplex.exact(theta, width * np.polyval(_LAG_EVEN, y2), -width * width * np.polyval(_LAG_ODD, y2))


def _per_axis(axes: tuple[WallLoop, ...], key: Callable[[WallLoop], Hashable],
              compute: Callable[[WallLoop], ThetaComplex]) -> list[ThetaComplex]:
    """``compute(axis)`` for every axis, computed once for the axes alike in ``key(axis)`` (what it depends on)."""
    found: dict[Hashable, ThetaComplex] = {}
    for axis in axes:
        if key(axis) not in found:
            found[key(axis)] = compute(axis)
    return [found[key(axis)] for axis in axes]


def _lift(parts: list[ThetaComplex], theta3: np.ndarray, column: bool) -> ThetaComplex:
    """Per-axis values ``(n,)`` stacked to an ``(n, N, 1)`` column or an ``(n, 1, N)`` row over ``theta3`` ``(n, 1, 1)``."""

    def stack(field: str) -> np.ndarray:
        values = np.empty((theta3.shape[0], len(parts)))
        for i, p in enumerate(parts):
            values[:, i] = getattr(p, field)
        return values[:, :, None] if column else values[:, None, :]

    return ThetaComplex(theta3, stack("re"), stack("im"), stack("mag_re"), stack("mag_im"))


@dataclass(frozen=True)
class HermitianImpedance:
    """``Herm Z = S + j A`` on a ``theta`` array (N s/m): ``symmetric`` ``S`` and ``antisymmetric`` ``A``,
    each ``(n, N, N)``, the ``scale`` ``(n,)`` of the terms summed, and ``Z`` itself (``full``)."""

    theta: np.ndarray
    symmetric: np.ndarray
    antisymmetric: np.ndarray
    scale: np.ndarray
    full: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        """``Herm Z`` as complex Hermitian matrices ``(n, N, N)``."""
        return self.symmetric + 1j * self.antisymmetric


def hermitian_impedance(loop: CoupledLoop, theta: np.ndarray) -> HermitianImpedance:
    """``Herm Z`` and ``Z`` of ``loop`` at ``theta`` (rad, in (0, pi]), N s/m (module docstring)."""
    theta = np.atleast_1d(np.asarray(theta, dtype=float))
    n, size, T = theta.size, loop.size, loop.T
    theta3 = theta[:, None, None]
    circle = half_angle(theta)
    terms = [hold_and_aliases(axis, circle) for axis in loop.axes]
    hold = terms[0][0]
    eps = _per_axis(loop.axes, lambda axis: axis.delay, lambda axis: delay_rotation(theta, axis.delay))
    mu = _per_axis(loop.axes, lambda axis: axis.velocity, lambda axis: measurement_terms(axis, theta))
    nu = _per_axis(loop.axes, lambda axis: axis.velocity, lambda axis: measurement_lag(axis, theta))
    alias = [P * (T / axis.m) for (_, _, P), axis in zip(terms, loop.axes)]

    h = ThetaComplex(theta3, hold.re[:, None, None], hold.im[:, None, None], hold.mag_re[:, None, None],
                     hold.mag_im[:, None, None])
    K, B = loop.K, loop.B
    L = ThetaComplex(theta3, T * K + B * h.re, B * h.im, T * np.abs(K) + np.abs(B) * h.mag_re, np.abs(B) * h.mag_im)
    X = _lift(alias, theta3, column=True) * L  # Dp L
    eye = np.eye(size)
    xr, xi = X.re + eye, X.im
    t2 = theta3 * theta3
    system = np.block([[np.swapaxes(xr, 1, 2), -t2 * np.swapaxes(xi, 1, 2)], [np.swapaxes(xi, 1, 2), np.swapaxes(xr, 1, 2)]])
    rhs = np.concatenate([np.broadcast_to(L.re, (n, size, size)), np.broadcast_to(L.im, (n, size, size))], axis=1)
    solution = np.linalg.solve(system, rhs)
    gr, gi = solution[:, :size], solution[:, size:]
    G = ThetaComplex(theta3, gr, gi, np.abs(gr), np.abs(gi))

    mu_row = _lift(mu, theta3, column=False)
    Y = _lift(eps, theta3, column=True) * G * mu_row
    b = np.array([axis.b for axis in loop.axes])
    symmetric = np.diag(b) + 0.5 * (Y.im + np.swapaxes(Y.im, 1, 2))

    D = np.array([float(axis.delay) for axis in loop.axes])
    half_sum, half_diff = 0.5 * (D[:, None] + D[None, :]), 0.5 * (D[:, None] - D[None, :])
    x = theta3 * (half_sum / np.pi)
    turn = cospi(x), -half_sum * sincpi(x)  # e^{-j theta (D_i + D_k)/2}
    gap = -2.0 * half_diff * sincpi(theta3 * (np.abs(half_diff) / np.pi))  # sinc is even; trig wants x >= 0
    rho = ThetaComplex(theta3, gap * turn[0], gap * turn[1], np.abs(gap * turn[0]), np.abs(gap * turn[1]))
    nu_col, nu_row = _lift(nu, theta3, column=True), _lift(nu, theta3, column=False)
    spread = nu_col + nu_row * -1.0
    omega = rho * mu_row + _lift(eps, theta3, column=False) * spread
    skew = G * omega
    antisymmetric = 0.5 * theta3 * skew.im
    antisymmetric = 0.5 * (antisymmetric - np.swapaxes(antisymmetric, 1, 2))

    y_mag = 0.5 * (Y.mag_im + np.swapaxes(Y.mag_im, 1, 2))
    scale = np.max(b) + np.linalg.norm(y_mag, axis=(1, 2)) + 0.5 * theta * np.linalg.norm(skew.mag_im, axis=(1, 2))
    m = np.array([axis.m for axis in loop.axes])
    full = np.diag(b) + Y.im + 1j * (theta3 * np.diag(m / T) - Y.re / theta3)
    return HermitianImpedance(theta, symmetric, antisymmetric, scale, full)


def least_eigenvalue(loop: CoupledLoop, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(least eigenvalue of Herm Z, SIGN_TOLERANCE * scale)`` at each ``theta``, N s/m."""
    part = hermitian_impedance(loop, theta)
    return np.linalg.eigvalsh(part.matrix)[:, 0], SIGN_TOLERANCE * part.scale


def worst_direction(loop: CoupledLoop, theta: float) -> np.ndarray:
    """The unit velocity direction (complex ``N``-vector) of the least eigenvalue of ``Herm Z(theta)``."""
    _, vectors = np.linalg.eigh(hermitian_impedance(loop, np.array([theta])).matrix[0])
    return _phase_fixed(vectors[:, 0])


def _phase_fixed(v: np.ndarray) -> np.ndarray:
    """``v`` turned so that its largest entry is real and positive (an eigenvector's phase is free)."""
    return v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))


@dataclass(frozen=True)
class CoupledVerdict(Verdict):
    """The coupled criterion's outcome: a :class:`~haptic_bus.analysis.criterion.Verdict` (``margin`` in
    N s/m, ``>= 0`` iff passive, at ``critical_theta`` rad; ``spectral_radius`` the largest pole
    magnitude over every group; ``lossless`` when every group is a free frictionless axis) with
    ``direction`` the worst velocity direction (complex, unit, one entry per axis of the loop),
    ``group`` the axes it lies in, and ``groups`` the axis groups judged apart (:func:`components`).
    """

    direction: tuple[complex, ...] = ()
    group: tuple[int, ...] = ()
    groups: tuple[tuple[int, ...], ...] = ()


@dataclass(frozen=True)
class _GroupResult:
    passive: bool
    stable: bool
    margin: float
    theta: float
    radius: float
    direction: np.ndarray
    lossless: bool = False


def _free_frictionless(loop: CoupledLoop) -> list[int]:
    """Frictionless axes among which the wall leaves a free direction (a ``z = 1`` mode), else ``[]``."""
    free = [i for i, axis in enumerate(loop.axes) if axis.b == 0.0]
    if not free:
        return []
    seen = np.vstack([loop.K[:, free], loop.B[:, free]])
    return free if np.linalg.matrix_rank(seen) < len(free) else []


def _axis_result(loop: WallLoop) -> _GroupResult:
    verdict = exact_verdict(loop)
    return _GroupResult(verdict.passive, verdict.stable, verdict.margin, verdict.critical_theta, verdict.spectral_radius,
                        np.ones(1, dtype=complex), verdict.lossless)


def _group_result(loop: CoupledLoop) -> _GroupResult:
    free = _free_frictionless(loop)
    if free:
        raise ParameterError("b", [loop.axes[i].b for i in free],
                             "an effective friction b > 0 N s/m on axes " + ", ".join(map(str, free))
                             + ": the wall leaves them a free frictionless direction (a z = 1 mode)", "coupled gate")
    poles = coupled_poles(loop)
    excess = float(radius_excess(poles[:1] - 1.0)[0])
    grid = np.unique(np.concatenate([theta_grid(axis, poles) for axis in loop.axes]))
    values, tolerance = least_eigenvalue(loop, grid)
    thetas, _ = refine_minima(lambda t: least_eigenvalue(loop, t)[0], grid, values)
    at = np.append(thetas, grid[np.argmin(values)])  # the refined points and the grid's least
    part = hermitian_impedance(loop, at)
    refined, vectors = np.linalg.eigh(part.matrix)
    ok = bool(np.all(values >= -tolerance) and np.all(refined[:, 0] >= -SIGN_TOLERANCE * part.scale))
    i = int(np.argmin(refined[:, 0]))
    theta, margin = float(at[i]), float(refined[i, 0])
    direction = _phase_fixed(vectors[i, :, 0])
    if excess >= 0.0:
        scale = max(axis.m for axis in loop.axes) / loop.T
        return _GroupResult(False, False, -max(excess * scale, math.ulp(1.0)), theta, 1.0 + excess, direction)
    if ok and margin < 0:
        margin = 0.0  # within the evaluation's round-off of the boundary
    return _GroupResult(ok, True, margin, theta, 1.0 + excess, direction)


def coupled_verdict(loop: CoupledLoop, split: bool = True) -> CoupledVerdict:
    """The exact criterion of the coupled loop (module docstring).

    ``split``: each group of linked axes judged on its own, a lone axis by the 1-D criterion
    (exactly today's verdict); ``False``: the whole loop by the matrix evaluation (the same
    numbers to round-off: what the reduction tests compare).  Raises ParameterError when
    frictionless axes keep a direction the wall does not see.
    """
    groups = components(loop) if split else [list(range(loop.size))]
    results = [_axis_result(loop.axis_loop(g[0])) if split and len(g) == 1 else _group_result(loop.part(g)) for g in groups]
    worst = min(range(len(groups)), key=lambda k: results[k].margin)
    direction = np.zeros(loop.size, dtype=complex)
    direction[groups[worst]] = results[worst].direction
    return CoupledVerdict(
        criterion=EXACT if loop.size == 1 else COUPLED,
        passive=all(r.passive for r in results),
        stable=all(r.stable for r in results),
        margin=results[worst].margin,
        critical_theta=results[worst].theta,
        spectral_radius=max(r.radius for r in results),
        method=_SEARCH,
        lossless=all(r.lossless for r in results),
        direction=tuple(complex(v) for v in direction),
        group=tuple(groups[worst]),
        groups=tuple(tuple(g) for g in groups),
    )
