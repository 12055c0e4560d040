"""What a drive states about itself, read without changing it: for ``haptic-bus profiles new --from-drive``.

CANopen: SDO uploads only (0x1000, then the scaling the masters read at commissioning,
:func:`drives.canopen.stated_scaling.read_stated_scaling`: 0x6076, 0x6072 and the CiA-402 factor
group through :mod:`drives.factor_group`); no NMT command, no SDO download, no SYNC, so a drive
someone else commissions is not disturbed.  Modbus: the map identity and the scaling registers
(:meth:`drives.modbus.drive.ModbusDrive.stated_scaling`), reads only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from drives.base import ScalingReading
from haptic_bus.errors import DriveProtocolError, DriveTimeout


@dataclass(frozen=True)
class DriveStatement:
    """``source``: where it was read (one line); ``scaling``: per :class:`~drives.base.DriveScaling`
    field the reading in use (a field the drive cannot state is absent); ``notes``: why not."""

    source: str
    scaling: dict[str, ScalingReading]
    notes: tuple[str, ...] = ()


def canopen_statement(bus: Mapping[str, Any], node_id: int, timeout: float = 1.0) -> DriveStatement:
    """What CANopen node ``node_id`` on ``bus`` (python-can keyword arguments) states; DriveTimeout if it
    is silent, DriveProtocolError if it is no CiA-402 device."""
    import canopen

    from drives.canopen.link import NetworkLink
    from drives.canopen.scan import device_kind
    from drives.canopen.sdo import SdoAccess
    from drives.canopen.stated_scaling import read_stated_scaling
    from drives.cia301 import DEVICE_PROFILE_402, DEVICE_TYPE
    from drives.cia402 import DataType

    name = f"node {node_id}"
    options = dict(bus)
    link = NetworkLink("profiles new", bus_args=(options.pop("interface", None), options.pop("channel", None),
                                                 options.pop("bitrate", None), options))
    network = link.open()
    try:
        node = network.add_node(canopen.RemoteNode(node_id, canopen.ObjectDictionary()))
        sdo = SdoAccess(name, node, timeout, lambda: None)
        try:
            device_type = sdo.read_int(DEVICE_TYPE, 0, DataType.UNSIGNED32)
        except DriveTimeout:
            raise DriveTimeout(name, f"no answer from node {node_id} within {timeout:g} s "
                                     "(haptic-bus scan lists the nodes on the bus)") from None
        kind = f"0x1000 = 0x{device_type:08X}: {device_kind(device_type)}"
        if device_type & 0xFFFF != DEVICE_PROFILE_402:
            raise DriveProtocolError(name, f"node {node_id} is not a CiA-402 drive ({kind})")
        found, notes = read_stated_scaling(name, sdo, None)
    finally:
        link.close()
    where = f"CANopen node {node_id} on {bus.get('interface', 'the configured bus')} {bus.get('channel', '')}".rstrip()
    return DriveStatement(f"{where} ({kind})", {field: readings[0] for field, readings in found.items()}, notes)


def modbus_statement(url: str, unit_id: int) -> DriveStatement:
    """What the Modbus drive at ``url`` (unit ``unit_id``) states; DriveError if it cannot be read."""
    from drives.modbus.drive import ModbusDrive

    drive = ModbusDrive.from_url(url, unit_id=unit_id)
    try:
        drive.link.open()
        drive.check_map_identity()
        found = drive.stated_scaling()
    finally:
        drive.close()  # never connected: nothing is written
    return DriveStatement(f"Modbus unit {unit_id} at {url}",
                          {field: ScalingReading(value, source) for field, (value, source) in found.items()})
