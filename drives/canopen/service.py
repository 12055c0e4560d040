"""A service tool's two jobs on one CANopen CiA-402 node: read its status, reset its fault.

:func:`read_status` sends SDO upload requests only (no NMT, no SYNC, no write): the CiA-402
state 0x6041, mode 0x6061, error code 0x603F, error register 0x1001, the pre-defined error field
0x1003, position 0x6064, velocity 0x606C and the safety chain's objects (heartbeat consumer
0x1016, RPDO1's deadline 0x1400:05, abort connection option 0x6007), while it listens for the
node's heartbeat (NMT state), its EMCYs and anyone's SYNC for ``listen`` s.  An object the node
lacks is reported absent; a node that lacks 0x1400:05 is recognised by 0x1400:00 (its highest
sub-index) without asking for it.

:func:`reset_fault` listens first (:data:`SYNC_WINDOW`): SYNC frames mean a master is cycling,
whose RPDOs carry the controlword, and the reset is refused; then the controlword sequence of
:func:`drives.fault_reset.reset_drive_fault` over SDO (0x6040 written, 0x6041 read).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from drives.canopen.client import NodeClient
from drives.cia301 import (
    CONSUMER_HEARTBEAT_TIME,
    PDO_EVENT_TIMER,
    PRE_DEFINED_ERROR_FIELD,
    RPDO_COMMUNICATION,
    describe_emcy_code,
    describe_error_register,
)
from drives.cia402 import DataType, ObjectSpec
from drives.drive_status import (
    DEFAULT_ANSWER_TIMEOUT,
    DEFAULT_LISTEN,
    ERROR_REGISTER_OBJECT,
    DriveStatus,
    Reading,
    StatusObject,
    missing_reading,
    read_readings,
)
from drives.errors import DriveError, DriveProtocolError
from drives.fault_reset import DEFAULT_WAIT, FaultResetOutcome, reset_drive_fault

SYNC_WINDOW = 0.1  # s: listened to before a fault reset (a master cycling at 100 ms would still be heard)
ENTRIES_SHOWN = 8  # the newest entries of 0x1003 and the first of 0x1016 that status reads


def _count(index: int, name: str) -> ObjectSpec:
    return ObjectSpec(index, f"{name}: highest sub-index", DataType.UNSIGNED8, "ro")


def _entry(index: int, subindex: int, name: str) -> ObjectSpec:
    return ObjectSpec(index, name, DataType.UNSIGNED32, "ro", subindex=subindex)


RPDO1_DEADLINE = ObjectSpec(RPDO_COMMUNICATION, "RPDO1 event timer", DataType.UNSIGNED16, "rw", "ms", PDO_EVENT_TIMER)


def _entries(client: NodeClient, key: str, label: str, index: int, name: str,
             decode: Callable[[int], dict[str, Any]]) -> tuple[Reading, list[dict[str, Any]]]:
    """An ARRAY's sub 0 as a Reading with its first :data:`ENTRIES_SHOWN` entries decoded."""
    try:
        n = client.read(_count(index, name))
        details = [decode(client.read(_entry(index, sub, name))) for sub in range(1, min(n, ENTRIES_SHOWN) + 1)]
    except DriveProtocolError as exc:
        return missing_reading(key, label, f"0x{index:04X}", exc), []
    return Reading(key, label, f"0x{index:04X}", n, "", None, tuple(details)), details


def _error_history(client: NodeClient) -> Reading:
    """0x1003: the number of errors and the newest ones (sub 1 is the newest, CiA 301 7.5.2.4)."""
    def decode(value: int) -> dict[str, Any]:
        code = value & 0xFFFF
        return {"code": code, "text": describe_emcy_code(code), "manufacturer_info": value >> 16}

    reading, details = _entries(client, "error_history", "error history", PRE_DEFINED_ERROR_FIELD, "Pre-defined error field",
                                decode)
    if reading.missing is None:
        listed = ", ".join(f"0x{d['code']:04X} {d['text']}" for d in details)
        text = f"{reading.value} error(s)" + (f", newest first: {listed}" if listed else "")
        reading = Reading(reading.key, reading.label, reading.source, reading.value, text, None, reading.details)
    return reading


