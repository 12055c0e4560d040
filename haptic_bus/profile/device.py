"""``[device]`` and ``[loop]``: the handle, its drive and the loop timing, as the controller and the
simulated drive both read them (SI units).

``[device]``: ``mass`` kg, effective ``friction`` b N s/m and its ``friction_source``, the drive's
scaling (0x606C, 0x6064, 0x6076 N m, transmission N/(N m), 0x6072), the ``velocity`` model of
0x606C, the handle's Coulomb friction ``coulomb_friction`` N (optional: a simulated drive's truth
and, when stated, what the gate judges the encoder's quantisation with), and a simulated drive's
hidden truth (``velocity_noise`` 0x606C counts rms, ``noise_seed``) that the controller never uses;
an optional ``[device.transmission]`` (``stiffness`` N/m, ``damping`` N s/m, ``motor_mass`` kg)
makes it a two-mass device, ``mass`` and ``friction`` the handle's, judged by the two-mass
criterion.  ``[loop]``: ``period`` T in s, ``timing`` (``"ideal"`` = no delay, ``"cia402"`` = torque applied at the next SYNC,
``"reception"`` = applied on arrival) and the loop ``delay`` in samples the gate judges with
(real; at least the timing's own, default it; required for ``"reception"``).
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Mapping
from dataclasses import dataclass

from drives.base import DriveScaling
from drives.cia402 import MAX_TORQUE, MOTOR_RATED_TORQUE, TARGET_TORQUE
from haptic_bus.analysis.loop import DELAY_RANGE, FRICTION_RANGE, MASS_RANGE, PERIOD_RANGE
from haptic_bus.analysis.resolution import COULOMB_RANGE, Quantisation
from haptic_bus.analysis.transmission import DAMPING_RANGE as TRANSMISSION_DAMPING
from haptic_bus.analysis.transmission import MOTOR_MASS_RANGE, Transmission
from haptic_bus.analysis.transmission import STIFFNESS_RANGE as TRANSMISSION_STIFFNESS
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.errors import ParameterError
from haptic_bus.profile.reader import REQUIRED, Reader, profile_error

TIMINGS: dict[str, float | None] = {"ideal": 0, "cia402": 1, "reception": None}
"""Timing name -> its least loop delay in samples, the default of ``[loop] delay`` (None: required)."""
ON_ARRIVAL = frozenset({"ideal", "reception"})
"""The timings whose drive applies a target as its RPDO arrives (not at the next SYNC): on a real bus the
loop delay is then at least the cycle's exchange, SYNC out to RPDO out (:mod:`haptic_bus.app.preflight`)."""
# The ranges a profile's [device] and the simulated drive's parameters (sim_drive.parameters) share:
NOISE_SEED_RANGE = (0, 2**64 - 1)
SCALE_RANGE = (0.0, 1e6)  # exclusive low: m/s per count, m per count, N per N m
NOISE_RANGE = (0.0, 2.0**31)  # 0x606C counts rms: up to the INTEGER32 range itself
# 0x6072 is UNSIGNED16, but a torque beyond the INTEGER16 0x6071 can never be commanded.
PERMILLE_RANGE = (1, min(MAX_TORQUE.data_type.range[1], TARGET_TORQUE.data_type.range[1]))
RATED_TORQUE_RANGE = (1e-3, MOTOR_RATED_TORQUE.data_type.range[1] / 1000.0)  # N m (0x6076 in mN m)


@dataclass(frozen=True)
class DeviceTable:
    """A profile's checked ``[device]`` table, the handle and its drive: ``mass`` kg, effective ``friction`` b N s/m (and where it
    comes from), drive scaling (0x606C, 0x6064, 0x6076 N m, transmission N/(N m), 0x6072), the
    ``velocity`` model of 0x606C.  ``coulomb_friction`` (N; None: not stated, 0 N to a simulated
    drive) is the handle's Coulomb friction: with ``position_per_count`` the gate's quantisation
    condition (:meth:`quantisation`).  ``velocity_noise`` (0x606C counts rms) and ``noise_seed``
    are a simulated drive's hidden truth: the controller never uses them."""

    mass: float
    friction: float
    friction_source: str
    velocity_per_count: float
    position_per_count: float
    rated_torque: float
    force_per_torque: float
    max_torque_permille: int
    velocity: VelocityModel
    coulomb_friction: float | None = None
    velocity_noise: float = 0.0
    noise_seed: int | None = None
    transmission: Transmission | None = None

    @property
    def max_force(self) -> float:
        """Handle force in N that 0x6072 allows: permille * rated torque * transmission / 1000."""
        return self.max_torque_permille * self.rated_torque * self.force_per_torque / 1000.0

    def quantisation(self) -> Quantisation | None:
        """The encoder resolution, 0x606C's quantum and the Coulomb friction the gate judges the
        quantisation condition with; None when the profile states no ``coulomb_friction``."""
        if self.coulomb_friction is None:
            return None
        return Quantisation(self.position_per_count, self.coulomb_friction, self.velocity_per_count)

    def scaling(self) -> DriveScaling:
        """The drive-unit conversion of :mod:`drives.base`."""
        return DriveScaling(self.velocity_per_count, self.position_per_count, self.rated_torque, self.force_per_torque,
                            self.max_torque_permille)

    def sim_parameters(self, period: float, timing: str, delay: float) -> dict[str, object]:
        """Keyword arguments of ``sim_drive.parameters.DeviceParameters`` for this device on a loop of
        ``period`` s and ``timing`` (with the hidden truth: Coulomb friction, velocity noise and its seed, and
        the transmission: a profile the drive runs is its truth, the two-mass handle the gate judges)."""
        parameters: dict[str, object] = {
            "mass": self.mass, "friction": self.friction, "period": period,
            "velocity_per_count": self.velocity_per_count, "position_per_count": self.position_per_count,
            "rated_torque": self.rated_torque, "force_per_torque": self.force_per_torque,
            "max_torque_permille": self.max_torque_permille, "velocity": self.velocity,
            "coulomb_friction": self.coulomb_friction or 0.0, "velocity_noise": self.velocity_noise,
            "noise_seed": self.noise_seed, "transmission": self.transmission}
        if timing == "reception":
            parameters["reception_delay"] = delay
        return parameters


