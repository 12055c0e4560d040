"""The exact passivity criterion of a two-mass device: the operator at the handle, the drive at the motor.

Passive (for operator forces below Nyquist) iff the closed loop is strictly stable and
``Re T_fund(theta) >= 0`` on ``(0, pi]``, ``T_fund`` the exact fundamental-harmonic response from
the operator's force at the handle to the handle's velocity -- the rigid criterion
(:mod:`haptic_bus.analysis.criterion`, DESIGN 3.2, 3.5) with the plant of
:mod:`haptic_bus.analysis.two_mass`.

**The impedance the operator feels.**  An operator force ``W e^{j omega t}`` meets, at its own
frequency, the handle ``m s + b`` and, through the coupling ``Z_c = k/s + c``, the motor side
``Z_load = m_motor s + Z_wall``: the fundamental of the held wall force is ``Z_wall`` times the
motor's fundamental velocity, where (sampled loop, DESIGN 3.5)

    Z_wall T/M = L E / (j theta U),   L = kappa + q (1 - z^{-1}),  E = e^{-j theta D} M(j theta),
                                      U = 1 + L z^{-d} g(theta),

``g`` the alias function of the *two-mass* plant's motor mobility (what the held force's harmonics
bring back to the sampled measurement: :mod:`haptic_bus.analysis.alias_sum`), so the wall is the
rigid formula with another ``g``.  Then

    Z = m s + b + Z_c Z_load / (Z_c + Z_load),
    Re Z = b + (c |Z_load|^2 + |Z_c|^2 Re Z_wall) / |Z_c + Z_load|^2,

a sum in which only ``Re Z_wall`` can be negative, and that is carried cancellation-free as the
rigid loop's is (``(Re, Im/theta)``); the magnitudes are sums of squares.  As ``k -> infinity``
``Re Z -> b + Re Z_wall`` with ``g`` the rigid handle's of mass ``m + m_motor``: the rigid criterion
of :attr:`~haptic_bus.analysis.two_mass.TwoMassLoop.rigid`.

**Where the minimum is looked for**: the rigid grid (:func:`~haptic_bus.analysis.theta_search.theta_grid`)
with fans at the lightly damped poles of the free loop *and* of the loop with the handle held
still (``Re Z`` swings where ``Z_c + Z_load`` is small: the motor's resonance against a clamped
handle), then the same zoom.  Stability: the eigenvalues of the closed-loop matrix
(:func:`~haptic_bus.analysis.two_mass.two_mass_stability`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.criterion import SIGN_TOLERANCE, Verdict, judge, verdict_lane
from haptic_bus.analysis.frequency import loop_terms, scaled_impedance
from haptic_bus.analysis.limits import PassiveSet
from haptic_bus.analysis.poles import MARGINAL_STATE, Stability
from haptic_bus.analysis.theta_search import Group, refine_lanes, theta_grid
from haptic_bus.analysis.two_mass import TwoMassLoop, two_mass_poles, two_mass_stability

TWO_MASS = ("exact, two-mass (operator at the handle, sensing and torque at the motor): closed-loop stability and "
            "Re T_fund >= 0 on (0, pi]")
SCALE_SAMPLES = 64
SCALE_BISECTIONS = 30
LEAST_STIFFNESS = 1e-3  # N/m: below this the bisection stops (the passive K then is 0 alone)
_FREE_PAIR = "a free pair (b = K = B = 0): the pair's translation (z = 1) is its only mode on the circle, none grows"


@dataclass(frozen=True)
class TwoMassImpedance:
    """``Z T/M`` on ``theta`` (``M = m + m_motor``): ``re`` accurate to ``~eps * scale``, ``im``, and
    ``scale`` the magnitude of the terms ``re`` is summed from."""

    re: np.ndarray
    im: np.ndarray
    scale: np.ndarray


def two_mass_impedance(loop: TwoMassLoop, theta: ArrayLike) -> TwoMassImpedance:
    """The scaled impedance the operator feels at the handle (module docstring), ``theta`` in (0, pi] rad."""
    theta = np.atleast_1d(np.asarray(theta, dtype=float))
    rigid = loop.rigid
    device = loop.device()
    mu_m, mu_h, kt, ct, ch = device.coefficients()
    terms = replace(loop_terms(rigid, theta, aliases=device), c=0.0)
    wall = scaled_impedance(terms, rigid.kappa, rigid.q)  # the handle's s = j theta alone left in im
    wall_re = wall.re
    load = wall_re + 1j * (wall.im - theta + theta / mu_m)
    coupling_theta = ct * theta - 1j * kt  # theta Z_c
    coupling2 = (ct * theta) ** 2 + kt * kt  # theta^2 |Z_c|^2
    load2 = load.real**2 + load.imag**2
    with np.errstate(divide="ignore", invalid="ignore"):
        total = coupling_theta + theta * load
        den = total.real**2 + total.imag**2
        series_re = (ct * theta * theta * load2 + coupling2 * wall_re) / den
        series_scale = (ct * theta * theta * load2 + coupling2 * wall.scale) / den
        series = coupling_theta * load / total
    return TwoMassImpedance(ch + series_re, theta / mu_h + series.imag, ch + series_scale)


def t_fund_two_mass(loop: TwoMassLoop, theta: ArrayLike) -> np.ndarray:
    """``T_fund(theta)``, operator force at the handle to the handle's velocity, m/(N s)."""
    z = two_mass_impedance(loop, theta)
    scale = loop.rigid.m / loop.rigid.T
    return 1.0 / (scale * (z.re + 1j * z.im))


