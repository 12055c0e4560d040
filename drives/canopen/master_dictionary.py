"""The master's object dictionary: the drive's EDS, or the minimal standard one.

(The ``sdo`` service command's dictionary, with more CiA-301 objects and a user's EDS checked
before a bus is opened, is :mod:`drives.canopen.service_dictionary`.)

The master needs an object dictionary for names in error messages and for canopen's generic
PDO path (used by the benchmark); what the drive itself has is read from the drive
(:mod:`drives.canopen.inventory`), never assumed from this dictionary.  Without an EDS,
:func:`minimal_cia402_od` builds the CiA-301 communication objects the master touches plus the
standard CiA-402 objects of :mod:`drives.cia402` (the factor group and SI unit objects too): a
real drive is met with the standard dictionary, never with ours.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

from canopen import objectdictionary as od

from drives.canopen.eds_import import import_eds
from drives.cia301 import COMMUNICATION_OBJECT_NAMES
from drives.cia402 import OBJECTS, RATIO_OBJECTS, UNIT_OBJECTS, DataType

_CANOPEN_TYPE = {
    DataType.INTEGER8: od.INTEGER8,
    DataType.INTEGER16: od.INTEGER16,
    DataType.INTEGER32: od.INTEGER32,
    DataType.UNSIGNED8: od.UNSIGNED8,
    DataType.UNSIGNED16: od.UNSIGNED16,
    DataType.UNSIGNED32: od.UNSIGNED32,
}


def load_object_dictionary(eds: str | os.PathLike | od.ObjectDictionary | None, node_id: int) -> od.ObjectDictionary:
    """The drive's object dictionary: from ``eds`` (path or OD), else the minimal CiA-402 one."""
    if isinstance(eds, od.ObjectDictionary):
        return eds
    if eds is None:
        return minimal_cia402_od()
    return import_eds(eds, node_id)


def new_variable(name: str, index: int, subindex: int, data_type: int, access: str, mappable: bool = False,
              default: int | None = None) -> od.ODVariable:
    """A dictionary entry: ``data_type`` a canopen type code, ``access`` "ro"/"rw"/"const"."""
    var = od.ODVariable(name, index, subindex)
    var.data_type = data_type
    var.access_type = access
    var.pdo_mappable = mappable
    var.default = default
    return var


def _pdo_records(dictionary: od.ObjectDictionary, com_base: int, map_base: int, kind: str) -> None:
    for n in range(4):
        com = od.ODRecord(f"{kind}{n + 1} communication parameter", com_base + n)
        com.add_member(new_variable("Highest sub-index supported", com_base + n, 0, od.UNSIGNED8, "const", default=5))
        com.add_member(new_variable("COB-ID", com_base + n, 1, od.UNSIGNED32, "rw"))
        com.add_member(new_variable("Transmission type", com_base + n, 2, od.UNSIGNED8, "rw"))
        com.add_member(new_variable("Inhibit time", com_base + n, 3, od.UNSIGNED16, "rw"))
        com.add_member(new_variable("Event timer", com_base + n, 5, od.UNSIGNED16, "rw"))
        dictionary.add_object(com)
        mapping = od.ODRecord(f"{kind}{n + 1} mapping parameter", map_base + n)
        mapping.add_member(new_variable("Number of mapped objects", map_base + n, 0, od.UNSIGNED8, "rw"))
        for sub in range(1, 9):
            mapping.add_member(new_variable(f"Mapped object {sub}", map_base + n, sub, od.UNSIGNED32, "rw"))
        dictionary.add_object(mapping)


def minimal_cia402_od() -> od.ObjectDictionary:
    """A minimal object dictionary: CiA-301 communication objects plus drives.cia402.OBJECTS."""
    dictionary = od.ObjectDictionary()
    dictionary.add_object(new_variable("Device type", 0x1000, 0, od.UNSIGNED32, "ro"))
    dictionary.add_object(new_variable("Error register", 0x1001, 0, od.UNSIGNED8, "ro"))
    dictionary.add_object(new_variable("Communication cycle period", 0x1006, 0, od.UNSIGNED32, "rw"))
    dictionary.add_object(new_variable("Producer heartbeat time", 0x1017, 0, od.UNSIGNED16, "rw"))
    _pdo_records(dictionary, 0x1400, 0x1600, "RPDO")
    _pdo_records(dictionary, 0x1800, 0x1A00, "TPDO")
    for spec in OBJECTS.values():
        dictionary.add_object(
            new_variable(spec.name, spec.index, spec.subindex, _CANOPEN_TYPE[spec.data_type], spec.access, mappable=True)
        )
    add_factor_group(dictionary)
    return dictionary


