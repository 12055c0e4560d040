"""The simulated drive as a real CANopen slave on a python-can bus.

:class:`CanopenSimDrive` wraps a :class:`~sim_drive.device.SimulatedDrive` in canopen's
``LocalNode`` (object dictionary from the shipped EDS, SDO server, NMT slave, EMCY producer)
and adds what ``LocalNode`` lacks: PDOs that follow SDO remapping (:mod:`sim_drive.canopen.pdo_table`),
SYNC handling with precompiled ``struct`` codecs, an NMT reset that boots again, a heartbeat
consumer, and fault injection.

One receive thread owns the bus: it blocks in ``bus.recv`` and handles SYNC and RPDOs
directly (the hot path), everything else through canopen's dispatcher.  Behaviour:

- NMT: boot-up message then PRE-OPERATIONAL on :meth:`start`; heartbeat every 0x1017 ms;
  SDO in PRE-OPERATIONAL and OPERATIONAL; PDOs only in OPERATIONAL; nothing but NMT in
  STOPPED; reset node / reset communication restore the EDS values and boot again.
- SYNC (COB-ID 0x1005) in PRE-OPERATIONAL and OPERATIONAL: apply buffered synchronous RPDOs,
  one :meth:`SimulatedDrive.sync` (the plant advances exactly ``T``), then TPDOs by
  transmission type: 1..240 every n-th SYNC, 0 on a SYNC when the data changed, 254/255
  whenever the data changed (checked after every SYNC, RPDO and SDO write).
- RPDOs with type 0..240 are applied at the next SYNC, 254/255 on reception.  With a sync
  window 0x1007 > 0, an RPDO arriving later than the window after the last SYNC (message
  timestamps) is discarded, counted and answered with EMCY 0x8250 (CiA 301 "RPDO timeout":
  it missed its cycle).  A short RPDO is discarded with EMCY 0x8210, a long one is used and
  reported with EMCY 0x8220.
- Heartbeat consumer (0x1016 sub 1): once the watched node's first heartbeat arrived, a gap
  longer than the consumer time raises EMCY 0x8130 and a drive FAULT (error code 0x8130).
- Not implemented: TPDO inhibit time, event timer and SYNC start value (the EDS does not
  offer them), RTR, SYNC counter checks, LSS, 0x1010/0x1011 store/restore.
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import can
import canopen
from canopen import LocalNode, SdoAbortedError
from canopen.objectdictionary import import_od

from drives.cia402 import State
from drives.errors import HapticBusError
from haptic_bus.validation import whole_in_range
from sim_drive.bus_timing import BusLoadMeter
from sim_drive.device import ObjectAccessError, SimulatedDrive
from sim_drive.eds import eds_path
from sim_drive.canopen.manufacturer import ManufacturerObjects, SlaveCounters
from sim_drive.operator import OperatorModel
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.canopen.pdo_table import COB_ID_MASK, FRAME_29_BIT, PDO_NOT_VALID, PdoChannel, PdoTable

logger = logging.getLogger(__name__)

EMCY_HEARTBEAT = 0x8130
EMCY_RPDO_LENGTH = 0x8210
EMCY_RPDO_TOO_LONG = 0x8220
EMCY_RPDO_LATE = 0x8250
FAULT_GENERIC = 0x1000
ERROR_REGISTER_GENERIC = 0x01
ERROR_REGISTER_COMMUNICATION = 0x10
SYNC_GENERATOR_BIT = 1 << 30
NMT_RESET_NODE, NMT_RESET_COMMUNICATION = 0x81, 0x82
RECV_TIMEOUT = 0.05  # s: longest the receive thread blocks before looking at its stop flag
_ABORTS = {"unknown": 0x06020000, "read-only": 0x06010002, "range": 0x06090030}
_EMCY = struct.Struct("<HB5s")


class _SlaveNetwork(canopen.Network):
    """canopen's Network whose sends honour the slave's silence and feed its bus meter."""

    def __init__(self, bus: can.BusABC, slave: "CanopenSimDrive") -> None:
        super().__init__(bus)
        self._slave = slave

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        """Send unless the slave is silent."""
        if self._slave.silent:
            return
        self._slave._meter_frame(len(data))
        super().send_message(can_id, data, remote)


class CanopenSimDrive:
    """A simulated CiA-402 drive that is a CANopen slave (node ``node_id``) on a python-can bus.

    ``bus``: an open ``can.BusABC`` (left open by :meth:`stop`) or the keyword arguments of
    ``can.Bus`` (``{"interface": "virtual", "channel": "x"}``; opened by :meth:`start`, shut
    down by :meth:`stop`).  ``timing``, ``parameters``, ``operator``: see
    :class:`~sim_drive.device.SimulatedDrive`.  ``bus_meter``: optional bit-time accounting.
    """

    def __init__(
        self,
        bus: can.BusABC | Mapping[str, Any],
        node_id: int,
        *,
        timing: Timing | str = Timing.CIA402,
        parameters: DeviceParameters | None = None,
        operator: OperatorModel | None = None,
        bus_meter: BusLoadMeter | None = None,
    ) -> None:
        self.node_id = whole_in_range("node_id", node_id, 1, 127, context="CANopen slave")
        self._bus: can.BusABC | None = bus if isinstance(bus, can.BusABC) else None
        self._bus_config = None if isinstance(bus, can.BusABC) else dict(bus)
        self.drive = SimulatedDrive(parameters, timing, operator, name=f"node {self.node_id}")
        self.counters = SlaveCounters()
        self.bus_meter = bus_meter
        self.silent = False
        self._power_on_period = self.drive.parameters.period
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._network: _SlaveNetwork | None = None
        self._od = import_od(str(eds_path()), self.node_id)
        self._node = LocalNode(self.node_id, self._od)
        self._node.add_read_callback(self._on_sdo_read)
        self._node.add_write_callback(self._on_sdo_write)
        self._manufacturer = ManufacturerObjects(self.drive, self.counters)
        self._pdos = PdoTable(self._od, self.drive.readable_objects(), self.drive.writable_objects(), self._on_pdo_change)
        self._nmt_state = "INITIALISING"
        self._short_next: dict[int, int] = {}
        self._pending_sync_rpdos: list[tuple[PdoChannel, bytes]] = []
        self._sync_timestamp: float | None = None
        self._reset_communication()

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> "CanopenSimDrive":
        """Open the bus (if given as a config), boot (boot-up message, PRE-OPERATIONAL), serve."""
        if self._thread is not None:
            raise RuntimeError(f"node {self.node_id}: already started")
        if self._bus is None:
            self._bus = can.Bus(**self._bus_config)
        self._network = _SlaveNetwork(self._bus, self)
        self._network.add_node(self._node)
        self._network.unsubscribe(0, self._node.nmt.on_command)
        self._network.subscribe(0, self._on_nmt)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"sim-drive-{self.node_id}", daemon=True)
        self._thread.start()
        with self._lock:
            self._boot()
        return self

    def stop(self) -> None:
        """Stop serving, stop the heartbeat, release the bus if this object opened it."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(timeout=5 * RECV_TIMEOUT + 1.0)
        self._thread = None
        self._node.nmt.stop_heartbeat()
        self._network.unsubscribe(0, self._on_nmt)
        self._network.subscribe(0, self._node.nmt.on_command)
        self._node.remove_network()
        if self._bus_config is not None and self._bus is not None:
            self._bus.shutdown()
            self._bus = None
        self._network = None

    def __enter__(self) -> "CanopenSimDrive":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def nmt_state(self) -> str:
        """The NMT state: INITIALISING, PRE-OPERATIONAL, OPERATIONAL or STOPPED."""
        return self._nmt_state

    # ----------------------------------------------------------------- fault injection
    def go_silent(self) -> None:
        """Disconnect: send nothing (no heartbeat either) and ignore every frame until :meth:`resume`."""
        with self._lock:
            self.silent = True
            self._node.nmt.stop_heartbeat()

    def resume(self) -> None:
        """Undo :meth:`go_silent` (and :meth:`stop_heartbeat`)."""
        with self._lock:
            self.silent = False
            self._start_heartbeat()

    def stop_heartbeat(self) -> None:
        """Heartbeat loss only: everything else keeps working."""
        self._node.nmt.stop_heartbeat()

    def send_emcy(self, code: int, register: int | None = None, data: bytes = b"") -> None:
        """Send one EMCY with ``code``; ``register`` defaults to the current 0x1001."""
        with self._lock:
            self._emcy(code, self._error_register() if register is None else register, data)

    def enter_fault(self, code: int = FAULT_GENERIC) -> None:
        """Drive fault with error ``code``: FAULT state, EMCY, event TPDOs."""
        with self._lock:
            self.drive.fault(code)
            self._emcy(code, self._error_register())
            self._send_event_tpdos()

    def short_next_tpdo(self, number: int = 1, missing_bytes: int = 1) -> None:
        """Make the next transmission of TPDO ``number`` (1..4) ``missing_bytes`` too short."""
        number = whole_in_range("number", number, 1, 4, context="short TPDO")
        missing = whole_in_range("missing_bytes", missing_bytes, 1, 8, context="short TPDO")
        with self._lock:
            self._short_next[number] = missing

    # ----------------------------------------------------------------- NMT and boot
    def _boot(self) -> None:
        nmt = self._node.nmt
        nmt.send_command(NMT_RESET_NODE)  # sends the boot-up message
        nmt.send_command(0x80)  # PRE-OPERATIONAL; starts the heartbeat from 0x1017
        self._nmt_state = nmt.state
        logger.info("node %d: boot-up, %s", self.node_id, self._nmt_state)

    def _start_heartbeat(self) -> None:
        self._node.nmt.start_heartbeat(self._node.sdo[0x1017].raw)

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        if data[0] in (NMT_RESET_NODE, NMT_RESET_COMMUNICATION):
            if data[0] == NMT_RESET_NODE:
                self.drive.reset_application()
            self._reset_communication()
            self._boot()
            return
        old = self._nmt_state
        self._node.nmt.on_command(can_id, data, timestamp)
        self._nmt_state = self._node.nmt.state
        if self._nmt_state != old:
            logger.info("node %d: NMT %s -> %s", self.node_id, old, self._nmt_state)
        if self._nmt_state == "OPERATIONAL" and old != "OPERATIONAL":
            self._last_tpdo.clear()
            self._send_event_tpdos()

    def _reset_communication(self) -> None:
        self._node.data_store = {i: subs for i, subs in self._node.data_store.items() if i >= 0x2000}
        self._pdos.reset()
        self._on_pdo_change(None)
        od = self._od
        self._sync_cob = od[0x1005].default & COB_ID_MASK
        self._sync_window_us = od[0x1007].default
        self._node.emcy.cob_id = od[0x1014].default & COB_ID_MASK
        self._emcy_enabled = True
        self._consumer_node: int | None = None
        self._consumer_period = 0.0
        self._consumer_deadline: float | None = None
        self.drive.reconfigure(period=self._power_on_period)

    # ----------------------------------------------------------------- PDO plans
    def _on_pdo_change(self, channel: PdoChannel | None) -> None:
        drive = self.drive
        self._rx_by_cob = {ch.cob_id: ch for ch in self._pdos.rx if ch.valid}
        self._tx_plan = [(ch, tuple(drive.reader(i) for i in ch.indices)) for ch in self._pdos.tx if ch.valid]
        self._tx_sync_counts = {ch.number: 0 for ch, _ in self._tx_plan}
        self._last_tpdo: dict[int, bytes] = {}
        self._own_ids = {ch.cob_id for ch in self._pdos.tx} | {0x580 + self.node_id, 0x700 + self.node_id}

    def _encode(self, channel: PdoChannel, readers: tuple[Callable[[], int], ...]) -> bytes:
        return channel.codec.pack(*[read() for read in readers])

    def _send_tpdo(self, channel: PdoChannel, data: bytes) -> None:
        self._last_tpdo[channel.number] = data
        missing = self._short_next.pop(channel.number, 0)
        self._send(channel.cob_id, data[: max(len(data) - missing, 0)] if missing else data)

    def _send_event_tpdos(self) -> None:
        if self._nmt_state != "OPERATIONAL":
            return
        for channel, readers in self._tx_plan:
            if channel.trans_type >= 254:
                data = self._encode(channel, readers)
                if self._last_tpdo.get(channel.number) != data:
                    self._send_tpdo(channel, data)

    def _send(self, cob_id: int, data: bytes) -> None:
        if self.silent:
            return
        message = can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)
        with self._network.send_lock:
            self._bus.send(message)
        self._meter_frame(len(data))

    def _meter_frame(self, data_bytes: int) -> None:
        if self.bus_meter is not None:
            self.bus_meter.frame(data_bytes)

    # ----------------------------------------------------------------- receive thread
    def _run(self) -> None:
        bus = self._bus
        while not self._stop.is_set():
            timeout = RECV_TIMEOUT
            deadline = self._consumer_deadline
            if deadline is not None:
                timeout = min(timeout, max(deadline - time.monotonic(), 0.0))
            try:
                message = bus.recv(timeout)
            except can.CanError as exc:
                logger.error("node %d: bus receive failed, slave stops: %s", self.node_id, exc)
                return
            with self._lock:
                if self._consumer_deadline is not None and time.monotonic() > self._consumer_deadline:
                    self._heartbeat_lost()
                if message is None or self.silent or message.is_error_frame or message.is_remote_frame:
                    continue
                if message.is_extended_id:
                    continue
                self._dispatch(message)

    def _dispatch(self, message: can.Message) -> None:
        cob_id = message.arbitration_id
        if cob_id == self._sync_cob:
            if self.bus_meter is not None:
                self.bus_meter.sync(min(len(message.data), 8))
            if self._nmt_state in ("PRE-OPERATIONAL", "OPERATIONAL"):
                self._on_sync(message)
            return
        if self.bus_meter is not None and cob_id not in self._own_ids and cob_id != self._node.emcy.cob_id:
            self.bus_meter.frame(len(message.data))
        channel = self._rx_by_cob.get(cob_id)
        if channel is not None:
            if self._nmt_state == "OPERATIONAL":
                self._on_rpdo(channel, message)
            return
        if self._consumer_node is not None and cob_id == 0x700 + self._consumer_node:
            self._consumer_deadline = time.monotonic() + self._consumer_period
            return
        if cob_id != 0 and self._nmt_state == "STOPPED":
            return
        self._network.notify(cob_id, message.data, message.timestamp)
        self._send_event_tpdos()

    def _on_sync(self, message: can.Message) -> None:
        self._sync_timestamp = message.timestamp
        for channel, data in self._pending_sync_rpdos:
            self._apply_rpdo(channel, data)
        self._pending_sync_rpdos.clear()
        self.drive.sync()
        if self._nmt_state != "OPERATIONAL":
            return
        counts = self._tx_sync_counts
        for channel, readers in self._tx_plan:
            trans_type = channel.trans_type
            if trans_type >= 254:
                continue
            if trans_type == 0:
                data = self._encode(channel, readers)
                if self._last_tpdo.get(channel.number) != data:
                    self._send_tpdo(channel, data)
                continue
            count = counts[channel.number]
            counts[channel.number] = count + 1
            if count % trans_type == 0:
                self._send_tpdo(channel, self._encode(channel, readers))
        self._send_event_tpdos()

    def _on_rpdo(self, channel: PdoChannel, message: can.Message) -> None:
        window = self._sync_window_us
        if window and self._sync_timestamp is not None and (message.timestamp - self._sync_timestamp) * 1e6 > window:
            self.counters.late_rpdos += 1
            self._emcy(EMCY_RPDO_LATE, self._error_register() | ERROR_REGISTER_COMMUNICATION)
            return
        data = bytes(message.data)
        size = channel.codec.size
        if len(data) < size:
            self.counters.rpdo_length_errors += 1
            self._emcy(EMCY_RPDO_LENGTH, self._error_register() | ERROR_REGISTER_COMMUNICATION)
            return
        if len(data) > size:
            self._emcy(EMCY_RPDO_TOO_LONG, self._error_register() | ERROR_REGISTER_COMMUNICATION)
            data = data[:size]
        if channel.synchronous:
            self._pending_sync_rpdos.append((channel, data))
        else:
            self._apply_rpdo(channel, data)
            self._send_event_tpdos()

    def _apply_rpdo(self, channel: PdoChannel, data: bytes) -> None:
        for index, value in zip(channel.indices, channel.codec.unpack(data)):
            try:
                self.drive.write_object(index, value)
            except ObjectAccessError as exc:
                logger.warning("node %d: RPDO%d value refused: %s", self.node_id, channel.number, exc)

    def _heartbeat_lost(self) -> None:
        self._consumer_deadline = None
        logger.warning("node %d: heartbeat of node %s lost", self.node_id, self._consumer_node)
        self.drive.fault(EMCY_HEARTBEAT)
        self._emcy(EMCY_HEARTBEAT, self._error_register() | ERROR_REGISTER_COMMUNICATION)
        self._send_event_tpdos()

    # ----------------------------------------------------------------- EMCY
    def _error_register(self) -> int:
        return ERROR_REGISTER_GENERIC if self.drive.state is State.FAULT else 0

    def _emcy(self, code: int, register: int, data: bytes = b"") -> None:
        if self._emcy_enabled and self._network is not None:
            self._network.send_message(self._node.emcy.cob_id, _EMCY.pack(code, register, data))

    # ----------------------------------------------------------------- SDO bridge
    def _on_sdo_read(self, index: int, subindex: int, od: Any) -> int | float | None:
        if subindex == 0 and index in self.drive.readable_objects():
            return self.drive.read_object(index)
        if subindex and self._manufacturer.owns(index):
            return self._manufacturer.read(index, subindex)
        if index == 0x1001:
            return self._error_register()
        if index == 0x1006:
            return self.drive.parameters.cycle_period_us
        return None

    def _on_sdo_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        value = od.decode_raw(data)
        if subindex == 0 and index in self.drive.readable_objects():
            try:
                self.drive.write_object(index, value)
            except ObjectAccessError as exc:
                raise SdoAbortedError(_ABORTS[exc.reason]) from exc
        elif self._manufacturer.owns(index):
            self._manufacturer.write(index, subindex, value)
        elif self._pdos.owns(index):
            self._pdos.write(index, subindex, value)
        else:
            self._write_communication(index, subindex, value)

    def _write_communication(self, index: int, subindex: int, value: int) -> None:
        if index == 0x1005:
            if value & (SYNC_GENERATOR_BIT | FRAME_29_BIT):
                raise SdoAbortedError(_ABORTS["range"])
            self._sync_cob = value & COB_ID_MASK
        elif index == 0x1006 and value:
            try:
                self.drive.reconfigure(period=value * 1e-6)
            except HapticBusError as exc:
                raise SdoAbortedError(_ABORTS["range"]) from exc
        elif index == 0x1007:
            self._sync_window_us = value
        elif index == 0x1014:
            self._emcy_enabled = not value & PDO_NOT_VALID
            self._node.emcy.cob_id = value & COB_ID_MASK
        elif index == 0x1016 and subindex == 1:
            node, period_ms = value >> 16 & 0x7F, value & 0xFFFF
            active = node and period_ms
            self._consumer_node = node if active else None
            self._consumer_period = period_ms / 1000.0
            self._consumer_deadline = None
