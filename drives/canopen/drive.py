"""CiA-402 master over CANopen: one servo drive in cyclic synchronous mode.

Built on ``canopen`` (NMT, SDO, object dictionaries) and ``python-can`` (any interface).
The master is the SYNC producer.  One cycle is::

    read_inputs()          SYNC  ->  drive samples, sends TPDO1 (statusword, velocity[, position])
    write_outputs(torque)  RPDO1 (controlword, target torque)  ->  applied at the next SYNC

The cyclic path does not use canopen's generic PDO objects (they update variables one by
one from a shared buffer, are not atomic per frame, and accept frames of any length).  It
packs and unpacks whole frames with precompiled ``struct`` codecs (:mod:`drives.canopen.pdo_codec`),
reuses its two outgoing ``can.Message`` objects, and never sleeps.  Two receive strategies:

``rx_mode="direct"`` (default)
    while cycling, the master reads the bus itself in the calling thread (canopen's notifier
    thread is paused; frames other than the TPDO are handed to canopen's dispatcher, so SDO,
    heartbeat and EMCY consumers keep working).  No thread hand-off per cycle.
``rx_mode="listener"``
    canopen's notifier thread keeps reading; the TPDO is handed over through a queue.

Safety: a missing TPDO for ``max_missed_tpdos`` consecutive cycles, a heartbeat loss, an
EMCY, a fault bit, or the node leaving NMT OPERATIONAL make the master send zero torque
with the safe controlword (DISABLE VOLTAGE) plus one SYNC so that it is applied, *then*
raise.  Until :meth:`CanopenDrive.fault_reset` or :meth:`CanopenDrive.enable`, every
``write_outputs`` sends that safe frame instead of the caller's torque.
"""

from __future__ import annotations

import logging
import queue
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import can
import canopen
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from drives.base import CyclicInputs, DriveError, DriveFault, DriveProtocolError, DriveScaling, DriveTimeout
from drives.bus_config import open_bus
from drives.canopen.od import default_eds_path, find_scaling_objects, load_object_dictionary, object_name
from drives.cia402 import (
    CONTROLWORD,
    MAX_TORQUE,
    MOTOR_RATED_TORQUE,
    POSITION_ACTUAL,
    STATUSWORD,
    TARGET_TORQUE,
    VELOCITY_ACTUAL,
    Command,
    DataType,
    ObjectSpec,
    OperationMode,
    State,
    decode_statusword,
)
from drives.cia402_master import SAFE_CONTROLWORD, Cia402Master, DriveStateError, UnsupportedModeError, state_name
from drives.emcy import EmcyMessage, decode_emcy
from drives.canopen.pdo_codec import MAX_PDO_BYTES, PdoCodec, object_spec

logger = logging.getLogger(__name__)

__all__ = [
    "CanopenDrive",
    "DriveStats",
    "UnsupportedModeError",
    "DriveStateError",
    "DEFAULT_TPDO",
    "DEFAULT_TPDO_WITH_POSITION",
    "DEFAULT_RPDO",
    "SAFE_CONTROLWORD",
    "split_into_frames",
]

DEFAULT_TPDO: tuple[ObjectSpec, ...] = (STATUSWORD, VELOCITY_ACTUAL)
DEFAULT_TPDO_WITH_POSITION: tuple[ObjectSpec, ...] = (STATUSWORD, VELOCITY_ACTUAL, POSITION_ACTUAL)
DEFAULT_RPDO: tuple[ObjectSpec, ...] = (CONTROLWORD, TARGET_TORQUE)


SYNC_COB_ID = 0x080
NMT_START, NMT_PRE_OPERATIONAL, NMT_RESET_COMMUNICATION = 0x01, 0x80, 0x82
NMT_OPERATIONAL_STATE, NMT_BOOTUP_STATE = 0x05, 0x00
_NMT_STATE_NAMES = {0x00: "BOOT-UP", 0x04: "STOPPED", 0x05: "OPERATIONAL", 0x7F: "PRE-OPERATIONAL"}
PDO_COB_INVALID = 1 << 31
SW_FAULT = 1 << 3
DEVICE_PROFILE_402 = 402

_USE_DEFAULT_EDS = object()

_EXPECTED_AFTER: dict[Command, State] = {
    Command.SHUTDOWN: State.READY_TO_SWITCH_ON,
    Command.SWITCH_ON: State.SWITCHED_ON,
    Command.ENABLE_OPERATION: State.OPERATION_ENABLED,
    Command.DISABLE_VOLTAGE: State.SWITCH_ON_DISABLED,
    Command.FAULT_RESET: State.SWITCH_ON_DISABLED,
}