def add_factor_group(dictionary: od.ObjectDictionary, values: Mapping[tuple[int, int], int] | None = None,
                     access: str = "rw") -> None:
    """Add the CiA-402 factor group and SI unit objects (drives.cia402 RATIO_OBJECTS, UNIT_OBJECTS)
    to ``dictionary``: every one, or (``values`` given) those ``values`` holds ``(index, subindex)``
    defaults for, with ``access``."""
    for spec in UNIT_OBJECTS:
        if values is None or (spec.index, 0) in values:
            default = None if values is None else values[spec.index, 0]
            dictionary.add_object(new_variable(spec.name, spec.index, 0, _CANOPEN_TYPE[spec.data_type], access, default=default))
    for ratio in RATIO_OBJECTS:
        if values is not None and (ratio.index, 1) not in values:
            continue
        array = od.ODArray(ratio.name, ratio.index)
        array.add_member(new_variable("Highest sub-index supported", ratio.index, 0, od.UNSIGNED8, "const", default=2))
        for subindex, name in ((1, ratio.numerator), (2, ratio.denominator)):
            default = None if values is None else values[ratio.index, subindex]
            array.add_member(new_variable(name, ratio.index, subindex, _CANOPEN_TYPE[ratio.data_type], access, default=default))
        dictionary.add_object(array)


def object_name(dictionary: od.ObjectDictionary | None, index: int, subindex: int = 0) -> str:
    """A readable name of ``index:subindex`` from the OD, the CiA-402 tables, or CiA-301."""
    if dictionary is not None:
        try:
            var = dictionary.get_variable(index, subindex)
        except Exception:  # a malformed EDS must not hide the real error
            var = None
        if var is not None:
            parent = getattr(var, "parent", None)
            if isinstance(parent, (od.ODRecord, od.ODArray)):
                return f"{parent.name}.{var.name}"
            return var.name
    if index in OBJECTS:
        return OBJECTS[index].name
    return COMMUNICATION_OBJECT_NAMES.get(index, "unknown object")


# Manufacturer scaling objects recognised by name (REAL32/REAL64, SI units at the handle).
SCALING_OBJECT_NAMES: dict[str, str] = {
    "velocity per count": "velocity_per_count",
    "position per count": "position_per_count",
    "force per torque": "force_per_torque",
}
_REAL_FORMATS = {od.REAL32: "<f", od.REAL64: "<d"}


def find_scaling_objects(dictionary: od.ObjectDictionary | None) -> dict[str, tuple[int, int, str]]:
    """Manufacturer objects (0x2000-0x5FFF) whose names announce a DriveScaling field.

    Returns ``{field: (index, subindex, struct format)}`` for REAL32/REAL64 variables named
    "Velocity per count ...", "Position per count ...", "Force per torque ..." (case-insensitive).
    """
    found: dict[str, tuple[int, int, str]] = {}
    if dictionary is None:
        return found
    for index in sorted(i for i in dictionary if isinstance(i, int) and 0x2000 <= i <= 0x5FFF):
        obj = dictionary[index]
        members = obj.values() if isinstance(obj, (od.ODRecord, od.ODArray)) else [obj]
        for var in members:
            data_type = getattr(var, "data_type", None)
            fmt = _REAL_FORMATS.get(data_type) if isinstance(data_type, int) else None
            if fmt is None:
                continue
            name = var.name.strip().lower()
            for prefix, field in SCALING_OBJECT_NAMES.items():
                if name.startswith(prefix) and field not in found:
                    found[field] = (var.index, var.subindex, fmt)
    return found
