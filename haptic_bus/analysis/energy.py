"""Time-domain energy check of the sampled-data wall loop (DESIGN 3.4): the arbiter.

The loop as it runs, for every velocity model and every real delay ``D = d + delta``: the handle
``m dv/dt + b v = w(t) - f(t)`` with its measurement state (:func:`~haptic_bus.analysis.sampled_loop.continuous_model`);
at every SYNC ``kT`` the controller reads ``y_k``, forms ``x_k = x_{k-1} + T y_k`` and
``u_k = K x_k + B y_k``; the drive holds ``u_{k-d-1}`` over ``[kT, kT + delta T)`` and ``u_{k-d}``
over ``[kT + delta T, (k+1) T)`` (``u_j = 0`` for ``j < 0``: the loop starts from rest).

The operator force is a sum of tones ``w(t) = sum_i A_i sin(omega_i t + phi_i)`` (:class:`Tones`;
any ``omega_i >= 0``, above the Nyquist frequency too, 0 for a constant push).  The tones come
from a linear oscillator appended to the plant's state, so between events the whole state obeys
one linear ODE, and both its solution and the operator's work ``int w v dt`` over each piece are
blocks of one matrix exponential (Van Loan, IEEE TAC 23 (1978): ``exp([[-F^T, Q], [0, F]] h)``
holds ``int_0^h e^{F^T t} Q e^{F t} dt``).  No force is held on sub-steps: the energy record
``E(t) = int_0^t w v dt`` (J) is exact to round-off at every piece boundary and, by one more
exponential, at any time (:meth:`EnergyRecord.energy_at`).

The sampled states follow from the closed-loop matrix of :mod:`haptic_bus.analysis.sampled_loop`
(its plant augmented by the oscillator), built here from ``scipy.linalg.expm`` of the continuous
model, independently of that module's closed-form period map.

:func:`mean_power` is the exact mean power of a sinusoid in the periodic steady state: the
frequency is rounded to ``2 pi p/q``, the state that repeats after ``q`` samples is solved for
(no transient to wait out), and the work over those ``q`` samples is summed.  Its prediction
``|W|^2 Re T_fund / 2`` (:mod:`haptic_bus.analysis.frequency`) must agree to round-off.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from haptic_bus.analysis.frequency import seed_t_zw, t_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import spectral_radius
from haptic_bus.analysis.sampled_loop import (
    ClosedLoopLayout,
    ContinuousModel,
    PeriodMap,
    continuous_model,
    event_times,
    shifted_closed_loop,
)
from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range, whole_in_range

MAX_SAMPLES = 10_000_000
MAX_SUBSTEPS = 4096
MAX_PERIOD_SAMPLES = 65_536


# --------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class Tones:
    """``w(t) = sum_i amplitudes[i] sin(omegas[i] t + phases[i])`` in N; ``omegas`` in rad/s (>= 0)."""

    omegas: tuple[float, ...]
    amplitudes: tuple[float, ...]
    phases: tuple[float, ...]

    def __post_init__(self) -> None:
        if not len(self.omegas) == len(self.amplitudes) == len(self.phases) or not self.omegas:
            raise ParameterError("tones", self, "equally many (>= 1) omegas, amplitudes and phases")
        for name, values in (("omega", self.omegas), ("amplitude", self.amplitudes), ("phase", self.phases)):
            low = 0.0 if name == "omega" else -math.inf
            for value in values:
                if not (math.isfinite(value) and value >= low):
                    raise ParameterError(name, value, "a finite real" + (" >= 0 rad/s" if name == "omega" else ""))

    def tones(self) -> Tones:
        """Itself (every operator force offers its tones)."""
        return self

    def __call__(self, t: ArrayLike) -> np.ndarray:
        """Force in N at times ``t`` (s)."""
        arg = np.multiply.outer(np.asarray(t, dtype=float), np.array(self.omegas)) + np.array(self.phases)
        return np.sin(arg) @ np.array(self.amplitudes)


class OperatorForce(Protocol):
    """Anything that is a sum of tones."""

    def tones(self) -> Tones: ...


def _theta_below_nyquist(name: str, theta: object) -> float:
    """A frequency ``theta = omega T`` strictly inside (0, pi), else ParameterError."""
    value = real_in_range(name, theta, 0.0, math.pi, low_inclusive=False, unit="rad (omega T)")
    if value >= math.pi:
        raise ParameterError(name, theta, "a finite real in (0, pi) rad: below the Nyquist frequency pi/T")
    return value


@dataclass(frozen=True)
class Sinusoid:
    """``w(t) = amplitude sin(theta t / T + phase)`` in N; ``theta = omega T`` in (0, pi) (band-limited)."""

    theta: float
    T: float
    amplitude: float = 1.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta", _theta_below_nyquist("theta", self.theta))

    def tones(self) -> Tones:
        """The one tone."""
        return Tones((self.theta / self.T,), (self.amplitude,), (self.phase,))

    def __call__(self, t: ArrayLike) -> np.ndarray:
        """Force in N at times ``t`` (s)."""
        return self.tones()(t)


@dataclass(frozen=True)
class Constant:
    """A constant push ``w(t) = force`` N (a tone of frequency 0)."""

    force: float

    def tones(self) -> Tones:
        """``force sin(0 t + pi/2)``."""
        return Tones((0.0,), (self.force,), (0.5 * math.pi,))


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

    @functools.cached_property
    def thetas(self) -> np.ndarray:
        """The tones' ``omega T`` (rad)."""
        return self._draw()[0]

    def _draw(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rng = np.random.default_rng(self.seed)
        thetas = rng.uniform(0.0, self.theta_max, self.count)
        weights = rng.uniform(0.2, 1.0, self.count)
        phases = rng.uniform(0.0, 2 * math.pi, self.count)
        return thetas, self.amplitude * weights / weights.sum(), phases

    def tones(self) -> Tones:
        """The ``count`` tones."""
        thetas, amplitudes, phases = self._draw()
        return Tones(tuple(thetas / self.T), tuple(amplitudes), tuple(phases))

    def __call__(self, t: ArrayLike) -> np.ndarray:
        """Force in N at times ``t`` (s)."""
        return self.tones()(t)


# --------------------------------------------------------------------------- the exact machine


def van_loan(F: np.ndarray, Q: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(e^{F h}, int_0^h e^{F^T t} Q e^{F t} dt)``.

    Over a step ``h0 = h / 2^s`` with ``||F|| h0 <= 1`` both are blocks of one exponential,
    ``exp([[-F^T, Q], [0, F]] h0)`` (the ``e^{-F^T h0}`` inside grows by at most ``e``, so a
    fast-decaying plant, ``bT/m = 90``, loses nothing); then ``s`` doublings
    ``I(2h) = I(h) + e^{F^T h} I(h) e^{F h}``, ``e^{2Fh} = (e^{Fh})^2``.
    """
    from scipy.linalg import expm  # lazily: the frequency-domain analysis does not need scipy

    n = F.shape[0]
    doublings = max(0, math.ceil(math.log2(max(float(np.linalg.norm(F, 1)) * h, 1e-300))))
    step = h / 2.0**doublings
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -F.T
    block[:n, n:] = Q
    block[n:, n:] = F
    e = expm(block * step)
    transition = e[n:, n:]
    integral = transition.T @ e[:n, n:]
    for _ in range(doublings):
        integral = integral + transition.T @ integral @ transition
        transition = transition @ transition
    return transition, integral


@dataclass(frozen=True)
class _Piece:
    """One stretch of a period: length ``h`` (periods), the work matrix over ``xi_k`` and the
    map from ``xi_k`` to the augmented state at its start (``[s, oscillator, held force]``)."""

    start: float
    h: float
    start_map: np.ndarray
    work: np.ndarray
    now: bool


class LoopMachine:
    """The loop driven by ``tones``: closed-loop matrix over ``xi = [s, oscillator, controller]`` and its pieces.

    ``model``: the plant and measurement in ``loop``'s scaled units (None: ``loop``'s rigid handle),
    with the operator's force entering at its ``operator_column`` and its power taken on the state
    ``handle`` (a two-mass device: :mod:`haptic_bus.analysis.two_mass`).
    """

    def __init__(self, loop: WallLoop, tones: Tones, substeps: int, model: ContinuousModel | None = None) -> None:
        model = continuous_model(loop) if model is None else model
        self.loop, self.tones = loop, tones
        T, m = loop.T, loop.m
        ns, nt = model.c.size, len(tones.omegas)
        nsg = ns + 2 * nt
        nx = nsg + 1  # + the held wall force (scaled)
        F = np.zeros((nx, nx))
        Q = np.zeros((nx, nx))
        F[:ns, :ns] = model.A
        F[:ns, -1] = -model.b
        for i, (omega, amplitude) in enumerate(zip(tones.omegas, tones.amplitudes)):
            cos_i, sin_i = ns + 2 * i, ns + 2 * i + 1
            F[cos_i, sin_i], F[sin_i, cos_i] = -omega * T, omega * T
            F[:ns, sin_i] = model.operator_column * amplitude * T / m  # the operator's force, scaled
            Q[model.handle, sin_i] = Q[sin_i, model.handle] = 0.5 * T * amplitude  # w v T per unit scaled time, J
        self.F, self.Q, self.nsg, self.ns, self.handle = F, Q, nsg, ns, model.handle
        self.reset = model.reset
        self.delta = loop.fractional_delay
        times = sorted(set(event_times(loop)) | {j / substeps for j in range(substeps)})
        exps = {h: van_loan(F, Q, h) for h in {round(b - a, 15) for a, b in itertools.pairwise(times)}}

        # the sampled plant + oscillator over one period, for the closed loop
        phi = np.eye(nsg)
        gam = {True: np.zeros(nsg), False: np.zeros(nsg)}
        for a, b in itertools.pairwise(times):
            phi, gam = self._reset(a, phi), {k: self._reset(a, g) for k, g in gam.items()}
            trans = exps[round(b - a, 15)][0]
            now = b > self.delta
            phi = trans[:nsg, :nsg] @ phi
            # the period map's gamma is the response to +u; the wall force acts as -u on the handle
            gam = {k: trans[:nsg, :nsg] @ g - (trans[:nsg, -1] if k == now else 0.0) for k, g in gam.items()}
        c = np.zeros(nsg)
        c[:ns] = model.c
        pmap = PeriodMap(phi - np.eye(nsg), gam[True], gam[False], c)
        layout = ClosedLoopLayout(pmap, loop.kappa, loop.q, loop.delay, loop.K > 0)
        self.layout = layout
        self.matrix = shifted_closed_loop(pmap, loop.kappa, loop.q, loop.delay, loop.K > 0) + np.eye(layout.size)

        # each piece's start state and work as maps of xi_k
        select = np.zeros((nsg, layout.size))
        select[:, :nsg] = np.eye(nsg)
        pieces = []
        for a, b in itertools.pairwise(times):
            select = self._reset(a, select)
            now = b > self.delta
            force = layout.force_now() if now else layout.force_before()
            start_map = np.vstack([select, force])
            trans, work = exps[round(b - a, 15)]
            pieces.append(_Piece(a, b - a, start_map, start_map.T @ work @ start_map, now))
            select = trans[:nsg] @ start_map
        self.pieces = pieces

    def _reset(self, time: float, rows: np.ndarray) -> np.ndarray:
        if self.reset is not None and time == self.reset[1]:
            rows = rows.copy()
            rows[self.reset[0]] = 0.0
        return rows

    def initial_state(self) -> np.ndarray:
        """``xi_0``: the loop at rest, the oscillator at the tones' phases."""
        xi = np.zeros(self.layout.size)
        for i, phase in enumerate(self.tones.phases):
            xi[self.ns + 2 * i] = math.cos(phase)
            xi[self.ns + 2 * i + 1] = math.sin(phase)
        return xi

    def run(self, xi0: np.ndarray, n: int) -> np.ndarray:
        """``xi_k`` for ``k = 0 .. n`` (rows)."""
        out = np.empty((n + 1, xi0.size))
        out[0] = xi0
        m = self.matrix
        for k in range(n):
            out[k + 1] = m @ out[k]
        return out

    def work(self, states: np.ndarray) -> np.ndarray:
        """Operator work (J) over each piece of each period: shape ``(len(states), pieces)``."""
        return np.stack([np.einsum("ki,ij,kj->k", states, p.work, states) for p in self.pieces], axis=1)

    @property
    def size(self) -> int:
        """Length of ``xi``."""
        return self.layout.size

    @property
    def piece_work(self) -> list[np.ndarray]:
        """Per piece of a period the matrix ``Q_p`` with the operator's work over it ``xi_k^T Q_p xi_k`` (J)."""
        return [p.work for p in self.pieces]

    @property
    def period_work(self) -> np.ndarray:
        """``Q`` with the operator's work over one whole period ``xi_k^T Q xi_k`` (J)."""
        return sum(self.piece_work[1:], self.piece_work[0])


# --------------------------------------------------------------------------- simulation


@dataclass(frozen=True)
class EnergyRecord:
    """One run of the energy check.

    ``t`` (s) and ``energy`` (J, ``int_0^t w v dt``), ``velocity`` (m/s) and ``operator_force`` (N)
    at the ``n_samples * substeps + 1`` sub-step boundaries ``j T/substeps``; ``wall_force`` (N)
    the force ``u_{k-d}`` held over the last ``(1 - delta)`` of each period; ``work_scale`` (J)
    the sum of ``|work|`` over all pieces, the scale of the round-off in ``energy``.
    """

    loop: WallLoop
    substeps: int
    t: np.ndarray
    energy: np.ndarray
    velocity: np.ndarray
    operator_force: np.ndarray
    wall_force: np.ndarray
    work_scale: float
    _machine: LoopMachine
    _states: np.ndarray

    @property
    def n_samples(self) -> int:
        """Number of controller periods simulated."""
        return self.wall_force.size

    def roundoff_bound(self) -> float:
        """A bound (J) on the round-off in any ``energy`` value.

        Recursive summation of ``n`` terms errs by at most ``(n - 1) u sum|x_i|`` (Higham,
        Accuracy and Stability, eq. 4.4), ``u = 2^-53``; each term carries a few ulps of its
        own; the states it uses come from a stable recursion whose round-off is amplified by
        at most ``1/(1 - rho)``.  Together, rounded up generously: ``(n + 64/(1 - rho)) u sum|work|``.
        """
        n = self.energy.size - 1
        rho = min(spectral_radius(self.loop), 1.0 - 1e-6)
        return (n + 64.0 / (1.0 - rho)) * 2.0**-53 * self.work_scale

    def energy_at(self, when: ArrayLike) -> np.ndarray:
        """``E`` (J) at arbitrary times ``when`` (s) in the run, exact: the partial piece is solved too."""
        machine = self._machine
        T = self.loop.T
        out = []
        for t in np.atleast_1d(np.asarray(when, dtype=float)):
            k = min(int(t // T), self.n_samples - 1)
            tau = t / T - k
            xi = self._states[k]
            total = self.energy[k * self.substeps]
            for piece in machine.pieces:
                if piece.start >= tau:
                    break
                if piece.start + piece.h <= tau:
                    total += float(xi @ piece.work @ xi)
                else:
                    x = piece.start_map @ xi
                    _, work = van_loan(machine.F, machine.Q, tau - piece.start)
                    total += float(x @ work @ x)
            out.append(total)
        return np.array(out)


def _check_run(n_samples: int, substeps: int) -> tuple[int, int]:
    return (
        whole_in_range("n_samples", n_samples, 1, MAX_SAMPLES),
        whole_in_range("substeps", substeps, 1, MAX_SUBSTEPS),
    )


def simulate(loop: WallLoop, force: OperatorForce, n_samples: int, substeps: int = 1) -> EnergyRecord:
    """Run the sampled-data loop from rest for ``n_samples`` periods under ``force``; the energy record in J.

    Exact (see the module docstring); ``substeps`` only sets how finely ``E(t)`` is recorded.
    """
    n_samples, substeps = _check_run(n_samples, substeps)
    tones = force.tones()
    machine = LoopMachine(loop, tones, substeps)
    states = machine.run(machine.initial_state(), n_samples)
    work = machine.work(states[:-1])  # (n, pieces)
    starts = np.array([p.start for p in machine.pieces])
    step = np.floor(starts * substeps + 1e-9).astype(int)  # the sub-step each piece lies in
    per_step = work @ (step[:, None] == np.arange(substeps)[None, :])  # (n, substeps)
    energy = np.concatenate([[0.0], np.cumsum(per_step.ravel())])
    recorded = [p for p in machine.pieces if any(abs(p.start - j / substeps) < 1e-12 for j in range(substeps))]
    velocity = np.stack([states[:-1] @ p.start_map[machine.handle] for p in recorded], axis=1).ravel()
    velocity = np.append(velocity, states[-1, machine.handle])
    t = np.arange(n_samples * substeps + 1) * (loop.T / substeps)
    wall = states[:-1] @ machine.layout.force_now() * (loop.m / loop.T)
    return EnergyRecord(loop, substeps, t, energy, velocity, tones(t), wall, float(np.abs(work).sum()), machine, states)


def wall_forces(loop: WallLoop, force: OperatorForce, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """``(u_k, u_{k-d})`` in N for ``k = 0 .. n_samples - 1``: the force the controller computes at
    ``kT`` and the one the drive holds from ``kT + delta T``, the loop starting from rest."""
    n_samples = whole_in_range("n_samples", n_samples, 1, MAX_SAMPLES)
    machine = LoopMachine(loop, force.tones(), 1)
    states = machine.run(machine.initial_state(), n_samples - 1)
    unit = loop.m / loop.T
    return states @ machine.layout.u_row * unit, states @ machine.layout.force_now() * unit


# --------------------------------------------------------------------------- mean power


def periodic_mean_power(loop: WallLoop, force: OperatorForce, samples: int, model: ContinuousModel | None = None
                        ) -> float:
    """Mean operator power (W) in the steady state of a force that repeats after ``samples`` periods.

    Every tone must satisfy ``omega T samples = 2 pi (whole number)``.  The state ``xi`` that
    repeats after ``samples`` periods is solved for (``(I - M^q) chi = M^q_{chi g} g``), then the
    work over those periods is summed exactly.  Needs a stable loop (``model``, another plant in
    ``loop``'s scaled units as :class:`LoopMachine` takes it: the caller has judged its stability).
    """
    samples = whole_in_range("samples", samples, 1, MAX_PERIOD_SAMPLES)
    if model is None and not spectral_radius(loop) < 1.0:
        raise ParameterError("loop", loop, "a stable loop (closed-loop spectral radius < 1) for a steady state")
    tones = force.tones()
    for omega in tones.omegas:
        turns = omega * loop.T * samples / (2 * math.pi)
        if abs(turns - round(turns)) > 1e-9 * max(1.0, turns):
            raise ParameterError("omega", omega, f"a whole number of turns in {samples} periods of {loop.T:g} s")
    machine = LoopMachine(loop, tones, 1, model)
    power = np.linalg.matrix_power(machine.matrix, samples)
    xi0 = machine.initial_state()
    osc = np.zeros(xi0.size, dtype=bool)
    osc[machine.ns : machine.nsg] = True
    rest = ~osc
    chi = np.linalg.solve(np.eye(rest.sum()) - power[np.ix_(rest, rest)], power[np.ix_(rest, osc)] @ xi0[osc])
    xi0[rest] = chi
    states = machine.run(xi0, samples - 1)
    return float(machine.work(states).sum() / (samples * loop.T))


@dataclass(frozen=True)
class MeanPower:
    """Mean power (W) a sinusoidal operator force puts in, in the periodic steady state.

    ``theta`` is the frequency actually used (``2 pi p/q``, the request rounded so that ``q``
    samples hold exactly ``p`` input periods), ``window`` = ``q``, ``predicted`` the exact
    prediction ``amplitude^2 Re T_fund(theta)/2`` (W), ``seed`` the same with the seed's ``T_zw``.
    """

    power: float
    theta: float
    window: int
    predicted: float
    seed: float

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


def mean_power(loop: WallLoop, theta: float, amplitude: float = 1.0, *, max_samples: int = 4096) -> MeanPower:
    """Mean operator power (W) for ``w = amplitude sin(omega t)``, ``theta = omega T`` in (0, pi), exact.

    ``theta`` is rounded to ``2 pi p/q`` (``q <= max_samples``) so that the steady state is
    periodic with ``q`` samples (:func:`periodic_mean_power`).  Needs a stable loop.
    """
    p, q = commensurate_theta(theta, max_samples)
    used = 2 * math.pi * p / q
    power = periodic_mean_power(loop, Sinusoid(used, loop.T, amplitude), q)
    predicted = 0.5 * amplitude**2 * float(t_fund(loop, used)[0].real)
    seed = 0.5 * amplitude**2 * float(seed_t_zw(loop, used)[0].real)
    return MeanPower(power, used, q, predicted, seed)