@dataclass(slots=True)
class DriveStats:
    """Counters of the cyclic exchange (all since connect)."""

    cycles: int = 0  # completed read_inputs (a TPDO received and decoded)
    syncs_sent: int = 0
    rpdos_sent: int = 0
    dropped_frames: int = 0  # TPDO frames of the wrong length, never decoded
    missed_tpdos: int = 0  # cycles whose TPDO did not arrive in tpdo_timeout
    stale_tpdos: int = 0  # TPDOs that arrived after their cycle had timed out
    emcy_count: int = 0
    heartbeats: int = 0
    saturated_outputs: int = 0  # torques clamped to +-0x6072
    suppressed_outputs: int = 0  # write_outputs replaced by the safe frame while tripped
    safe_stops: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def split_into_frames(objects: Sequence[ObjectSpec | int]) -> list[tuple[ObjectSpec, ...]]:
    """Pack ``objects`` in order into as few CAN frames (<= 8 bytes each) as that order allows."""
    frames: list[list[ObjectSpec]] = []
    used = MAX_PDO_BYTES
    for obj in objects:
        spec = object_spec(obj)
        if used + spec.data_type.size > MAX_PDO_BYTES:
            frames.append([])
            used = 0
        frames[-1].append(spec)
        used += spec.data_type.size
    return [tuple(frame) for frame in frames]


def _pack(spec_type: DataType, value: int) -> bytes:
    return struct.pack("<" + spec_type.struct_format, value)


