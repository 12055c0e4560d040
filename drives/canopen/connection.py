"""What a connected CANopen drive holds: its node, SDO access, events and what commissioning found.

A :class:`~drives.canopen.drive.CanopenDrive` is built without touching the bus (its arguments
are checked, nothing more); ``connect()`` builds a :class:`CanopenConnection` whole, returns it
and keeps it until ``close()``.  Nothing in a connection is ever None, so nothing that uses one
checks for a half-built state: a drive method that needs the bus asks the drive for its
connection (``DriveError`` "not connected" before ``connect()`` and after ``close()``) and then
uses every part of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import canopen

from drives.canopen.commissioning import Commissioned
from drives.canopen.events import DriveEvents
from drives.canopen.sdo import SdoAccess


@dataclass(frozen=True, slots=True)
class CanopenConnection:
    """A commissioned drive on an open network: ``node`` (canopen's), ``sdo`` (typed SDO access
    with timeouts), ``events`` (EMCY, heartbeat, NMT state) and ``commissioned`` (the PDO layout,
    scaling readings and safety findings of commissioning)."""

    node: canopen.RemoteNode
    sdo: SdoAccess
    events: DriveEvents
    commissioned: Commissioned
