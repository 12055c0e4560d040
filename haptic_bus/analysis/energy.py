"""Time-domain energy check of the sampled-data wall loop (DESIGN 3.4): the arbiter.

The loop as it runs: the handle ``m dv/dt + b v = w(t) - f(t)`` is advanced *exactly*
between instants (zero-order-hold solution, :mod:`haptic_bus.analysis.plant`); every period ``T``
the controller samples the velocity ``v_k = v(kT)``, forms ``x_k = x_{k-1} + T v_k`` and
``u_k = K x_k + B v_k``, and the drive holds ``f = u_{k-d}`` over ``[kT, (k+1)T)`` (``d``
the loop delay in samples; ``u_j = 0`` for ``j < 0``: the loop starts from rest).

Each period is split into ``S`` sub-steps of ``h = T/S``.  The operator force is held
constant over a sub-step at its value at the sub-step's midpoint, so the operator's work
over a sub-step is ``w * displacement`` with the displacement from the exact plant: the
energy record ``E(t) = int_0^t w v dt`` (J) has no integration error at all, only
round-off.

Inputs: :class:`Sinusoid`, :class:`Chirp` and :class:`RandomSinusoids`, all band-limited
below the Nyquist frequency ``pi/T`` (every frequency as ``theta = omega T`` in (0, pi)).
A verdict drawn from them covers such operator forces only; content above ``pi/T`` can pair a
frequency with its alias and is out of scope here (DESIGN 3.4).  Strictly, a force switched
on at ``t = 0`` and held on sub-steps is not band-limited; both effects are small and are
measured in the tests (switch-on: a transient; hold: a relative ``O((theta/S)^2)``).

Speed: the loop is linear and time-invariant at the sample instants, so the sample recursion
is one :func:`scipy.signal.lfilter` through ``(z - 1) z^d / P(z)`` (``P`` the closed-loop
characteristic polynomial) and the sub-step states follow by superposition (one small
matrix product).  :func:`simulate_reference` is the same loop written out plainly, one
:class:`~haptic_bus.analysis.plant.ExactPlant` step at a time, to check the fast path against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.signal import lfilter

from drives.errors import ParameterError
from haptic_bus.analysis.frequency import seed_t_zw, t_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import ExactPlant, phi1_array, phi2_array, zoh_coefficients
from haptic_bus.analysis.poles import characteristic_polynomial, spectral_radius
from haptic_bus.validation import real_in_range, whole_in_range

DEFAULT_SUBSTEPS = 16
MAX_SAMPLES = 10_000_000
MAX_SUBSTEPS = 4096

OperatorForce = Callable[[np.ndarray], np.ndarray]


# --------------------------------------------------------------------------- inputs


def _theta_below_nyquist(name: str, theta: object) -> float:
    """A frequency ``theta = omega T`` strictly inside (0, pi), else ParameterError."""
    value = real_in_range(name, theta, 0.0, math.pi, low_inclusive=False, unit="rad (omega T)")
    if value >= math.pi:
        raise ParameterError(name, theta, "a finite real in (0, pi) rad: below the Nyquist frequency pi/T")
    return value


@dataclass(frozen=True)
class Sinusoid:
    """``w(t) = amplitude sin(theta t / T + phase)`` in N; ``theta = omega T`` in (0, pi)."""

    theta: float
    T: float
    amplitude: float = 1.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta", _theta_below_nyquist("theta", self.theta))

    @property
    def max_theta(self) -> float:
        """Highest frequency present, as ``omega T`` (rad)."""
        return self.theta

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Force in N at times ``t`` (s)."""
        return self.amplitude * np.sin(self.theta / self.T * np.asarray(t) + self.phase)


