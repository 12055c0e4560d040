"""The CiA-402 factor group and SI unit objects, read as the SI scaling of a linear haptic handle.

The objects (names as in :mod:`drives.cia402`), all UNSIGNED32:

- 0x608F position encoder resolution = sub 1 encoder increments / sub 2 motor revolutions;
- 0x6090 velocity encoder resolution = sub 1 encoder increments per second / sub 2 motor
  revolutions per second;
- 0x6091 gear ratio = sub 1 motor shaft revolutions / sub 2 driving shaft revolutions;
- 0x6092 feed constant = sub 1 feed (in position units) / sub 2 driving shaft revolutions;
- 0x60A8 SI unit position, 0x60A9 SI unit velocity: byte 3 (bits 24-31) the exponent of a power
  of ten (a signed byte: FDh = -3), byte 2 (bits 16-23) the unit, byte 1 (bits 8-15) the time
  unit of a velocity (0 for a position), byte 0 reserved (0).  FD010000h is mm, FD010300h mm/s,
  00B44700h rev/min.

How a drive uses them (the factor group): position actual value 0x6064, in position units, =
position internal value (encoder increments) x feed constant / (position encoder resolution x
gear ratio).  So 0x6064 counts *position units*, whose size 0x60A8 names: with a length unit
(m, inch, foot) one 0x6064 count is ``10^exponent`` of it, and the feed constant is the length
per driving shaft revolution in that unit.  With increments, revolutions or angles as the
position unit no object states a length, and the handle's scaling must come from elsewhere
(the profile).  Velocity 0x606C counts velocity units, which 0x60A9 names: a length per time
directly; a revolution or an angle of the driving shaft per time (the gear ratio applied, the
feed not, as the unit table below says), converted with the feed; or encoder increments per
time, converted with the feed, the gear and 0x6090 (0x608F where the drive has no 0x6090).

Sources followed (the standard's text was not at hand; these public manuals of CiA-402
implementations agree with each other, and this module follows them):

- Nanotec, Technical Manual PD4-E-M (EtherCAT), section 5.3 "User-defined units" (FIR-v1748),
  and the Nanotec C5-E / PD6-E online manuals, "User-defined units": the byte layout above, the
  examples FD010000h = millimetre and FF410000h = tenth of a degree, gear ratio = 6091h:1 /
  6091h:2, feed constant = 6092h:1 / 6092h:2, and the unit table: metre 01h, inch C1h, foot C2h,
  gon 40h, radian 10h, degree 41h, arcminute 42h, arcsecond 43h, revolution B4h (gear ratio
  applied, feed constant not), encoder increment B5h (neither), step ACh, electrical pole C0h;
- Copley Controls' CML example ``CANopenFactorGroups.cpp`` and Mitsubishi MR-J5 manual 17.4:
  0x6064 = 0x6063 x feed constant / (0x608F x 0x6091), all factor objects 1 by default;
- Synapticon SOMANET object 0x60A9: 00B44700h = 1 rpm (B4h revolution per 47h minute),
  FDB44700h = 0.001 rpm; heig-vd-iai/canopen-stack defaults FD010000h (mm) and FD010300h
  (mm/s): 03h is the second.

Time units accepted: 03h second, 47h minute (the two the sources show).  Exponents accepted:
-18..18 (the SI prefixes atto..exa).

Force per torque: a lossless transmission that moves the handle ``L`` metres per motor
revolution turns a motor torque ``tau`` into the handle force ``F`` with ``F v = tau omega`` and
``v = L omega / (2 pi)``, so ``F = 2 pi tau / L`` and ``force_per_torque = 2 pi / L`` N/(N m),
``L = feed x position unit / shaft revolutions / gear ratio``.  Torque is the motor's (0x6071 and
0x6076 are torques at the motor shaft).

Rounding: a feed is a length rounded to a whole number of position units, so a factor that
uses the feed carries a relative rounding of ``0.5 / feed``; exponents, units, gear ratios and
encoder resolutions are exact.  :class:`~drives.base.ScalingReading` carries it as ``tolerance``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

from drives.base import ScalingReading
from drives.cia402 import (
    FEED_CONSTANT,
    GEAR_RATIO,
    POSITION_ENCODER_RESOLUTION,
    SI_UNIT_POSITION,
    SI_UNIT_VELOCITY,
    VELOCITY_ENCODER_RESOLUTION,
    ObjectSpec,
    RatioSpec,
)
from drives.errors import DriveProtocolError

EXPONENT_RANGE = (-18, 18)
UINT32_MAX = 0xFFFFFFFF
METRE, INCH, FOOT = 0x01, 0xC1, 0xC2
REVOLUTION, INCREMENT, DEGREE = 0xB4, 0xB5, 0x41
SECOND, MINUTE = 0x03, 0x47
LENGTH_UNITS: dict[int, tuple[str, Fraction]] = {
    METRE: ("m", Fraction(1)),
    INCH: ("in", Fraction(254, 10_000)),
    FOOT: ("ft", Fraction(3048, 10_000)),
}
# Angles of the driving shaft, in revolutions (the radian's is the one inexact value).
ANGLE_UNITS: dict[int, tuple[str, Fraction]] = {
    REVOLUTION: ("rev", Fraction(1)),
    DEGREE: ("deg", Fraction(1, 360)),
    0x40: ("gon", Fraction(1, 400)),
    0x42: ("arcmin", Fraction(1, 360 * 60)),
    0x43: ("arcsec", Fraction(1, 360 * 3600)),
    0x10: ("rad", 1 / Fraction(math.tau)),
}
# Units a drive may name that carry no length the master can know without a manufacturer object.
OTHER_UNITS: dict[int, str] = {0x00: "dimensionless", INCREMENT: "inc", 0xAC: "step", 0xC0: "electrical pole"}
TIME_UNITS: dict[int, tuple[str, int]] = {SECOND: ("s", 1), MINUTE: ("min", 60)}


@dataclass(frozen=True)
class SiUnit:
    """0x60A8 or 0x60A9 decoded: ``10^exponent`` ``unit`` per ``time`` (``time`` 0 for a position)."""

    exponent: int
    unit: int
    time: int = 0

    @classmethod
    def decode(cls, raw: int) -> SiUnit:
        """The fields of the UNSIGNED32 ``raw`` (no check; see :func:`check_unit`)."""
        exponent = raw >> 24 & 0xFF
        return cls(exponent - 0x100 if exponent & 0x80 else exponent, raw >> 16 & 0xFF, raw >> 8 & 0xFF)

    def encode(self) -> int:
        """The UNSIGNED32 a drive reports for this unit."""
        return (self.exponent & 0xFF) << 24 | self.unit << 16 | self.time << 8

    @property
    def scale(self) -> Fraction:
        """``10^exponent`` exactly."""
        return Fraction(10) ** self.exponent

    def __str__(self) -> str:
        name = {**{k: v[0] for k, v in LENGTH_UNITS.items()}, **{k: v[0] for k, v in ANGLE_UNITS.items()}, **OTHER_UNITS}
        text = f"10^{self.exponent} {name.get(self.unit, f'unit 0x{self.unit:02X}')}"
        return text + (f"/{TIME_UNITS[self.time][0]}" if self.time in TIME_UNITS else "")


@dataclass(frozen=True)
class FactorGroup:
    """The raw objects as read from a drive; None where the drive lacks the object.

    Ratios are ``(sub 1, sub 2)``: ``position_encoder`` 0x608F, ``velocity_encoder`` 0x6090,
    ``gear_ratio`` 0x6091, ``feed_constant`` 0x6092; ``position_unit`` 0x60A8 and
    ``velocity_unit`` 0x60A9 are the raw UNSIGNED32 values.
    """

    position_unit: int | None = None
    velocity_unit: int | None = None
    position_encoder: tuple[int, int] | None = None
    velocity_encoder: tuple[int, int] | None = None
    gear_ratio: tuple[int, int] | None = None
    feed_constant: tuple[int, int] | None = None

    def ratios(self) -> tuple[tuple[RatioSpec, tuple[int, int] | None], ...]:
        """Each ratio object with its value."""
        return ((POSITION_ENCODER_RESOLUTION, self.position_encoder), (VELOCITY_ENCODER_RESOLUTION, self.velocity_encoder),
                (GEAR_RATIO, self.gear_ratio), (FEED_CONSTANT, self.feed_constant))

    def objects(self) -> dict[tuple[int, int], int]:
        """The objects present as a drive reports them: ``{(index, subindex): raw}``, a ratio as sub 1 and sub 2."""
        values = {(spec.index, 0): raw for spec, raw in ((SI_UNIT_POSITION, self.position_unit),
                                                          (SI_UNIT_VELOCITY, self.velocity_unit)) if raw is not None}
        for spec, ratio in self.ratios():
            if ratio is not None:
                values[spec.index, 1], values[spec.index, 2] = ratio
        return values


def _object_error(node: str, index: int, subindex: int, name: str, value: int, allowed: str) -> DriveProtocolError:
    """A factor-group or SI-unit object ``index:subindex`` holding ``value``, which no drive may report."""
    return DriveProtocolError(node, f"0x{index:04X}:{subindex:02X} ({name}) = {value} (0x{value:08X}) is invalid; "
                                    f"allowed: {allowed}")


def _unit_error(node: str, spec: ObjectSpec, raw: int, allowed: str) -> DriveProtocolError:
    return _object_error(node, spec.index, 0, spec.name, raw, allowed)


def check_unit(node: str, spec: ObjectSpec, raw: int) -> SiUnit:
    """Decode 0x60A8 (``spec`` SI_UNIT_POSITION) or 0x60A9; DriveProtocolError for a value no drive may report."""
    unit = SiUnit.decode(raw)
    low, high = EXPONENT_RANGE
    known = sorted({*LENGTH_UNITS, *ANGLE_UNITS, *OTHER_UNITS})
    codes = ", ".join(f"{c:02X}h" for c in known)
    if not low <= unit.exponent <= high:
        raise _unit_error(node, spec, raw, f"an exponent (bits 24-31) in {low}..{high}")
    if unit.unit not in known:
        raise _unit_error(node, spec, raw, f"a unit (bits 16-23) among {codes}")
    if spec is SI_UNIT_POSITION and raw & 0xFFFF:
        raise _unit_error(node, spec, raw, "bits 0-15 zero (reserved) in a position unit")
    if spec is SI_UNIT_VELOCITY and (raw & 0xFF or unit.time not in TIME_UNITS):
        times = ", ".join(f"{c:02X}h {name}" for c, (name, _) in TIME_UNITS.items())
        raise _unit_error(node, spec, raw, f"a time unit (bits 8-15) among {times} and bits 0-7 zero")
    return unit


def check_ratio(node: str, spec: RatioSpec, value: tuple[int, int]) -> tuple[int, int]:
    """A ratio object's two values, each a whole number in 1..2^32-1; DriveProtocolError otherwise."""
    for subindex, (number, name) in enumerate(zip(value, (spec.numerator, spec.denominator), strict=True), 1):
        if not 1 <= number <= UINT32_MAX:
            raise _object_error(node, spec.index, subindex, f"{spec.name}: {name}", number,
                                f"1..{UINT32_MAX} (both terms of {spec.name.lower()} = sub 1 / sub 2 are > 0)")
    return value