def _grid(loop: TwoMassLoop) -> np.ndarray:
    poles = np.concatenate([two_mass_poles(loop), two_mass_poles(loop, clamped=True)])
    return theta_grid(loop.rigid, poles)


def two_mass_verdict(loop: TwoMassLoop) -> Verdict:
    """The exact criterion for the two-mass loop (module docstring); margin in N s/m, as the rigid :class:`Verdict`."""
    criterion = f"{TWO_MASS}; transmission {loop.transmission.describe()}"
    if loop.handle.lossless:
        return Verdict(criterion, True, True, 0.0, math.pi, 1.0, _FREE_PAIR, lossless=True)

    def evaluate(theta: np.ndarray) -> np.ndarray:
        z = two_mass_impedance(loop, theta)
        return np.stack([z.re, z.re + SIGN_TOLERANCE * z.scale])

    grid = _grid(loop)
    [minimum] = refine_lanes(grid, [verdict_lane(evaluate(grid))], {"impedance": Group(evaluate, shared=False)},
                             lambda theta: None)
    state, excess = two_mass_stability(loop)
    verdict = judge(loop.rigid, Stability(state, excess), minimum)
    if state == MARGINAL_STATE and verdict.oscillator:  # the rigid limit's lossless oscillator is not this loop
        verdict = replace(verdict, oscillator=False, method="closed-loop poles on the unit circle")
    return replace(verdict, criterion=criterion)


def largest_passive_stiffness(loop: TwoMassLoop, relative: float = 1e-6, ceiling: float = 1e9) -> float | None:
    """The upper end (N/m) of the passive ``K`` from 0 at the loop's ``B``, by bisection on the verdict to
    ``relative`` (0 when no ``K`` above :data:`LEAST_STIFFNESS` passes); None if ``K = 0`` is not passive,
    ``ceiling`` if every ``K`` up to it is."""
    if not two_mass_verdict(loop.with_wall(0.0, loop.handle.B)).passive:
        return None
    low, high = 0.0, 1.0
    while two_mass_verdict(loop.with_wall(high, loop.handle.B)).passive:
        low, high = high, 4.0 * high
        if high > ceiling:
            return ceiling
    while high - low > relative * high and high > LEAST_STIFFNESS:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if two_mass_verdict(loop.with_wall(middle, loop.handle.B)).passive else (low, middle)
    return low


def two_mass_passive_scales(loop: TwoMassLoop) -> PassiveSet:
    """The scales ``s`` in [0, 1] at which the wall ``(s K, s B)`` is passive on the two-mass device: a
    **sampled** search -- the verdict at ``s = j/``:data:`SCALE_SAMPLES` and a bisection to ``2^-30`` at
    every change -- not the rigid loop's exact continuum (:func:`~haptic_bus.analysis.limits.passive_scales`):
    a passive or an active stretch shorter than ``1/64`` between two samples of the same verdict is missed."""
    h = loop.handle

    def passive(s: float) -> bool:
        return two_mass_verdict(loop.with_wall(s * h.K, s * h.B)).passive

    samples = [j / SCALE_SAMPLES for j in range(SCALE_SAMPLES + 1)]
    verdicts = [passive(s) for s in samples]
    edges = []
    for (a, pa), (b, pb) in itertools.pairwise(zip(samples, verdicts)):
        if pa != pb:
            for _ in range(SCALE_BISECTIONS):
                middle = 0.5 * (a + b)
                a, b = (middle, b) if passive(middle) == pa else (a, middle)
            edges.append(a if pa else b)  # the last passive scale on each side
    bounds = ([0.0] if verdicts[0] else []) + edges + ([1.0] if verdicts[-1] else [])
    return PassiveSet("scale", tuple(zip(bounds[0::2], bounds[1::2])))
