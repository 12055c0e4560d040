"""The service tools' object dictionary (``haptic-bus sdo``): the user's EDS, or the standard one.

Without an EDS, :func:`standard_dictionary` is the master's minimal CiA-402 dictionary
(:func:`drives.canopen.master_dictionary.minimal_cia402_od`) plus the CiA-301 objects a person reads on any
node: the pre-defined error field 0x1003, the SYNC and EMCY objects, the device name and
versions (0x1008-0x100A), the heartbeat consumer 0x1016 and the identity 0x1018.  With one, the
EDS (or DCF) is the drive's own dictionary, whatever its vendor: its names, types and limits.
"""

from __future__ import annotations

import os

from canopen import objectdictionary as od

from drives.canopen.eds_import import import_eds
from drives.canopen.master_dictionary import minimal_cia402_od, new_variable
from drives.cia301 import (
    COB_ID_EMCY,
    COB_ID_SYNC,
    COMMUNICATION_OBJECT_NAMES,
    CONSUMER_HEARTBEAT_TIME,
    IDENTITY,
    PRE_DEFINED_ERROR_FIELD,
    SYNCHRONOUS_WINDOW_LENGTH,
)
from drives.errors import ParameterError

_DEVICE_STRINGS = {0x1008: "Manufacturer device name", 0x1009: "Manufacturer hardware version",
                   0x100A: "Manufacturer software version"}
_IDENTITY_FIELDS = ("Vendor-ID", "Product code", "Revision number", "Serial number")


def _array(index: int, count_name: str, entry_name: str, access: str) -> od.ODArray:
    """An ARRAY of UNSIGNED32 entries (canopen makes sub-indices 2..255 from sub 1)."""
    array = od.ODArray(COMMUNICATION_OBJECT_NAMES[index], index)
    array.add_member(new_variable(count_name, index, 0, od.UNSIGNED8, access))
    array.add_member(new_variable(entry_name, index, 1, od.UNSIGNED32, access))
    return array


def standard_dictionary() -> od.ObjectDictionary:
    """The standard CiA-301/402 objects (module docstring)."""
    dictionary = minimal_cia402_od()
    for index in (COB_ID_SYNC, SYNCHRONOUS_WINDOW_LENGTH, COB_ID_EMCY):
        dictionary.add_object(new_variable(COMMUNICATION_OBJECT_NAMES[index], index, 0, od.UNSIGNED32, "rw"))
    for index, name in _DEVICE_STRINGS.items():
        dictionary.add_object(new_variable(name, index, 0, od.VISIBLE_STRING, "const"))
    dictionary.add_object(_array(PRE_DEFINED_ERROR_FIELD, "Number of errors", "Standard error field", "ro"))
    dictionary.add_object(_array(CONSUMER_HEARTBEAT_TIME, "Highest sub-index supported", "Consumer heartbeat time", "rw"))
    identity = od.ODRecord(COMMUNICATION_OBJECT_NAMES[IDENTITY], IDENTITY)
    identity.add_member(new_variable("Highest sub-index supported", IDENTITY, 0, od.UNSIGNED8, "const"))
    for subindex, name in enumerate(_IDENTITY_FIELDS, 1):
        identity.add_member(new_variable(name, IDENTITY, subindex, od.UNSIGNED32, "ro"))
    dictionary.add_object(identity)
    return dictionary


def load_dictionary(eds: str | os.PathLike[str] | None, node_id: int) -> od.ObjectDictionary:
    """The EDS/DCF at ``eds`` (``$NODEID`` resolved for ``node_id``), or :func:`standard_dictionary`;
    ParameterError naming the file if it cannot be read as one (checked before any bus is opened)."""
    if eds is None:
        return standard_dictionary()
    path = os.fspath(eds)
    if not os.path.isfile(path):
        raise ParameterError("--eds", path, "an existing EDS or DCF file")
    try:
        dictionary = import_eds(path, node_id)
    except Exception as exc:  # configparser, KeyError, ValueError...: whatever a malformed EDS raises
        reason = " ".join(str(exc).split())  # one line, whatever the parser's message spans
        raise ParameterError("--eds", path, f"an EDS or DCF file canopen can read ({type(exc).__name__}: {reason})") from None
    if not len(dictionary):
        raise ParameterError("--eds", path, "an EDS or DCF file with objects (this one has none)")
    return dictionary


def find_variable(dictionary: od.ObjectDictionary, index: int, subindex: int) -> od.ODVariable | None:
    """The dictionary's entry for ``index:subindex``, or None if it has none (canopen hands out a
    VAR for any sub-index of its index: only sub-index 0 is that VAR)."""
    try:
        variable = dictionary.get_variable(index, subindex)
    except (KeyError, IndexError):
        return None
    return variable if variable is not None and variable.subindex == subindex else None