@dataclass(frozen=True)
class _Mechanics:
    """The length the objects state per revolution: of the driving shaft and of the motor (m, exact)."""

    per_shaft_rev: Fraction
    per_motor_rev: Fraction
    chain: str  # the objects it came from
    rounding: float  # relative, from the feed


def derive(node: str, group: FactorGroup) -> tuple[dict[str, ScalingReading], tuple[str, ...]]:
    """The DriveScaling fields the objects determine (velocity_per_count, position_per_count,
    force_per_torque), each a :class:`ScalingReading`, and notes on the fields they cannot
    give.  Every object present is checked first (DriveProtocolError names a bad one)."""
    ratios = {spec.index: Fraction(*check_ratio(node, spec, value)) for spec, value in group.ratios() if value is not None}
    position = check_unit(node, SI_UNIT_POSITION, group.position_unit) if group.position_unit is not None else None
    velocity = check_unit(node, SI_UNIT_VELOCITY, group.velocity_unit) if group.velocity_unit is not None else None
    found: dict[str, ScalingReading] = {}
    notes: list[str] = []
    mechanics = None
    if position is None or position.unit not in LENGTH_UNITS:
        what = "no 0x60A8" if position is None else f"0x60A8 = {group.position_unit:08X}h ({position}), not a length"
        notes.append(f"position_per_count, force_per_torque: the drive has {what}, so no object states a length")
    else:
        unit = position.scale * LENGTH_UNITS[position.unit][1]  # m per 0x6064 count
        found["position_per_count"] = ScalingReading(float(unit), "0x60A8", 0.0, f"{position} per count")
        if group.feed_constant is None:
            notes.append("force_per_torque: the drive has no 0x6092 feed constant")
        else:
            mechanics = _mechanics(unit, ratios, group.feed_constant[0])
            found["force_per_torque"] = ScalingReading(
                float(Fraction(math.tau) / mechanics.per_motor_rev), mechanics.chain, mechanics.rounding,
                f"2 pi / {float(mechanics.per_motor_rev):.12g} m per motor revolution"
                + ("" if GEAR_RATIO.index in ratios else " (no 0x6091: gear 1:1)"))
    reading = _velocity(velocity, ratios, mechanics)
    if reading is not None:
        found["velocity_per_count"] = reading
    else:
        what = "no 0x60A9" if velocity is None else f"0x60A9 = {group.velocity_unit:08X}h ({velocity})"
        notes.append(f"velocity_per_count: the drive has {what}, and no length the master knows per count follows")
    return found, tuple(notes)


