"""The simulated CiA-402 core behind a user's own EDS (``haptic-bus sim --eds FILE``).

The slave serves the EDS as it stands, through canopen's EDS import (:func:`canopen.import_od`):

- an object or sub-index the EDS lacks is absent (SDO abort 0x06020000 / 0x06090011), so a
  master meets exactly the dictionary it will meet on the real drive (no 0x1016, no 0x6007,
  0x1400 with sub 0-2 only, ...);
- the PDOs are the EDS's: the RPDOs and TPDOs it declares, the entries each mapping record holds
  (and the HighLimit of its sub 0), its default mappings and COB-IDs
  (:mod:`sim_drive.canopen.pdo_table`);
- the CiA-402 objects the core implements are live where the EDS has them; its other objects
  hold their EDS default, and what is written to them (:mod:`sim_drive.canopen.pdo_access`);
  the manufacturer area is the vendor's (stored values), never the simulator's 0x2000..;
- the factor group and SI unit objects the EDS has state the simulated plant's scaling, as with
  ``--od standard`` (:class:`~sim_drive.canopen.standard_od.StandardObjects`);
- a number the EDS gives no DefaultValue (vendors leave many out: the device fills them in)
  reads 0, and 0x1000 without one reads 0x00020192 (a CiA-402 servo drive, which the core is).

:func:`core_gaps` lists the objects a CiA-402 master in cyclic synchronous torque mode relies on
that the EDS lacks: the simulator logs them at start, a rehearsal's first findings.
"""

from __future__ import annotations

import os

from canopen.objectdictionary import NUMBER_TYPES, ObjectDictionary, ODArray, ODRecord

from drives.canopen.eds_import import import_eds
from drives.cia301 import DEVICE_TYPE
from haptic_bus.errors import ParameterError

SERVO_DEVICE_TYPE = 0x00020192  # 0x1000 of a CiA-402 servo drive (type 0x0002, profile 402)

# What a CiA-402 master in CST mode writes or maps, and what it then lacks: (index, subindex, meaning)
CORE_OBJECTS: tuple[tuple[int, int, str], ...] = (
    (0x1006, 0, "communication cycle period"),
    (0x1016, 1, "heartbeat consumer (stop on the master's heartbeat loss)"),
    (0x1017, 0, "heartbeat producer"),
    (0x1400, 5, "RPDO1 event timer (receive deadline)"),
    (0x6007, 0, "abort connection option code"),
    (0x6040, 0, "controlword"),
    (0x6041, 0, "statusword"),
    (0x606C, 0, "velocity actual value"),
    (0x6071, 0, "target torque (cyclic synchronous torque mode)"),
    (0x6072, 0, "max torque"),
    (0x6076, 0, "motor rated torque"),
)


def load_vendor_eds(path: str | os.PathLike[str], node_id: int) -> ObjectDictionary:
    """The object dictionary of the EDS at ``path`` for ``node_id``; ParameterError (one line) if
    it cannot be read or is no EDS of a CiA-402 device's communication objects."""
    name = os.fspath(path)
    if not os.path.isfile(name):
        raise ParameterError("eds", name, "an EDS file that exists", "simulated drive")
    try:
        dictionary = import_eds(name, node_id)
    except Exception as exc:  # canopen's EDS import raises whatever its parser meets
        raise ParameterError("eds", name, f"an EDS canopen can import ({type(exc).__name__}: {exc})",
                             "simulated drive") from exc
    if 0x1000 not in dictionary or 0x6041 not in dictionary:
        raise ParameterError("eds", name, "an EDS with 0x1000 (device type) and 0x6041 (statusword)", "simulated drive")
    _fill_defaults(dictionary)
    return dictionary


def _fill_defaults(dictionary: ObjectDictionary) -> None:
    """A default for every number without one: 0, and :data:`SERVO_DEVICE_TYPE` for 0x1000."""
    for index in list(dictionary.indices):
        obj = dictionary[index]
        for variable in obj.values() if isinstance(obj, (ODRecord, ODArray)) else [obj]:
            if variable.default is None and variable.value is None and variable.data_type in NUMBER_TYPES:
                variable.default = SERVO_DEVICE_TYPE if variable.index == DEVICE_TYPE else 0


def has(dictionary: ObjectDictionary, index: int, subindex: int = 0) -> bool:
    """True if ``dictionary`` has ``index:subindex``."""
    obj = dictionary.get(index)
    if isinstance(obj, (ODRecord, ODArray)):
        return subindex in obj.subindices
    return obj is not None and subindex == 0


def core_gaps(dictionary: ObjectDictionary) -> list[str]:
    """"0x1016:01 heartbeat consumer (...)" for each of :data:`CORE_OBJECTS` the dictionary lacks."""
    return [f"0x{index:04X}" + (f":{subindex:02X}" if subindex else "") + f" {meaning}"
            for index, subindex, meaning in CORE_OBJECTS if not has(dictionary, index, subindex)]
