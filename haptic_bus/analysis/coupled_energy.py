"""Time-domain energy check of the coupled axes (DESIGN 3.4, issue 22): the arbiter of the coupled gate.

The loop as it runs: every axis' handle ``m_i dv_i/dt + b_i v_i = w_i(t) - f_i(t)`` with its
measurement states (:func:`~haptic_bus.analysis.sampled_loop.continuous_model`); at every SYNC
``kT`` the controller reads every ``y_{i,k}``, forms ``x_k = x_{k-1} + T y_k`` and
``u_k = K x_k + B y_k`` (N); axis ``i``'s drive holds ``u_{i,k-d_i-1}`` over
``[kT, kT + delta_i T)`` and ``u_{i,k-d_i}`` after (``u_j = 0`` for ``j < 0``: from rest).

The operator pushes with one tone in a chosen direction, ``w(t) = Re(W e^{j omega t})``, ``W``
a complex ``N``-vector (N): the adversarial input is ``W = Z(theta*) v*``, the force that drives
the worst velocity direction ``v*`` of :func:`~haptic_bus.analysis.coupled.worst_direction` at
the critical ``theta*``.  The tone comes from an oscillator in the state, so between the
period's events (every axis' force switch ``delta_i`` and window reset) the whole state obeys
one linear ODE, and both its solution and the operator's work ``sum_i int w_i v_i dt`` over
each piece are blocks of one matrix exponential (:func:`~haptic_bus.analysis.energy.van_loan`).
Nothing here uses the frequency-domain formulas or the closed-form period maps: only the
continuous models and ``scipy.linalg.expm``.

:class:`CoupledMachine` is one loop and one input: its period matrix ``M`` over
``xi_k = [plant states, oscillator, x_{k-1}, held forces]`` and the work of each piece as a
quadratic form in ``xi_k``.  :func:`simulate_energies` runs many machines at once (states
padded to one size, one batched product per period): the energy ``E`` (J) at every piece
boundary from rest.  :func:`energy_after` gives ``E`` after ``2^j`` periods by doubling (exact
sums of quadratic forms, no stepping, with a bound on their round-off), :func:`steady_mean_power` the exact mean power of the
periodic steady state.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple, Protocol

import numpy as np

from haptic_bus.analysis.coupled import hermitian_impedance
from haptic_bus.analysis.coupled_loop import CoupledLoop
from haptic_bus.analysis.energy import van_loan
from haptic_bus.analysis.sampled_loop import continuous_model

_UNIT_ROUNDOFF = 2.0**-53


class PeriodMachine(Protocol):
    """A loop and its input over one period: ``xi_{k+1} = matrix xi_k``, the operator's work per piece
    as quadratic forms in ``xi_k`` (J), and the state it starts from (:class:`CoupledMachine`, and
    :class:`~haptic_bus.analysis.energy.LoopMachine` of one handle, rigid or two-mass)."""

    @property
    def matrix(self) -> np.ndarray: ...

    @property
    def size(self) -> int: ...

    @property
    def piece_work(self) -> list[np.ndarray]: ...

    @property
    def period_work(self) -> np.ndarray: ...

    def initial_state(self) -> np.ndarray: ...


class CoupledMachine:
    """The coupled loop driven by ``w(t) = Re(W e^{j theta t/T})`` (``force`` = ``W`` in N), exactly.

    ``matrix``: ``xi_{k+1} = M xi_k``; ``piece_work``: per piece of a period the matrix ``Q_p``
    with the operator's work over that piece ``xi_k^T Q_p xi_k`` (J).
    """

    def __init__(self, loop: CoupledLoop, theta: float, force: np.ndarray) -> None:
        self.loop = loop
        T = loop.T
        models = [continuous_model(axis) for axis in loop.axes]
        sizes = [model.c.size for model in models]
        starts = np.cumsum([0, *sizes])
        ns, nx = int(starts[-1]), loop.size
        osc = ns  # cos, sin
        held = ns + 2
        nz = held + nx
        W = np.asarray(force, dtype=complex)
        F, Q = np.zeros((nz, nz)), np.zeros((nz, nz))
        for i, (model, axis) in enumerate(zip(models, loop.axes)):
            at = slice(int(starts[i]), int(starts[i + 1]))
            unit = T / axis.m  # scaled force per N
            F[at, at] = model.A
            F[at, osc] = model.b * unit * W[i].real
            F[at, osc + 1] = -model.b * unit * W[i].imag
            F[at, held + i] = -model.b * unit
            v = int(starts[i])
            Q[v, osc] = Q[osc, v] = 0.5 * T * W[i].real
            Q[v, osc + 1] = Q[osc + 1, v] = -0.5 * T * W[i].imag
        F[osc, osc + 1], F[osc + 1, osc] = -theta, theta

        # discrete state: [s, osc, x_{k-1}, registers]; axis i keeps d_i (+1 with a fractional delay) past forces
        lags = [axis.whole_delay + (1 if axis.fractional_delay > 0 else 0) for axis in loop.axes]
        first_x = ns + 2
        first_slot = first_x + nx + np.cumsum([0, *lags])[:-1]
        size = first_x + nx + sum(lags)
        y = np.zeros((nx, size))
        for i, model in enumerate(models):
            y[i, int(starts[i]) : int(starts[i + 1])] = model.c
        x_prev = np.zeros((nx, size))
        x_prev[:, first_x : first_x + nx] = np.eye(nx)
        u_now = loop.K @ (x_prev + T * y) + loop.B @ y

        def held_row(i: int, lag: int) -> np.ndarray:
            if lag == 0:
                return u_now[i]
            row = np.zeros(size)
            row[first_slot[i] + lag - 1] = 1.0
            return row

        events = {0.0, 1.0} | {axis.fractional_delay for axis in loop.axes}
        resets: dict[float, list[int]] = {}
        for i, model in enumerate(models):
            if model.reset is not None:
                events.add(model.reset[1])
                resets.setdefault(model.reset[1], []).append(int(starts[i]) + model.reset[0])
        times = sorted(events)
        exps = {h: van_loan(F, Q, h) for h in {round(b - a, 15) for a, b in itertools.pairwise(times)}}
        current = np.zeros((held, size))
        current[:, :held] = np.eye(held)
        pieces = []
        for a, b in itertools.pairwise(times):
            for index in resets.get(a, ()):
                current[index] = 0.0
            forces = np.vstack([held_row(i, axis.whole_delay + (1 if b <= axis.fractional_delay else 0))
                                for i, axis in enumerate(loop.axes)])
            start_map = np.vstack([current, forces])
            transition, work = exps[round(b - a, 15)]
            pieces.append(start_map.T @ work @ start_map)
            current = transition[:held] @ start_map
        M = np.zeros((size, size))
        M[:held] = current
        M[first_x : first_x + nx] = x_prev + T * y
        for i, lag in enumerate(lags):
            if lag:
                M[first_slot[i]] = u_now[i]
                for j in range(1, lag):
                    M[first_slot[i] + j, first_slot[i] + j - 1] = 1.0
        self.matrix = M
        self.piece_work = pieces
        self.size = size
        self.oscillator = osc

    def initial_state(self) -> np.ndarray:
        """``xi_0``: every axis at rest, no force held, the oscillator at ``(cos 0, sin 0)``."""
        xi = np.zeros(self.size)
        xi[self.oscillator] = 1.0
        return xi

    @property
    def period_work(self) -> np.ndarray:
        """``Q`` with the operator's work over one whole period ``xi_k^T Q xi_k`` (J)."""
        return sum(self.piece_work[1:], self.piece_work[0])


