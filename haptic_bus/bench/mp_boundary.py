"""High-precision reference of the passive boundary (mpmath, 40 digits), for the benchmark.

Straight from the definitions (DESIGN 3.2), with no reformulation: the impedance the operator
feels is ``Z = 1/T_fund``, ``T_fund = G11 [1 - (H/T) K_d' G11 / (1 + G11d K_d')]`` at
``z = e^{j theta}``, ``s = j theta/T``.  The largest passive ``K`` at a given ``B`` (or ``B``
at a given ``K``) is where ``min_theta Re Z`` touches zero:

1. scan ``Re Z`` at the double-precision estimate on 240 uniform points of ``(0, pi]`` plus a
   logarithmic fan from ``1e-12`` (standing in for ``theta -> 0``: ``Re Z`` is even in
   ``theta``, so it is off by ``O(1e-24)``) and refine every interior local minimum by golden
   section (to ``1e-15`` rad);
2. the global minimum at ``theta = pi`` (an end point): the boundary is the root of
   ``Re Z(X, pi) = 0`` (the flip boundary); at ``theta -> 0``: the root of
   ``Re Z(X, 1e-12) = 0`` (a low-frequency boundary); in the interior: the tangency, the root in ``X``
   of the envelope ``min_theta Re Z(X, theta)`` with the minimum located by golden section
   (to ``1e-19`` rad, so the envelope is exact to ~1e-38 relative) inside the scan's bracket;
   both roots bracketed and solved by Anderson-Bjorck (``mp.findroot``);
3. verified: at ``X (1 - 1e-14)`` the scan's minimum is ``>= 0`` and every closed-loop pole
   (``mp.polyroots`` of the characteristic polynomial) is inside the unit circle; at
   ``X (1 + 1e-14)`` the minimum is negative or a pole is outside.
"""

from __future__ import annotations

from dataclasses import dataclass

import mpmath as mp

from haptic_bus.analysis.loop import WallLoop

DIGITS = 40
_UNIFORM = 240
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


def _impedance(m, b, T, K, B, d: int, theta):
    """``1/T_fund`` in N s/m at ``theta`` (all mpf), from the definition."""
    omega = theta / T
    z = mp.expj(theta)
    g11 = 1 / (m * 1j * omega + b)
    k1 = -mp.expm1(-b * T / m) / b if b > 0 else T / m
    g11d = k1 / (z - mp.exp(-b * T / m))
    wall = (K * T * z / (z - 1) + B) * z ** (-d)
    hold = (1 - mp.expj(-theta)) / (1j * omega) / T
    return 1 / (g11 * (1 - hold * wall * g11 / (1 + g11d * wall)))


class _Loop:
    def __init__(self, loop: WallLoop, which: str) -> None:
        if which not in ("K", "B"):
            raise ValueError(f"which = {which!r}; allowed: 'K' or 'B'")
        self.m, self.b, self.T, self.K, self.B = (mp.mpf(x) for x in (loop.m, loop.b, loop.T, loop.K, loop.B))
        self.d = loop.delay
        self.which = which

    def wall(self, x):
        return (x, self.B) if self.which == "K" else (self.K, x)

    def re_z(self, x, theta):
        K, B = self.wall(x)
        return mp.re(_impedance(self.m, self.b, self.T, K, B, self.d, theta))

    def spectral_radius(self, x):
        K, B = self.wall(x)
        m, b, T, d = self.m, self.b, self.T, self.d
        a = mp.exp(-b * T / m)
        k1 = -mp.expm1(-b * T / m) / b if b > 0 else T / m
        if K > 0:  # (z - a)(z - 1) z^d + k1 (K T z + B (z - 1))
            coeffs = [mp.mpf(1), -(1 + a), a] + [mp.mpf(0)] * d
            coeffs[-2] += k1 * (K * T + B)
            coeffs[-1] -= k1 * B
        else:  # (z - a) z^d + k1 B
            coeffs = [mp.mpf(1), -a] + [mp.mpf(0)] * d
            coeffs[-1] += k1 * B
        roots = mp.polyroots(coeffs, maxsteps=200, extraprec=2 * DIGITS)
        return max(abs(r) for r in roots)

    def minimum(self, x) -> tuple[mp.mpf, mp.mpf, tuple]:
        """(min Re Z over (0, pi], theta there, bracket): dense scan, then golden section at each local minimum."""
        thetas = [mp.pi * i / _UNIFORM for i in range(1, _UNIFORM + 1)]
        low = -mp.log10(THETA_LOW)
        fan = [mp.mpf(10) ** (-low + (mp.log10(mp.pi / _UNIFORM) + low) * i / _FAN) for i in range(_FAN)]
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

    def passive(self, x) -> bool:
        return self.spectral_radius(x) < 1 and self.minimum(x)[0] >= 0


def _bracketed_root(f, x0):
    """Root of ``f`` (positive below, negative above) near ``x0``: bracket, then Anderson-Bjorck."""
    width = mp.mpf("1e-6")
    while True:
        lo, hi = x0 * (1 - width), x0 * (1 + width)
        if f(lo) >= 0 > f(hi):
            return mp.findroot(f, (lo, hi), solver="anderson", verify=False)
        width *= 8
        if width > mp.mpf("0.5"):
            raise ArithmeticError(f"no sign change of Re Z(pi) within 50 % of {mp.nstr(x0, 15)}")


def reference_boundary(loop: WallLoop, which: str, estimate: float) -> ReferenceBoundary:
    """The largest passive ``K`` (``which = "K"``, at the loop's ``B``) or ``B`` (at its ``K``), 40 digits.

    ``estimate``: a double-precision value near the boundary (where the scan looks for the
    critical frequency; the result does not depend on it beyond that).
    """
    with mp.workdps(DIGITS):
        ref = _Loop(loop, which)
        x0 = mp.mpf(estimate)
        _, theta0, bracket = ref.minimum(x0)
        if theta0 == mp.pi:
            x = _bracketed_root(lambda v: ref.re_z(v, mp.pi), x0)
            theta, kind = mp.pi, "flip (theta = pi)"
        elif theta0 < _FLAT_BELOW:  # Re Z = Re Z(0) + O(theta^2): the minimum is the theta -> 0 limit
            x = _bracketed_root(lambda v: ref.re_z(v, THETA_LOW), x0)
            theta, kind = THETA_LOW, "low frequency (theta -> 0)"
        else:  # the root of the envelope min_theta Re Z(x, theta), the minimum by golden section
            x = _bracketed_root(lambda v: ref._golden(v, bracket[0], bracket[1], _TANGENCY_TOL)[0], x0)
            theta, kind = ref._golden(x, bracket[0], bracket[1], _TANGENCY_TOL)[1], "tangency"
        verified = bool(ref.passive(x * (1 - _VERIFY)) and not ref.passive(x * (1 + _VERIFY)))
        return ReferenceBoundary(float(x), float(theta), kind, verified)
