"""The responses the model predicts, exact for the sampled loop (DESIGN 3.5), at ``theta = omega T`` (rad).

The plant as the controller sees it: the force ``F_k`` sent in answer to sample ``k`` (N, what the
drive applies from ``(k + D) T`` on, held) to the velocity the drive reports, ``y`` (m/s):

    P(z) = (T/m) z^{-d} G(z),   G = c (zI - Phi)^{-1} (gamma_now + gamma_before / z)

from the analysis package's exact period map (:func:`~haptic_bus.analysis.sampled_loop.period_map`,
:func:`~haptic_bus.analysis.sampled_loop.pulse_transfer`: plant, velocity model and the fractional
delay ``delta`` of ``D = d + delta``), ``z = e^{j theta}``.  The hold is the controller's wall law
``u_k = K x_k + B y_k``, ``x_k = x_{k-1} + T y_k``: ``C(z) = K T z/(z - 1) + B``.  With the probe
``p_k`` the controller sends ``F_k = p_k - u_k``, so the probe's responses are

    velocity: P / (1 + P C)  (m/s per N),   position: T z/(z - 1) P / (1 + P C)  (m per N).

A periodic probe in a stable loop reaches exactly these at its own frequencies once the start's
transient has decayed: no continuous approximation anywhere.  A loop that states a transmission (a
profile's ``[device.transmission]``, which the gate judges) has the two-mass plant in place of the
rigid one (:mod:`~haptic_bus.validate.two_mass`), so validate checks the model the gate judges with.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.sampled_loop import period_map, pulse_transfer
from haptic_bus.validate import two_mass
from haptic_bus.validate.circle import unit_circle


def plant_response(loop: DeviceLoop, theta: np.ndarray) -> np.ndarray:
    """``P(e^{j theta})``: force sent (N) to the reported velocity (m/s), exact (module docstring); behind
    the loop's transmission when it states one (:func:`~haptic_bus.validate.two_mass.response`)."""
    if loop.transmission is not None:
        return two_mass.response(loop, loop.transmission, theta)
    wall = loop.wall(0.0, 0.0)
    z, z_minus_1 = unit_circle(theta)
    return wall.T / wall.m * z ** (-wall.whole_delay) * pulse_transfer(period_map(wall), z, z_minus_1)


def integrator(period: float, theta: np.ndarray) -> np.ndarray:
    """``T z/(z - 1)``: the controller's position from its velocity samples (s)."""
    z, z_minus_1 = unit_circle(theta)
    return period * z / z_minus_1


@dataclass(frozen=True)
class Hold:
    """The gentle wall that holds the handle: ``stiffness`` N/m, ``damping`` N s/m."""

    stiffness: float
    damping: float

    def response(self, period: float, theta: np.ndarray) -> np.ndarray:
        """``C(e^{j theta}) = K T z/(z - 1) + B`` (N s/m): the wall force per reported velocity."""
        return self.stiffness * integrator(period, theta) + self.damping


@dataclass(frozen=True)
class Prediction:
    """What the model predicts at ``theta`` (rad): the plant (m/s per N) and the probe's responses
    in velocity (m/s per N) and position (m per N)."""

    theta: np.ndarray
    plant: np.ndarray
    velocity: np.ndarray
    position: np.ndarray


def predict(loop: DeviceLoop, hold: Hold, theta: np.ndarray) -> Prediction:
    """The model's responses for ``loop`` held by ``hold`` (module docstring)."""
    plant = plant_response(loop, theta)
    velocity = plant / (1.0 + plant * hold.response(loop.T, theta))
    return Prediction(theta, plant, velocity, integrator(loop.T, theta) * velocity)


def with_delay(loop: DeviceLoop, delay: float) -> DeviceLoop:
    """``loop`` with another loop delay (samples)."""
    return dataclasses.replace(loop, delay=delay)