class CanopenDrive(Cia402Master):
    """A CiA-402 servo drive on CANopen, driven in cyclic synchronous torque mode.

    Bus, one of: ``network`` (a :class:`canopen.Network`, connected or not), ``bus`` (a
    :class:`can.BusABC`), or ``interface``/``channel``/``bitrate``/``bus_kwargs`` with
    python-can's configuration chain filling the gaps (env ``CAN_INTERFACE`` ..., ``~/.canrc``).
    The drive shuts down only a bus it opened itself.  With ``rx_mode="direct"`` on a shared
    ``network``, the network's notifier is paused while this drive cycles (other nodes' frames
    are still dispatched, from the cycling thread) and restarted for SDO and on close().

    ``period`` (s) is the cycle time written to 0x1006.  ``tpdo_objects`` are the objects the
    drive sends each cycle, in order, packed into TPDO1.. (8 bytes each; must hold 0x6041 and
    0x606C; with 0x6064, :data:`DEFAULT_TPDO_WITH_POSITION`, position travels in TPDO2).
    RPDO1 is 0x6040 + 0x6071.  All are transmission type 1 (every SYNC); unused PDOs are
    invalidated.  ``rx_mode``: see the module docstring.  Timeouts in s; ``max_missed_tpdos``
    consecutive cycles without TPDO raise DriveTimeout; heartbeat times in ms (consumer
    default 3x producer; 0 disables).
    ``scaling``: the caller's :class:`DriveScaling`; connect() replaces ``rated_torque`` and
    ``max_torque_permille`` by 0x6076/0x6072, and the other fields by manufacturer scaling
    objects the EDS names (:func:`drives.canopen.od.find_scaling_objects`); a field neither
    the drive nor the caller gives makes connect() fail naming it.
    """

    def __init__(
        self,
        node_id: int,
        *,
        interface: str | None = None,
        channel: Any = None,
        bitrate: int | None = None,
        bus: can.BusABC | None = None,
        network: canopen.Network | None = None,
        bus_kwargs: dict[str, Any] | None = None,
        eds: Any = _USE_DEFAULT_EDS,
        period: float = 0.001,
        tpdo_objects: Sequence[ObjectSpec | int] = DEFAULT_TPDO,
        scaling: DriveScaling | None = None,
        rx_mode: str = "direct",
        sdo_timeout: float = 0.3,
        boot_timeout: float = 1.0,
        state_timeout: float = 1.0,
        tpdo_timeout: float = 0.05,
        max_missed_tpdos: int = 3,
        heartbeat_producer_ms: int = 100,
        heartbeat_consumer_ms: int | None = None,
        reset_communication: bool = True,
        check_device_type: bool = True,
    ) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"node_id = {node_id!r} is invalid; allowed: 1..127")
        if not 1e-6 <= period <= 4294.967295:
            raise ValueError(f"period = {period!r} s is invalid; allowed: 1e-6..4294.967295 s (0x1006 in us)")
        if rx_mode not in ("direct", "listener"):
            raise ValueError(f"rx_mode = {rx_mode!r} is invalid; allowed: 'direct', 'listener'")
        if max_missed_tpdos < 1:
            raise ValueError(f"max_missed_tpdos = {max_missed_tpdos!r} is invalid; allowed: >= 1")
        if tpdo_timeout <= 0:
            raise ValueError(f"tpdo_timeout = {tpdo_timeout!r} s is invalid; allowed: > 0")
        if not 0 <= heartbeat_producer_ms <= 0xFFFF:
            raise ValueError(f"heartbeat_producer_ms = {heartbeat_producer_ms!r} is invalid; allowed: 0..65535")
        if heartbeat_consumer_ms is not None and heartbeat_consumer_ms < 0:
            raise ValueError(f"heartbeat_consumer_ms = {heartbeat_consumer_ms!r} is invalid; allowed: >= 0 (0 disables)")
        self.node_id = node_id
        self.name = f"CANopen node {node_id}"
        self.period = period
        self.rx_mode = rx_mode
        self.sdo_timeout = sdo_timeout
        self.boot_timeout = boot_timeout
        self.state_timeout = state_timeout
        self.max_commands_per_step = max(100, int(4 * state_timeout / max(period, 1e-4)))
        self.tpdo_timeout = tpdo_timeout
        self.max_missed_tpdos = max_missed_tpdos
        self.heartbeat_producer_ms = heartbeat_producer_ms
        if heartbeat_consumer_ms is None:
            heartbeat_consumer_ms = 3 * heartbeat_producer_ms
        self.heartbeat_consumer_ms = heartbeat_consumer_ms
        self.reset_communication = reset_communication
        self.check_device_type = check_device_type

        frames = split_into_frames(tpdo_objects)
        if not 1 <= len(frames) <= 4:
            raise ValueError(f"tpdo_objects need {len(frames)} TPDOs; a drive has at most 4 (1..32 bytes in total)")
        self.tpdo_codecs: tuple[PdoCodec, ...] = tuple(
            PdoCodec(frame, name=f"TPDO{n} of node {node_id}") for n, frame in enumerate(frames, start=1)
        )
        self.rpdo_codec = PdoCodec(DEFAULT_RPDO, name=f"RPDO1 of node {node_id}")
        flat = [(spec.index, spec.subindex) for codec in self.tpdo_codecs for spec in codec.entries]
        for required in (STATUSWORD, VELOCITY_ACTUAL):
            if (required.index, 0) not in flat:
                raise ValueError(f"tpdo_objects must contain 0x{required.index:04X} ({required.name})")
        self._sw_at = flat.index((STATUSWORD.index, 0))
        self._vel_at = flat.index((VELOCITY_ACTUAL.index, 0))
        self._pos_at: int | None = flat.index((POSITION_ACTUAL.index, 0)) if (POSITION_ACTUAL.index, 0) in flat else None

        if eds is _USE_DEFAULT_EDS:
            eds = default_eds_path()
        self.eds = eds
        self._given_scaling = scaling
        self.scaling = scaling  # complete after connect(); see _read_scaling

        self._given_network = network
        self._given_bus = bus
        self._bus_args = (interface, channel, bitrate, dict(bus_kwargs or {}))
        self._owns_bus = network is None and bus is None
        self.network: canopen.Network | None = None
        self.node: canopen.RemoteNode | None = None
        self._bus: can.BusABC | None = None

        self.stats = DriveStats()
        self.scaling_sources: dict[str, str] = {}
        self.device_type: int | None = None
        self.last_emcy: EmcyMessage | None = None
        self.emcy_log: list[EmcyMessage] = []
        self.last_inputs: CyclicInputs | None = None
        self.nmt_state: int | None = None

        rpdo_cob = 0x200 + node_id
        self._rpdo_cob = rpdo_cob
        self._set_tpdo_cobs([0x180 + 0x100 * n + node_id for n in range(len(self.tpdo_codecs))])
        self._rpdo_pack_into = self.rpdo_codec.struct.pack_into
        self._sync_msg = can.Message(arbitration_id=SYNC_COB_ID, data=b"", is_extended_id=False)
        self._rpdo_msg = can.Message(arbitration_id=rpdo_cob, data=bytes(self.rpdo_codec.size), is_extended_id=False)
        self._safe_msg = can.Message(
            arbitration_id=rpdo_cob, data=self.rpdo_codec.encode(SAFE_CONTROLWORD, 0), is_extended_id=False
        )
        self._torque_limit = 0x7FFF
        self._controlword = SAFE_CONTROLWORD

        self._send_lock = threading.Lock()
        self._rx_queue: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self._cycling = False  # direct mode: notifier paused, we read the bus
        self._connected = False
        self._closed = False
        self._armed = False  # OPERATION ENABLED reached: fault bit raises
        self._tripped: DriveError | None = None
        self._missed_in_row = 0
        self._pending_emcy: EmcyMessage | None = None
        self._pending_nmt: int | None = None
        self._last_heartbeat: float | None = None
        self._heartbeat_limit = heartbeat_consumer_ms / 1000.0
        self._booted = threading.Event()
        self._heartbeat_seen = threading.Event()

    # ------------------------------------------------------------------ connection

    def connect(self) -> None:
        """Reach the drive and configure it (NMT, SDO, PDO mapping, 0x1006, heartbeat); raise DriveTimeout."""
        if self._closed:
            raise DriveError(self.name, "the drive object is closed; create a new one")
        if self._connected:
            return
        self._open_network()
        try:
            self._configure()
        except BaseException:
            self._teardown(reachable=False)
            raise
        self._connected = True

    def _open_network(self) -> None:
        try:
            dictionary = load_object_dictionary(self.eds, self.node_id)
        except (OSError, ValueError, KeyError) as exc:
            raise DriveProtocolError(self.name, f"cannot load the object dictionary {self.eds!r}: {exc}") from exc
        if self._given_network is not None:
            network = self._given_network
        else:
            bus = self._given_bus
            if bus is None:
                interface, channel, bitrate, kwargs = self._bus_args
                bus = open_bus(interface, channel, bitrate, **kwargs)
            network = canopen.Network(bus)
        # A short notifier cycle so that pausing it (rx_mode="direct") is quick.
        network.NOTIFIER_CYCLE = 0.02
        if network.notifier is None or network.notifier.stopped:
            network.connect()
        self.network = network
        self._bus = network.bus
        self._send_lock = network.send_lock  # shared with canopen's own sends (SDO, NMT)
        node = canopen.RemoteNode(self.node_id, dictionary)
        node.sdo.RESPONSE_TIMEOUT = self.sdo_timeout
        network.add_node(node)
        self.node = node
        network.subscribe(0x700 + self.node_id, self._on_heartbeat)
        network.subscribe(0x080 + self.node_id, self._on_emcy)

    def _configure(self) -> None:
        self._nmt_reach()
        if self.check_device_type:
            self.device_type = self._sdo_read_int(0x1000, 0, DataType.UNSIGNED32)
            if self.device_type & 0xFFFF != DEVICE_PROFILE_402:
                raise DriveProtocolError(
                    self.name,
                    f"0x1000 device type = 0x{self.device_type:08X} is not a CiA-402 drive "
                    f"(profile {self.device_type & 0xFFFF}, expected {DEVICE_PROFILE_402})",
                )
        period_us = round(self.period * 1e6)
        self._sdo_write_int(0x1006, 0, DataType.UNSIGNED32, period_us)
        cobs = [self._map_pdo(0x1800 + n, 0x1A00 + n, cob, codec)
                for n, (cob, codec) in enumerate(zip(self._tpdo_cobs, self.tpdo_codecs))]
        self._set_tpdo_cobs(cobs)
        self._rpdo_cob = self._map_pdo(0x1400, 0x1600, self._rpdo_cob, self.rpdo_codec)
        self._rpdo_msg.arbitration_id = self._safe_msg.arbitration_id = self._rpdo_cob
        if self.rx_mode == "listener":
            for cob in self._tpdo_cobs:
                self.network.subscribe(cob, self._on_tpdo)
        for n in range(len(self.tpdo_codecs), 4):
            self._disable_pdo(0x1800 + n)
        for n in range(1, 4):
            self._disable_pdo(0x1400 + n)
        self._read_scaling()
        self._sdo_write_int(0x1017, 0, DataType.UNSIGNED16, self.heartbeat_producer_ms)
        self._heartbeat_seen.clear()
        self.node.nmt.send_command(NMT_START)
        if self.heartbeat_producer_ms:
            limit = max(self.boot_timeout, 2 * self._heartbeat_limit)
            deadline = time.monotonic() + limit
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or not self._heartbeat_seen.wait(remaining):
                    raise DriveTimeout(
                        self.name,
                        f"no heartbeat showing OPERATIONAL within {limit:.3g} s after NMT start "
                        f"(0x1017 = {self.heartbeat_producer_ms} ms)",
                    )
                self._heartbeat_seen.clear()
                if self.nmt_state == NMT_OPERATIONAL_STATE:
                    break
        self._pending_nmt = None

    def _nmt_reach(self) -> None:
        """Reset communication and wait for the boot-up message, or for an SDO answer."""
        self._booted.clear()
        how = "NMT reset communication"
        if self.reset_communication:
            self.node.nmt.send_command(NMT_RESET_COMMUNICATION)
            if self._booted.wait(self.boot_timeout):
                return
        else:
            how = "NMT pre-operational"
            self.node.nmt.send_command(NMT_PRE_OPERATIONAL)
        # No boot-up (a drive may not reset communication on command): does it answer SDO?
        sdo = self.node.sdo
        saved = sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES
        sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = self.boot_timeout, 1
        try:
            sdo.upload(0x1000, 0)
            return
        except SdoAbortedError:
            return  # it answered
        except SdoCommunicationError:
            pass
        finally:
            sdo.RESPONSE_TIMEOUT, sdo.MAX_RETRIES = saved
        seen = sorted(n for n in self.network.scanner.nodes if n != self.node_id)
        hint = f"; nodes seen on the bus: {', '.join(map(str, seen))}" if seen else "; no other node seen on the bus"
        raise DriveTimeout(
            self.name,
            f"no boot-up after {how} and no SDO answer within {self.boot_timeout:.3g} s "
            f"(check node id {self.node_id}, bitrate, wiring{hint})",
        )

    def _set_tpdo_cobs(self, cobs: list[int]) -> None:
        self._tpdo_cobs = tuple(cobs)
        self._tpdo_cob = cobs[0]
        self._tpdo_size = self.tpdo_codecs[0].size
        self._tpdo_unpack = self.tpdo_codecs[0].struct.unpack
        self._multi_tpdo = len(cobs) > 1
        self._tpdo_slots = {cob: (slot, codec.size, codec.struct.unpack)
                            for slot, (cob, codec) in enumerate(zip(cobs, self.tpdo_codecs))}

    def _map_pdo(self, com: int, mapping: int, cob_id: int, codec: PdoCodec) -> int:
        """Remap one PDO over SDO (invalidate, transmission type 1, mapping, validate); its COB-ID."""
        current = self._sdo_read_int(com, 1, DataType.UNSIGNED32)
        keep = current & 0x7FFFFFFF if current & 0x7FF else cob_id
        if keep & 0x7FF != cob_id:
            logger.info("%s: 0x%04X uses COB-ID 0x%X, not the predefined 0x%X", self.name, com, keep & 0x7FF, cob_id)
        self._sdo_write_int(com, 1, DataType.UNSIGNED32, keep | PDO_COB_INVALID)
        self._sdo_write_int(com, 2, DataType.UNSIGNED8, 1)  # synchronous, every SYNC
        self._sdo_write_int(mapping, 0, DataType.UNSIGNED8, 0)
        for sub, word in enumerate(codec.mapping_words, start=1):
            self._sdo_write_int(mapping, sub, DataType.UNSIGNED32, word)
        self._sdo_write_int(mapping, 0, DataType.UNSIGNED8, len(codec.mapping_words))
        self._sdo_write_int(com, 1, DataType.UNSIGNED32, keep & ~PDO_COB_INVALID)
        count = self._sdo_read_int(mapping, 0, DataType.UNSIGNED8)
        if count != len(codec.mapping_words):
            raise DriveProtocolError(
                self.name, f"0x{mapping:04X}:00 reads back {count} mapped objects after writing {len(codec.mapping_words)}"
            )
        return keep & 0x7FF

    def _disable_pdo(self, com: int) -> None:
        """Invalidate an unused PDO so that only the configured frames travel (absent PDOs are fine)."""
        try:
            current = self._sdo_read_int(com, 1, DataType.UNSIGNED32)
            if not current & PDO_COB_INVALID:
                self._sdo_write_int(com, 1, DataType.UNSIGNED32, current | PDO_COB_INVALID)
        except DriveProtocolError as exc:
            if getattr(exc, "abort_code", None) in (0x06020000, 0x06090011):
                return
            raise

    def _read_scaling(self) -> None:
        """Scaling from the drive: 0x6076, 0x6072, and manufacturer scaling objects named in the EDS.

        What the drive does not have stays as the caller gave it.
        """
        given = self._given_scaling
        names = ("velocity_per_count", "position_per_count", "rated_torque", "force_per_torque", "max_torque_permille")
        values: dict[str, Any] = {name: getattr(given, name) for name in names} if given is not None else {}
        self.scaling_sources = dict.fromkeys(values, "caller")
        try:
            values["rated_torque"] = self.read_object(MOTOR_RATED_TORQUE) / 1000.0  # mN m -> N m
            self.scaling_sources["rated_torque"] = "0x6076"
        except DriveProtocolError as exc:
            logger.info("%s: keeping the given rated torque (%s)", self.name, exc)
        try:
            values["max_torque_permille"] = self.read_object(MAX_TORQUE)
            self.scaling_sources["max_torque_permille"] = "0x6072"
        except DriveProtocolError as exc:
            logger.info("%s: keeping the given max torque (%s)", self.name, exc)
        for field_name, (index, subindex, fmt) in find_scaling_objects(self._od).items():
            data = self.sdo_read(index, subindex)
            if len(data) != struct.calcsize(fmt):
                raise DriveProtocolError(
                    self.name, f"0x{index:04X}:{subindex:02X} ({field_name}) answered {len(data)} bytes, expected {struct.calcsize(fmt)}"
                )
            values[field_name] = struct.unpack(fmt, data)[0]
            self.scaling_sources[field_name] = f"0x{index:04X}:{subindex:02X}"
        missing = [name for name in names if name not in values]
        if missing:
            raise DriveProtocolError(
                self.name,
                f"scaling unknown for {', '.join(missing)}: the drive has no such objects "
                f"(0x6076, 0x6072, manufacturer scaling in the EDS); pass scaling=DriveScaling(...)",
            )
        for field_name in names[:4]:
            value = values[field_name]
            if not value > 0 or value == float("inf"):
                raise DriveProtocolError(
                    self.name, f"scaling {field_name} = {value!r} (from {self.scaling_sources[field_name]}); must be finite and > 0"
                )
        self.scaling = DriveScaling(**values)
        self._torque_limit = min(values["max_torque_permille"], 0x7FFF)

    # ------------------------------------------------------------------ SDO helpers

    def _sdo_call(self, what: str, index: int, subindex: int, func, *args):
        self._ensure_notifier()
        try:
            return func(index, subindex, *args)
        except SdoAbortedError as exc:
            text = SdoAbortedError.CODES.get(exc.code, "unknown abort code")
            error = DriveProtocolError(
                self.name,
                f"SDO abort {what} 0x{index:04X}:{subindex:02X} ({object_name(self._od, index, subindex)}): "
                f"0x{exc.code:08X} {text}",
            )
            error.abort_code = exc.code
            error.index, error.subindex = index, subindex
            raise error from exc
        except SdoCommunicationError as exc:
            raise DriveTimeout(
                self.name,
                f"no SDO answer {what} 0x{index:04X}:{subindex:02X} ({object_name(self._od, index, subindex)}) "
                f"within {self.sdo_timeout:.3g} s: {exc}",
            ) from exc

    @property
    def _od(self):
        return self.node.object_dictionary if self.node is not None else None

    def sdo_read(self, index: int, subindex: int = 0) -> bytes:
        """Upload ``index:subindex`` (raw bytes); DriveProtocolError on abort, DriveTimeout on silence."""
        return self._sdo_call("reading", index, subindex, self.node.sdo.upload)

    def sdo_write(self, index: int, subindex: int, data: bytes) -> None:
        """Download raw ``data`` to ``index:subindex``; DriveProtocolError on abort, DriveTimeout on silence."""
        self._sdo_call("writing", index, subindex, self.node.sdo.download, bytes(data))

    def _sdo_read_int(self, index: int, subindex: int, data_type: DataType) -> int:
        data = self.sdo_read(index, subindex)
        if len(data) < data_type.size:
            raise DriveProtocolError(
                self.name, f"0x{index:04X}:{subindex:02X} answered {len(data)} bytes, {data_type.name} needs {data_type.size}"
            )
        return struct.unpack_from("<" + data_type.struct_format, data)[0]

    def _sdo_write_int(self, index: int, subindex: int, data_type: DataType, value: int) -> None:
        self.sdo_write(index, subindex, _pack(data_type, value))

    def read_object(self, spec: ObjectSpec | int) -> int:
        """Read a CiA-402 object (ObjectSpec or index of drives.cia402) over SDO, in drive units."""
        spec = object_spec(spec)
        return self._sdo_read_int(spec.index, spec.subindex, spec.data_type)

    def write_object(self, spec: ObjectSpec | int, value: int) -> None:
        """Write a CiA-402 object (ObjectSpec or index of drives.cia402) over SDO, in drive units."""
        spec = object_spec(spec)
        low, high = spec.data_type.range
        if not low <= value <= high:
            raise ValueError(f"0x{spec.index:04X} ({spec.name}) = {value} outside {spec.data_type.name} [{low}, {high}]")
        self._sdo_write_int(spec.index, spec.subindex, spec.data_type, value)

    # ------------------------------------------------------------------ receive plumbing

    def _ensure_notifier(self) -> None:
        """Make sure canopen's notifier reads the bus (SDO needs it); ends a direct-mode cyclic phase."""
        if self._cycling:
            self._cycling = False
            self.network.notifier = can.Notifier(self._bus, self.network.listeners, self.network.NOTIFIER_CYCLE)

    def _begin_cyclic(self) -> None:
        """Direct mode: pause canopen's notifier so that the calling thread reads the bus itself."""
        if self.rx_mode == "direct" and not self._cycling:
            notifier = self.network.notifier
            if notifier is not None and not notifier.stopped:
                notifier.stop(timeout=5.0)
                if notifier.exception is not None:
                    raise DriveError(self.name, f"CAN receive thread failed: {notifier.exception}")
            self._cycling = True

    def _on_tpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        self._rx_queue.put((can_id, bytes(data)))

    def _on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if not data:
            return
        state = data[0] & 0x7F
        self._last_heartbeat = time.monotonic()
        self.stats.heartbeats += 1
        self.nmt_state = state
        if state == NMT_BOOTUP_STATE:
            self._booted.set()
        if self._armed and state != NMT_OPERATIONAL_STATE:
            self._pending_nmt = state
        self._heartbeat_seen.set()

    def _on_emcy(self, can_id: int, data: bytearray, timestamp: float) -> None:
        emcy = decode_emcy(data, time.monotonic())
        if emcy is None:
            self.stats.dropped_frames += 1
            return
        self.stats.emcy_count += 1
        self.emcy_log.append(emcy)
        if len(self.emcy_log) > 256:
            del self.emcy_log[:128]
        if not emcy.is_reset:
            self.last_emcy = emcy
            self._pending_emcy = emcy

    def _dispatch(self, msg: can.Message) -> None:
        """Direct mode: hand a frame that is not our TPDO to canopen's subscribers."""
        if msg.is_error_frame or msg.is_remote_frame:
            return
        self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)

    def _drain(self) -> None:
        """Before a SYNC: consume what arrived since the last cycle (late TPDOs are counted, not used)."""
        if self._cycling:
            recv = self._bus.recv
            slots = self._tpdo_slots
            msg = recv(0.0)
            while msg is not None:  # late TPDOs, heartbeats, EMCYs, SDO answers, own echoes
                slot = slots.get(msg.arbitration_id)
                if slot is None:
                    self._dispatch(msg)
                elif len(msg.data) != slot[1]:
                    self.stats.dropped_frames += 1
                else:
                    self.stats.stale_tpdos += 1
                msg = recv(0.0)
            return
        rxq = self._rx_queue
        slots = self._tpdo_slots
        while not rxq.empty():
            try:
                can_id, data = rxq.get_nowait()
            except queue.Empty:
                break
            if len(data) != slots[can_id][1]:
                self.stats.dropped_frames += 1
            else:
                self.stats.stale_tpdos += 1

    def _exchange_sync(self) -> tuple[int, ...] | None:
        """Send SYNC and wait for this cycle's TPDO(s); the decoded values in mapping order, or None on timeout."""
        if self._multi_tpdo:
            return self._exchange_sync_multi()
        perf = time.perf_counter
        if self._cycling:
            bus = self._bus
            recv = bus.recv
            tpdo_cob = self._tpdo_cob
            size = self._tpdo_size
            with self._send_lock:
                bus.send(self._sync_msg)
            self.stats.syncs_sent += 1
            deadline = perf() + self.tpdo_timeout
            while True:
                remaining = deadline - perf()
                if remaining <= 0.0:
                    return None
                msg = recv(remaining)
                if msg is None:
                    return None
                if msg.arbitration_id == tpdo_cob and not msg.is_remote_frame:
                    data = msg.data
                    if len(data) != size or msg.dlc != size:
                        self.stats.dropped_frames += 1
                        continue
                    return self._tpdo_unpack(data)
                self._dispatch(msg)
        rxq = self._rx_queue
        size = self._tpdo_size
        with self._send_lock:
            self._bus.send(self._sync_msg)
        self.stats.syncs_sent += 1
        deadline = perf() + self.tpdo_timeout
        while True:
            remaining = deadline - perf()
            if remaining <= 0.0:
                return None
            try:
                _, data = rxq.get(True, remaining)
            except queue.Empty:
                return None
            if len(data) != size:
                self.stats.dropped_frames += 1
                continue
            return self._tpdo_unpack(data)

    def _exchange_sync_multi(self) -> tuple[int, ...] | None:
        """Like :meth:`_exchange_sync` for a mapping spread over several TPDOs (all of one SYNC)."""
        perf = time.perf_counter
        slots = self._tpdo_slots
        parts: list[tuple[int, ...] | None] = [None] * len(slots)
        missing = len(slots)
        with self._send_lock:
            self._bus.send(self._sync_msg)
        self.stats.syncs_sent += 1
        deadline = perf() + self.tpdo_timeout
        while missing:
            remaining = deadline - perf()
            if remaining <= 0.0:
                return None
            if self._cycling:
                msg = self._bus.recv(remaining)
                if msg is None:
                    return None
                slot = slots.get(msg.arbitration_id)
                if slot is None or msg.is_remote_frame:
                    self._dispatch(msg)
                    continue
                data = msg.data
                if msg.dlc != slot[1]:
                    self.stats.dropped_frames += 1
                    continue
            else:
                try:
                    can_id, data = self._rx_queue.get(True, remaining)
                except queue.Empty:
                    return None
                slot = slots[can_id]
            index, size, unpack = slot
            if len(data) != size:
                self.stats.dropped_frames += 1
                continue
            if parts[index] is None:
                missing -= 1
            else:
                self.stats.stale_tpdos += 1
            parts[index] = unpack(data)
        values: tuple[int, ...] = ()
        for part in parts:
            values += part
        return values

    def _send_rpdo(self, controlword: int, torque: int) -> None:
        msg = self._rpdo_msg
        self._rpdo_pack_into(msg.data, 0, controlword, torque)
        with self._send_lock:
            self._bus.send(msg)
        self.stats.rpdos_sent += 1

    def _safe_stop(self) -> None:
        """Zero torque with the safe controlword, and one SYNC so that the drive applies it."""
        self._controlword = SAFE_CONTROLWORD
        self._armed = False
        self.stats.safe_stops += 1
        try:
            with self._send_lock:
                self._bus.send(self._safe_msg)
                self.stats.rpdos_sent += 1
                self._bus.send(self._sync_msg)
                self.stats.syncs_sent += 1
        except (can.CanError, OSError) as exc:  # the error being raised matters more
            logger.error("%s: could not send the safe stop frame: %s", self.name, exc)

    def _trip(self, error: DriveError) -> DriveError:
        self._safe_stop()
        self._tripped = error
        return error

    # ------------------------------------------------------------------ cyclic hot path

    def read_inputs(self) -> CyclicInputs:
        """Send SYNC, wait for this cycle's TPDO (<= tpdo_timeout s) and decode it; raise on fault/timeout."""
        if not self._connected:
            raise DriveError(self.name, "not connected; call connect() first")
        self._begin_cyclic()
        self._drain()
        if self._tripped is None:
            self._check_events()
        values = self._exchange_sync()
        if values is None:
            self.stats.missed_tpdos += 1
            self._missed_in_row += 1
            if self._missed_in_row >= self.max_missed_tpdos:
                raise self._trip(
                    DriveTimeout(
                        self.name,
                        f"no TPDO (COB-ID 0x{self._tpdo_cob:03X}) for {self._missed_in_row} consecutive cycles "
                        f"(timeout {self.tpdo_timeout * 1e3:.3g} ms each); torque set to zero",
                    )
                )
            if self.last_inputs is not None:
                return self.last_inputs
            return CyclicInputs(0, 0, None if self._pos_at is None else 0)
        self._missed_in_row = 0
        self.stats.cycles += 1
        statusword = values[self._sw_at]
        pos_at = self._pos_at
        inputs = CyclicInputs(statusword, values[self._vel_at], None if pos_at is None else values[pos_at])
        self.last_inputs = inputs
        if statusword & SW_FAULT and self._armed:
            emcy = self._pending_emcy or self.last_emcy
            self._pending_emcy = None
            detail = f"; {emcy}" if emcy is not None else ""
            raise self._trip(
                DriveFault(
                    self.name,
                    f"fault bit set in statusword 0x{statusword:04X} ({state_name(decode_statusword(statusword))}){detail}",
                    code=emcy.code if emcy is not None else None,
                )
            )
        return inputs

    def _check_events(self) -> None:
        """Raise (after a safe stop) for an EMCY, an NMT state change or a heartbeat loss seen so far."""
        if self._pending_emcy is not None:
            emcy, self._pending_emcy = self._pending_emcy, None
            raise self._trip(DriveFault(self.name, f"{emcy}", code=emcy.code))
        if self._pending_nmt is not None:
            state, self._pending_nmt = self._pending_nmt, None
            raise self._trip(
                DriveFault(self.name, f"node left NMT OPERATIONAL (heartbeat shows {_NMT_STATE_NAMES.get(state, state)})")
            )
        last = self._last_heartbeat
        if self._armed and last is not None and self.heartbeat_consumer_ms:
            silent = time.monotonic() - last
            if silent > self._heartbeat_limit:
                raise self._trip(
                    DriveTimeout(
                        self.name,
                        f"heartbeat lost: none for {silent * 1e3:.0f} ms (consumer time {self.heartbeat_consumer_ms} ms)",
                    )
                )

    def write_outputs(self, target_torque: int) -> None:
        """Send RPDO1: the held controlword and ``target_torque`` (per mille, saturated at +-0x6072)."""
        if not self._connected:
            raise DriveError(self.name, "not connected; call connect() first")
        if self._tripped is not None:
            self.stats.suppressed_outputs += 1
            self._send_rpdo(SAFE_CONTROLWORD, 0)
            return
        limit = self._torque_limit
        if target_torque > limit:
            target_torque = limit
            self.stats.saturated_outputs += 1
        elif target_torque < -limit:
            target_torque = -limit
            self.stats.saturated_outputs += 1
        self._send_rpdo(self._controlword, target_torque)

    # ------------------------------------------------------------------ state machine

    def _cycle_raw(self, controlword: int) -> int:
        """One exchange for the state machine: SYNC/TPDO, then RPDO(controlword, 0); the statusword."""
        self._begin_cyclic()
        self._drain()
        values = self._exchange_sync()
        self._send_rpdo(controlword, 0)
        if values is None:
            raise DriveTimeout(self.name, f"no TPDO within {self.tpdo_timeout * 1e3:.3g} ms while commanding the state machine")
        statusword = values[self._sw_at]
        pos_at = self._pos_at
        self.last_inputs = CyclicInputs(statusword, values[self._vel_at], None if pos_at is None else values[pos_at])
        return statusword

    def state(self) -> State | None:
        """The drive's CiA-402 state: one SYNC/TPDO exchange, answered with the held controlword and zero torque."""
        if not self._connected:
            raise DriveError(self.name, "not connected; call connect() first")
        return decode_statusword(self._cycle_raw(self._hold_word()))

    def _command(self, controlword: int) -> int:
        return self._cycle_raw(controlword)

    def _hold_word(self) -> int:
        return self._controlword if self._tripped is None else SAFE_CONTROLWORD

    def enable(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """Check 0x6502, write 0x6060, await 0x6061, walk to OPERATION ENABLED (timeouts per step)."""
        if not self._connected:
            raise DriveError(self.name, "not connected; call connect() first")
        self._select_mode(mode)
        self._tripped = None
        self._pending_emcy = None
        self._pending_nmt = None
        self._missed_in_row = 0
        self._walk(State.OPERATION_ENABLED, self._hold_word())
        self._controlword = Command.ENABLE_OPERATION.word
        self._armed = True

    def disable(self) -> None:
        """Zero torque, DISABLE VOLTAGE, and check the drive reaches SWITCH ON DISABLED (or sits in FAULT)."""
        if not self._connected:
            return
        self._armed = False
        self._controlword = SAFE_CONTROLWORD
        self._walk(State.SWITCH_ON_DISABLED, SAFE_CONTROLWORD, accept=(State.FAULT,))

    def fault_reset(self) -> None:
        """Rising edge of controlword bit 7, then back to 0; check the drive leaves FAULT."""
        if not self._connected:
            raise DriveError(self.name, "not connected; call connect() first")
        self._armed = False
        self._pending_emcy = None
        self._pending_nmt = None
        self._missed_in_row = 0
        self._reset_fault()
        self._controlword = SAFE_CONTROLWORD
        self._tripped = None

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        """Stop cycling, NMT pre-operational if reachable, release listeners and (if owned) the bus."""
        if self._closed:
            return
        self._closed = True
        self._teardown(reachable=self._connected)
        self._connected = False

    def _teardown(self, reachable: bool) -> None:
        network = self.network
        if network is None:
            return
        try:
            if reachable and self._bus is not None:
                try:
                    self._send_rpdo(SAFE_CONTROLWORD, 0)
                    with self._send_lock:
                        self._bus.send(self._sync_msg)
                    self.node.nmt.send_command(NMT_PRE_OPERATIONAL)
                except (can.CanError, OSError, RuntimeError) as exc:
                    logger.warning("%s: could not send the closing frames: %s", self.name, exc)
            subscriptions = [(0x700 + self.node_id, self._on_heartbeat), (0x080 + self.node_id, self._on_emcy)]
            subscriptions += [(cob, self._on_tpdo) for cob in self._tpdo_cobs]
            for can_id, callback in subscriptions:
                try:
                    network.unsubscribe(can_id, callback)
                except (KeyError, ValueError):
                    pass
            if self.node is not None and network.nodes.get(self.node_id) is self.node:
                del network[self.node_id]
        finally:
            if self._owns_bus or self._given_bus is not None:
                if self._cycling:
                    self._cycling = False
                    network.notifier = None
                if self._owns_bus:
                    network.disconnect()
                elif network.notifier is not None:
                    network.notifier.stop(timeout=5.0)
            elif self._cycling:
                self._ensure_notifier()  # give the caller's network its notifier back
            self.network = None
            self._bus = None

    def __repr__(self) -> str:
        return f"CanopenDrive(node_id={self.node_id}, period={self.period}, rx_mode={self.rx_mode!r})"
