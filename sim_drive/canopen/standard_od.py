"""The simulated drive with standard objects only (``haptic-bus sim --od standard``).

What a master meets on a drive it has no EDS for: the shipped EDS's CiA-301 communication
objects and CiA-402 objects, no manufacturer area (no object in 0x2000-0x5FFF at all: the
loop timing is then the command line's or the profile's, never an SDO write), and the scaling
in the CiA-402 factor group and SI unit objects, read-only, as :mod:`drives.factor_group`
reads them.  :func:`encode` writes a :class:`~sim_drive.parameters.DeviceParameters` there:

- 0x6076 rated torque (mN m) and 0x6072 max torque, as in the shipped EDS;
- position: ``position_per_count`` = 10^e m (e in -18..18) gives 0x60A8 = e, metre (01h): 0x6064
  counts 10^e m.  Any other ``position_per_count`` gives 0x60A8 = encoder increments (B5h): then
  no object states a length, and a master takes position_per_count, velocity_per_count and
  force_per_torque from its profile (as with a real drive that reports increments);
- mechanics: ``L = 2 pi / force_per_torque`` m per motor revolution (:mod:`drives.factor_group`
  derives the factor).  With a length unit ``u``: 0x6092 feed constant = F / S, the fraction of
  32-bit terms closest to ``L / u`` (F position units per S shaft revolutions), 0x6091 gear ratio
  1 / 1, 0x608F position encoder resolution F / S (one increment is one position unit, so
  0x6064 = increments x feed constant / (resolution x gear) holds).  The relative rounding
  ``|F/S - L/u| / (L/u)`` is 4.5e-14 for the defaults (F/S = 1697716670/1351 in 0.1 um); the
  plant keeps the exact ``force_per_torque``.  With increments: 0x608F = 0x6092 = the closest
  fraction to ``L / position_per_count`` and 0x6091 1 / 1 (the feed counted in increments);
- velocity: ``velocity_per_count`` = 10^e m/s gives 0x60A9 = e, metre, second (FA010300h for
  the default 1 um/s).  Otherwise, with a length unit, 0x60A9 = increments per second (00B50300h)
  and 0x6090 velocity encoder resolution = the closest 32-bit fraction to ``L /
  velocity_per_count`` increments per motor revolution; with increments as the position unit and
  ``velocity_per_count == position_per_count``, 0x60A9 = increments per second (0x608F applies);
  else no 0x60A9.

Objects the encoding leaves out are absent (SDO abort 0x06020000), as on a drive that lacks
them.  The set of objects is fixed when the slave is built; their values follow
:meth:`~sim_drive.device.SimulatedDrive.reconfigure` (a value the new parameters cannot express
answers SDO abort 0x08000024, no data available).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from fractions import Fraction
from typing import Any

from canopen import SdoAbortedError
from canopen.objectdictionary import ObjectDictionary

from drives.canopen.eds_import import import_eds
from drives.canopen.master_dictionary import add_factor_group
from drives.cia402 import SI_UNIT_POSITION, SI_UNIT_VELOCITY
from drives.factor_group import INCREMENT, METRE, SECOND, FactorGroup, SiUnit, best_ratio, power_of_ten
from haptic_bus.errors import ParameterError
from sim_drive.canopen.vendor_od import load_vendor_eds
from sim_drive.device import SimulatedDrive
from sim_drive.eds import OD_KINDS, eds_path
from sim_drive.parameters import DeviceParameters

MANUFACTURER_AREA = range(0x2000, 0x6000)
NO_DATA = 0x08000024  # SDO abort: no data available

Encoding = dict[tuple[int, int], int]
ReadCallback = Callable[..., "int | None"]


def encode(parameters: DeviceParameters) -> Encoding:
    """The factor-group and SI unit objects that state ``parameters``' scaling: ``{(index, subindex): raw}``."""
    per_motor_rev = Fraction(math.tau) / Fraction(parameters.force_per_torque)  # m, exactly what a master inverts
    position = power_of_ten(parameters.position_per_count)
    velocity = power_of_ten(parameters.velocity_per_count)
    if position is not None:
        feed = best_ratio(per_motor_rev / Fraction(10) ** position)
        resolution = None
        velocity_unit = None
        if velocity is not None:
            velocity_unit = SiUnit(velocity, METRE, SECOND).encode()
        elif feed is not None and (resolution := best_ratio(per_motor_rev / Fraction(parameters.velocity_per_count))):
            velocity_unit = SiUnit(0, INCREMENT, SECOND).encode()
        return FactorGroup(SiUnit(position, METRE).encode(), velocity_unit, position_encoder=feed,
                           velocity_encoder=resolution, gear_ratio=None if feed is None else (1, 1),
                           feed_constant=feed).objects()
    increments = best_ratio(per_motor_rev / Fraction(parameters.position_per_count))
    in_increments = parameters.velocity_per_count == parameters.position_per_count
    return FactorGroup(SiUnit(0, INCREMENT).encode(), SiUnit(0, INCREMENT, SECOND).encode() if in_increments else None,
                       position_encoder=increments, gear_ratio=None if increments is None else (1, 1),
                       feed_constant=increments).objects()


def standard_dictionary(node_id: int, parameters: DeviceParameters) -> ObjectDictionary:
    """The shipped EDS without its manufacturer area, plus the read-only objects :func:`encode` gives."""
    dictionary = import_eds(eds_path(), node_id)
    for index in [i for i in dictionary.indices if i in MANUFACTURER_AREA]:
        del dictionary[index]
    add_factor_group(dictionary, encode(parameters), access="ro")
    return dictionary


class StandardObjects:
    """SDO read callback serving the factor-group objects of ``drive``'s current parameters."""

    def __init__(self, drive: SimulatedDrive) -> None:
        self._drive = drive
        self._parameters: DeviceParameters | None = None
        self._values: Encoding = {}

    def read(self, index: int, subindex: int, od: Any) -> int | None:
        """The raw value of a factor-group object, None for any other object (left to the slave and the OD)."""
        if not (0x608F <= index <= 0x6092 and subindex) and index not in (SI_UNIT_POSITION.index, SI_UNIT_VELOCITY.index):
            return None
        if self._drive.parameters is not self._parameters:
            self._parameters = self._drive.parameters
            self._values = encode(self._parameters)
        value = self._values.get((index, subindex))
        if value is None:
            raise SdoAbortedError(NO_DATA)
        return value


def object_dictionary(kind: str, node_id: int, drive: SimulatedDrive, given: ObjectDictionary | None = None,
                      eds: str | os.PathLike[str] | None = None) -> tuple[ObjectDictionary, ReadCallback | None]:
    """The slave's dictionary for ``kind`` ("haptic": the shipped EDS; "standard":
    :func:`standard_dictionary`), or ``given`` instead, or a user's ``eds`` (a vendor's, kind
    "haptic" only: :mod:`sim_drive.canopen.vendor_od`), and the SDO read callback the dictionary
    needs besides the slave's own (None for the shipped EDS)."""
    if kind not in OD_KINDS:
        raise ParameterError("od", kind, " or ".join(map(repr, OD_KINDS)), "simulated drive")
    if eds is not None:
        if kind != "haptic" or given is not None:
            raise ParameterError("eds", os.fspath(eds), "an EDS alone (not with --od standard or a dictionary)",
                                 "simulated drive")
        return load_vendor_eds(eds, node_id), StandardObjects(drive).read
    if kind == "haptic":
        return given if given is not None else import_eds(eds_path(), node_id), None
    return given if given is not None else standard_dictionary(node_id, drive.parameters), StandardObjects(drive).read
