"""A device's resolution and Coulomb friction, validated: what the quantisation condition
(:mod:`haptic_bus.analysis.quantisation`) judges a wall with, and what a device's loop
(:class:`~haptic_bus.analysis.loop.DeviceLoop`) carries to the gate.  SI units.
"""

from __future__ import annotations

from dataclasses import dataclass

from haptic_bus.validation import real_in_range

RESOLUTION_RANGE = (0.0, 1e6)  # m per 0x6064 increment (0: exact positions), as a profile's position_per_count
VELOCITY_RESOLUTION_RANGE = (0.0, 1e6)  # m/s per 0x606C unit (0: exact velocities)
COULOMB_RANGE = (0.0, 1e6)  # N, as a profile's [device] coulomb_friction


@dataclass(frozen=True)
class Quantisation:
    """A device's resolution and Coulomb friction: ``position_resolution`` Delta (m per 0x6064
    increment), ``velocity_resolution`` vq (m/s per 0x606C unit, 0: not known or exact) and
    ``coulomb`` f_c (N).  Raises ParameterError naming a value outside its range."""

    position_resolution: float
    coulomb: float
    velocity_resolution: float = 0.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "position_resolution", real_in_range("position_resolution", self.position_resolution,
                                                        *RESOLUTION_RANGE, unit="m"))
        set_(self, "coulomb", real_in_range("coulomb", self.coulomb, *COULOMB_RANGE, unit="N"))
        set_(self, "velocity_resolution", real_in_range("velocity_resolution", self.velocity_resolution,
                                                        *VELOCITY_RESOLUTION_RANGE, unit="m/s"))
