"""The exact passivity criterion of the sampled-data wall loop, and the seed's verdict beside it.

Passive (for operator forces band-limited below the Nyquist frequency ``pi/T``) iff

1. every closed-loop pole lies strictly inside the unit circle (:mod:`haptic_bus.analysis.poles`), and
2. ``Re T_fund(theta) >= 0`` on ``(0, pi]`` -- every velocity model, every real delay.

Condition 2 is judged on the impedance ``Z = 1/T_fund``: ``Re Z = Re T / |T|^2`` has the same
sign, stays finite as ``theta -> 0``, and its minimum is the least net damping the operator
feels at any frequency, in N s/m: the **margin** of a stable loop.  For an unstable loop the
margin is ``-(rho - 1) m / T`` (N s/m), ``rho`` the largest pole magnitude, and at least the
smallest negative number.  Either way ``margin >= 0`` iff passive.

**The sign.**  ``Re Z = b + (wall terms)`` is evaluated as ``c + Im(L E conj U)/(theta |U|^2)``
(:mod:`haptic_bus.analysis.frequency`) with the magnitudes of the terms it is summed from
(``scale``).  ``Re Z`` counts as ``>= 0`` when ``Re Z >= -SIGN_TOLERANCE * scale``: the
tolerance is relative to the quantities that cancel, not to ``|Z|`` (which at ``m/T = 1e15``
is ``1e15`` times larger than a friction of 1 N s/m and would hide it).

**The lossless loops.**  Two loops neither dissipate nor generate energy below Nyquist
(``Re Z = 0`` at every frequency):

* the free frictionless mass with no wall (``b = K = B = 0``): its only mode is the constant
  velocity (``z = 1``, the integrator of the handle itself).  Judged *lossless*: passive,
  marginally stable, margin 0.
* a spring on a frictionless handle with no damper, no delay and point velocity
  (``b = B = 0``, ``K T^2/m < 4``): a *lossless oscillator*, its two poles on the unit circle at
  ``e^{+-j theta0}``, ``cos theta0 = 1 - K T^2/(2m)`` (their product is 1).  The strict rule does
  **not** call it passive: its poles are not strictly inside; an operator force at ``theta0``
  builds the motion without bound (``T_fund`` is infinite there: no steady state to take the
  mean power of); and it has no margin either way -- the least friction or damper makes it
  passive, the least lag (a fraction of a sample, an averaging drive) unstable.  Its margin is
  the smallest negative number.  Any other loop with a pole exactly on the circle (a wall at its
  flip boundary) is *marginal*, likewise not passive.

How the minimum is found: :mod:`haptic_bus.analysis.theta_search` (grid with fans at the
low-pass corner and lightly damped poles, vectorised zoom on the three lowest minima, parabola).
:func:`verdict_lane` and :func:`impedance_group` let a caller zoom the margin jointly with other
functions of ``theta`` (``haptic-bus check`` does, with the seed's test and the limits).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.frequency import LoopTerms, grid_terms, loop_terms, scaled_impedance, seed_impedance
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import MARGINAL_STATE, Stability, closed_loop_poles, stability
from haptic_bus.analysis.theta_search import Group, Lane, LaneMinimum, refine_lanes

SIGN_TOLERANCE = 64 * np.finfo(float).eps  # ~1.4e-14, relative to the magnitude of the terms that cancel
SEED_TOLERANCE = 1e-14  # relative to |Z_zw|, as the seed's test has always been judged
NOT_PASSIVE_FLOOR = -math.ulp(0.0)  # the margin of a loop that fails by its poles alone (on the circle)

EXACT = "exact: closed-loop stability and Re T_fund >= 0 on (0, pi]"
SEED = "seed: Re T_zw >= 0 on (0, pi] (eq. 11)"
LOSSLESS = "lossless: a free frictionless mass (b = K = B = 0), Re Z = 0 at every frequency"
OSCILLATOR = ("lossless oscillator: b = B = 0, no delay, point velocity; Re Z = 0 at every frequency, "
              "poles on the unit circle (not strictly inside: not passive)")
_SEARCH = "grid (uniform + log fan + corner/pole fans) + vectorised zoom + parabola"
_EXTENDED = " (poles judged in 50 digits: within round-off of the unit circle in double precision)"


@dataclass(frozen=True)
class Verdict:
    """The outcome of one passivity criterion.

    ``margin`` in N s/m (``>= 0`` iff passive), ``critical_theta`` the ``omega T`` where the
    margin is attained (rad), ``spectral_radius`` the largest pole magnitude, ``method`` how
    the minimum was located, ``lossless`` for the free frictionless mass (passive, ``stable``
    in the sense that no mode grows: its one mode is the constant velocity, ``z = 1``),
    ``oscillator`` for the lossless oscillator (poles on the circle: not passive), ``marginal``
    for any loop with a pole on the unit circle and none outside.
    """

    criterion: str
    passive: bool
    stable: bool
    margin: float
    critical_theta: float
    spectral_radius: float
    method: str
    lossless: bool = False
    oscillator: bool = False
    marginal: bool = False

    @property
    def outcome(self) -> str:
        """``"lossless"``, ``"passive"``, ``"lossless oscillator"``, ``"marginal"`` (a pole on the unit
        circle), ``"not passive"`` (stable, some ``Re Z < 0``) or ``"unstable"``."""
        if self.lossless:
            return "lossless"
        if self.passive:
            return "passive"
        if self.oscillator:
            return "lossless oscillator"
        if self.marginal:
            return "marginal"
        return "not passive" if self.stable else "unstable"


def impedance_group(loop: WallLoop, seed: bool = False) -> Group:
    """The lanes' group of ``Re Z``: from the loop's terms, rows ``Re Z T/m`` and that plus its sign
    tolerance; with ``seed``, also ``Re Z_zw T/m`` of the seed's test and that plus its tolerance
    (:func:`~haptic_bus.analysis.frequency.seed_impedance`, from the same terms)."""

    def evaluate(terms: LoopTerms) -> np.ndarray:
        z = scaled_impedance(terms, loop.kappa, loop.q)
        rows = [z.re, z.re + SIGN_TOLERANCE * z.scale]
        if seed:
            re, im = seed_impedance(terms, loop.kappa, loop.q)
            rows += [re, re + SEED_TOLERANCE * np.hypot(re, im)]
        return np.stack(rows)

    return Group(evaluate)


def verdict_lane(data: np.ndarray) -> Lane:
    """The lane of the margin, from :func:`impedance_group`'s ``data`` on the grid."""
    return Lane(data[0], "impedance", lambda part: part[0], lambda part: part[1], data[1], rounds=1)


