"""The seed's design tools (section IV and Figs. 4-6), as plain numerical functions.

* :func:`bandwidth_rule` -- the servo-design rule ``alpha > 6`` (eq. 25).
* :func:`force_step_response` -- the wall force ``u_k`` after a unit step of operator force
  (Fig. 6), from the exact sampled loop (velocity model and delay included), with overshoot
  and settling.
* :func:`nyquist_data` -- the seed's ``T_zw`` on ``[0, pi]`` (Fig. 5) and the exact ``T_fund``.
* :func:`passive_region_curves` -- the ``alpha``-``beta`` boundaries of Fig. 4, and
  :func:`exact_region_boundary`, the exact criterion's boundary in the same plane.

Units: ``m`` kg, ``b`` and ``B`` N s/m, ``K`` N/m, ``T`` s, forces N, admittances m/(N s);
``alpha = B/(K T)`` and ``beta = b/B`` are dimensionless.

**The Fig. 4 convention.**  Eq. (24) is not a curve in the ``alpha``-``beta`` plane alone: its
factor ``tanh(c/2)``, ``c = bT/m``, depends on ``b`` and ``T`` again.  The seed fixes the device
("we assume m = 0.5 kg, b = 0.1 N s/m") and draws one solid curve per sampling period, so here
``m`` and ``b`` are fixed (the device) and ``T`` labels the curve; a point ``(alpha, beta)`` then
is the wall ``B = b/beta``, ``K = B/(alpha T)``.  (The other reading, ``B`` fixed and ``b = beta B``
varying along the axis, would make ``c`` change along a curve and has no single device behind
it.)  The seed does not say which three periods it drew; the default is ``T = 1, 5, 10 ms``
(its design period and two slower ones: larger ``T``, higher curve, smaller region, as the
seed's text says).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.closed_form import colgate_beta, liu2011_beta, velocity_sampling_beta
from haptic_bus.analysis.energy import Constant, wall_forces
from haptic_bus.analysis.frequency import seed_t_zw, t_fund
from haptic_bus.analysis.limits import max_damping, max_stiffness
from haptic_bus.analysis.loop import BANDWIDTH_ALPHA, FRICTION_RANGE, MASS_RANGE, PERIOD_RANGE, WallLoop
from haptic_bus.analysis.plant import phi1
from haptic_bus.analysis.poles import closed_loop_poles, spectral_radius
from haptic_bus.analysis.velocity import POINT, VelocityModel
from haptic_bus.validation import real_in_range, whole_in_range

SEED_PERIODS = (1e-3, 5e-3, 1e-2)
"""Sampling periods (s) of the three velocity-sampling curves of Fig. 4 (the seed does not list them)."""

SETTLING_BAND = 0.02
_MAX_STEP_SAMPLES = 10_000_000


# --------------------------------------------------------------------------- eq. 25


def bandwidth_rule(loop: WallLoop) -> tuple[float, bool]:
    """Eq. (25): ``(alpha, alpha > 6)`` with ``alpha = B/(K T)`` (dimensionless; inf when K = 0)."""
    alpha = loop.alpha
    return alpha, bool(alpha > BANDWIDTH_ALPHA)


# --------------------------------------------------------------------------- Fig. 6


@dataclass(frozen=True)
class StepReport:
    """Figures of merit of the wall-force step response.

    ``final_value`` (N) is the exact DC gain of operator force to wall force (1 N per N for
    any wall with ``K > 0``: the wall holds the handle); ``peak`` (N) and ``peak_time`` (s);
    ``overshoot`` in % of the final value (0 if the response never exceeds it);
    ``settling_time`` (s), the first sample time after which ``u`` stays within 2 % of the
    final value (nan if the run is too short to tell); ``poles`` the closed-loop poles;
    ``oscillatory`` True if any pole is not real and positive (a ringing response).
    """

    final_value: float
    peak: float
    peak_time: float
    overshoot: float
    settling_time: float
    poles: np.ndarray
    oscillatory: bool


@dataclass(frozen=True)
class StepResponse:
    """Wall force after a unit operator-force step at ``t = 0``.

    ``time`` (s) the sample instants ``kT``; ``force`` (N) the wall force ``u_k`` the controller
    computes from ``y_k`` at ``kT``; ``applied`` (N) the force the drive holds from ``kT + delta T``
    to ``(k+1)T``, i.e. ``u_{k-d}`` (equal to ``force`` when ``D = 0``).
    """

    time: np.ndarray
    force: np.ndarray
    applied: np.ndarray
    report: StepReport


def _dc_gain(loop: WallLoop) -> float:
    """Exact ``U/W`` at ``z = 1`` (N/N), formed without cancellation (every velocity model reads the
    steady velocity exactly: ``M(0) = 1``)."""
    if loop.K > 0:
        return 1.0  # k1 K T / P(1) and P(1) = k1 K T exactly
    k1_b = phi1(loop.c) * loop.B * loop.T / loop.m
    decay = -math.expm1(-loop.c)  # 1 - a
    return k1_b / (decay + k1_b)


def _default_step_samples(loop: WallLoop) -> int:
    rho = spectral_radius(loop)
    if not rho < 1.0:
        return 200
    if rho == 0.0:
        return 20
    return int(min(max(math.ceil(math.log(1e-6) / math.log(rho)), 20), 200_000)) + math.ceil(loop.delay)


def force_step_response(loop: WallLoop, n_samples: int | None = None) -> StepResponse:
    """Wall force ``u_k`` (N) for a unit step of operator force (N), at ``t_k = kT`` (s).

    The seed's Fig. 6, from the exact sampled loop (:func:`haptic_bus.analysis.energy.wall_forces`:
    velocity model and delay included).  In the steady state ``v = 0``, ``x = W/K`` and the wall
    force equals the operator push (final value 1 N per N).  ``n_samples`` defaults to the time
    the slowest closed-loop mode needs to decay to 1e-6.
    """
    n = _default_step_samples(loop) if n_samples is None else whole_in_range("n_samples", n_samples, 2, _MAX_STEP_SAMPLES)
    force, applied = wall_forces(loop, Constant(1.0), n)
    time = np.arange(n) * loop.T
    final = _dc_gain(loop)
    peak_i = int(np.argmax(force))
    overshoot = max(0.0, (force[peak_i] - final) / final * 100.0) if final > 0 else float("nan")
    outside = np.flatnonzero(np.abs(force - final) > SETTLING_BAND * abs(final))
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] >= n - 1 or spectral_radius(loop) >= 1.0:
        settling = float("nan")
    else:
        settling = float(time[outside[-1] + 1])
    poles = closed_loop_poles(loop)
    oscillatory = bool(np.any((np.abs(poles.imag) > 1e-12 * np.abs(poles)) | (poles.real < 0)))
    report = StepReport(final, float(force[peak_i]), float(time[peak_i]), overshoot, settling, poles, oscillatory)
    return StepResponse(time, force, applied, report)


# --------------------------------------------------------------------------- Fig. 5


@dataclass(frozen=True)
class NyquistData:
    """``theta = omega T`` (rad) on (0, pi] and both admittances there, m/(N s)."""

    theta: np.ndarray
    t_zw: np.ndarray
    t_fund: np.ndarray


def nyquist_data(loop: WallLoop, n: int = 2000) -> NyquistData:
    """The seed's ``T_zw`` (Fig. 5) and the exact ``T_fund`` on ``n`` points of (0, pi].

    Half the points are logarithmic from ``1e-5 pi`` (both curves leave the origin there:
    the wall's integrator pins ``v`` at DC), half uniform, ``pi`` included.
    """
    n = whole_in_range("n", n, 4, 10_000_000)
    theta = np.unique(np.concatenate([np.geomspace(1e-5 * math.pi, math.pi, n // 2),
                                      np.linspace(math.pi / n, math.pi, n - n // 2)]))
    return NyquistData(theta, seed_t_zw(loop, theta), t_fund(loop, theta))


# --------------------------------------------------------------------------- Fig. 4


@dataclass(frozen=True)
class RegionCurves:
    """Boundaries ``beta(alpha)`` of Fig. 4 (above each: passive by that condition).

    ``velocity`` has one row per entry of ``periods`` (eq. 24 with ``c = b T/m``);
    ``colgate`` is eq. (3), ``liu2011`` eq. (5) (neither depends on the device).
    """

    alpha: np.ndarray
    periods: np.ndarray
    velocity: np.ndarray
    colgate: np.ndarray
    liu2011: np.ndarray
    m: float
    b: float


def passive_region_curves(
    alpha: ArrayLike, m: float = 0.5, b: float = 0.1, periods: Sequence[float] = SEED_PERIODS
) -> RegionCurves:
    """Fig. 4's boundaries on ``alpha`` for the device (``m`` kg, ``b`` N s/m) and ``periods`` (s).

    Vectorised over ``alpha`` and ``periods``; see the module docstring for the convention
    (device fixed, ``B = b/beta``, ``K = B/(alpha T)``).
    """
    m = real_in_range("m", m, *MASS_RANGE, unit="kg")
    b = real_in_range("b", b, *FRICTION_RANGE, unit="N s/m")
    alpha = np.asarray(alpha, dtype=float)
    checked = np.asarray([real_in_range("T", T, *PERIOD_RANGE, unit="s") for T in periods])
    c = b * checked / m
    velocity = velocity_sampling_beta(alpha[None, ...], c.reshape((-1,) + (1,) * alpha.ndim))
    return RegionCurves(alpha, checked, velocity, colgate_beta(alpha), liu2011_beta(alpha), m, b)


def exact_region_floor(m: float, b: float, T: float, delay: float, velocity: VelocityModel | str = POINT) -> float | None:
    """Least passive ``beta`` as ``alpha -> inf`` (no spring, ``K = 0``): ``b / B_max(K = 0)``.

    The exact criterion's boundary approaches this ``beta`` asymptotically; None if no
    ``B > 0`` is passive without a spring (then the boundary has no such asymptote).
    ``delay`` in samples (real), ``velocity`` the drive's velocity model.
    """
    b_max = max_damping(WallLoop(m, b, T, 0.0, 0.0, delay, VelocityModel.parse(velocity)))
    if b_max is None or not b_max > 0:
        return None
    return b / b_max


def exact_region_boundary(m: float, b: float, T: float, delay: float, beta: ArrayLike,
                          velocity: VelocityModel | str = POINT) -> np.ndarray:
    """The exact criterion's boundary in Fig. 4's plane: least passive ``alpha`` for each ``beta``.

    For each ``beta`` the wall damping is ``B = b/beta`` and :func:`haptic_bus.analysis.limits.max_stiffness`
    gives the largest passive ``K`` (the exact criterion: velocity model and real delay
    included); ``alpha = B/(K T)``.  NaN where no wall with that ``B`` is passive (not even
    ``K = 0``); inf where only ``K = 0`` is.
    """
    beta = np.atleast_1d(np.asarray(beta, dtype=float))
    base = WallLoop(m, b, T, 0.0, 0.0, delay, VelocityModel.parse(velocity))
    out = np.full(beta.shape, np.nan)
    for i, value in enumerate(beta.flat):
        if not value > 0:
            continue
        damping = b / value
        k_max = max_stiffness(base.with_wall(0.0, damping))
        if k_max is None:
            continue
        out.flat[i] = damping / (k_max * T) if k_max > 0 else math.inf
    return out