@dataclass(frozen=True)
class Chirp:
    """Linear chirp in N: ``theta`` sweeps from ``theta0`` to ``theta1`` (both in (0, pi)) over ``duration`` s."""

    theta0: float
    theta1: float
    T: float
    duration: float
    amplitude: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta0", _theta_below_nyquist("theta0", self.theta0))
        object.__setattr__(self, "theta1", _theta_below_nyquist("theta1", self.theta1))

    @property
    def max_theta(self) -> float:
        """Highest instantaneous frequency, as ``omega T`` (rad)."""
        return max(self.theta0, self.theta1)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Force in N at times ``t`` (s); the sweep holds ``theta1`` after ``duration``."""
        t = np.asarray(t, dtype=float)
        w0, w1 = self.theta0 / self.T, self.theta1 / self.T
        rate = (w1 - w0) / self.duration
        tc = np.minimum(t, self.duration)
        phase = w0 * tc + 0.5 * rate * tc * tc + w1 * (t - tc)
        return self.amplitude * np.sin(phase)


@dataclass(frozen=True)
class RandomSinusoids:
    """A seeded random sum of ``count`` sinusoids in N, frequencies uniform in (0, ``theta_max``).

    Amplitudes are random and scaled so that their sum is ``amplitude`` (peak force <= it);
    phases are uniform.  ``theta_max`` < pi keeps the sum band-limited below Nyquist.
    """

    T: float
    seed: int
    count: int = 8
    theta_max: float = 0.95 * math.pi
    amplitude: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta_max", _theta_below_nyquist("theta_max", self.theta_max))
        rng = np.random.default_rng(self.seed)
        thetas = rng.uniform(0.0, self.theta_max, self.count)
        weights = rng.uniform(0.2, 1.0, self.count)
        phases = rng.uniform(0.0, 2 * math.pi, self.count)
        object.__setattr__(self, "thetas", thetas)
        object.__setattr__(self, "amplitudes", self.amplitude * weights / weights.sum())
        object.__setattr__(self, "phases", phases)

    @property
    def max_theta(self) -> float:
        """Highest frequency present, as ``omega T`` (rad)."""
        return float(np.max(self.thetas))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Force in N at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        arg = np.multiply.outer(t, self.thetas / self.T) + self.phases
        return np.sin(arg) @ self.amplitudes


# --------------------------------------------------------------------------- simulation


@dataclass(frozen=True)
class EnergyRecord:
    """One run of the energy check.

    ``t`` (s) and ``energy`` (J, ``int_0^t w v dt``) and ``velocity`` (m/s) at the
    ``n_samples * substeps + 1`` sub-step boundaries; ``operator_force`` (N) per sub-step;
    ``wall_force`` (N) held over each period (``u_{k-d}``); ``work_scale`` (J) the sum of
    ``|w dx|`` over all sub-steps, the scale of the round-off in ``energy``.
    """

    loop: WallLoop
    substeps: int
    t: np.ndarray
    energy: np.ndarray
    velocity: np.ndarray
    operator_force: np.ndarray
    wall_force: np.ndarray
    work_scale: float

    @property
    def n_samples(self) -> int:
        """Number of controller periods simulated."""
        return self.wall_force.size

    def roundoff_bound(self) -> float:
        """A bound (J) on the round-off in any ``energy`` value.

        Recursive summation of ``n`` terms errs by at most ``(n - 1) u sum|x_i|`` (Higham,
        Accuracy and Stability, eq. 4.4), ``u = 2^-53``; each term carries a few ulps of its
        own; the velocities it uses come from a stable recursion whose round-off is
        amplified by at most ``1/(1 - rho)``.  Taken together and rounded up generously:
        ``(n + 64/(1 - rho)) u sum|w dx|``.
        """
        n = self.energy.size - 1
        rho = min(spectral_radius(self.loop), 1.0 - 1e-6)
        return (n + 64.0 / (1.0 - rho)) * 2.0**-53 * self.work_scale

    def energy_at(self, when: ArrayLike) -> np.ndarray:
        """``E`` (J) at arbitrary times ``when`` (s), exact: the partial sub-step is solved too."""
        when = np.atleast_1d(np.asarray(when, dtype=float))
        h = self.loop.T / self.substeps
        index = np.clip(np.floor(when / h).astype(int), 0, self.operator_force.size - 1)
        tau = when - index * h
        c = self.loop.b * tau / self.loop.m
        p_v = tau * phi1_array(c)
        p_f = tau * tau / self.loop.m * phi2_array(c)
        k = index // self.substeps
        w = self.operator_force[index]
        displacement = p_v * self.velocity[index] + p_f * (w - self.wall_force[k])
        return self.energy[index] + w * displacement


def _check_run(n_samples: int, substeps: int) -> tuple[int, int]:
    return (
        whole_in_range("n_samples", n_samples, 1, MAX_SAMPLES),
        whole_in_range("substeps", substeps, 1, MAX_SUBSTEPS),
    )


def _midpoints(T: float, n_samples: int, substeps: int) -> np.ndarray:
    h = T / substeps
    return (np.arange(n_samples * substeps) + 0.5) * h


def simulate(loop: WallLoop, force: OperatorForce, n_samples: int, substeps: int = DEFAULT_SUBSTEPS) -> EnergyRecord:
    """Run the sampled-data loop from rest for ``n_samples`` periods; the energy record in J.

    ``force(t)`` gives the operator force in N at times ``t`` (s, a vector); it is held
    over each sub-step of ``T/substeps`` at its midpoint value.  Vectorised (lfilter +
    superposition); :func:`simulate_reference` is the plain loop it must agree with.
    """
    n_samples, substeps = _check_run(n_samples, substeps)
    m, b, T = loop.m, loop.b, loop.T
    h = T / substeps
    w = np.asarray(force(_midpoints(T, n_samples, substeps)), dtype=float).reshape(n_samples, substeps)

    # Sub-step coefficients.  A velocity at the start of sub-step j of a period is
    #   v_kj = decay[j] v_k - gain[j] f_k + (w_k @ inject.T)[j]
    co = zoh_coefficients(m, b, h)
    j = np.arange(substeps + 1)
    c_h = b * h / m
    decay = np.exp(-c_h * j)  # a_h^j
    gain = (j * h / m) * phi1_array(c_h * j)  # velocity from unit force held j sub-steps
    lag = j[:substeps, None] - 1 - j[None, :substeps]
    inject = np.where(lag >= 0, np.exp(-c_h * np.maximum(lag, 0)) * co.k1, 0.0)  # (S, S)
    to_end = np.exp(-c_h * (substeps - 1 - j[:substeps])) * co.k1  # (S,)

    g = w @ to_end  # operator's velocity increment over each period, m/s
    poly = characteristic_polynomial(loop)
    if loop.K > 0:
        # v_{k+1} = a v_k - k1 u_{k-d} + g_k with u = (K T z/(z - 1) + B) v  =>  V/G = (z - 1) z^d / P(z)
        v = lfilter([0.0, 1.0, -1.0], poly, g)
        u = lfilter([loop.K * T + loop.B, -loop.B], [1.0, -1.0], v)
    else:
        v = lfilter([0.0, 1.0], poly, g)  # V/G = z^d / P(z), P = (z - a) z^d + k1 B
        u = loop.B * v
    d = loop.delay
    f = np.concatenate([np.zeros(min(d, n_samples)), u[: n_samples - d]]) if d else u

    v_sub = decay[None, :substeps] * v[:, None] - gain[None, :substeps] * f[:, None] + w @ inject.T
    work = w * (co.p_v * v_sub + co.p_f * (w - f[:, None]))
    v_end = decay[substeps] * v[-1] - gain[substeps] * f[-1] + g[-1]
    energy = np.concatenate([[0.0], np.cumsum(work.ravel())])
    velocity = np.concatenate([v_sub.ravel(), [v_end]])
    t = np.arange(n_samples * substeps + 1) * h
    return EnergyRecord(loop, substeps, t, energy, velocity, w.ravel(), f, float(np.abs(work).sum()))


def simulate_reference(
    loop: WallLoop, force: OperatorForce, n_samples: int, substeps: int = DEFAULT_SUBSTEPS
) -> EnergyRecord:
    """:func:`simulate` written out as the controller and the plant run: slow, obviously right."""
    n_samples, substeps = _check_run(n_samples, substeps)
    T = loop.T
    h = T / substeps
    w_all = np.asarray(force(_midpoints(T, n_samples, substeps)), dtype=float)
    plant = ExactPlant(loop.m, loop.b, h)
    x = 0.0
    pending = [0.0] * loop.delay  # forces computed but not yet applied (oldest first)
    energy, velocity, applied = [0.0], [], []
    total, scale = 0.0, 0.0
    for k in range(n_samples):
        v_k = plant.velocity  # the drive samples the velocity at kT
        x += T * v_k
        pending.append(loop.K * x + loop.B * v_k)
        f = pending.pop(0)
        applied.append(f)
        for jj in range(substeps):
            w = float(w_all[k * substeps + jj])
            velocity.append(plant.velocity)
            dw = w * plant.advance(w - f)
            total += dw
            scale += abs(dw)
            energy.append(total)
    velocity.append(plant.velocity)
    t = np.arange(n_samples * substeps + 1) * h
    return EnergyRecord(loop, substeps, t, np.array(energy), np.array(velocity), w_all, np.array(applied), scale)


# --------------------------------------------------------------------------- mean power


@dataclass(frozen=True)
class MeanPower:
    """Mean power (W) a sinusoidal operator force puts in, in the periodic steady state.

    ``theta`` is the frequency actually used (``2 pi p/q``, the request rounded so that
    ``q`` samples hold exactly ``p`` input periods), ``window`` the number of samples averaged
    (whole input periods), ``settle`` the samples skipped as transient, ``predicted`` the
    exact prediction ``amplitude^2 Re T_fund(theta)/2`` (W), ``seed`` the same with the seed's
    ``T_zw``.
    """

    power: float
    theta: float
    window: int
    settle: int
    predicted: float
    seed: float
    record: EnergyRecord

    @property
    def relative_error(self) -> float:
        """``(power - predicted)/|predicted|`` (dimensionless)."""
        return (self.power - self.predicted) / abs(self.predicted)


def commensurate_theta(theta: float, max_samples: int = 4096) -> tuple[int, int]:
    """``(p, q)`` with ``2 pi p/q`` closest to ``theta`` and ``q <= max_samples`` samples."""
    theta = _theta_below_nyquist("theta", theta)
    ratio = Fraction(theta / (2 * math.pi)).limit_denominator(max_samples)
    if ratio.numerator == 0:
        ratio = Fraction(1, max_samples)
    return ratio.numerator, ratio.denominator


def mean_power(
    loop: WallLoop,
    theta: float,
    amplitude: float = 1.0,
    *,
    substeps: int = DEFAULT_SUBSTEPS,
    min_window: int = 4000,
    transient: float = 1e-10,
) -> MeanPower:
    """Mean operator power (W) for ``w = amplitude sin(omega t)``, ``theta = omega T`` in (0, pi).

    ``theta`` is rounded to ``2 pi p/q`` (``q <= 4096``) so that the sampled-data loop's
    steady state is periodic with ``q`` samples; the loop is run until its slowest mode has
    decayed to ``transient`` of its start (``rho^settle <= transient``) and the energy is
    averaged over whole multiples of ``q`` samples (at least ``min_window``).  Needs a stable loop.
    """
    rho = spectral_radius(loop)
    if not rho < 1.0:
        raise ParameterError("loop", loop, "a stable loop (closed-loop spectral radius < 1) for a steady state")
    p, q = commensurate_theta(theta)
    used = 2 * math.pi * p / q
    settle = int(math.ceil(math.log(transient) / math.log(rho))) if rho > 0 else 1
    settle = q * int(math.ceil(settle / q))
    window = q * max(1, int(math.ceil(min_window / q)))
    record = simulate(loop, Sinusoid(used, loop.T, amplitude), settle + window, substeps)
    start, stop = settle * substeps, (settle + window) * substeps
    power = (record.energy[stop] - record.energy[start]) / (window * loop.T)
    predicted = 0.5 * amplitude**2 * float(t_fund(loop, used)[0].real)
    seed = 0.5 * amplitude**2 * float(seed_t_zw(loop, used)[0].real)
    return MeanPower(power, used, window, settle, predicted, seed, record)