@dataclass(frozen=True)
class EnergyRuns:
    """Energies from rest of several machines: ``energy`` (J) at every period boundary ``(runs, n + 1)``,
    ``lowest`` (J) the least over every piece boundary of each run, ``roundoff`` (J) a bound on its error."""

    energy: np.ndarray
    lowest: np.ndarray
    roundoff: np.ndarray


def simulate_energies(machines: list[PeriodMachine], n_samples: int) -> EnergyRuns:
    """Run every machine from rest for ``n_samples`` periods at once (batched); the operator's energy.

    The round-off bound is ``(n + 64) u sum|work|`` per run (recursive summation, DESIGN 3.4's
    bound with the state recursion's own round-off folded into the constant), ``u = 2^-53``.
    """
    size = max(m.size for m in machines)
    pieces = max(len(m.piece_work) for m in machines)
    runs = len(machines)
    M = np.zeros((runs, size, size))
    partial = np.zeros((runs, pieces, size, size))  # work from the period start to the end of each piece
    xi = np.zeros((runs, size))
    for r, machine in enumerate(machines):
        n = machine.size
        M[r, :n, :n] = machine.matrix
        acc = np.zeros((n, n))
        for p in range(pieces):
            acc = acc + (machine.piece_work[p] if p < len(machine.piece_work) else 0.0)
            partial[r, p, :n, :n] = acc
        xi[r, :n] = machine.initial_state()
    energy = np.zeros((runs, n_samples + 1))
    lowest = np.zeros(runs)
    magnitude = np.zeros(runs)
    for k in range(n_samples):
        within = np.einsum("ri,rpij,rj->rp", xi, partial, xi)
        step_low = energy[:, k] + within.min(axis=1)
        lowest = np.minimum(lowest, step_low)
        energy[:, k + 1] = energy[:, k] + within[:, -1]
        magnitude += np.abs(within).max(axis=1)
        xi = np.einsum("rij,rj->ri", M, xi)
    return EnergyRuns(energy, lowest, (n_samples + 64) * _UNIT_ROUNDOFF * magnitude)


