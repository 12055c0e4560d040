"""A transmission that is not rigid: a motor-side mass coupled to the handle by a spring and a damper.

Belts, cables and gearboxes put a resonance between the motor, where the encoder and the torque
are, and the handle, where the operator is (issue 27).  :class:`Transmission` holds what a profile's
``[device.transmission]`` and ``--transmission STIFFNESS:DAMPING:MOTOR_MASS`` state: the coupling's
``stiffness`` N/m and ``damping`` N s/m and the ``motor_mass`` kg (the rotor's inertia as a mass
at the handle's coordinate).  The handle keeps the device's mass ``m`` and its viscous friction
``b``: the profile's ``b`` acts at the handle, the motor side has none of its own (a drive's own
damping loop would act at the motor: state it as the coupling's damping only if it is in series).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range

STIFFNESS_RANGE = (0.0, 1e12)  # N/m, exclusive low: no coupling is no transmission
DAMPING_RANGE = (0.0, 1e9)  # N s/m
MOTOR_MASS_RANGE = (1e-9, 1e9)  # kg: the handle's own range (loop.MASS_RANGE; loop imports this module)
SPELLING = "STIFFNESS:DAMPING:MOTOR_MASS (N/m, N s/m, kg)"


@dataclass(frozen=True)
class Transmission:
    """The coupling between motor and handle: ``stiffness`` N/m (> 0), ``damping`` N s/m (>= 0) and
    the ``motor_mass`` kg on the motor side, where the drive senses and applies its torque."""

    stiffness: float
    damping: float
    motor_mass: float

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "stiffness", real_in_range("transmission stiffness", self.stiffness, *STIFFNESS_RANGE,
                                              low_inclusive=False, unit="N/m"))
        set_(self, "damping", real_in_range("transmission damping", self.damping, *DAMPING_RANGE, unit="N s/m"))
        set_(self, "motor_mass", real_in_range("transmission motor_mass", self.motor_mass, *MOTOR_MASS_RANGE,
                                               unit="kg"))

    @classmethod
    def parse(cls, text: str) -> Transmission:
        """``"20000:2:0.3"`` -> the transmission (N/m, N s/m, kg); ParameterError naming the range."""
        parts = text.split(":")
        try:
            if len(parts) != 3:
                raise ValueError
            stiffness, damping, motor_mass = (float(part) for part in parts)
        except ValueError:
            raise ParameterError("transmission", text, SPELLING) from None
        return cls(stiffness, damping, motor_mass)

    def resonance(self, handle_mass: float) -> float:
        """The undamped resonance of the free pair, ``sqrt(k (1/m_motor + 1/m))/(2 pi)`` in Hz (``m`` kg)."""
        return math.sqrt(self.stiffness * (1.0 / self.motor_mass + 1.0 / handle_mass)) / (2.0 * math.pi)

    def describe(self) -> str:
        """``stiffness 20000 N/m, damping 2 N s/m, motor mass 0.3 kg`` for messages."""
        return f"stiffness {self.stiffness:g} N/m, damping {self.damping:g} N s/m, motor mass {self.motor_mass:g} kg"

    def to_dict(self) -> dict[str, float]:
        """The profile's keys: ``stiffness``, ``damping``, ``motor_mass``."""
        return {"stiffness": self.stiffness, "damping": self.damping, "motor_mass": self.motor_mass}