def _heartbeat_consumers(client: NodeClient) -> Reading:
    """0x1016: which nodes' heartbeats the drive watches, and for how long (node id bits 16-23, ms bits 0-15)."""
    def decode(value: int) -> dict[str, Any]:
        return {"node_id": value >> 16 & 0xFF, "time_ms": value & 0xFFFF}

    reading, details = _entries(client, "heartbeat_consumer", "heartbeat consumer", CONSUMER_HEARTBEAT_TIME,
                                "Consumer heartbeat time", decode)
    if reading.missing is None:
        watched = [f"node {d['node_id']} within {d['time_ms']} ms" for d in details if d["time_ms"] and d["node_id"]]
        text = ", ".join(watched) or "no heartbeat watched (every entry 0)"
        reading = Reading(reading.key, reading.label, reading.source, reading.value, text, None, reading.details)
    return reading


def _rpdo_deadline(client: NodeClient) -> Reading:
    """0x1400:05, RPDO1's event timer read as a receive deadline; absent where 0x1400:00 stops short of 5."""
    key, label = "rpdo1_deadline", "RPDO1 deadline"
    try:
        highest = client.read(_count(RPDO_COMMUNICATION, "RPDO1 communication parameter"))
    except DriveProtocolError as exc:
        return missing_reading(key, label, "0x1400:05", exc)
    if highest < PDO_EVENT_TIMER:
        return Reading(key, label, "0x1400:05", None, f"0x1400 has sub-indices 0..{highest} only", "absent")
    reading = StatusObject(key, label, RPDO1_DEADLINE, lambda v: f"{v} ms" if v else "0: off")
    return reading.read(client)


def _emcys(client: NodeClient) -> list[dict[str, Any]]:
    now = client.opened + client.listened()
    return [{"code": emcy.code, "text": describe_emcy_code(emcy.code), "error_register": emcy.register,
             "error_register_text": describe_error_register(emcy.register), "data": bytes(emcy.data).hex(),
             "age_s": round(now - arrived, 4)}
            for emcy, arrived in client.emcys.entries()]


def read_status(bus: Mapping[str, Any], node_id: int, listen: float = DEFAULT_LISTEN,
                timeout: float = DEFAULT_ANSWER_TIMEOUT) -> DriveStatus:
    """Node ``node_id``'s status on ``bus`` (python-can keyword arguments), listening ``listen`` s
    and waiting ``timeout`` s for each SDO answer (module docstring).  DriveTimeout if the node
    does not answer; DriveError if the bus cannot be opened."""
    with NodeClient(bus, node_id, timeout) as client:
        readings = read_readings(client, (ERROR_REGISTER_OBJECT.read, _error_history),
                                 (_heartbeat_consumers, _rpdo_deadline))
        client.listen_until(listen)
        client.check_receive()
        status = DriveStatus(client.name, "canopen", readings, round(client.listened(), 3), client.nmt_state(),
                             client.heartbeats.count(node_id), client.syncs.count, _emcys(client))
        malformed = client.heartbeats.state(node_id)[2]
        if malformed:
            status.notes.append(f"{malformed} frame(s) on its heartbeat COB-ID that are not 1-byte heartbeats")
        if client.emcys.malformed:
            status.notes.append(f"{client.emcys.malformed} frame(s) on its EMCY COB-ID that are not 8-byte EMCYs")
    return status


def reset_fault(bus: Mapping[str, Any], node_id: int, wait: float = DEFAULT_WAIT,
                timeout: float = DEFAULT_ANSWER_TIMEOUT) -> FaultResetOutcome:
    """Reset node ``node_id``'s fault over SDO and wait (``wait`` s) for SWITCH ON DISABLED
    (module docstring); DriveError if a master is cycling, DriveTimeout if the node is silent."""
    with NodeClient(bus, node_id, timeout) as client:
        client.listen_until(SYNC_WINDOW)
        if client.syncs.count:
            raise DriveError(client.name, f"another master is cycling ({client.syncs.count} SYNC frames in "
                                          f"{client.listened() * 1e3:.0f} ms) and its RPDOs carry the controlword: "
                                          "stop it (or let it reset the fault) first")
        outcome = reset_drive_fault(client, wait)
        client.check_receive()
    return outcome
