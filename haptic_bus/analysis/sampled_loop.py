"""The sampled wall loop over one period, exactly: plant, measurement, held force, controller, delay.

One construction for every velocity model and every real delay ``D = d + delta`` (DESIGN 3.5).
Scaled units throughout: time ``t/T``, velocity as is, force ``f T/m`` (a velocity), the
controller's position ``x/T``; then the plant is ``dv/dt = -c v + f`` (``c = bT/m``) and the
wall is ``u_k = kappa x_k + q y_k``, ``x_k = x_{k-1} + y_k`` with ``kappa = K T^2/m``,
``q = B T/m``.

**The plant and its measurement** (:func:`continuous_model`): states ``s = [v]`` (``point``),
``[v, p]`` with ``dp/dt = v`` reset to 0 a window ``w = TW/T`` before each sample and
``y = p/w`` (``average``: ``w = 1``; ``window``), or ``[v, nu]`` with
``dnu/dt = lambda (v - nu)``, ``lambda = T/TAU`` and ``y = nu`` (``lowpass``).

**Over one period** (:func:`period_map`) the wall force computed at sample ``j`` acts from
``(j + D) T``: during ``[kT, kT + delta T)`` it is ``u_{k-d-1}``, after that ``u_{k-d}``, so

    s_{k+1} = Phi s_k + gamma_now u_{k-d} + gamma_before u_{k-d-1},      y_k = c s_k.

``Phi`` and the ``gamma`` are composed from the exact solution over each piece between the
period's events (force switch at ``delta``, window reset at ``1 - w``), in closed form:
``e^{-ch}``, ``h phi1(ch)``, ``h^2 phi2(ch)`` and, for the filter, ``lambda h exp[-lambda h, -ch]``
and ``lambda h^2 exp[-lambda h, -ch, 0]`` (divided differences of ``exp``); every entry is a sum
of products of positive terms, and ``Phi - I`` is kept with its diagonal from ``expm1``, so a
plant that barely moves in a period (``c``, ``lambda`` tiny) keeps all its digits.

**The closed loop** (:func:`shifted_closed_loop`): the state
``xi_k = [s_k, x_{k-1} (if K > 0), u_{k-1}, ..., u_{k-L}]`` (``L = d``, plus one if
``delta > 0``) obeys ``xi_{k+1} = M xi_k``; returned is ``M - I``, formed entry by entry without
cancellation, whose eigenvalues ``w`` give the poles ``z = 1 + w``.  Without a spring the
controller's integrator drives nothing and is left out (its mode ``z = 1`` is no pole of the loop).
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import exp_divided_difference, phi1, phi2
from haptic_bus.analysis.trig import cospi, sincpi, sinpi
from haptic_bus.analysis.velocity import VelocityModel


@dataclass(frozen=True)
class ContinuousModel:
    """The plant with its measurement between events, in scaled units (time ``t/T``).

    ``ds/dt = A s + b f`` with ``f`` the scaled net force on the handle; the measurement is
    ``y = c s`` at the sample; ``reset`` = (state index, time in [0, 1) of the period) at which
    that state is set to 0 (the window's start), or None.
    """

    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    reset: tuple[int, float] | None
    operator: np.ndarray | None = None
    handle: int = 0

    @property
    def operator_column(self) -> np.ndarray:
        """Where the operator's scaled force enters: ``operator``, or ``b`` (a rigid handle: where the wall's does)."""
        return self.b if self.operator is None else self.operator


def continuous_model(loop: WallLoop) -> ContinuousModel:
    """The scaled continuous model of ``loop``'s rigid plant ``dv/dt = -c v + f`` and velocity measurement."""
    return measured_model(np.array([[-loop.c]]), np.array([1.0]), 0, loop)


def measured_model(A: np.ndarray, b: np.ndarray, sensed: int, loop: WallLoop,
                   operator: np.ndarray | None = None, handle: int = 0) -> ContinuousModel:
    """The scaled plant ``ds/dt = A s + b f`` (``n`` states) with ``loop``'s velocity model measuring state ``sensed``.

    ``point``: the plant alone, ``y = s[sensed]``; ``lowpass``/``average``/``window``: one more
    state, the filter ``nu`` or the window's integral ``p`` of ``s[sensed]`` (module docstring).
    ``operator``: the column of the operator's scaled force (None: ``b``), ``handle``: the state
    the operator's hand moves with (the operator's power is its force times that velocity).
    """
    n = b.size
    kind = loop.velocity.kind
    if kind == "point":
        c = np.zeros(n)
        c[sensed] = 1.0
        return ContinuousModel(A, b, c, None, operator, handle)
    big = np.zeros((n + 1, n + 1))
    big[:n, :n] = A
    c = np.zeros(n + 1)
    if kind == "lowpass":
        rate = loop.T / loop.velocity.time
        big[n, sensed], big[n, n] = rate, -rate
        c[n] = 1.0
        reset = None
    else:
        width = window_fraction(loop)
        big[n, sensed] = 1.0
        c[n] = 1.0 / width
        reset = (n, 1.0 - width)
    pad = None if operator is None else np.append(operator, 0.0)
    return ContinuousModel(big, np.append(b, 0.0), c, reset, pad, handle)