def _mechanics(unit: Fraction, ratios: dict[int, Fraction], feed: int) -> _Mechanics:
    """Metres per driving shaft and per motor revolution from the feed (in position units of ``unit`` m) and the gear."""
    per_shaft_rev = ratios[FEED_CONSTANT.index] * unit
    gear = ratios.get(GEAR_RATIO.index)
    chain = ("0x6091/" if gear is not None else "") + "0x6092/0x60A8"
    return _Mechanics(per_shaft_rev, per_shaft_rev / (gear or 1), chain, 0.5 / feed)


def _velocity(velocity: SiUnit | None, ratios: dict[int, Fraction], mechanics: _Mechanics | None) -> ScalingReading | None:
    """m/s per 0x606C count: a length per time directly, an angle of the driving shaft or encoder
    increments per time through the feed (and the gear, and the encoder's resolution); None if unknown."""
    if velocity is None:
        return None
    per_time = Fraction(1, TIME_UNITS[velocity.time][1])
    if velocity.unit in LENGTH_UNITS:
        value = velocity.scale * LENGTH_UNITS[velocity.unit][1] * per_time
        return ScalingReading(float(value), "0x60A9", 0.0, f"{velocity} per count")
    if mechanics is None:
        return None
    if velocity.unit in ANGLE_UNITS:
        value = velocity.scale * ANGLE_UNITS[velocity.unit][1] * mechanics.per_shaft_rev * per_time
        return ScalingReading(float(value), f"0x60A9/{mechanics.chain.removeprefix('0x6091/')}", mechanics.rounding,
                              f"{velocity} of the driving shaft per count")
    encoder = next((spec for spec in (VELOCITY_ENCODER_RESOLUTION, POSITION_ENCODER_RESOLUTION) if spec.index in ratios), None)
    if velocity.unit != INCREMENT or encoder is None:
        return None
    per_increment = mechanics.per_motor_rev / ratios[encoder.index]
    value = velocity.scale * per_increment * per_time
    return ScalingReading(float(value), f"0x60A9/0x{encoder.index:04X}/{mechanics.chain}", mechanics.rounding,
                          f"{velocity} of {float(per_increment):.12g} m increments per count")


# ----------------------------------------------------------------------------- encoding (a drive's side)

def power_of_ten(value: float, rel_tol: float = 1e-12) -> int | None:
    """``e`` with ``value == 10^e`` (to ``rel_tol``) and ``e`` in :data:`EXPONENT_RANGE`, or None."""
    if not value > 0 or not math.isfinite(value):
        return None
    exponent = round(math.log10(value))
    low, high = EXPONENT_RANGE
    if low <= exponent <= high and math.isclose(value, float(Fraction(10) ** exponent), rel_tol=rel_tol):
        return exponent
    return None


def best_ratio(value: Fraction) -> tuple[int, int] | None:
    """``(p, q)``, both in 1..2^32-1, with ``p/q`` the closest such fraction to ``value`` > 0
    (continued fractions, :meth:`fractions.Fraction.limit_denominator`), or None if none is near."""
    if value <= 0:
        return None
    limit = min(UINT32_MAX, math.floor(UINT32_MAX / value))
    for bound in (limit, limit - 1):  # p = round(value q) may pass 2^32-1 by one at the first bound
        if bound < 1:
            return None
        ratio = value.limit_denominator(bound)
        if 1 <= ratio.numerator <= UINT32_MAX:
            return ratio.numerator, ratio.denominator
    return None
