"""High-precision reference of the passive boundary (mpmath, 40 digits), for the benchmark and the tests.

Straight from the definitions (DESIGN 3.5), with no reformulation, for every velocity model and
real delay ``D = d + delta``.  The sampled map from wall force to measured velocity is built
from matrix exponentials (``mp.expm``) of the physical plant ``m dv/dt = -b v + f`` with the
measurement's state (position for a differencing window, the filter state for a low-pass),
piece by piece over the period (force switch at ``delta T``, window start at ``T - TW``):
``G_md = z^{-d} C (zI - Phi)^{-1} (g_now + g_before/z)``.  The impedance the operator feels is
``Z = 1/T_fund``, ``T_fund = G11 [1 - (H/T) e^{-j omega D T} K_d M G11 / (1 + G_md K_d)]`` at
``z = e^{j theta}``, ``s = j theta/T``.  Stability: the eigenvalues (``mp.eig``) of the closed-loop
matrix on ``[plant states, x_{k-1}, u_{k-1}, ..]``; for a delay over 60 samples the Schur-Cohn
recursion on its characteristic polynomial (:func:`schur_cohn_stable`, in the working precision).
The largest passive ``K`` at a given ``B``
(or ``B`` at a given ``K``) is where ``min_theta Re Z`` touches zero:

1. scan ``Re Z`` at the double-precision estimate on 240 uniform points of ``(0, pi]`` (4 per turn
   of a long delay's ``e^{-j theta D}`` if more) plus a
   logarithmic fan from ``1e-12`` (standing in for ``theta -> 0``: ``Re Z`` is even in
   ``theta``, so it is off by ``O(1e-24)``) and refine every interior local minimum by golden
   section (to ``1e-15`` rad);
2. the global minimum at ``theta = pi`` (an end point): the boundary is the root of
   ``Re Z(X, pi) = 0`` (the flip boundary); at ``theta -> 0``: the root of
   ``Re Z(X, 1e-12) = 0`` (a low-frequency boundary); in the interior: the tangency, the root in ``X``
   of the envelope ``min_theta Re Z(X, theta)`` with the minimum located by golden section
   (to ``1e-19`` rad, so the envelope is exact to ~1e-38 relative) inside the scan's bracket;
   both roots bracketed and solved by Anderson-Bjorck (``mp.findroot``);
3. verified: at ``X (1 - 1e-14)`` the scan's minimum is ``>= 0`` and every closed-loop pole is
   inside the unit circle; at ``X (1 + 1e-14)`` the minimum is negative or a pole is outside.

The same works for a *lower* end of a passive interval (``lower=True``: passive above, active below).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import mpmath as mp  # type: ignore[import-untyped]  # no stubs

from haptic_bus.analysis.loop import WallLoop

DIGITS = 40
_UNIFORM = 240
_PER_TURN = 4  # scan points per turn of e^{-j theta D} at least (a long delay winds D times)
_DENSE_DELAY = 60  # samples: above, stability by the Schur-Cohn recursion instead of mp.eig
_FAN = 24
_FLAT_BELOW = mp.mpf("1e-6")
THETA_LOW = mp.mpf("1e-12")  # stands in for theta -> 0: Re Z is even, so it errs by O(theta^2)
_GOLDEN_TOL = mp.mpf("1e-15")
_VERIFY = mp.mpf("1e-14")
_TANGENCY_TOL = mp.mpf("1e-19")


@dataclass(frozen=True)
class ReferenceBoundary:
    """The boundary value (N/m or N s/m), where it is attained, and whether it was verified."""

    value: float
    theta: float
    kind: str  # "flip (theta = pi)" or "tangency"
    verified: bool


def _model(loop: WallLoop) -> tuple[Any, Any, Any, tuple[int, Any] | None]:
    """Physical (A, b, C, reset) of the plant with its measurement; reset = (state, time in s) or None."""
    m, b, T = (mp.mpf(x) for x in (loop.m, loop.b, loop.T))
    kind = loop.velocity.kind
    if kind == "point":
        return mp.matrix([[-b / m]]), mp.matrix([1 / m]), mp.matrix([[1]]), None
    if kind == "lowpass":
        tau = mp.mpf(loop.velocity.time)
        return mp.matrix([[-b / m, 0], [1 / tau, -1 / tau]]), mp.matrix([1 / m, 0]), mp.matrix([[0, 1]]), None
    width = T if kind == "average" else mp.mpf(loop.velocity.time)
    return mp.matrix([[-b / m, 0], [1, 0]]), mp.matrix([1 / m, 0]), mp.matrix([[0, 1 / width]]), (1, T - width)


def sampled_map(loop: WallLoop) -> tuple[Any, Any, Any, Any]:
    """(Phi, g_now, g_before, C) of one period, physical units, from matrix exponentials (cached per precision)."""
    return _sampled_map(loop.m, loop.b, loop.T, loop.delay, loop.velocity, mp.mp.dps)


@functools.lru_cache(maxsize=64)
def _sampled_map(m_, b_, T_, delay, velocity, dps):
    loop = WallLoop(m_, b_, T_, 0.0, 0.0, delay, velocity)
    A, bu, C, reset = _model(loop)
    n = A.rows
    T = mp.mpf(loop.T)
    delta = mp.mpf(loop.delay) - int(mp.floor(mp.mpf(loop.delay)))
    times = sorted({mp.mpf(0), T, delta * T} | ({reset[1]} if reset else set()))
    phi = mp.eye(n)
    g = {"now": mp.zeros(n, 1), "before": mp.zeros(n, 1)}
    for start, stop in itertools.pairwise(times):
        if reset and start == reset[1]:
            for j in range(n):
                phi[reset[0], j] = 0
            for key in g:
                g[key][reset[0]] = 0
        aug = mp.zeros(n + 1, n + 1)
        for i in range(n):
            aug[i, n] = bu[i]
            for j in range(n):
                aug[i, j] = A[i, j]
        e = mp.expm(aug * (stop - start))
        trans = mp.matrix([[e[i, j] for j in range(n)] for i in range(n)])
        col = mp.matrix([e[i, n] for i in range(n)])
        phi = trans * phi
        g = {k: trans * v for k, v in g.items()}
        key = "before" if stop <= delta * T else "now"
        g[key] = g[key] + col
    return phi, g["now"], g["before"], C


def measurement(loop: WallLoop, s: Any) -> Any:
    """``M(s)`` of the velocity model (dimensionless) at the Laplace variable ``s`` (1/s)."""
    kind = loop.velocity.kind
    if kind == "point":
        return mp.mpf(1)
    if kind == "lowpass":
        return 1 / (1 + s * mp.mpf(loop.velocity.time))
    width = mp.mpf(loop.T) if kind == "average" else mp.mpf(loop.velocity.time)
    return (1 - mp.exp(-s * width)) / (s * width)


def response_terms(loop: WallLoop, theta: Any, K: Any = None, B: Any = None) -> tuple[Any, Any, Any, Any]:
    """(G11, G_md, K_d, (H/T) e^{-s D T} M(s)) at theta (mpf), the wall K, B overriding the loop's."""
    m, b, T = (mp.mpf(x) for x in (loop.m, loop.b, loop.T))
    K = mp.mpf(loop.K if K is None else K)
    B = mp.mpf(loop.B if B is None else B)
    theta = mp.mpf(theta)
    omega = theta / T
    s = 1j * omega
    z = mp.exp(1j * theta)
    D = mp.mpf(loop.delay)
    d = int(mp.floor(D))
    phi, g_now, g_before, C = sampled_map(loop)
    n = phi.rows
    resolvent = mp.inverse(z * mp.eye(n) - phi)
    g_md = (C * resolvent * (g_now + g_before / z))[0] * z ** (-d)
    g11 = 1 / (m * s + b)
    wall = K * T * z / (z - 1) + B
    hold = (1 - mp.exp(-s * T)) / (s * T)
    return g11, g_md, wall, hold * mp.exp(-s * D * T) * measurement(loop, s)


