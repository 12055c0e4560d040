"""Who is on a CANopen bus: a read-only scan for ``haptic-bus scan``.

What goes on the bus: SDO upload requests (reads), nothing else: no NMT command, no SDO
download, no SYNC.  (canopen's SDO client sends an SDO abort 0x05040000 to a node that leaves
a read unanswered, as CiA 301 asks of a client that gives up.)

1. Open the bus and subscribe to the heartbeat COB-IDs 0x701..0x77F (boot-up and heartbeat
   give the NMT state).  canopen's :class:`~canopen.network.NodeScanner` (``network.scanner``)
   notes, from then on, every node id that answers an SDO or sends a heartbeat, a TPDO or an
   EMCY.
2. The probe: one SDO upload request of 0x1000:00 to every node id asked for, all at once
   (what ``NodeScanner.search`` sends, to a chosen set of ids; a full transmit queue is waited
   for instead of failing half-way, see :func:`_send_probe`).
3. Listen until ``timeout`` s after the probe: answers, boot-ups, heartbeats (a heartbeat
   period longer than ``timeout`` may go unheard: ``nmt_state`` is then None).
4. From every node seen, read 0x1000, 0x1018:01..04 and, for a CiA-402 device, 0x6502, the
   statusword 0x6041 (its CiA-402 state) and the error code 0x603F, each read bounded by
   ``answer_timeout`` s; the nodes are read in parallel, and a node that lets one read time out
   is not asked again.

Total time: at most ``timeout + 8 * answer_timeout`` s plus opening and closing the bus.

Device type 0x1000 (CiA 301 7.5.2.1): bits 0..15 the device profile number (402 = drives and
motion control), bits 16..23 the profile's type (CiA 402: 1 frequency converter, 2 servo
drive, 3 stepper motor), bits 24..31 mode bits.  0x6502 bit ``mode - 1`` announces mode
``mode`` (bit 9: cyclic synchronous torque), see :func:`drives.cia402.cst_announced`.  0x6502,
0x6041 and 0x603F are read only where 0x1000 names profile 402: in another profile they are
not those objects.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, ClassVar

import can
import canopen
from canopen.sdo.constants import REQUEST_UPLOAD

from drives.canopen.link import NetworkLink
from drives.canopen.listen import HeartbeatLog
from drives.canopen.sdo import SdoAccess
from drives.cia301 import (
    DEVICE_PROFILE_402,
    DEVICE_TYPE,
    HEARTBEAT_BASE,
    IDENTITY,
    NODE_ID_RANGE,
    NODE_IDS,
    SDO_RX_BASE,
)
from drives.cia402 import ERROR_CODE, STATUSWORD, SUPPORTED_DRIVE_MODES, DataType
from drives.errors import DriveError, DriveRefusal, DriveTimeout
from drives.scan_arguments import DEFAULT_ANSWER_TIMEOUT, DEFAULT_TIMEOUT, checked_ids, checked_seconds
from drives.scanned_device import ScannedDevice

__all__ = ["CanopenNode", "Identity", "device_kind", "scan_canopen"]

SEND_RETRY = 0.001  # s: wait before sending again into a full transmit queue
_PROBE = struct.pack("<BHB4x", REQUEST_UPLOAD, DEVICE_TYPE, 0)  # SDO upload request of 0x1000:00
_DEVICE_KINDS_402 = {1: "frequency converter", 2: "servo drive", 3: "stepper motor"}
_IDENTITY_FIELDS = ("vendor_id", "product_code", "revision", "serial")


@dataclass(frozen=True)
class Identity:
    """Object 0x1018: sub 1 vendor-ID, 2 product code, 3 revision number, 4 serial number (None: not read)."""

    vendor_id: int | None = None
    product_code: int | None = None
    revision: int | None = None
    serial: int | None = None


@dataclass(frozen=True)
class CanopenNode(ScannedDevice):
    """One node found by :func:`scan_canopen`; None where a value could not be read (see ``notes``)."""

    protocol: ClassVar[str] = "canopen"

    node_id: int
    device_type: int | None
    identity: Identity
    nmt_state: str | None  # from the last boot-up or heartbeat heard; None: none heard
    boot_up_seen: bool
    supported_drive_modes: int | None  # 0x6502, read only from a CiA-402 device
    notes: tuple[str, ...] = ()
    statusword: int | None = None  # 0x6041, CiA-402 devices only
    error_code: int | None = None  # 0x603F, CiA-402 devices only

    @property
    def device_profile(self) -> int | None:
        """The device profile number, bits 0..15 of 0x1000 (402: a CiA-402 drive; 0: none)."""
        return None if self.device_type is None else self.device_type & 0xFFFF

    @property
    def cia402(self) -> bool:
        """True if 0x1000 names the CiA-402 profile."""
        return self.device_profile == DEVICE_PROFILE_402

    def identity_dict(self) -> dict[str, Any]:
        """The node id, 0x1000 (also in words), 0x1018 and the NMT state heard."""
        return {
            "node_id": self.node_id,
            "device_type": self.device_type,
            "device_profile": self.device_profile,
            "device_kind": None if self.device_type is None else device_kind(self.device_type),
            **{field: getattr(self.identity, field) for field in _IDENTITY_FIELDS},
            "nmt_state": self.nmt_state,
            "boot_up_seen": self.boot_up_seen,
        }


def device_kind(device_type: int) -> str:
    """What 0x1000 says in words: ``"CiA-402 servo drive"``, ``"no device profile"``, ``"CiA-401 (type 0x02)"``."""
    profile, kind = device_type & 0xFFFF, device_type >> 16 & 0xFF
    if profile == 0:
        return "no device profile"
    if profile == DEVICE_PROFILE_402 and kind in _DEVICE_KINDS_402:
        return f"CiA-402 {_DEVICE_KINDS_402[kind]}"
    return f"CiA-{profile} (type 0x{kind:02X})"


def _send_probe(network: canopen.Network, node_ids: list[int], deadline: float) -> None:
    """The 0x1000 upload request to every id, back to back.  A transmit queue that is full (SocketCAN's
    default ``txqueuelen`` of 10 on ``can0``: ENOBUFS) is waited for, up to ``deadline``."""
    for node_id in node_ids:
        while True:
            try:
                network.send_message(SDO_RX_BASE + node_id, _PROBE)
                break
            except can.CanError as exc:
                if time.monotonic() >= deadline:
                    raise DriveError("scan", f"cannot send the probe to node {node_id}: {exc}") from exc
                time.sleep(SEND_RETRY)


def _read_details(node_id: int, sdo: SdoAccess, heartbeats: HeartbeatLog) -> CanopenNode:
    """0x1000, 0x1018:01..04 and (CiA-402 only) 0x6502, 0x6041, 0x603F of node ``node_id``; stops at its
    first timeout."""
    values: dict[tuple[int, int], int | None] = {}
    notes: list[str] = []
    reads = [(DEVICE_TYPE, 0), *((IDENTITY, sub) for sub in range(1, 5))]
    try:
        for index, subindex in reads:
            values[index, subindex] = _read_optional(sdo, index, subindex, notes)
        device_type = values[DEVICE_TYPE, 0]
        if device_type is not None and device_type & 0xFFFF == DEVICE_PROFILE_402:
            for spec in (SUPPORTED_DRIVE_MODES, STATUSWORD, ERROR_CODE):
                values[spec.index, 0] = _read_optional(sdo, spec.index, 0, notes, spec.data_type)
    except DriveTimeout as exc:
        notes.append(f"{exc.message}; not asked again")
    except DriveError as exc:  # a malformed answer: the node is there, its answer unusable
        notes.append(exc.message)
    state, booted, malformed = heartbeats.state(node_id)
    if malformed:
        notes.append(f"{malformed} frame(s) on COB-ID 0x{HEARTBEAT_BASE + node_id:03X} that are not 1-byte heartbeats")
    identity = Identity(*(values.get((IDENTITY, sub)) for sub in range(1, 5)))
    return CanopenNode(node_id, values.get((DEVICE_TYPE, 0)), identity, state, booted,
                       values.get((SUPPORTED_DRIVE_MODES.index, 0)), tuple(notes),
                       values.get((STATUSWORD.index, 0)), values.get((ERROR_CODE.index, 0)))


def _read_optional(sdo: SdoAccess, index: int, subindex: int, notes: list[str],
                   data_type: DataType = DataType.UNSIGNED32) -> int | None:
    """An integer object of ``data_type``, or None (and a note) if the node aborts the read."""
    try:
        return sdo.read_int(index, subindex, data_type)
    except DriveRefusal as exc:
        notes.append(exc.message)
        return None


def scan_canopen(
    bus: Mapping[str, Any],
    node_ids: Iterable[int] = range(NODE_ID_RANGE[0], NODE_ID_RANGE[1] + 1),
    timeout: float = DEFAULT_TIMEOUT,
    answer_timeout: float = DEFAULT_ANSWER_TIMEOUT,
) -> list[CanopenNode]:
    """The nodes among ``node_ids`` on the CAN bus ``bus`` (python-can keyword arguments:
    ``interface``, ``channel``, ``bitrate``, ...; missing ones from python-can's configuration),
    by node id.  ``timeout``: the listening window after the probe, s; ``answer_timeout``: each
    SDO read of the details, s (module docstring).  ParameterError for bad arguments (before the
    bus is opened), DriveError if the bus cannot be opened or the scan fails."""
    ids = checked_ids("node ids", node_ids, NODE_IDS, *NODE_ID_RANGE)
    window = checked_seconds("timeout", timeout)
    answer = checked_seconds("answer timeout", answer_timeout)
    options = dict(bus)
    link = NetworkLink("scan", bus_args=(options.pop("interface", None), options.pop("channel", None),
                                         options.pop("bitrate", None), options))
    network = link.open()
    try:
        heartbeats = HeartbeatLog()
        for node_id in range(NODE_ID_RANGE[0], NODE_ID_RANGE[1] + 1):
            network.subscribe(HEARTBEAT_BASE + node_id, heartbeats.on_heartbeat)
        end = time.monotonic() + window
        _send_probe(network, ids, end)
        time.sleep(max(0.0, end - time.monotonic()))
        seen = sorted((set(network.scanner.nodes) | heartbeats.heard()) & set(ids))
        accesses = {}
        for node_id in seen:
            node = network.add_node(canopen.RemoteNode(node_id, canopen.ObjectDictionary()))
            accesses[node_id] = SdoAccess(f"node {node_id}", node, answer, lambda: None)
        with ThreadPoolExecutor(max_workers=max(1, len(accesses)), thread_name_prefix="scan") as pool:
            futures = [pool.submit(_read_details, node_id, sdo, heartbeats) for node_id, sdo in accesses.items()]
            found = [future.result() for future in futures]
        failure = link.receive_failure()
        if failure is not None:
            raise DriveError("scan", f"CAN receive failed during the scan, answers may be missing: {failure!r}")
        return found
    except (can.CanError, OSError) as exc:
        raise DriveError("scan", f"the CAN bus failed: {exc}") from exc
    finally:
        link.close()
