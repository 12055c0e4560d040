"""The exact sampled plant of a handle behind a compliant transmission, for the fit of a resonance.

The motor side (mass ``m_motor``, where the encoder and the torque are) is coupled to the handle
(the profile's ``m`` and ``b``) by a :class:`~haptic_bus.analysis.transmission.Transmission`
(spring ``k``, damper ``c``).  The analysis package's exact two-mass period map
(:class:`~haptic_bus.analysis.two_mass.TwoMassDevice`: the plant with the loop's velocity model and
the delay's fraction ``delta``, in the scaled units of the total mass ``M = m + m_motor``) gives
``G(z)``, so the force sent (N) to the reported velocity (m/s) is

    P(z) = (T/M) z^{-d} G(z),

as :func:`~haptic_bus.validate.model.plant_response` is for the rigid handle (which it becomes as
``k`` grows, with the mass ``M``).  The free pair's oscillating mode is the complex pole pair of
the plant's continuous matrix.  SI units; frequencies in Hz.
"""

from __future__ import annotations

import math

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.analysis.two_mass import TwoMassDevice
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.validate.circle import unit_circle


def device(loop: DeviceLoop, transmission: Transmission) -> TwoMassDevice:
    """``loop``'s handle and timing behind ``transmission`` (the delay's whole samples left to :func:`response`)."""
    delta = float(loop.delay - math.floor(loop.delay))
    return TwoMassDevice(loop.m, loop.b, loop.T, delta, VelocityModel.parse(loop.velocity), transmission.stiffness,
                         transmission.damping, transmission.motor_mass)


def response(loop: DeviceLoop, transmission: Transmission, theta: np.ndarray) -> np.ndarray:
    """``P(e^{j theta})``: force sent (N) to the reported velocity (m/s) at ``theta`` (rad), exact."""
    pair = device(loop, transmission)
    z, z_minus_1 = unit_circle(theta)
    sampled = pair.sampled_over_hold(z, z_minus_1) * z_minus_1 / z
    return loop.T / pair.scale_mass * z ** (-math.floor(loop.delay)) * sampled


def mode(loop: DeviceLoop, transmission: Transmission) -> tuple[float, float]:
    """The free pair's oscillating mode: natural frequency (Hz) and damping ratio (an over-damped pair:
    its fastest real pole, damping 1 or more)."""
    poles = np.linalg.eigvals(device(loop, transmission).plant().A[:3, :3]) / loop.T  # 1/s
    oscillating = poles[np.argmax(np.abs(poles.imag))]
    if oscillating.imag == 0.0:
        oscillating = poles[np.argmax(np.abs(poles))]
    radius = float(np.abs(oscillating))
    return radius / (2.0 * math.pi), float(-oscillating.real / radius)