def impedance(loop: WallLoop, K: Any, B: Any, theta: Any) -> Any:
    """``1/T_fund`` in N s/m at ``theta`` for the wall ``K``, ``B`` (all mpf), from the definition."""
    g11, g_md, wall, path = response_terms(loop, theta, K, B)
    return 1 / (g11 * (1 - path * wall * g11 / (1 + g_md * wall)))


def closed_loop_matrix(loop: WallLoop, K: Any, B: Any) -> Any:
    """``M`` of ``xi_{k+1} = M xi_k``, ``xi = [s, x_{k-1}, u_{k-1}, .., u_{k-L}]`` (physical units, mpf)."""
    phi, g_now, g_before, C = sampled_map(loop)
    T = mp.mpf(loop.T)
    D = mp.mpf(loop.delay)
    d = int(mp.floor(D))
    slots = d + (1 if d < D else 0)
    n = phi.rows
    integ = 1 if K > 0 else 0
    size = n + integ + slots
    M = mp.zeros(size, size)
    u_row = [((K * T + B) if integ else B) * C[0, j] for j in range(n)] + ([K] if integ else []) + [0] * slots

    def held(lag):
        if lag == 0:
            return u_row
        row = [0] * size
        row[n + integ + lag - 1] = 1
        return row

    for i in range(n):
        for j in range(n):
            M[i, j] = phi[i, j]
        for j, value in enumerate(held(d)):
            M[i, j] -= g_now[i] * value
        if d < D:
            for j, value in enumerate(held(d + 1)):
                M[i, j] -= g_before[i] * value
    if integ:
        for j in range(n):
            M[n, j] = T * C[0, j]
        M[n, n] = 1
    if slots:
        for j, value in enumerate(u_row):
            M[n + integ, j] = value
        for j in range(1, slots):
            M[n + integ + j, n + integ + j - 1] = 1
    return M