def energy_after(machine: PeriodMachine, doublings: int) -> tuple[np.ndarray, np.ndarray]:
    """``(E, bound)`` in J from rest after ``2^j`` periods, ``j = 0 .. doublings`` (NaN after an overflow).

    ``E(n) = xi_0^T S_n xi_0`` with ``S_n = sum_{k<n} M^{kT} Q M^k``, by ``S_2n = S_n + M^{nT} S_n M^n``
    and ``M^2n = (M^n)^2``: no stepping.  The bound carries the magnitudes alongside
    (``|S|_2n = |S|_n + |M^n|^T |S|_n |M^n|``): each doubling's products and sum err by at most
    ``(2 size + 2) u`` times them (elementwise bound of a matrix product, Higham 3.5), and the
    errors of ``j`` doublings add: ``(j + 1)(2 size + 2) u xi_0^T |S| xi_0``.
    """
    xi0 = machine.initial_state()
    S, power = machine.period_work, machine.matrix
    magnitude = np.abs(S)
    energies, bounds = np.full(doublings + 1, np.nan), np.full(doublings + 1, np.nan)
    per_step = (2 * machine.size + 2) * _UNIT_ROUNDOFF
    with np.errstate(over="ignore", invalid="ignore"):
        for j in range(doublings + 1):
            value = float(xi0 @ S @ xi0)
            if not math.isfinite(value):
                break
            energies[j] = value
            bounds[j] = (j + 1) * per_step * float(xi0 @ magnitude @ xi0)
            S = S + power.T @ S @ power
            magnitude = magnitude + np.abs(power).T @ magnitude @ np.abs(power)
            power = power @ power
    return energies, bounds


def commensurate(theta: float, max_samples: int = 4096) -> tuple[float, int]:
    """``(2 pi p/q, q)``: the frequency nearest ``theta`` (rad) that repeats after ``q <= max_samples`` samples."""
    ratio = Fraction(theta / (2 * math.pi)).limit_denominator(max_samples)
    if ratio.numerator == 0:
        ratio = Fraction(1, max_samples)
    return 2 * math.pi * ratio.numerator / ratio.denominator, ratio.denominator


class SteadyPower(NamedTuple):
    """The exact mean power of a periodic steady state (W), and the bound on its round-off (W)."""

    mean: float
    roundoff: float


def steady_mean_power(machine: CoupledMachine, samples: int) -> SteadyPower:
    """Mean operator power (W) of the periodic steady state of a tone that repeats after ``samples`` periods.

    The state that repeats is solved for (``(I - M^q) chi = M^q_{chi, osc} osc_0``, least
    squares: the controller's position across the wall's normal is integrated but never fed
    back, a ``z = 1`` mode the work does not see), then the exact work over those ``q`` periods
    summed.  Needs a stable loop.

    The round-off bound is ``2 q eps sum_k |w_k| / (q T)``: recursive summation of ``q`` terms
    errs by at most ``(q - 1) eps sum |w_k|`` (Higham, *Accuracy and Stability*, 2002, sec. 4.2),
    and each term, propagated through at most ``q`` products with ``M``, carries an error of the
    same order.  Near Nyquist or at a slow tone the terms cancel to a small mean, and this bound,
    not the mean, sets how many digits are right.
    """
    M = machine.matrix
    power = np.linalg.matrix_power(M, samples)
    xi = machine.initial_state()
    osc = np.zeros(machine.size, dtype=bool)
    osc[machine.oscillator : machine.oscillator + 2] = True
    rest = ~osc
    xi[rest] = np.linalg.lstsq(np.eye(int(rest.sum())) - power[np.ix_(rest, rest)], power[np.ix_(rest, osc)] @ xi[osc],
                               rcond=None)[0]
    Q = machine.period_work
    total = 0.0
    magnitude = 0.0
    for _ in range(samples):
        work = float(xi @ Q @ xi)
        total += work
        magnitude += abs(work)
        xi = M @ xi
    duration = samples * machine.loop.T
    return SteadyPower(total / duration, 2.0 * samples * float(np.finfo(float).eps) * magnitude / duration)


def adversarial_input(loop: CoupledLoop, thetas: np.ndarray) -> tuple[float, np.ndarray]:
    """``(theta, W)``: the tone that takes energy out fastest, chosen from ``Herm Z``'s eigenvectors.

    At each candidate ``theta`` the least eigenvalue ``lambda`` of ``Herm Z`` (N s/m) and its
    eigenvector ``v`` give the force ``W = Z v`` (N) with mean power ``lambda/2`` (W); the tone
    picked is the one with the least ``lambda theta / ||Z||``, the mean power per period over
    the energy it stores: for an active loop the one that drives ``E`` below zero soonest.
    """
    part = hermitian_impedance(loop, thetas)
    values, vectors = np.linalg.eigh(part.matrix)
    size = np.linalg.norm(part.full, ord=2, axis=(1, 2))
    k = int(np.argmin(values[:, 0] * part.theta / size))
    return float(part.theta[k]), part.full[k] @ vectors[k, :, 0]