class Measured(Protocol):
    """What a velocity model's response needs of a loop: its period ``T`` (s) and ``velocity`` model."""

    @property
    def T(self) -> float: ...

    @property
    def velocity(self) -> VelocityModel: ...


def measurement_response(loop: Measured, theta: np.ndarray) -> np.ndarray:
    """``M(j theta)``: the velocity model's continuous response at (complex) ``theta = omega T``.

    ``1`` (point), ``(1 - e^{-j theta w})/(j theta w)`` (window ``w = TW/T``), ``1/(1 + j theta TAU/T)`` (lowpass).
    """
    kind = loop.velocity.kind
    if kind == "point":
        return np.ones_like(theta, dtype=complex)
    if kind == "lowpass":
        return 1.0 / (1.0 + 1j * theta * (loop.velocity.time / loop.T))
    width = window_fraction(loop)
    if not np.iscomplexobj(theta):  # e^{-j theta w/2} sinc(theta w/2), exact at multiples of pi
        x = theta * (0.5 * width / np.pi)
        return (cospi(x) - 1j * sinpi(x)) * sincpi(x)
    jx = 1j * theta * width
    safe = np.where(jx == 0, 1.0, jx)
    return np.where(jx == 0, 1.0, -np.expm1(-safe) / safe)


def window_fraction(loop: Measured) -> float:
    """``TW / T`` of a differencing model (1 for ``average``); ValueError for the others."""
    window = loop.velocity.window(loop.T)
    if window is None:
        raise ValueError(f"velocity model {loop.velocity} has no window")
    return min(window / loop.T, 1.0)


@dataclass(frozen=True)
class PeriodMap:
    """``s_{k+1} = Phi s_k + gamma_now u_{k-d} + gamma_before u_{k-d-1}``, ``y_k = c s_k`` (scaled).

    ``phi_minus_identity`` is ``Phi - I`` (lower triangular), accurate entry by entry.
    """

    phi_minus_identity: np.ndarray
    gamma_now: np.ndarray
    gamma_before: np.ndarray
    c: np.ndarray


