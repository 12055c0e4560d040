"""The exact passivity criterion of the sampled-data wall loop, and the seed's verdict beside it.

Passive (for operator forces band-limited below the Nyquist frequency ``pi/T``) iff

1. every closed-loop pole lies strictly inside the unit circle (:mod:`haptic_bus.analysis.poles`), and
2. ``Re T_fund(theta) >= 0`` on ``(0, pi]`` -- every velocity model, every real delay.

Condition 2 is judged on the impedance ``Z = 1/T_fund``: ``Re Z = Re T / |T|^2`` has the same
sign, stays finite as ``theta -> 0``, and its minimum is the least net damping the operator
feels at any frequency, in N s/m: the **margin** of a stable loop.  For an unstable loop the
margin is ``-(rho - 1) m / T`` (N s/m), ``rho`` the largest pole magnitude.  Either way
``margin >= 0`` iff passive.

**The sign.**  ``Re Z = b + (wall terms)`` is evaluated as ``c + Im(L E conj U)/(theta |U|^2)``
(:mod:`haptic_bus.analysis.frequency`) with the magnitudes of the terms it is summed from
(``scale``).  ``Re Z`` counts as ``>= 0`` when ``Re Z >= -SIGN_TOLERANCE * scale``: the
tolerance is relative to the quantities that cancel, not to ``|Z|`` (which at ``m/T = 1e15``
is ``1e15`` times larger than a friction of 1 N s/m and would hide it).

**The lossless loop.**  A free frictionless mass with no wall (``b = K = B = 0``) has
``Re Z = 0`` at every frequency and its only mode is the constant velocity (``z = 1``): it is
judged *lossless* -- passive, marginally stable -- not unstable.

How the minimum is found: :mod:`haptic_bus.analysis.theta_search` (grid with fans at the
low-pass corner and lightly damped poles, vectorised zoom on the three lowest minima, parabola).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.frequency import loop_terms, scaled_impedance, seed_z_zw
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import closed_loop_poles, stability
from haptic_bus.analysis.theta_search import refine_minima, theta_grid

SIGN_TOLERANCE = 64 * np.finfo(float).eps  # ~1.4e-14, relative to the magnitude of the terms that cancel
SEED_TOLERANCE = 1e-14  # relative to |Z|: the seed's T_zw is evaluated as an ordinary complex number

EXACT = "exact: closed-loop stability and Re T_fund >= 0 on (0, pi]"
SEED = "seed: Re T_zw >= 0 on (0, pi] (eq. 11)"
LOSSLESS = "lossless: a free frictionless mass (b = K = B = 0), Re Z = 0 at every frequency"
_SEARCH = "grid (uniform + log fan + corner/pole fans) + vectorised zoom + parabola"

RealParts = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Verdict:
    """The outcome of one passivity criterion.

    ``margin`` in N s/m (``>= 0`` iff passive), ``critical_theta`` the ``omega T`` where the
    margin is attained (rad), ``spectral_radius`` the largest pole magnitude, ``method`` how
    the minimum was located, ``lossless`` for the free frictionless mass (passive, ``stable``
    in the sense that no mode grows: its one mode is the constant velocity, ``z = 1``).
    """

    criterion: str
    passive: bool
    stable: bool
    margin: float
    critical_theta: float
    spectral_radius: float
    method: str
    lossless: bool = False

    @property
    def outcome(self) -> str:
        """``"lossless"``, ``"passive"``, ``"not passive"`` (stable, some ``Re Z < 0``) or ``"unstable"``."""
        if self.lossless:
            return "lossless"
        if self.passive:
            return "passive"
        return "not passive" if self.stable else "unstable"


def minimum_real_part(real_parts: RealParts, loop: WallLoop, poles: np.ndarray) -> tuple[float, float, bool]:
    """``(min Re, theta there, every point passed its sign test)`` of ``real_parts(theta) -> (re, scale)``.

    The sign test at each evaluated point is ``re >= -scale`` (``scale`` already times the tolerance).
    """
    grid = theta_grid(loop, poles)
    re, scale = real_parts(grid)
    thetas, values = refine_minima(lambda t: real_parts(t)[0], grid, re)
    refined_re, refined_scale = real_parts(thetas) if thetas.size else (values, values)
    all_theta = np.concatenate([grid, thetas])
    all_re = np.concatenate([re, refined_re])
    ok = bool(np.all(all_re >= -np.concatenate([scale, refined_scale])))
    i = int(np.argmin(all_re))
    return float(all_re[i]), float(all_theta[i]), ok


def _verdict(loop: WallLoop, real_parts: RealParts, criterion: str, require_stability: bool) -> Verdict:
    poles = closed_loop_poles(loop)
    judged = stability(loop)
    excess, radius, stable = judged.excess, judged.radius, judged.stable
    value, theta, ok = minimum_real_part(real_parts, loop, poles)
    scale = loop.m / loop.T
    if require_stability and not stable:
        margin = -max(excess * scale, math.ulp(1.0))
        return Verdict(criterion, False, False, margin, theta, radius, "closed-loop poles (unstable)")
    margin = value * scale
    if ok and margin < 0:
        margin = 0.0  # within the evaluation's round-off of the boundary
    return Verdict(criterion, ok, stable, margin, theta, radius, _SEARCH)


def exact_real_parts(loop: WallLoop) -> RealParts:
    """``theta -> (Re Z T/m, SIGN_TOLERANCE * scale)`` of the exact impedance ``1/T_fund``."""

    def real_parts(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = scaled_impedance(loop_terms(loop, theta), loop.kappa, loop.q)
        return z.re, SIGN_TOLERANCE * z.scale

    return real_parts


def exact_verdict(loop: WallLoop) -> Verdict:
    """The exact criterion (stability and ``Re T_fund >= 0``): what the passivity gate uses."""
    if loop.lossless:
        return Verdict(EXACT, True, True, 0.0, math.pi, 1.0, LOSSLESS, lossless=True)
    return _verdict(loop, exact_real_parts(loop), EXACT, require_stability=True)


def seed_verdict(loop: WallLoop) -> Verdict:
    """The seed's frequency test ``Re T_zw >= 0`` alone (no stability test, as in the seed)."""

    def real_parts(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = (loop.T / loop.m) * seed_z_zw(loop, theta)
        return z.real, SEED_TOLERANCE * np.abs(z)

    return _verdict(loop, real_parts, SEED, require_stability=False)
