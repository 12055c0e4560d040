"""Validated parameters of the simulated drive: plant, scaling, cycle, measurement, its hidden truth, and its loop timing.

Defaults (the seed's device on a typical servo drive):

=======================  ============  ==============================================
field                    default       meaning
=======================  ============  ==============================================
``mass``                 0.5 kg        handle mass ``m``
``friction``             0.1 N s/m     viscous friction ``b``
``period``               1 ms          SYNC period ``T`` (0x1006 = 1000 us)
``velocity_per_count``   1e-6 m/s      one 0x606C velocity unit at the handle
``position_per_count``   1e-7 m        one 0x6064 increment at the handle
``rated_torque``         0.2 N m       0x6076 = 200 mN m
``force_per_torque``     50 N/(N m)    transmission: handle force per motor torque
``max_torque_permille``  3000          0x6072 (per mille of rated torque)
``substeps``             1             plant sub-steps per SYNC (operator force re-evaluated each)
``velocity``             point         what 0x606C is (:class:`~haptic_bus.analysis.velocity.VelocityModel`)
``reception_delay``      0.25          ``delta`` in samples, ``[0, 1)``: when ``reception`` timing applies a target
``coulomb_friction``     0 N           Coulomb friction force ``Fc`` opposing motion (the drive's truth)
``velocity_noise``       0 counts      rms of zero-mean Gaussian noise on 0x606C (the drive's truth)
``noise_seed``           None          seed of the noise generator (None: fresh entropy)
``transmission``         None          a motor-side mass behind a spring and damper (the drive's truth)
``extra_delay``          0 samples     the drive applies each target this much later than its timing says
=======================  ============  ==============================================

So one per mille of 0x6071 is 0.2 N m / 1000 * 50 N/(N m) = 10 mN at the handle, and
0x6072 = 3000 allows +-30 N.  ``coulomb_friction``, ``velocity_noise``, ``noise_seed``,
``transmission`` and ``extra_delay`` are what the simulated hardware *is*; the controller is
never told them (no SDO object or Modbus register serves them; its profile may say otherwise,
and the gate judges what the controller believes).

``transmission`` (:class:`~haptic_bus.analysis.transmission.Transmission`, or its ``STIFFNESS:DAMPING:MOTOR_MASS``
spelling): the encoder and the torque act on a motor-side mass coupled to the handle (``mass``,
``friction``) by a spring and a damper; not with Coulomb friction or a ``lowpass`` velocity.
``extra_delay`` (samples, real, in ``[0, 100]``): every target acts that much later than the
timing says, the torque switching at the delayed instant within the period.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from drives.base import DriveScaling
from drives.cia402 import MAX_TORQUE, MOTOR_RATED_TORQUE
from haptic_bus.analysis.loop import FRICTION_RANGE, MASS_RANGE, PERIOD_RANGE
from haptic_bus.analysis.transmission import (
    DAMPING_RANGE,
    MOTOR_MASS_RANGE,
    SPELLING,
    STIFFNESS_RANGE,
    Transmission,
)
from haptic_bus.analysis.velocity import POINT, VelocityModel
from haptic_bus.errors import ParameterError
from haptic_bus.profile.device import COULOMB_RANGE, NOISE_RANGE, NOISE_SEED_RANGE, SCALE_RANGE
from haptic_bus.validation import real_in_range, whole_in_range

SUBSTEP_RANGE = (1, 100_000)
DEFAULT_RECEPTION_DELAY = 0.25  # samples
EXTRA_DELAY_RANGE = (0.0, 100.0)  # samples


class Timing(enum.Enum):
    """When a target torque takes effect relative to the SYNCs (written in answer to sample k).

    ``CIA402``: latched at SYNC k+1, applied during [t_{k+1}, t_{k+2}) (one sample of delay, as a
    real synchronous drive).  ``IDEAL``: applied during [t_k, t_{k+1}) (the seed's zero-delay
    loop).  ``RECEPTION``: applied on reception, a fraction ``delta`` of the period after SYNC k,
    until the next target arrives (delay ``D = delta``): over [t_k, t_{k+1}) the drive holds the
    previous target for ``delta T`` and the new one after.  In virtual time the plant only
    advances at SYNC, so ``delta`` is a parameter (:attr:`DeviceParameters.reception_delay`);
    in real time it stands for the bus and compute time from the SYNC to the torque acting:
    the SYNC-to-RPDO latency (timestamp both frames on the bus, e.g. ``candump -t a`` or a CAN
    analyser, and take a high percentile of the difference) plus the drive's own
    command-to-current latency (its manual), over ``T``; over Modbus, the poll's round trip.
    """

    CIA402 = "cia402"
    IDEAL = "ideal"
    RECEPTION = "reception"

    @property
    def delay(self) -> float:
        """The loop delay ``D`` in samples: 1.0, 0.0, or (``RECEPTION``) the default ``delta``.

        ``RECEPTION``'s delay is the drive's :attr:`DeviceParameters.reception_delay`; use
        :meth:`loop_delay` with it.
        """
        return self.loop_delay(DEFAULT_RECEPTION_DELAY)

    def loop_delay(self, reception_delay: float) -> float:
        """The loop delay ``D`` in samples when ``RECEPTION`` applies targets ``reception_delay`` samples after SYNC."""
        if self is Timing.RECEPTION:
            return float(reception_delay)
        return 1.0 if self is Timing.CIA402 else 0.0


_TRANSMISSION_ALLOWED = (f"{SPELLING}, stiffness in (0, {STIFFNESS_RANGE[1]:g}] N/m, damping in "
                         f"[0, {DAMPING_RANGE[1]:g}] N s/m, motor mass in [{MOTOR_MASS_RANGE[0]:g}, "
                         f"{MOTOR_MASS_RANGE[1]:g}] kg")


@dataclass(frozen=True)
class DeviceParameters:
    """The simulated drive's plant, scaling, measurement and truth, in SI units (see the module table)."""

    mass: float = 0.5
    friction: float = 0.1
    period: float = 1e-3
    velocity_per_count: float = 1e-6
    position_per_count: float = 1e-7
    rated_torque: float = 0.2
    force_per_torque: float = 50.0
    max_torque_permille: int = 3000
    substeps: int = 1
    velocity: VelocityModel = POINT
    reception_delay: float = DEFAULT_RECEPTION_DELAY
    coulomb_friction: float = 0.0
    velocity_noise: float = 0.0
    noise_seed: int | None = None
    transmission: Transmission | str | None = None
    extra_delay: float = 0.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        ctx = "simulated drive"
        set_(self, "mass", real_in_range("mass", self.mass, *MASS_RANGE, unit="kg", context=ctx))
        set_(self, "friction", real_in_range("friction", self.friction, *FRICTION_RANGE, unit="N s/m", context=ctx))
        set_(self, "period", real_in_range("period", self.period, *PERIOD_RANGE, unit="s", context=ctx))
        for name, unit in (("velocity_per_count", "m/s"), ("position_per_count", "m"), ("force_per_torque", "N/(N m)")):
            value = real_in_range(name, getattr(self, name), *SCALE_RANGE, low_inclusive=False, unit=unit, context=ctx)
            set_(self, name, value)
        high = MOTOR_RATED_TORQUE.data_type.range[1]
        rated = real_in_range("rated_torque", self.rated_torque, 1e-3, high / 1000.0, unit="N m", context=ctx)
        if not math.isclose(rated * 1000.0, round(rated * 1000.0), rel_tol=1e-12, abs_tol=1e-9):
            raise ParameterError("rated_torque", self.rated_torque, "a whole number of mN m (0x6076 is UNSIGNED32 in mN m)", ctx)
        set_(self, "rated_torque", rated)
        permille = whole_in_range("max_torque_permille", self.max_torque_permille, *MAX_TORQUE.data_type.range, context=ctx)
        set_(self, "max_torque_permille", permille)
        set_(self, "substeps", whole_in_range("substeps", self.substeps, *SUBSTEP_RANGE, context=ctx))
        try:
            velocity = VelocityModel.parse(self.velocity)
            velocity.check_period(self.period)
        except ParameterError as exc:  # the same message, said to be the drive's
            raise ParameterError(exc.name, exc.value, exc.allowed, ctx) from None
        set_(self, "velocity", velocity)
        delta = real_in_range("reception_delay", self.reception_delay, 0.0, 1.0, unit="samples", context=ctx)
        if delta >= 1.0:
            raise ParameterError("reception_delay", self.reception_delay, "a finite real in [0, 1) samples", ctx)
        set_(self, "reception_delay", delta)
        coulomb = real_in_range("coulomb_friction", self.coulomb_friction, *COULOMB_RANGE, unit="N", context=ctx)
        set_(self, "coulomb_friction", coulomb)
        noise = real_in_range("velocity_noise", self.velocity_noise, *NOISE_RANGE, unit="0x606C counts rms", context=ctx)
        set_(self, "velocity_noise", noise)
        if self.noise_seed is not None:
            set_(self, "noise_seed", whole_in_range("noise_seed", self.noise_seed, *NOISE_SEED_RANGE, context=ctx))
        set_(self, "extra_delay", real_in_range("extra_delay", self.extra_delay, *EXTRA_DELAY_RANGE, unit="samples",
                                                context=ctx))
        if isinstance(self.transmission, str):
            try:
                set_(self, "transmission", Transmission.parse(self.transmission))
            except ParameterError:  # one line with every range, whichever part is wrong
                raise ParameterError("transmission", self.transmission, _TRANSMISSION_ALLOWED, ctx) from None
        if self.coupling is not None and (coulomb or velocity.kind == "lowpass"):
            raise ParameterError("transmission", self.coupling.describe(), "no transmission with Coulomb friction or "
                                 "a lowpass velocity (not modelled)", ctx)

    @property
    def coupling(self) -> Transmission | None:
        """The transmission (parsed), or None for a rigid handle."""
        return self.transmission if isinstance(self.transmission, Transmission) else None

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