def judge(loop: WallLoop, judged: Stability, minimum: LaneMinimum) -> Verdict:
    """The exact :class:`Verdict` from the poles' :class:`~haptic_bus.analysis.poles.Stability` and
    the margin lane's zoomed minimum (scaled ``Re Z``)."""
    method = _SEARCH + (_EXTENDED if judged.extended else "")
    scale = loop.m / loop.T
    theta = minimum.theta
    if not judged.stable:
        oscillator = loop.oscillator and judged.state == MARGINAL_STATE
        margin = min(-judged.excess * scale, NOT_PASSIVE_FLOOR)
        what = OSCILLATOR if oscillator else "closed-loop poles " + ("on the unit circle" if judged.state == MARGINAL_STATE
                                                                    else "(unstable)")
        return Verdict(EXACT, False, False, margin, theta, judged.radius, what + (_EXTENDED if judged.extended else ""),
                       oscillator=oscillator, marginal=judged.state == MARGINAL_STATE)
    ok = minimum.check >= 0.0
    margin = minimum.value * scale
    if ok and margin < 0:
        margin = 0.0  # within the evaluation's round-off of the boundary
    return Verdict(EXACT, ok, True, margin, theta, judged.radius, method)


def lossless_verdict() -> Verdict:
    """The free frictionless mass: lossless, passive, margin 0."""
    return Verdict(EXACT, True, True, 0.0, math.pi, 1.0, LOSSLESS, lossless=True)


def exact_verdict(loop: WallLoop) -> Verdict:
    """The exact criterion (stability and ``Re T_fund >= 0``): what the passivity gate uses."""
    if loop.lossless:
        return lossless_verdict()
    terms = grid_terms(loop, closed_loop_poles(loop))
    group = impedance_group(loop)
    [minimum] = refine_lanes(terms.theta, [verdict_lane(group.evaluate(terms))], {"impedance": group},
                             lambda theta: loop_terms(loop, theta))
    return judge(loop, stability(loop), minimum)


def seed_lane(data: np.ndarray) -> Lane:
    """The lane of the seed's margin, from :func:`impedance_group`'s ``data`` (with ``seed``) on the grid."""
    return Lane(data[2], "impedance", lambda part: part[2], lambda part: part[3], data[3], rounds=1)


def seed_judgement(loop: WallLoop, minimum: LaneMinimum) -> Verdict:
    """The seed's :class:`Verdict` from its lane's zoomed minimum (no stability test, as in the seed)."""
    ok = minimum.check >= 0.0
    margin = minimum.value * loop.m / loop.T
    if ok and margin < 0:
        margin = 0.0
    judged = stability(loop)
    return Verdict(SEED, ok, judged.stable, margin, minimum.theta, judged.radius, _SEARCH)


def seed_verdict(loop: WallLoop) -> Verdict:
    """The seed's frequency test ``Re T_zw >= 0`` alone (no stability test, as in the seed)."""
    terms = grid_terms(loop, closed_loop_poles(loop))
    group = impedance_group(loop, seed=True)
    [minimum] = refine_lanes(terms.theta, [seed_lane(group.evaluate(terms))], {"impedance": group},
                             lambda theta: loop_terms(loop, theta))
    return seed_judgement(loop, minimum)
