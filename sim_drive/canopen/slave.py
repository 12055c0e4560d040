"""The simulated drive as a real CANopen slave on a python-can bus.

:class:`CanopenSimDrive` wraps a :class:`~sim_drive.device.SimulatedDrive` in canopen's
``LocalNode`` (object dictionary from the shipped EDS, SDO server, EMCY producer) and adds
what ``LocalNode`` lacks: PDOs that follow SDO remapping (:mod:`~sim_drive.canopen.pdo_table`,
:mod:`~sim_drive.canopen.pdo_engine`), SYNC handling, NMT that boots again after a reset, the
heartbeat producer, consumer and RPDO deadlines (:mod:`~sim_drive.canopen.timers`), EMCY and
the error register (:mod:`~sim_drive.canopen.emergency`), and fault injection.

One receive thread owns the bus and every timer: it blocks in ``bus.recv`` until the next frame
or due time, handles SYNC and RPDOs directly (the hot path), the rest through canopen's
dispatcher.  On a lock-step bus (:mod:`drives.lockstep_bus`) frames reach the node in the
sender's thread (a master in the process has its TPDO when its SYNC ``send`` returns); the
thread keeps only the timers (wall clock: they guard against a dead peer, never pace the plant).
No frame can stop it: an unusable frame is counted and dropped, a receive error counted, and if
the bus keeps failing the node stops its heartbeat and faults the drive.

- NMT: boot-up then PRE-OPERATIONAL on :meth:`start` (the boot-up is the first heartbeat, then
  one every 0x1017 ms); SDO in PRE-OPERATIONAL and OPERATIONAL; PDOs only in OPERATIONAL; only
  NMT and the heartbeat in STOPPED; reset node restores the power-on values and the manufacturer
  area, reset communication the EDS values of 0x1000..0x1FFF, and both boot again.
- SYNC (COB-ID 0x1005, 0 data bytes) in PRE-OPERATIONAL and OPERATIONAL: one drive SYNC (the plant
  advances ``T``, or the time since the last SYNC with a wall clock); another length: EMCY 0x8240.
- Abort connection (0x6007 applied by the drive, CiA 402): the master's heartbeat lost
  (0x1016, EMCY 0x8130), an RPDO deadline missed (0x1400+n sub 5, EMCY 0x8250), or NMT taking
  the node out of OPERATIONAL while the power stage is on (0x8100).
- Not implemented: TPDO inhibit time and event timer, SYNC start value, RTR, SYNC counter, LSS, 0x1010/0x1011.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import can
from canopen import SdoAbortedError
from canopen.objectdictionary import ObjectDictionary

from drives.bus_config import open_bus
from drives.canopen.local_node import StrictLocalNode
from drives.cia301 import (
    ERROR_REGISTER,
    HEARTBEAT_BASE,
    NMT_COB_ID,
    NODE_ID_RANGE,
    NODE_IDS,
    EmcyCode,
    NmtCommand,
    NmtState,
    SdoAbort,
)
from drives.lockstep_bus import LockstepBus
from haptic_bus.validation import whole_in_range
from sim_drive.bus_timing import BusLoadMeter
from sim_drive.canopen.communication import CommunicationObjects
from sim_drive.canopen.emergency import Emergency
from sim_drive.canopen.manufacturer import ManufacturerObjects
from sim_drive.canopen.pdo_access import PdoAccess
from sim_drive.canopen.pdo_engine import PdoEngine, SlaveCounters
from sim_drive.canopen.pdo_table import PdoChannel, PdoTable
from sim_drive.canopen.slave_network import SlaveNetwork
from sim_drive.canopen.standard_od import object_dictionary
from sim_drive.canopen.timers import NodeTimers, Watchdog
from sim_drive.device import POWER_STAGE_ON, ObjectAccessError, SimulatedDrive
from sim_drive.operator import OperatorModel
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.sync_clock import SyncClock, WallSyncClock

logger = logging.getLogger(__name__)

FAULT_GENERIC = 0x1000
RECV_TIMEOUT = 0.05  # s: longest the receive thread blocks before looking at its stop flag
MAX_RECEIVE_ERRORS_IN_ROW = 100  # a bus that fails this often in a row ...
RECEIVE_FAILURE_TIME = 0.5  # s: ... and for this long, with no receive that worked in between, is gone
MAX_FRAMES_PER_WAKE = 256  # frames handled before the timers are looked at (a flood cannot starve them)
SDO_FRAME_LENGTH = 8
_ABORTS = {"unknown": SdoAbort.NO_OBJECT, "read-only": SdoAbort.READ_ONLY, "range": SdoAbort.VALUE_RANGE}
_NMT_STATES: dict[int, NmtState] = {
    NmtCommand.START: NmtState.OPERATIONAL,
    NmtCommand.STOP: NmtState.STOPPED,
    NmtCommand.ENTER_PRE_OPERATIONAL: NmtState.PRE_OPERATIONAL,
}
_SERVING = (NmtState.PRE_OPERATIONAL, NmtState.OPERATIONAL)


class CanopenSimDrive:
    """A simulated CiA-402 drive that is a CANopen slave (node ``node_id``) on a python-can bus.

    ``bus``: an open ``can.BusABC`` (left open by :meth:`stop`) or the keyword arguments of
    ``can.Bus`` (``{"interface": "virtual", "channel": "x"}``; opened by :meth:`start`, shut
    down by :meth:`stop`).  ``timing``, ``parameters``, ``operator``, ``hand_needs_power``: see
    :class:`~sim_drive.device.SimulatedDrive`.  ``bus_meter``: optional bit-time accounting.
    ``od``: "haptic" (the shipped EDS, manufacturer area included) or "standard" (CiA-301/402
    objects only, the scaling in the factor group: :mod:`sim_drive.canopen.standard_od`).
    ``dictionary``: an object dictionary to use instead of the kind's default.  ``eds``: a user's
    own EDS (a vendor's) instead: the simulated core behind that dictionary, objects it lacks
    absent, its PDO limits, its manufacturer area stored values (:mod:`sim_drive.canopen.vendor_od`).
    ``sync_clock``: how long the interval each SYNC closes was (:mod:`sim_drive.sync_clock`;
    None: exactly ``T``).
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
        dictionary: ObjectDictionary | None = None,
        od: str = "haptic",
        eds: str | os.PathLike[str] | None = None,
        sync_clock: SyncClock | None = None,
        hand_needs_power: bool = False,
    ) -> None:
        self.node_id = whole_in_range("node_id", node_id, *NODE_ID_RANGE, context="CANopen slave", allowed=NODE_IDS)
        self._bus: can.BusABC | None = bus if isinstance(bus, can.BusABC) else None
        self._bus_config = None if isinstance(bus, can.BusABC) else dict(bus)
        self.drive = SimulatedDrive(parameters, timing, operator, name=f"node {self.node_id}",
                                    hand_needs_power=hand_needs_power)
        self.counters = SlaveCounters()
        self.bus_meter = bus_meter
        self.silent = False
        self.nmt = NmtState.BOOT_UP
        self._errors_in_row = 0
        self._failing_since = 0.0  # time.monotonic() of the first receive error in a row
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._network: SlaveNetwork | None = None
        dictionary, read_standard = object_dictionary(od, self.node_id, self.drive, dictionary, eds)
        self._node = StrictLocalNode(self.node_id, dictionary)
        self._node.add_read_callback(self._on_sdo_read)
        if read_standard is not None:
            self._node.add_read_callback(read_standard)
        self._node.add_write_callback(self._on_sdo_write)
        self.timers = NodeTimers()
        self.emergency = Emergency(self._node.emcy, self.drive, self._may_send_emcy)
        self._comm = CommunicationObjects(dictionary, self.drive, self.timers, self.emergency, self.node_id)
        self._manufacturer = ManufacturerObjects(self.drive, self.counters) if eds is None else None  # a vendor's area is its own
        access = PdoAccess(self.drive, self._node)
        self._pdos = PdoTable(dictionary, access, self._on_pdo_change)
        self._engine = PdoEngine(self._pdos, self.drive, access, self._send, self.emergency, self.counters, sync_clock)
        self._reset_communication()

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> CanopenSimDrive:
        """Open the bus (if given as a config), boot (boot-up message, PRE-OPERATIONAL), serve."""
        if self._thread is not None:
            raise RuntimeError(f"node {self.node_id}: already started")
        bus = self._bus = self._bus if self._bus is not None else open_bus(**(self._bus_config or {}))
        self._network = SlaveNetwork(bus, self)
        self._network.add_node(self._node)
        self._network.unsubscribe(NMT_COB_ID, self._node.nmt.on_command)
        self._stop.clear()
        with self._lock:
            self._boot()
        if isinstance(bus, LockstepBus):
            bus.set_receiver(self._on_frame)
            self._thread = threading.Thread(target=self._run_timers, name=f"sim-drive-{self.node_id}", daemon=True)
        else:
            self._thread = threading.Thread(target=self._run, args=(bus,), name=f"sim-drive-{self.node_id}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving (and so the heartbeat), release the bus if this object opened it."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(timeout=5 * RECV_TIMEOUT + 1.0)
        self._thread = None
        if isinstance(self._bus, LockstepBus):
            self._bus.set_receiver(None)
        if self._network is not None:
            self._network.subscribe(NMT_COB_ID, self._node.nmt.on_command)
        self._node.remove_network()
        if self._bus_config is not None and self._bus is not None:
            self._bus.shutdown()
            self._bus = None
        self._network = None

    def __enter__(self) -> CanopenSimDrive:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def nmt_state(self) -> str:
        """The NMT state: INITIALISING, PRE-OPERATIONAL, OPERATIONAL or STOPPED."""
        return "INITIALISING" if self.nmt is NmtState.BOOT_UP else self.nmt.label

    @property
    def object_dictionary(self) -> ObjectDictionary:
        """The dictionary the slave serves (the shipped EDS, the standard objects, or a user's EDS)."""
        return self._node.object_dictionary

    @property
    def serving(self) -> bool:
        """True while the receive thread runs."""
        return self._thread is not None and self._thread.is_alive()

    # ----------------------------------------------------------------- fault injection
    def go_silent(self) -> None:
        """Disconnect: send nothing (no heartbeat either) and ignore every frame until :meth:`resume`."""
        with self._lock:
            self.silent = True

    @contextmanager
    def paused(self) -> Iterator[None]:
        """Take no frame and keep no clock while in the block, then every frame that waited, in order: what
        SIGSTOP and SIGCONT do to a drive's process (a request is applied, and answered, late)."""
        with self._lock:
            yield

    def resume(self) -> None:
        """Undo :meth:`go_silent` (and :meth:`stop_heartbeat`)."""
        with self._lock:
            self.silent = False
            self._start_heartbeat()

    def stop_heartbeat(self) -> None:
        """Heartbeat loss only: everything else keeps working."""
        with self._lock:
            self.timers.stop_producer()

    def send_emcy(self, code: int, data: bytes = b"") -> None:
        """Send one EMCY with ``code`` and the current 0x1001."""
        with self._lock:
            self.emergency.send(code, data)

    def enter_fault(self, code: int = FAULT_GENERIC) -> None:
        """Drive fault with error ``code``: FAULT state, EMCY, event TPDOs."""
        with self._lock:
            self.drive.fault(code)
            self._send_event_tpdos()

    def short_next_tpdo(self, number: int = 1, missing_bytes: int = 1) -> None:
        """Make the next transmission of TPDO ``number`` (1..4) ``missing_bytes`` too short."""
        number = whole_in_range("number", number, 1, 4, context="short TPDO")
        missing = whole_in_range("missing_bytes", missing_bytes, 1, 8, context="short TPDO")
        with self._lock:
            self._engine.short_next(number, missing)

    # ----------------------------------------------------------------- NMT and boot
    def _boot(self) -> None:
        """Boot-up message (the first heartbeat), then PRE-OPERATIONAL."""
        self.nmt = NmtState.BOOT_UP
        self._send(HEARTBEAT_BASE + self.node_id, b"\x00")
        self.nmt = NmtState.PRE_OPERATIONAL
        self._start_heartbeat()
        logger.info("node %d: boot-up, %s", self.node_id, self.nmt_state)

    def _start_heartbeat(self) -> None:
        """The producer at 0x1017's current value (the boot-up or the resume counts as the first)."""
        self.timers.start_producer(self._comm.producer_ms / 1000.0, time.monotonic())

    def _on_nmt(self, data: bytearray) -> None:
        if len(data) != 2:
            self.counters.malformed_frames += 1
            return
        command, node = data[0], data[1]
        if node not in (0, self.node_id):
            return
        if command in (NmtCommand.RESET_NODE, NmtCommand.RESET_COMMUNICATION):
            self._abort_connection()
            if command == NmtCommand.RESET_NODE:
                self.drive.reset_application()
                self._node.data_store.clear()  # the manufacturer area too
            self._reset_communication()
            self._boot()
            return
        new = _NMT_STATES.get(command)
        if new is None or new is self.nmt:
            return
        if self.nmt is NmtState.OPERATIONAL:
            self.timers.stop_rpdo_monitoring()
            self._abort_connection()  # while still OPERATIONAL: its EMCY may go out
        logger.info("node %d: NMT %s -> %s", self.node_id, self.nmt.label, new.label)  # logged before it shows
        self.nmt = new
        if new is NmtState.OPERATIONAL:
            self._engine.forget_sent()
            self._send_event_tpdos()

    def _reset_communication(self) -> None:
        self._node.data_store = {i: subs for i, subs in self._node.data_store.items() if i >= 0x2000}
        self._pdos.reset()
        self._on_pdo_change(None)
        self._comm.reset()
        self.emergency.active.clear()
        self.drive.reconfigure(period=self.drive.power_on_parameters.period)
        if isinstance(self._engine.sync_clock, WallSyncClock):
            self._engine.sync_clock.restart()  # the idle time before a reset is not stepped through

    def _abort_connection(self) -> None:
        """NMT takes the node out of OPERATIONAL (or resets it) with the power stage on: 0x6007's
        reaction, and its EMCY 0x8100 (through the fault, or as a one-off event)."""
        if self.drive.state in POWER_STAGE_ON and not self.drive.connection_lost(EmcyCode.COMMUNICATION):
            self.emergency.communication_event(EmcyCode.COMMUNICATION)

    # ----------------------------------------------------------------- PDO plans
    def _on_pdo_change(self, channel: PdoChannel | None) -> None:
        self._engine.rebuild()
        for rpdo in self._pdos.rx:
            self.timers.configure_rpdo(rpdo.number, rpdo.event_timer / 1000.0 if rpdo.valid else 0.0)

    def _send_event_tpdos(self) -> None:
        if self.nmt is NmtState.OPERATIONAL:
            self._engine.send_event_tpdos()

    def _may_send_emcy(self) -> bool:
        return self.nmt in _SERVING and not self.silent

    def _send(self, cob_id: int, data: bytes) -> None:
        bus, network = self._bus, self._network
        if self.silent or bus is None or network is None:
            return
        message = can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)
        with network.send_lock:
            bus.send(message)
        self.meter_frame(len(data))

    def meter_frame(self, data_bytes: int) -> None:
        """Count one frame of ``data_bytes`` data bytes on the bus meter (if the slave has one)."""
        if self.bus_meter is not None:
            self.bus_meter.frame(data_bytes)

    # ----------------------------------------------------------------- receive thread
    def _run(self, bus: can.BusABC) -> None:
        """Frames and timers until :meth:`stop`; if the bus is gone, stop saying alive and fault."""
        try:
            while not self._stop.is_set():
                due = self.timers.next_due()
                message = self._receive(bus, RECV_TIMEOUT if due is None else min(RECV_TIMEOUT, max(due - time.monotonic(), 0.0)))
                with self._lock:
                    for _ in range(MAX_FRAMES_PER_WAKE):  # everything that arrived, then the timers
                        if message is None:
                            break
                        self._take(message)
                        message = self._receive(bus, 0.0)
                    self._tick(time.monotonic())
        except Exception as exc:
            self.lose_bus(exc)

    def lose_bus(self, exc: BaseException) -> None:
        """The bus is gone (``exc`` said so): stop saying alive and fault, as a drive that lost its bus does."""
        logger.error("node %d: cannot serve any more, heartbeat stopped and drive faulted: %r", self.node_id, exc)
        with self._lock:
            self.timers.stop_producer()
            self.drive.fault(EmcyCode.COMMUNICATION)

    def _run_timers(self) -> None:
        """Lock-step bus: the frames come inline (:meth:`_on_frame`); this thread keeps the timers."""
        while not self._stop.is_set():
            due = self.timers.next_due()
            self._stop.wait(RECV_TIMEOUT if due is None else min(RECV_TIMEOUT, max(due - time.monotonic(), 0.0)))
            with self._lock:
                self._tick(time.monotonic())

    def _on_frame(self, message: can.Message) -> None:
        """Lock-step bus: one frame, in the sender's thread."""
        with self._lock:
            self._take(message)

    def _take(self, message: can.Message) -> None:
        """One received frame (the lock held): used unless silent, an error, remote or extended frame."""
        if not (self.silent or message.is_error_frame or message.is_remote_frame or message.is_extended_id):
            self._guarded_dispatch(message)

    def _receive(self, bus: can.BusABC, timeout: float) -> can.Message | None:
        """The next frame within ``timeout`` s, or None; a receive error is counted and dropped,
        and re-raised only when every receive failed for :data:`RECEIVE_FAILURE_TIME` s, at least
        :data:`MAX_RECEIVE_ERRORS_IN_ROW` times: a dead interface, not a burst of bad datagrams
        (those drain in milliseconds, and the first receive that works starts the count over)."""
        try:
            message = bus.recv(timeout)
        except Exception as exc:  # any interface's receive failure
            now = time.monotonic()
            self.counters.receive_errors += 1
            self._errors_in_row += 1
            if self._errors_in_row == 1:
                self._failing_since = now
                logger.warning("node %d: bus receive failed: %r", self.node_id, exc)
            if self._errors_in_row >= MAX_RECEIVE_ERRORS_IN_ROW and now - self._failing_since >= RECEIVE_FAILURE_TIME:
                raise
            return None
        if self._errors_in_row > 1:
            logger.warning("node %d: bus receive failed %d times in a row", self.node_id, self._errors_in_row)
        self._errors_in_row = 0
        return message

    def _tick(self, now: float) -> None:
        """Heartbeat out if due; the consumer and the RPDO deadlines."""
        if self.timers.heartbeat_due(now):
            self._send(HEARTBEAT_BASE + self.node_id, bytes([self.nmt]))
        for expiry in self.timers.expired(now):
            if expiry.watchdog is Watchdog.HEARTBEAT:
                logger.warning("node %d: heartbeat of node %s lost", self.node_id, self.timers.consumer_node)
                self._watchdog(EmcyCode.HEARTBEAT)
            elif self.nmt is NmtState.OPERATIONAL:
                logger.warning("node %d: RPDO%d missed its deadline", self.node_id, expiry.rpdo)
                self._watchdog(EmcyCode.RPDO_TIMEOUT)

    def _watchdog(self, code: int) -> None:
        self.emergency.communication_error(code, announce=False)
        if not self.drive.connection_lost(code):
            self.emergency.send(code)
        self._send_event_tpdos()

    def _guarded_dispatch(self, message: can.Message) -> None:
        try:
            self._dispatch(message)
        except Exception as exc:  # a frame canopen's handlers cannot take: drop it, keep serving
            self.counters.malformed_frames += 1
            logger.debug("node %d: frame 0x%03X %s dropped: %r", self.node_id, message.arbitration_id,
                         bytes(message.data).hex(), exc)

    def _dispatch(self, message: can.Message) -> None:
        cob_id = message.arbitration_id
        nmt = self.nmt
        if cob_id == NMT_COB_ID:
            self._on_nmt(message.data)
            return
        if cob_id == self._comm.sync_cob:
            if self.bus_meter is not None:
                self.bus_meter.sync(min(len(message.data), 8))
            if nmt in _SERVING:
                if message.data:
                    self.counters.malformed_frames += 1
                    self.emergency.communication_event(EmcyCode.SYNC_LENGTH)
                else:
                    self._engine.on_sync(message.timestamp, nmt is NmtState.OPERATIONAL)
            return
        engine = self._engine
        if self.bus_meter is not None and cob_id not in engine.tx_cobs and cob_id != self._node.emcy.cob_id:
            self.bus_meter.frame(len(message.data))
        channel = engine.rx_by_cob.get(cob_id)
        if channel is not None:
            if nmt is NmtState.OPERATIONAL and engine.on_rpdo(channel, message, self._comm.sync_window_us):
                self.timers.rpdo_seen(channel.number, time.monotonic())
                if EmcyCode.RPDO_TIMEOUT in self.emergency.active:
                    self.emergency.communication_recovered(EmcyCode.RPDO_TIMEOUT)
            return
        if HEARTBEAT_BASE < cob_id <= HEARTBEAT_BASE + 127:
            if self.timers.heartbeat_seen(cob_id - HEARTBEAT_BASE, time.monotonic()):
                self.emergency.communication_recovered(EmcyCode.HEARTBEAT)
            return
        if nmt not in _SERVING:
            return  # STOPPED: nothing but NMT
        if cob_id == self._node.sdo.rx_cobid and len(message.data) != SDO_FRAME_LENGTH:
            self.counters.malformed_frames += 1  # CiA 301: every SDO frame carries 8 bytes
            return
        if self._network is not None:  # None only once stopped
            self._network.notify(cob_id, message.data, message.timestamp)
        self._send_event_tpdos()

    # ----------------------------------------------------------------- SDO bridge
    def _on_sdo_read(self, index: int, subindex: int, od: Any) -> int | float | None:
        if subindex == 0 and index in self.drive.readable_objects():
            return self.drive.read_object(index)
        if subindex and self._manufacturer is not None and self._manufacturer.owns(index):
            return self._manufacturer.read(index, subindex)
        if index == ERROR_REGISTER:
            return self.emergency.register
        return None

    def _on_sdo_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        value = od.decode_raw(data)
        if subindex == 0 and index in self.drive.readable_objects():
            try:
                self.drive.write_object(index, value)
            except ObjectAccessError as exc:
                raise SdoAbortedError(_ABORTS[exc.reason]) from exc
        elif self._manufacturer is not None and self._manufacturer.owns(index):
            self._manufacturer.write(index, subindex, value)
        elif self._pdos.owns(index):
            self._pdos.write(index, subindex, value)
        elif self._comm.owns(index):
            self._comm.write(index, subindex, value)