def _piece(c: float, kind: str, rate: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact transition and force column of the scaled plant over ``h`` periods (closed form).

    ``rate`` is the low-pass ``lambda = T/TAU`` (unused by the other models).
    """
    ch = c * h
    decay, ramp = math.exp(-ch), h * phi1(ch)
    if kind == "point":
        return np.array([[decay]]), np.array([ramp])
    if kind == "lowpass":
        rh = rate * h
        transition = np.array([[decay, 0.0], [rh * exp_divided_difference(-rh, -ch), math.exp(-rh)]])
        return transition, np.array([ramp, rate * h * h * exp_divided_difference(-rh, -ch, 0.0)])
    return np.array([[decay, 0.0], [ramp, 1.0]]), np.array([ramp, h * h * phi2(ch)])


def event_times(loop: WallLoop) -> list[float]:
    """The period's event times in [0, 1]: 0, the force switch ``delta``, the window reset, 1."""
    model = continuous_model(loop)
    return _event_times(loop.fractional_delay, None if model.reset is None else model.reset[1])


def _event_times(delta: float, reset: float | None) -> list[float]:
    return sorted({0.0, 1.0, delta} | ({reset} if reset is not None else set()))


def period_map(loop: WallLoop) -> PeriodMap:
    """The exact period map of ``loop``'s plant and measurement (see the module docstring); cached."""
    kind = loop.velocity.kind
    rate = loop.T / loop.velocity.time if kind == "lowpass" else 0.0
    width = window_fraction(loop) if kind in ("average", "window") else 0.0
    return _period_map(loop.c, loop.fractional_delay, kind, rate, width)


@functools.lru_cache(maxsize=1024)
def _period_map(c: float, delta: float, kind: str, rate: float, width: float) -> PeriodMap:
    n = 1 if kind == "point" else 2
    reset = 1.0 - width if width else None
    phi = np.eye(n)
    gamma = {"now": np.zeros(n), "before": np.zeros(n)}
    times = _event_times(delta, reset)
    # time left to the sample, exact for the window's start (a window of 1e-9 T keeps its digits)
    left = {t: 1.0 - t for t in times} | ({reset: width} if reset is not None else {})
    for start, stop in itertools.pairwise(times):
        if start == reset:
            keep = np.array([1.0, 0.0])
            phi, gamma = keep[:, None] * phi, {k: keep * g for k, g in gamma.items()}
        length = stop - start if start < 0.5 else left[start] - left[stop]
        transition, force = _piece(c, kind, rate, length)
        phi = transition @ phi
        gamma = {k: transition @ g for k, g in gamma.items()}
        key = "before" if stop <= delta else "now"
        gamma[key] = gamma[key] + force
    shifted = phi - np.eye(n)
    shifted[0, 0] = math.expm1(-c)
    if kind == "lowpass":
        shifted[1, 1] = math.expm1(-rate)
    measure = np.array([1.0]) if kind == "point" else np.array([0.0, 1.0 / width if width else 1.0])
    arrays = (shifted, gamma["now"], gamma["before"], measure)
    for array in arrays:
        array.setflags(write=False)  # shared by the cache
    return PeriodMap(*arrays)


def pulse_transfer(pmap: PeriodMap, z: np.ndarray, z_minus_1: np.ndarray) -> np.ndarray:
    """``G(z) = c (zI - Phi)^{-1} (gamma_now + gamma_before / z)``: scaled force ``u`` to ``y``, delay ``d`` excluded.

    ``z_minus_1`` is ``z - 1`` formed without cancellation (``2j sin(theta/2) e^{j theta/2}``);
    ``zI - Phi = (z - 1) I - (Phi - I)`` is lower triangular and solved by forward substitution.
    """
    shifted = pmap.phi_minus_identity
    rhs = pmap.gamma_now[:, None] + pmap.gamma_before[:, None] / z[None, :]
    n = shifted.shape[0]
    solution = np.empty((n, z.size), dtype=complex)
    for i in range(n):  # elementwise (n <= 2): no BLAS call for a long theta array
        acc = rhs[i] + sum(shifted[i, j] * solution[j] for j in range(i)) if i else rhs[i]
        solution[i] = acc / (z_minus_1 - shifted[i, i])
    return sum(pmap.c[i] * solution[i] for i in range(n))


class ClosedLoopLayout:
    """Where things sit in the closed-loop state ``xi_k = [s_k, x_{k-1} (if integrator), u_{k-1}, ..., u_{k-L}]``.

    ``n`` plant states (``pmap.c.size``, any extra exogenous states included), the wall force
    ``u_k`` as a row over ``xi_k`` (:attr:`u_row`, scaled units) and the force held at any lag
    (:meth:`held`): ``u_{k-d}`` acts from ``delta`` to the period's end, ``u_{k-d-1}`` before.
    """

    def __init__(self, pmap: PeriodMap, kappa: float, q: float, delay: float, integrator: bool) -> None:
        self.d = math.floor(delay)
        self.has_before = delay > self.d
        self.n = pmap.c.size
        self.integrator = integrator
        self.slots = self.d + (1 if self.has_before else 0)
        self.first_slot = self.n + (1 if integrator else 0)
        self.size = self.first_slot + self.slots
        u_row = np.zeros(self.size)
        u_row[: self.n] = (kappa + q if integrator else q) * pmap.c
        if integrator:
            u_row[self.n] = kappa
        self.u_row = u_row

    def held(self, lag: int) -> np.ndarray:
        """``u_{k-lag}`` as a row over ``xi_k``."""
        if lag == 0:
            return self.u_row
        row = np.zeros(self.size)
        row[self.first_slot + lag - 1] = 1.0
        return row

    def force_now(self) -> np.ndarray:
        """The force held from ``delta`` to the end of the period, ``u_{k-d}``, as a row over ``xi_k``."""
        return self.held(self.d)

    def force_before(self) -> np.ndarray:
        """The force held over ``[0, delta)``, ``u_{k-d-1}`` (zero row without a fractional delay)."""
        return self.held(self.d + 1) if self.has_before else np.zeros(self.size)


def shifted_closed_loop(pmap: PeriodMap, kappa: float, q: float, delay: float, integrator: bool) -> np.ndarray:
    """``M - I`` of the closed loop ``xi_{k+1} = M xi_k`` (see the module docstring), formed without cancellation.

    ``kappa``, ``q``: the scaled wall; ``delay`` ``D`` in samples; ``integrator``: carry the
    controller's position ``x_{k-1}`` (needed when ``kappa > 0``).  Any extra plant states in
    ``pmap`` (e.g. an operator-force generator, with ``c`` and ``gamma`` zero there) ride along.
    """
    lay = ClosedLoopLayout(pmap, kappa, q, delay, integrator)
    n, size, first = lay.n, lay.size, lay.first_slot
    shifted = np.zeros((size, size))
    shifted[:n, :n] = pmap.phi_minus_identity
    shifted[:n] -= np.outer(pmap.gamma_now, lay.force_now())  # the wall force opposes the motion
    if lay.has_before:
        shifted[:n] -= np.outer(pmap.gamma_before, lay.force_before())
    if integrator:
        shifted[n, :n] = pmap.c
    if lay.slots:
        shifted[first] = lay.u_row
        shifted[first, first] -= 1.0
        for j in range(1, lay.slots):
            shifted[first + j, first + j - 1] = 1.0
            shifted[first + j, first + j] = -1.0
    return shifted


def loop_matrix(loop: WallLoop) -> np.ndarray:
    """``M - I`` of ``loop``'s closed loop in scaled units (dimensionless)."""
    return shifted_closed_loop(period_map(loop), loop.kappa, loop.q, loop.delay, integrator=loop.K > 0)
