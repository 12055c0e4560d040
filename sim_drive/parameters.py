"""Validated parameters of the simulated drive: plant, scaling, cycle, and its loop timing.

Defaults (the seed's device on a typical servo drive):

=====================  ============  ==============================================
field                  default       meaning
=====================  ============  ==============================================
``m``                  0.5 kg        handle mass
``b``                  0.1 N s/m     viscous friction
``period``             1 ms          SYNC period ``T`` (0x1006 = 1000 us)
``velocity_per_count`` 1e-6 m/s      one 0x606C velocity unit at the handle
``position_per_count`` 1e-7 m        one 0x6064 increment at the handle
``rated_torque``       0.2 N m       0x6076 = 200 mN m
``force_per_torque``   50 N/(N m)    transmission: handle force per motor torque
``max_torque_permille`` 3000         0x6072 (per mille of rated torque)
``substeps``           1             plant sub-steps per SYNC (operator force re-evaluated each)
=====================  ============  ==============================================

So one per mille of 0x6071 is 0.2 N m / 1000 * 50 N/(N m) = 10 mN at the handle, and
0x6072 = 3000 allows +-30 N.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from drives.base import DriveScaling
from drives.cia402 import MAX_TORQUE, MOTOR_RATED_TORQUE
from drives.errors import ParameterError
from haptic_bus.analysis.loop import FRICTION_RANGE, MASS_RANGE, PERIOD_RANGE
from haptic_bus.validation import real_in_range, whole_in_range

SCALE_RANGE = (0.0, 1e6)  # exclusive low: m/s per count, m per count, N per N m
SUBSTEP_RANGE = (1, 100_000)


class Timing(enum.Enum):
    """When a target torque takes effect relative to the SYNCs.

    ``CIA402``: written during cycle k, latched at SYNC k+1, applied during [t_{k+1}, t_{k+2})
    (one sample of delay, as a real synchronous drive).  ``IDEAL``: written after SYNC k,
    applied during [t_k, t_{k+1}) (the seed's zero-delay loop).
    """

    CIA402 = "cia402"
    IDEAL = "ideal"

    @property
    def delay(self) -> int:
        """The loop delay in whole samples this timing adds (0 or 1)."""
        return 1 if self is Timing.CIA402 else 0


@dataclass(frozen=True)
class DeviceParameters:
    """The simulated drive's plant and scaling, in SI units (see the module table)."""

    m: float = 0.5
    b: float = 0.1
    period: float = 1e-3
    velocity_per_count: float = 1e-6
    position_per_count: float = 1e-7
    rated_torque: float = 0.2
    force_per_torque: float = 50.0
    max_torque_permille: int = 3000
    substeps: int = 1

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        ctx = "simulated drive"
        set_(self, "m", real_in_range("m", self.m, *MASS_RANGE, unit="kg", context=ctx))
        set_(self, "b", real_in_range("b", self.b, *FRICTION_RANGE, unit="N s/m", context=ctx))
        set_(self, "period", real_in_range("period", self.period, *PERIOD_RANGE, unit="s", context=ctx))
        for name, unit in (("velocity_per_count", "m/s"), ("position_per_count", "m"), ("force_per_torque", "N/(N m)")):
            set_(self, name, real_in_range(name, getattr(self, name), *SCALE_RANGE, low_inclusive=False, unit=unit, context=ctx))
        low, high = MOTOR_RATED_TORQUE.data_type.range
        rated = real_in_range("rated_torque", self.rated_torque, 1e-3, high / 1000.0, unit="N m", context=ctx)
        if not math.isclose(rated * 1000.0, round(rated * 1000.0), rel_tol=1e-12, abs_tol=1e-9):
            raise ParameterError("rated_torque", self.rated_torque, "a whole number of mN m (0x6076 is UNSIGNED32 in mN m)", ctx)
        set_(self, "rated_torque", rated)
        set_(self, "max_torque_permille", whole_in_range("max_torque_permille", self.max_torque_permille, *MAX_TORQUE.data_type.range, context=ctx))
        set_(self, "substeps", whole_in_range("substeps", self.substeps, *SUBSTEP_RANGE, context=ctx))

    @property
    def rated_torque_mnm(self) -> int:
        """0x6076 in mN m."""
        return round(self.rated_torque * 1000.0)

    @property
    def cycle_period_us(self) -> int:
        """0x1006 in microseconds (rounded)."""
        return round(self.period * 1e6)

    @property
    def scaling(self) -> DriveScaling:
        """The same numbers as the controller-side :class:`drives.base.DriveScaling`."""
        return DriveScaling(
            velocity_per_count=self.velocity_per_count,
            position_per_count=self.position_per_count,
            rated_torque=self.rated_torque,
            force_per_torque=self.force_per_torque,
            max_torque_permille=self.max_torque_permille,
        )
