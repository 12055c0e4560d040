"""The sampled wall loop of a two-mass device, exactly: plant, measurement at the motor, held force, delay.

The device (:class:`TwoMassLoop`): the handle (mass ``m`` kg, viscous friction ``b`` N s/m, where
the operator pushes) coupled by the :class:`~haptic_bus.analysis.transmission.Transmission`
(stiffness ``k`` N/m, damping ``c`` N s/m) to the motor (mass ``m_motor`` kg), where the drive
senses the velocity (by the loop's velocity model) and applies the wall's force.  The state is
``[v_motor, v_handle, e]``, ``e = (x_handle - x_motor)/T`` the coupling's stretch: the two
positions enter only through it, and their common part (where the pair stands) is an integrator
that feeds nothing back, left out as the rigid loop leaves out the controller's integrator without
a spring (its ``z = 1`` would be no pole of the loop).

**Scaled units** are the rigid loop's (:mod:`haptic_bus.analysis.sampled_loop`) with the *total*
mass ``M = m + m_motor``: time ``t/T``, force ``f T/M``, ``kappa = K T^2/M``, ``q = B T/M``; so the
wall's rows, the delay line and the closed-loop matrix are the rigid construction's
(:func:`~haptic_bus.analysis.sampled_loop.shifted_closed_loop`), only the plant differs:

    dv_motor/dt = (M/m_motor) [-f_wall + kt e + ct (v_handle - v_motor)]
    dv_handle/dt = (M/m) [w - ch v_handle - kt e - ct (v_handle - v_motor)],     de/dt = v_handle - v_motor,

``kt = k T^2/M``, ``ct = c T/M``, ``ch = b T/M``.  As ``k -> infinity`` the pair moves as one body
of mass ``M`` with friction ``b``: the rigid loop :attr:`TwoMassLoop.rigid`.

**Over one period** (:func:`two_mass_period_map`) the plant with its measurement state is solved
exactly between the period's events (force switch at ``delta``, window reset) by one matrix
exponential of the augmented system per piece, ``exp([[A h, [I, b] h], [0, 0]])``, whose
upper-right block ``int_0^h e^{A s} ds [I, b]`` gives both ``Phi - I = A int e^{As} ds`` (no
``e^{Ah} - I`` cancellation) and the held force's column.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import radius_excess
from haptic_bus.analysis.sampled_loop import (
    ContinuousModel,
    PeriodMap,
    measured_model,
    shifted_closed_loop,
)
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.analysis.velocity import VelocityModel

_TAYLOR_NORM = 0.5
_TAYLOR_TERMS = 18
STABILITY_TRUST = 1e-10
"""``|z| - 1`` within this (times ``sqrt(max(1, max|M - I|))``) of 0: a pole on the circle as far as
double precision tells (*marginal*, not passive; the rigid loop's 50-digit refinement is not done here)."""


@dataclass(frozen=True)
class TwoMassLoop:
    """A wall loop on a two-mass device: ``handle`` the loop as stated (its ``m``, ``b`` the handle's,
    wall, delay and velocity model as usual) and the ``transmission`` to the motor."""

    handle: WallLoop
    transmission: Transmission

    @property
    def rigid(self) -> WallLoop:
        """The rigid limit (``k -> infinity``): one body of mass ``m + m_motor`` with friction ``b``, the same
        wall and timing; its ``m`` is the two-mass loop's scale mass."""
        h = self.handle
        return WallLoop(h.m + self.transmission.motor_mass, h.b, h.T, h.K, h.B, h.delay, h.velocity, h.discretisation)

    def with_wall(self, K: float, B: float) -> TwoMassLoop:
        """The same device and timing with another wall (N/m, N s/m)."""
        return TwoMassLoop(self.handle.with_wall(K, B), self.transmission)

    def device(self) -> TwoMassDevice:
        """The wall-independent part (what the period map and the alias function depend on)."""
        h, t = self.handle, self.transmission
        return TwoMassDevice(h.m, h.b, h.T, h.fractional_delay, h.velocity, t.stiffness, t.damping, t.motor_mass)


@dataclass(frozen=True)
class TwoMassDevice:
    """A two-mass device and its timing without the wall: handle ``m`` kg, ``b`` N s/m, period ``T`` s,
    the delay's fraction ``delta`` (samples), the ``velocity`` model, and the transmission's
    ``stiffness`` N/m, ``damping`` N s/m and ``motor_mass`` kg.  An
    :class:`~haptic_bus.analysis.alias_sum.AliasDevice` (hashable: its series and maps are cached)."""

    m: float
    b: float
    T: float
    delta: float
    velocity: VelocityModel
    stiffness: float
    damping: float
    motor_mass: float

    @property
    def fractional_delay(self) -> float:
        """``delta`` in [0, 1) samples."""
        return self.delta

    @property
    def scale_mass(self) -> float:
        """``M = m + m_motor`` (kg): the scaled units' mass."""
        return self.m + self.motor_mass

    def loop(self) -> WallLoop:
        """The rigid loop of mass ``M`` with no wall and this fractional delay (timing and measurement)."""
        return WallLoop(self.scale_mass, self.b, self.T, 0.0, 0.0, self.delta, self.velocity)

    def coefficients(self) -> tuple[float, float, float, float, float]:
        """``(M/m_motor, M/m, kt, ct, ch)`` of the scaled plant (module docstring)."""
        M, T = self.scale_mass, self.T
        return M / self.motor_mass, M / self.m, self.stiffness * T * T / M, self.damping * T / M, self.b * T / M

    def plant(self, clamped: bool = False) -> ContinuousModel:
        """The scaled plant with its measurement at the motor (``clamped``: the handle held still,
        states ``[v_motor, e]``: where the operator's impedance has its poles)."""
        mu_m, mu_h, kt, ct, ch = self.coefficients()
        if clamped:
            A = np.array([[-mu_m * ct, mu_m * kt], [-1.0, 0.0]])
            return measured_model(A, np.array([mu_m, 0.0]), 0, self.loop())
        A = np.array([[-mu_m * ct, mu_m * ct, mu_m * kt],
                      [mu_h * ct, -mu_h * (ct + ch), -mu_h * kt],
                      [-1.0, 1.0, 0.0]])
        return measured_model(A, np.array([mu_m, 0.0, 0.0]), 0, self.loop(), operator=np.array([0.0, mu_h, 0.0]),
                              handle=1)

    def mobility(self, theta: np.ndarray) -> np.ndarray:
        """The motor's scaled velocity per scaled force at the motor, ``G_p(j theta)``, handle free (complex ``theta``)."""
        mu_m, mu_h, kt, ct, ch = self.coefficients()
        s = 1j * np.asarray(theta)
        handle = ch + s / mu_h
        coupling = ct * s + kt  # s times the coupling's impedance
        return 1.0 / (s / mu_m + coupling * handle / (coupling + s * handle))

    def path_over_hold(self, theta: np.ndarray) -> np.ndarray:
        """``G_p(j theta)/(j theta)``."""
        return self.mobility(theta) / (1j * np.asarray(theta))

    def theta_poles(self) -> tuple[complex, ...]:
        """The plant's poles in the ``theta`` plane, ``-j`` times the eigenvalues of its scaled ``A``."""
        return _theta_poles(self)

    def sampled_over_hold(self, z: np.ndarray, z_minus_1: np.ndarray) -> np.ndarray:
        """``G(z)/(1 - z^{-1})``: the sampled map from the held force to the measurement, ``delta`` included."""
        return general_pulse_transfer(two_mass_period_map(self), z, z_minus_1) * z / z_minus_1


@functools.lru_cache(maxsize=256)
def _theta_poles(device: TwoMassDevice) -> tuple[complex, ...]:
    plant = device.plant()
    n = 3
    return tuple(complex(-1j * w) for w in np.linalg.eigvals(plant.A[:n, :n]))


def small_expm(X: np.ndarray) -> np.ndarray:
    """``e^X`` of a small matrix: Taylor's series of ``X/2^s`` (``||X/2^s||_1 <= 1/2``, 18 terms: truncation
    below ``2^-19/19! ~ 1e-23``), squared ``s`` times.  numpy products only: scipy's ``expm`` spends
    milliseconds per call in its LAPACK threads on a busy machine, this microseconds."""
    norm = float(np.max(np.sum(np.abs(X), axis=0))) if X.size else 0.0
    squarings = max(0, math.ceil(math.log2(norm / _TAYLOR_NORM))) if norm > _TAYLOR_NORM else 0
    Y = X / 2.0**squarings
    identity = np.eye(X.shape[0])
    result = identity.copy()
    for k in range(_TAYLOR_TERMS, 0, -1):  # Horner: I + Y/1 (I + Y/2 (I + ...))
        result = identity + (Y @ result) / k
    for _ in range(squarings):
        result = result @ result
    return result


def _augmented_step(A: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``(e^{A h} - I, int_0^h e^{A s} ds b)`` from one exponential of the augmented system (``h`` periods)."""
    n = b.size
    big = np.zeros((2 * n + 1, 2 * n + 1))
    big[:n, :n] = A * h
    big[:n, n:2 * n] = np.eye(n) * h
    big[:n, 2 * n] = b * h
    e = small_expm(big)
    integral = e[:n, n:2 * n]
    return A @ integral, e[:n, 2 * n]


def period_map_of(model: ContinuousModel, delta: float) -> PeriodMap:
    """The exact period map of any scaled plant-and-measurement ``model`` with the force switch at ``delta``.

    ``s_{k+1} = Phi s_k + gamma_now u_{k-d} + gamma_before u_{k-d-1}`` (the response to ``+u``), ``Phi - I``
    kept without cancellation: over each piece ``S <- S_p + S + S_p S``, at the window's reset
    ``S <- R S - e e^T`` (``R`` zeroes the reset state's row ``e``).
    """
    n = model.b.size
    shifted = np.zeros((n, n))
    gamma = {"now": np.zeros(n), "before": np.zeros(n)}
    times = sorted({0.0, 1.0, delta} | ({model.reset[1]} if model.reset is not None else set()))
    for start, stop in itertools.pairwise(times):
        if model.reset is not None and start == model.reset[1]:
            row = model.reset[0]
            shifted[row] = 0.0
            shifted[row, row] = -1.0
            gamma = {k: np.where(np.arange(n) == row, 0.0, g) for k, g in gamma.items()}
        step, force = _augmented_step(model.A, model.b, stop - start)
        shifted = step + shifted + step @ shifted
        gamma = {k: g + step @ g for k, g in gamma.items()}
        key = "before" if stop <= delta else "now"
        gamma[key] = gamma[key] + force
    return PeriodMap(shifted, gamma["now"], gamma["before"], model.c)


@functools.lru_cache(maxsize=256)
def two_mass_period_map(device: TwoMassDevice, clamped: bool = False) -> PeriodMap:
    """The device's exact period map (scaled units; ``clamped``: the handle held still); cached."""
    return period_map_of(device.plant(clamped), device.delta)


def general_pulse_transfer(pmap: PeriodMap, z: np.ndarray, z_minus_1: np.ndarray) -> np.ndarray:
    """``G(z) = c ((z - 1) I - (Phi - I))^{-1} (gamma_now + gamma_before/z)`` for a full ``Phi`` (complex ``z``)."""
    z, z_minus_1 = np.atleast_1d(z), np.atleast_1d(z_minus_1)
    n = pmap.c.size
    matrices = z_minus_1[:, None, None] * np.eye(n) - pmap.phi_minus_identity
    rhs = pmap.gamma_now[None, :] + pmap.gamma_before[None, :] / z[:, None]
    return np.linalg.solve(matrices, rhs[..., None])[..., 0] @ pmap.c


def two_mass_loop_matrix(loop: TwoMassLoop, clamped: bool = False) -> np.ndarray:
    """``M - I`` of the two-mass closed loop (``clamped``: with the handle held still), scaled units."""
    rigid = loop.rigid
    return shifted_closed_loop(two_mass_period_map(loop.device(), clamped), rigid.kappa, rigid.q, rigid.delay,
                               integrator=rigid.K > 0)


def two_mass_poles(loop: TwoMassLoop, clamped: bool = False) -> np.ndarray:
    """The closed-loop poles in the z-plane, largest magnitude first (``clamped``: the handle held still)."""
    w = np.linalg.eigvals(two_mass_loop_matrix(loop, clamped)).astype(complex)
    return 1.0 + w[np.argsort(-radius_excess(w), kind="stable")]


def two_mass_stability(loop: TwoMassLoop) -> tuple[str, float]:
    """``("stable" | "marginal" | "unstable", largest |z| - 1)`` of the free loop (see :data:`STABILITY_TRUST`)."""
    matrix = two_mass_loop_matrix(loop)
    excess = float(np.max(radius_excess(np.linalg.eigvals(matrix))))
    trust = STABILITY_TRUST * math.sqrt(max(1.0, float(np.max(np.abs(matrix)))))
    return ("stable" if excess < -trust else "unstable" if excess > trust else "marginal"), excess


def two_mass_model(loop: TwoMassLoop) -> ContinuousModel:
    """The scaled continuous plant with its measurement (the energy check's model, operator at the handle)."""
    return loop.device().plant()

