"""What the simulated drive measures at each SYNC: 0x606C velocity and 0x6064 position, in counts.

The handle's true state is quantised to the drive's units (rounded, saturated at INTEGER32,
never wrapped): ``velocity_per_count`` m/s and ``position_per_count`` m per count.
"""

from __future__ import annotations

from sim_drive.handle import Handle
from sim_drive.parameters import DeviceParameters

INT32_RANGE = (-(1 << 31), (1 << 31) - 1)


def saturate(value: int, low: int, high: int) -> int:
    """``value`` clipped to ``[low, high]`` (saturate, never wrap)."""
    return low if value < low else high if value > high else value


class Sensor:
    """The drive's encoder and velocity estimate, sampled at each SYNC."""

    def __init__(self, parameters: DeviceParameters) -> None:
        self.velocity_counts = 0
        self.position_counts = 0
        self._per_velocity = 1.0
        self._per_position = 1.0
        self.configure(parameters)

    def configure(self, parameters: DeviceParameters) -> None:
        """Take new scaling (counts per m/s and per m)."""
        self._per_velocity = 1.0 / parameters.velocity_per_count
        self._per_position = 1.0 / parameters.position_per_count

    def sample(self, handle: Handle) -> None:
        """Quantise the handle's velocity and position now."""
        low, high = INT32_RANGE
        self.velocity_counts = saturate(round(handle.velocity * self._per_velocity), low, high)
        self.position_counts = saturate(round(handle.position * self._per_position), low, high)