def _poly_mul(a: list, b: list) -> list:
    """Product of two polynomials given by ascending coefficient lists."""
    out = [mp.mpf(0)] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return out


def _poly_add(a: list, b: list) -> list:
    n = max(len(a), len(b))
    return [(a[i] if i < len(a) else 0) + (b[i] if i < len(b) else 0) for i in range(n)]


def characteristic_parts(loop: WallLoop, K: Any, B: Any) -> tuple[int, list, list]:
    """``(L, top, bottom)`` with ``det(zI - M) = z^L top(z) + bottom(z)`` (ascending coefficients, mpf):
    ``top = (z - 1) det(zI - Phi)`` (with the controller's integrator, ``K > 0``) or ``det(zI - Phi)``,
    ``bottom = C adj(zI - Phi) (g_now z + g_before) (K T z + B (z - 1))`` (or ``B`` alone without the
    integrator); ``g_now`` alone and ``L = d`` for a whole delay, ``L = d + 1`` with a fraction."""
    phi, g_now, g_before, C = sampled_map(loop)
    n = phi.rows
    T, D = mp.mpf(loop.T), mp.mpf(loop.delay)
    d = int(mp.floor(D))
    fraction = D > d
    if n == 1:
        det = [-phi[0, 0], mp.mpf(1)]
        adj = [[[mp.mpf(1)]]]
    else:
        det = [phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0], -(phi[0, 0] + phi[1, 1]), mp.mpf(1)]
        adj = [[[-phi[1, 1], mp.mpf(1)], [phi[0, 1]]], [[phi[1, 0]], [-phi[0, 0], mp.mpf(1)]]]
    numerator: list = [mp.mpf(0)]
    for i in range(n):
        for j in range(n):
            force = [g_before[j], g_now[j]] if fraction else [g_now[j]]
            numerator = _poly_add(numerator, [C[0, i] * c for c in _poly_mul(adj[i][j], force)])
    integrator = K > 0
    wall = [-B, K * T + B] if integrator else [B]
    top = _poly_mul([mp.mpf(-1), mp.mpf(1)], det) if integrator else det
    return (d + 1 if fraction else d), top, _poly_mul(numerator, wall)


def schur_cohn_stable(loop: WallLoop, K: Any, B: Any) -> bool:
    """Every zero of ``det(zI - M)`` strictly inside the unit circle: the Schur-Cohn (Jury) recursion
    on the polynomial, in the working precision, every reflection coefficient below 1 in magnitude."""
    lag, top, bottom = characteristic_parts(loop, K, B)
    a = [mp.mpf(0)] * (lag + len(top))
    for i, c in enumerate(bottom):
        a[i] += c
    for i, c in enumerate(top):
        a[lag + i] += c
    while len(a) > 1:
        k = a[0] / a[-1]
        if abs(k) >= 1:
            return False
        a = [a[i + 1] - k * a[len(a) - 2 - i] for i in range(len(a) - 1)]
    return True