@dataclass(frozen=True)
class LoopTiming:
    """A profile's checked ``[loop]`` table, the control loop's timing: ``period`` T in s, ``timing``
    ("ideal", "cia402" or "reception") and the loop ``delay`` D in samples (real; an int when whole)
    that the gate judges with."""

    period: float
    timing: str
    delay: float


def read_device(path: pathlib.Path, table: object, prefix: str = "device",
                silent: Mapping[str, object] | None = None) -> DeviceTable:
    """A ``[device]`` table (``prefix``: its dotted name, e.g. ``axes[1].device``); ``silent``:
    defaults for keys the caller lets be left out (the simulated drive's), else every key but the
    hidden truth is required."""
    r = Reader(path, prefix, table, silent)
    mass = r.real("mass", *MASS_RANGE, "kg")
    friction = r.real("friction", *FRICTION_RANGE, "N s/m")
    source = r.text("friction_source")
    velocity = r.real("velocity_per_count", *SCALE_RANGE, "m/s per 0x606C unit", low_inclusive=False)
    position = r.real("position_per_count", *SCALE_RANGE, "m per 0x6064 increment", low_inclusive=False)
    rated = r.real("rated_torque", *RATED_TORQUE_RANGE, "N m (0x6076)")
    if not math.isclose(rated * 1000.0, round(rated * 1000.0), rel_tol=1e-12, abs_tol=1e-9):
        raise profile_error(path, r.field("rated_torque"), rated, "a whole number of mN m (0x6076 is UNSIGNED32 in mN m)")
    transmission = r.real("force_per_torque", *SCALE_RANGE, "N/(N m)", low_inclusive=False)
    permille = r.whole("max_torque_permille", *PERMILLE_RANGE)
    model = r.velocity_model("velocity")
    stated = "coulomb_friction" in r.table
    coulomb = r.real("coulomb_friction", *COULOMB_RANGE, "N (the handle's Coulomb friction)") if stated else None
    r.used.add("coulomb_friction")
    noise = r.real("velocity_noise", *NOISE_RANGE, "0x606C counts rms (a simulated drive's truth)", default=0.0)
    seed = r.whole("noise_seed", *NOISE_SEED_RANGE, default=None) if "noise_seed" in r.table else None
    r.used.add("noise_seed")
    coupling = read_transmission(path, r.raw("transmission", "a [device.transmission] table", default=None),
                                 r.field("transmission"))
    r.done()
    return DeviceTable(mass, friction, source, velocity, position, rated, transmission, permille, model,
                       coulomb, noise, seed, transmission=coupling)


def read_transmission(path: pathlib.Path, table: object, prefix: str) -> Transmission | None:
    """An optional ``[device.transmission]`` table (None: a rigid handle): ``stiffness`` N/m (> 0), ``damping``
    N s/m and ``motor_mass`` kg, the motor side the drive senses and drives; ``[device]``'s mass and friction
    are then the handle's."""
    if table is None:
        return None
    r = Reader(path, prefix, table)
    r.only(("stiffness", "damping", "motor_mass"))
    stiffness = r.real("stiffness", *TRANSMISSION_STIFFNESS, "N/m", low_inclusive=False)
    damping = r.real("damping", *TRANSMISSION_DAMPING, "N s/m")
    motor_mass = r.real("motor_mass", *MOTOR_MASS_RANGE, "kg")
    r.done()
    return Transmission(stiffness, damping, motor_mass)


def read_timing(r: Reader) -> tuple[str, float]:
    """``timing`` and the loop ``delay`` (samples, an int when whole) of the table ``r`` reads."""
    timing = r.text("timing", choices=tuple(TIMINGS))
    least = TIMINGS[timing]
    delay = r.real("delay", 0.0 if least is None else least, DELAY_RANGE[1], f"samples (timing {timing!r})",
                   default=REQUIRED if least is None else least)
    return timing, int(delay) if float(delay).is_integer() else delay


def read_loop(path: pathlib.Path, table: object, silent: Mapping[str, object] | None = None) -> LoopTiming:
    """A ``[loop]`` table: ``period``, ``timing`` and ``delay`` (``silent`` as :func:`read_device`'s)."""
    r = Reader(path, "loop", table, silent)
    period = r.real("period", *PERIOD_RANGE, "s")
    timing, delay = read_timing(r)
    r.done()
    return LoopTiming(period, timing, delay)


def check_velocity_period(path: pathlib.Path, field: str, device: DeviceTable, period: float) -> None:
    """The velocity model against the period: a window longer than T is no model of this loop."""
    try:
        device.velocity.check_period(period)
    except ParameterError as error:
        raise profile_error(path, field, error.value, error.allowed) from None
