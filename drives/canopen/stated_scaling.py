"""What a CANopen CiA-402 drive states about its scaling, read over SDO (uploads only, nothing written).

The standard objects 0x6076 (rated torque, mN m), 0x6072 (max torque, per mille) and the factor
group (0x608F, 0x6090, 0x6091, 0x6092, 0x60A8, 0x60A9; :func:`drives.factor_group.derive`) where
the drive has them, and manufacturer objects only where an EDS the user gave names them
(:func:`drives.canopen.master_dictionary.find_scaling_objects`).  Commissioning reads it before a run
(:mod:`drives.canopen.commissioning`); ``haptic-bus profiles new --from-drive`` writes it into a
profile.
"""

from __future__ import annotations

import logging

from canopen import objectdictionary

from drives.base import ScalingReading
from drives.canopen.master_dictionary import find_scaling_objects
from drives.canopen.sdo import SdoAccess
from drives.cia301 import SdoAbort
from drives.cia402 import MAX_TORQUE, MOTOR_RATED_TORQUE, RATIO_OBJECTS, UNIT_OBJECTS, DataType, RatioSpec
from drives.cia402_master import REAL32_ROUNDING
from drives.errors import DriveRefusal
from drives.factor_group import FactorGroup, derive

logger = logging.getLogger(__name__)

Readings = dict[str, tuple[ScalingReading, ...]]


def read_stated_scaling(name: str, sdo: SdoAccess,
                        dictionary: objectdictionary.ObjectDictionary | None) -> tuple[Readings, tuple[str, ...]]:
    """The scaling the drive states, per :class:`~drives.base.DriveScaling` field in order of
    precedence (manufacturer objects ``dictionary`` names, then the standard objects), and notes
    on what the standard objects cannot give; ``name`` names the drive in errors."""
    notes: list[str] = []
    standard: dict[str, ScalingReading] = {}
    rated = _optional(name, sdo, MOTOR_RATED_TORQUE.index, 0, MOTOR_RATED_TORQUE.data_type, notes)
    if rated is not None:
        standard["rated_torque"] = ScalingReading(rated / 1000.0, "0x6076", 0.5 / rated if rated else 0.0, f"{rated} mN m")
    permille = _optional(name, sdo, MAX_TORQUE.index, 0, MAX_TORQUE.data_type, notes)
    if permille is not None:
        standard["max_torque_permille"] = ScalingReading(permille, "0x6072")
    position_unit, velocity_unit = (_optional(name, sdo, spec.index, 0, spec.data_type, notes) for spec in UNIT_OBJECTS)
    group = FactorGroup(position_unit, velocity_unit, *(_optional_ratio(name, sdo, spec, notes) for spec in RATIO_OBJECTS))
    derived, derive_notes = derive(name, group)
    standard.update(derived)
    found: Readings = {}
    for field, (index, subindex, fmt) in find_scaling_objects(dictionary).items():
        rounding = REAL32_ROUNDING if fmt == "<f" else 0.0
        found[field] = (ScalingReading(sdo.read_real(index, subindex, fmt), f"0x{index:04X}:{subindex:02X}", rounding,
                                       "manufacturer object named by the EDS"),)
    for field, reading in standard.items():
        found[field] = (*found.get(field, ()), reading)
    return found, (*derive_notes, *notes)


def _optional(name: str, sdo: SdoAccess, index: int, subindex: int, data_type: DataType, notes: list[str]) -> int | None:
    """An object the drive may lack: None if it answers with an SDO abort (noted unless "no such object")."""
    try:
        return sdo.read_int(index, subindex, data_type)
    except DriveRefusal as exc:
        if exc.code not in (SdoAbort.NO_OBJECT, SdoAbort.NO_SUBINDEX):
            notes.append(f"0x{index:04X}:{subindex:02X} not read: {exc.message}")
        logger.debug("%s: %s", name, exc)
        return None


def _optional_ratio(name: str, sdo: SdoAccess, spec: RatioSpec, notes: list[str]) -> tuple[int, int] | None:
    """Sub 1 and sub 2 of a factor-group ratio the drive may lack (None unless both answer)."""
    numerator = _optional(name, sdo, spec.index, 1, spec.data_type, notes)
    denominator = _optional(name, sdo, spec.index, 2, spec.data_type, notes) if numerator is not None else None
    return None if numerator is None or denominator is None else (numerator, denominator)