class _Loop:
    def __init__(self, loop: WallLoop, which: str) -> None:
        if which not in ("K", "B"):
            raise ValueError(f"which = {which!r}; allowed: 'K' or 'B'")
        self.loop = loop
        self.K, self.B = mp.mpf(loop.K), mp.mpf(loop.B)
        self.which = which

    def wall(self, x):
        return (x, self.B) if self.which == "K" else (self.K, x)

    def re_z(self, x, theta):
        K, B = self.wall(x)
        return mp.re(impedance(self.loop, K, B, theta))

    def spectral_radius(self, x):
        K, B = self.wall(x)
        return max(abs(e) for e in mp.eig(closed_loop_matrix(self.loop, K, B), left=False, right=False))

    def minimum(self, x: Any) -> tuple[Any, Any, tuple]:
        """(min Re Z over (0, pi], theta there, bracket): dense scan, then golden section at each local minimum."""
        uniform = max(_UNIFORM, _PER_TURN * (int(mp.ceil(mp.mpf(self.loop.delay))) + 1))
        thetas = [mp.pi * i / uniform for i in range(1, uniform + 1)]
        low = -mp.log10(THETA_LOW)
        fan = [mp.mpf(10) ** (-low + (mp.log10(mp.pi / uniform) + low) * i / _FAN) for i in range(_FAN)]
        grid = sorted(fan + thetas)
        values = [self.re_z(x, t) for t in grid]
        best = (values[-1], grid[-1], (grid[-1], grid[-1]))
        if values[0] < best[0]:  # the low end: Re Z is even in theta
            best = (values[0], grid[0], (grid[0], grid[0]))
        for i in range(1, len(grid) - 1):
            if values[i] <= values[i - 1] and values[i] <= values[i + 1]:
                value, theta = self._golden(x, grid[i - 1], grid[i + 1], _GOLDEN_TOL)
                if value < best[0]:
                    best = (value, theta, (grid[i - 1], grid[i + 1]))
        return best

    def _golden(self, x, lo, hi, tol):
        ratio = (mp.sqrt(5) - 1) / 2
        c, d = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        fc, fd = self.re_z(x, c), self.re_z(x, d)
        while hi - lo > tol * max(1, abs(hi)):
            if fc < fd:
                hi, d, fd = d, c, fc
                c = hi - ratio * (hi - lo)
                fc = self.re_z(x, c)
            else:
                lo, c, fc = c, d, fd
                d = lo + ratio * (hi - lo)
                fd = self.re_z(x, d)
        return (fc, c) if fc < fd else (fd, d)

    def stable(self, x: Any) -> bool:
        """Eigenvalues of the closed-loop matrix for a short delay; the Schur-Cohn recursion for a long one."""
        if self.loop.delay <= _DENSE_DELAY:
            return bool(self.spectral_radius(x) < 1)
        K, B = self.wall(x)
        return schur_cohn_stable(self.loop, K, B)

    def passive(self, x: Any) -> bool:
        return self.stable(x) and self.minimum(x)[0] >= 0


def _bracketed_root(f: Callable[[Any], Any], x0: Any, lower: bool = False) -> Any:
    """Root of ``f`` (positive below and negative above, or the reverse if ``lower``) near ``x0``:
    bracket, then Anderson-Bjorck."""
    width = mp.mpf("1e-6")
    sign = -1 if lower else 1
    while True:
        lo, hi = x0 * (1 - width), x0 * (1 + width)
        if sign * f(lo) >= 0 > sign * f(hi):
            return mp.findroot(f, (lo, hi), solver="anderson", verify=False)
        width *= 8
        if width > mp.mpf("0.5"):
            raise ArithmeticError(f"no sign change of Re Z(pi) within 50 % of {mp.nstr(x0, 15)}")


def reference_boundary(loop: WallLoop, which: str, estimate: float, lower: bool = False) -> ReferenceBoundary:
    """The largest passive ``K`` (``which = "K"``, at the loop's ``B``) or ``B`` (at its ``K``), 40 digits.

    ``estimate``: a double-precision value near the boundary (where the scan looks for the
    critical frequency; the result does not depend on it beyond that).  ``lower``: the lower
    end of a passive interval instead (active below it, passive above).
    """
    with mp.workdps(DIGITS):
        ref = _Loop(loop, which)
        x0 = mp.mpf(estimate)
        _, theta0, bracket = ref.minimum(x0)
        if theta0 == mp.pi:
            x = _bracketed_root(lambda v: ref.re_z(v, mp.pi), x0, lower)
            theta, kind = mp.pi, "flip (theta = pi)"
        elif theta0 < _FLAT_BELOW:  # Re Z = Re Z(0) + O(theta^2): the minimum is the theta -> 0 limit
            x = _bracketed_root(lambda v: ref.re_z(v, THETA_LOW), x0, lower)
            theta, kind = THETA_LOW, "low frequency (theta -> 0)"
        else:  # the root of the envelope min_theta Re Z(x, theta), the minimum by golden section
            x = _bracketed_root(lambda v: ref._golden(v, bracket[0], bracket[1], _TANGENCY_TOL)[0], x0, lower)
            theta, kind = ref._golden(x, bracket[0], bracket[1], _TANGENCY_TOL)[1], "tangency"
        inside, outside = (x * (1 + _VERIFY), x * (1 - _VERIFY)) if lower else (x * (1 - _VERIFY), x * (1 + _VERIFY))
        verified = bool(ref.passive(inside) and not ref.passive(outside))
        return ReferenceBoundary(float(x), float(theta), kind, verified)
