"""The exact sampled plant of a handle behind a compliant transmission, for the fit of a resonance.

The motor side (mass ``M``, where the encoder and the torque are) is coupled to the handle (mass
``m``, viscous friction ``b``: the profile's) by a spring ``k`` and a damper ``c``; with the state
``s = [v_m, x_m, v_h, x_h]`` and the motor force ``F``::

    M dv_m/dt = F - k (x_m - x_h) - c (v_m - v_h),   m dv_h/dt = -b v_h + k (x_m - x_h) + c (v_m - v_h).

The force sent in answer to sample ``j`` acts from ``(j + D) T``, ``D = d + delta``: over one period
the force of the sample before holds for ``delta T`` and the new one after, so from two matrix
exponentials of the system augmented by its held input (``Phi_1, g_1`` over ``delta T`` and
``Phi_2, g_2`` over ``(1 - delta) T``)::

    s_{k+1} = Phi_2 Phi_1 s_k + g_2 F_{k-d} + Phi_2 g_1 F_{k-d-1}.

The drive reports ``v_m(kT)`` (``point``) or ``(x_m(kT) - x_m(kT - T))/T`` (``average``), so the
response at ``z = e^{j theta}`` is ``c (zI - Phi)^{-1} (g_2 + Phi_2 g_1 / z) z^{-d}`` with ``c``
picking ``v_m``, or ``x_m`` times ``(1 - 1/z)/T``.  As ``k`` grows it is the rigid plant of
``m + M`` (:func:`~haptic_bus.validate.model.plant_response`); the other velocity models are not
built here.  SI units; frequencies in Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.velocity import VelocityModel

KINDS = ("point", "average")


@dataclass(frozen=True)
class TwoMass:
    """A transmission: ``stiffness`` N/m, ``damping`` N s/m, ``motor_mass`` kg, behind the handle ``m`` kg, ``b`` N s/m."""

    stiffness: float
    damping: float
    motor_mass: float
    m: float
    b: float

    def matrix(self) -> np.ndarray:
        """``A`` of ``ds/dt = A s + e_0 F / M`` (1/s, 1/s^2 entries)."""
        k, c, big, m, b = self.stiffness, self.damping, self.motor_mass, self.m, self.b
        return np.array([[-c / big, -k / big, c / big, k / big],
                         [1.0, 0.0, 0.0, 0.0],
                         [c / m, k / m, -(b + c) / m, -k / m],
                         [0.0, 0.0, 1.0, 0.0]])

    def mode(self) -> tuple[float, float]:
        """The oscillating mode's natural frequency (Hz) and damping ratio: from the complex pole pair of ``A``."""
        poles = np.linalg.eigvals(self.matrix())
        oscillating = poles[np.argmax(np.abs(poles.imag))]
        if oscillating.imag == 0.0:  # over-damped: the fastest real pole, critically damped or more
            oscillating = poles[np.argmax(np.abs(poles))]
        radius = float(np.abs(oscillating))
        return radius / (2.0 * math.pi), float(-oscillating.real / radius)

    def response(self, loop: DeviceLoop, theta: np.ndarray) -> np.ndarray:
        """Force sent (N) to the reported velocity (m/s) at ``theta`` (rad), with ``loop``'s ``T``, delay
        and velocity model (``point`` or ``average``; ValueError for the others)."""
        from scipy.linalg import expm  # lazily: only a fit needs it

        kind = VelocityModel.parse(loop.velocity).kind
        if kind not in KINDS:
            raise ValueError(f"a two-mass plant is built for {' and '.join(KINDS)} velocity, not {kind}")
        whole = math.floor(loop.delay)
        delta = loop.delay - whole
        block = np.zeros((5, 5))
        block[:4, :4] = self.matrix()
        block[0, 4] = 1.0 / self.motor_mass
        first, second = expm(block * (delta * loop.T)), expm(block * ((1.0 - delta) * loop.T))
        phi = second[:4, :4] @ first[:4, :4]
        now, before = second[:4, 4], second[:4, :4] @ first[:4, 4]
        z = np.exp(1j * theta)
        system = z[:, None, None] * np.eye(4) - phi  # one 4x4 system per frequency
        rhs = now[None, :] + before[None, :] / z[:, None]
        state = np.linalg.solve(system, rhs[..., None])[..., 0]
        if kind == "point":
            measured = state[:, 0]
        else:
            measured = state[:, 1] * (1.0 - 1.0 / z) / loop.T
        return measured * z ** (-whole)
