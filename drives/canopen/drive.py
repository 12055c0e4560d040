"""CiA-402 master over CANopen: one servo drive in cyclic synchronous torque mode.

Built on ``canopen`` (NMT, SDO, EMCY and heartbeat consumers, PDO configuration) and
``python-can`` (any interface).  The master is the SYNC producer.  One cycle is::

    read_inputs()          SYNC  ->  drive samples, sends TPDO1 (statusword, velocity[, position])
    write_outputs(torque)  RPDO1 (controlword, target torque)  ->  applied at the next SYNC

(more TPDOs or RPDOs where the drive's PDOs make commissioning split the objects).

The pieces: :mod:`~drives.canopen.link` (the network and who owns it),
:mod:`~drives.canopen.commissioning` (NMT, PDO mapping, scaling), :mod:`~drives.canopen.sync_cycle`
(the cycle on the wire: SYNC out, TPDOs in, read in the control thread),
:mod:`~drives.canopen.exchange` (this drive's TPDO layout, RPDOs and counters),
:mod:`~drives.canopen.events` (EMCY, heartbeat, NMT state).  A drive alone owns the cycle of
its one exchange; the drives of :mod:`~drives.canopen.axes` share one, which runs their cycles
(one SYNC for all), and run none of their own (one axis there: the drive runs that cycle of one).

Safety: a missing TPDO for ``max_missed_tpdos`` consecutive cycles, a heartbeat loss, an
EMCY, a malformed EMCY or heartbeat, a fault bit, the node leaving NMT OPERATIONAL or a bus
that cannot be read make the master send zero torque with the safe controlword (DISABLE
VOLTAGE) plus one SYNC so that it is applied, *then* raise a :class:`~drives.errors.DriveError`.
Until :meth:`CanopenDrive.fault_reset` or :meth:`CanopenDrive.enable`, every
``write_outputs`` sends that safe frame instead of the caller's torque.

A connected drive: the object is built without touching the bus; ``connect()`` returns a
:class:`~drives.canopen.connection.CanopenConnection` (node, SDO access, events, what
commissioning found) built whole, which the drive keeps until ``close()``.  The drive stays the
one object users hold (the controller, the CLI and the multi-axis master keep one name for one
drive through connect, runs, reconnects and close), and its methods that need the bus take the
connection first (``DriveError`` "not connected" otherwise), so nothing checks for a part that is
None.  A loop takes its cycles from ``with drive.cyclic(limit) as cycle``
(:class:`~drives.base.DriveCycle`): the bus read in the control thread from then on, the way
frames are sent resolved at connect, ``read``/``saturate``/``write`` bound once.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import os
from collections.abc import Sequence
from typing import Any

import can
import canopen
from canopen import objectdictionary as od

from drives.base import CyclicInputs, DriveCycle
from drives.canopen.commissioning import Commissioned, Commissioning, CommissioningSettings
from drives.canopen.connection import CanopenConnection
from drives.canopen.events import DriveEvents
from drives.canopen.exchange import CanopenExchange, CanopenStats
from drives.canopen.heartbeat import HeartbeatProducer
from drives.canopen.inventory import MAX_MAPPING_ENTRIES
from drives.canopen.link import NetworkLink
from drives.canopen.master_dictionary import load_object_dictionary
from drives.canopen.pdo_codec import PdoCodec, object_spec
from drives.canopen.pdo_plan import pack
from drives.canopen.sdo import SdoAccess
from drives.canopen.sync_cycle import SyncCycle
from drives.cia301 import CONSUMER_HEARTBEAT_TIME, NODE_ID_RANGE, NODE_IDS, PRODUCER_HEARTBEAT_TIME, NmtCommand
from drives.cia402 import (
    CONTROLWORD,
    POSITION_ACTUAL,
    SAFE_CONTROLWORD,
    STATUSWORD,
    TARGET_TORQUE,
    VELOCITY_ACTUAL,
    DataType,
    ObjectSpec,
    State,
    decode_statusword,
)
from drives.cia402_master import Cia402Master
from drives.errors import DriveError, DriveProtocolError, DriveTimeout, ParameterError
from drives.safety import DEFAULT_SAFETY, SafetySettings

logger = logging.getLogger(__name__)

DEFAULT_TPDO: tuple[ObjectSpec, ...] = (STATUSWORD, VELOCITY_ACTUAL)
DEFAULT_TPDO_WITH_POSITION: tuple[ObjectSpec, ...] = (STATUSWORD, VELOCITY_ACTUAL, POSITION_ACTUAL)
DEFAULT_RPDO: tuple[ObjectSpec, ...] = (CONTROLWORD, TARGET_TORQUE)


def split_into_frames(objects: Sequence[ObjectSpec | int]) -> list[tuple[ObjectSpec, ...]]:
    """Pack ``objects`` in order into as few CAN frames (<= 8 bytes each) as that order allows."""
    specs = [object_spec(obj) for obj in objects]
    return [frame for _, frame in pack(specs, [MAX_MAPPING_ENTRIES] * len(specs)) or ()]


def _check(name: str, ok: bool, value: object, allowed: str) -> None:
    if not ok:
        raise ParameterError(name, value, allowed, "CANopen drive")


class CanopenDrive(Cia402Master[CanopenConnection]):
    """A CiA-402 servo drive on CANopen, driven in cyclic synchronous torque mode.

    Bus, one of: ``network`` (a :class:`canopen.Network`, connected or not), ``bus`` (a
    :class:`can.BusABC`), or ``interface``/``channel``/``bitrate``/``bus_kwargs`` with
    python-can's configuration chain filling the gaps (env ``CAN_INTERFACE`` ..., ``~/.canrc``);
    see :mod:`drives.canopen.link` for what closing gives back.

    ``eds``: the drive's EDS (path or object dictionary); None (default) uses the standard
    CiA-301/402 dictionary.  ``period`` (s) is the cycle time written to 0x1006.
    ``tpdo_objects`` are the objects the drive sends each cycle, in order, packed into
    TPDO1.. (8 bytes each; must hold 0x6041 and 0x606C; the default,
    :data:`DEFAULT_TPDO_WITH_POSITION`, adds 0x6064 in TPDO2: the controller's port observer
    needs it; :data:`DEFAULT_TPDO` leaves it out); the RPDO carries 0x6040 +
    0x6071.  That is the plan for a drive whose PDOs allow it: connect() reads what the drive
    has and, where its mapping records hold fewer entries or it refuses a mapping, splits the
    objects further or takes its default mapping (:mod:`drives.canopen.pdo_plan`;
    ``commissioned.mapping_notes`` says so), and ``tpdo_codecs`` are then the ones in use.
    All are transmission type 1 (every SYNC); unused PDOs are invalidated.  What the drive
    lacks of the safety chain is one warning per object (``safety_warnings``), or a refusal
    with ``safety.strict``; no object the drive lacks is ever written, at connect or close.
    ``cycle`` and ``heartbeat``: a SYNC cycle (:mod:`drives.canopen.sync_cycle`, on its link) and the
    master's heartbeat producer the caller owns (:mod:`drives.canopen.axes`): the drive joins the
    cycle -- one of several drives is marked ``shared``, and the drive runs none of its own; one it
    alone joins it runs as its own -- connect() opens the link and starts the heartbeat if they are
    not yet, close() leaves a shared link or heartbeat running.  Timeouts in s (``tpdo_timeout``:
    how long the drive's own cycle waits for its TPDOs, default 50 ms and never more than half the
    shortest stall that faults the drive, :meth:`~drives.safety.SafetySettings.longest_tpdo_wait`;
    a given cycle has its own);
    ``max_missed_tpdos`` consecutive cycles without TPDO raise DriveTimeout; heartbeat times in
    ms (consumer default 3x producer; 0 disables).
    ``scaling``: the caller's :class:`~drives.base.DriveScaling` (``scaling_source`` labels it
    in the report, e.g. "profile [device]").  connect() takes each field from the drive where it states it --
    manufacturer scaling objects an EDS names, else the standard objects (0x6076, 0x6072 and
    the factor group 0x608F/0x6090/0x6091/0x6092/0x60A8/0x60A9, :mod:`drives.factor_group`) --
    and from the caller otherwise; two sources of a field that disagree beyond the rounding of
    the drive's objects raise a :class:`~drives.errors.DriveError` (the drive is never
    enabled), a field neither gives makes connect() fail naming it.  After connect(),
    ``scaling_report`` (:class:`~drives.base.ScalingReport`) says where each factor came from,
    ``scaling_sources`` the same as field -> source.
    """

    stats: CanopenStats

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
        eds: str | os.PathLike[str] | od.ObjectDictionary | None = None,
        period: float = 0.001,
        tpdo_objects: Sequence[ObjectSpec | int] = DEFAULT_TPDO_WITH_POSITION,
        scaling: Any = None,
        scaling_source: str = "caller",
        sdo_timeout: float = 0.3,
        boot_timeout: float = 1.0,
        state_timeout: float = 1.0,
        tpdo_timeout: float | None = None,
        max_missed_tpdos: int = 3,
        heartbeat_producer_ms: int = 100,
        heartbeat_consumer_ms: int | None = None,
        reset_communication: bool = True,
        check_device_type: bool = True,
        safety: SafetySettings = DEFAULT_SAFETY,
        cycle: SyncCycle | None = None,
        heartbeat: HeartbeatProducer | None = None,
    ) -> None:
        low, high = NODE_ID_RANGE
        _check("node_id", isinstance(node_id, int) and low <= node_id <= high, node_id, NODE_IDS)
        _check("period", 1e-6 <= period <= 4294.967295, period, "1e-6..4294.967295 s (0x1006 in us)")
        _check("max_missed_tpdos", max_missed_tpdos >= 1, max_missed_tpdos, ">= 1")
        _check("heartbeat_producer_ms", 0 <= heartbeat_producer_ms <= 0xFFFF, heartbeat_producer_ms, "0..65535 ms")
        if heartbeat_consumer_ms is None:
            heartbeat_consumer_ms = 3 * heartbeat_producer_ms
        _check("heartbeat_consumer_ms", heartbeat_consumer_ms >= 0, heartbeat_consumer_ms, ">= 0 ms (0 disables)")
        frames = split_into_frames(tpdo_objects)
        _check("tpdo_objects", 1 <= len(frames) <= 4, len(frames), "objects that fit 1..4 TPDOs (1..32 bytes)")
        flat = [(spec.index, spec.subindex) for frame in frames for spec in frame]
        for required in (STATUSWORD, VELOCITY_ACTUAL):
            _check("tpdo_objects", (required.index, 0) in flat, [f"0x{i:04X}" for i, _ in flat],
                   f"a mapping that holds 0x{required.index:04X} ({required.name})")
        _check("master_node_id", safety.master_node_id != node_id, safety.master_node_id,
               f"a node id other than the drive's ({node_id})")

        stats = CanopenStats()
        self._init_master(f"CANopen node {node_id}", stats, scaling, scaling_source)
        self.node_id = node_id
        self.eds = eds
        self.state_timeout = state_timeout
        self.max_commands_per_step = max(100, int(4 * state_timeout / max(period, 1e-4)))
        self.max_missed_tpdos = max_missed_tpdos
        self.settings = CommissioningSettings(period, boot_timeout, sdo_timeout, reset_communication,
                                              check_device_type, heartbeat_producer_ms, heartbeat_consumer_ms)
        self.safety = safety
        _check("cycle", cycle is None or (network is None and bus is None and interface is None and channel is None),
               "a shared cycle", "no network, bus, interface or channel besides it")
        self.heartbeat = heartbeat if heartbeat is not None else HeartbeatProducer(
            safety.master_node_id or 0, safety.heartbeat_ms / 1000.0 if safety.master_node_id is not None else 0.0)
        self.link = cycle.link if cycle is not None else NetworkLink(
            self.name, network=network, bus=bus, bus_args=(interface, channel, bitrate, dict(bus_kwargs or {})))
        self.tpdo_objects = tuple(spec for frame in frames for spec in frame)
        tpdo_codecs = tuple(PdoCodec(frame, name=f"TPDO{n} of node {node_id}") for n, frame in enumerate(frames, 1))
        self.exchange = CanopenExchange(self.name, self.link, tpdo_codecs,
                                        (PdoCodec(DEFAULT_RPDO, name=f"RPDO1 of node {node_id}"),), stats)
        self.cycle = cycle if cycle is not None else SyncCycle(self.name, self.link,
                                                               safety.longest_tpdo_wait(period, tpdo_timeout))
        self.cycle.join(self.exchange)
        self._missed_in_row = 0

    @property
    def period(self) -> float:
        """The cycle period in s (0x1006)."""
        return self.settings.period

    @property
    def tpdo_codecs(self) -> tuple[PdoCodec, ...]:
        """The codecs of TPDO1.. in order."""
        return self.exchange.tpdo_codecs

    @property
    def commissioned(self) -> Commissioned | None:
        """What commissioning found (None before connect and after close)."""
        return self.connection.commissioned if self.connection is not None else None

    @property
    def nmt_state(self) -> int | None:
        """The NMT state the drive's last heartbeat showed (0x05 OPERATIONAL, ...)."""
        return self.connection.events.nmt_state if self.connection is not None else None

    @property
    def device_type(self) -> int | None:
        """0x1000 as commissioning read it (None before connect, or with the check off)."""
        return self.connection.commissioned.device_type if self.connection is not None else None

    @property
    def safety_warnings(self) -> tuple[str, ...]:
        """What commissioning found missing in the drive's safety chain (empty when complete)."""
        return self.connection.commissioned.safety_warnings if self.connection is not None else ()

    @property
    def last_emcy(self) -> canopen.emcy.EmcyError | None:
        """The newest EMCY other than an error reset."""
        return self.connection.events.last_emcy if self.connection is not None else None

    # ------------------------------------------------------------------ connection

    def _establish(self) -> CanopenConnection:
        """NMT, SDO, PDO mapping, 0x1006, heartbeat (connect() calls it); raise DriveTimeout."""
        try:
            dictionary = load_object_dictionary(self.eds, self.node_id)
        except (OSError, ValueError, KeyError) as exc:
            raise DriveProtocolError(self.name, f"cannot load the object dictionary {self.eds!r}: {exc}") from exc
        network = self.link.open()
        node: canopen.RemoteNode | None = None
        events: DriveEvents | None = None
        try:
            node = canopen.RemoteNode(self.node_id, dictionary)
            network.add_node(node)
            events = DriveEvents(self.name, node, network, self.stats)
            sdo = SdoAccess(self.name, node, self.settings.sdo_timeout, self.cycle.end)
            commissioning = Commissioning(self.name, node, sdo, events, self.settings, self.safety)
            answered = commissioning.refuse_another_master()
            if network.bus is None:
                raise DriveError(self.name, "the CAN network has no bus after connecting")
            self.heartbeat.start(self.link.send)  # boot-up first, before the drive is touched
            found = commissioning.run(self.tpdo_objects, DEFAULT_RPDO, answered=answered)
            self.exchange.configure(found.tpdo_codecs, found.tpdo_cobs, found.rpdo_codecs, found.rpdo_cobs)
            self.cycle.configure()
            self._adopt_scaling(found.scaling, found.scaling_notes)
            beats = found.inventory.has(PRODUCER_HEARTBEAT_TIME)  # a drive without 0x1017 sends no heartbeat
            events.heartbeat_limit = self.settings.heartbeat_consumer_ms / 1000.0 if beats else 0.0
            events.clear()
        except BaseException:
            self._release(node, events)
            raise
        return CanopenConnection(node, sdo, events, found)

    def _clear_events(self) -> None:
        self._missed_in_row = 0
        if self.connection is not None:
            self.connection.events.clear()

    # ------------------------------------------------------------------ acyclic

    def sdo_read(self, index: int, subindex: int = 0) -> bytes:
        """Upload ``index:subindex`` (raw bytes); DriveRefusal on abort, DriveTimeout on silence."""
        return self.connected().sdo.upload(index, subindex)

    def sdo_write(self, index: int, subindex: int, data: bytes) -> None:
        """Download raw ``data`` to ``index:subindex``; DriveRefusal on abort, DriveTimeout on silence."""
        self.connected().sdo.download(index, subindex, data)

    def read_object(self, spec: ObjectSpec | int) -> int:
        """Read a CiA-402 object (ObjectSpec or index of drives.cia402) over SDO, in drive units."""
        sdo = self.connected().sdo
        spec = object_spec(spec)
        return sdo.read_int(spec.index, spec.subindex, spec.data_type)

    def write_object(self, spec: ObjectSpec | int, value: int) -> None:
        """Write a CiA-402 object (ObjectSpec or index of drives.cia402) over SDO, in drive units."""
        sdo = self.connected().sdo
        spec = object_spec(spec)
        low, high = spec.data_type.range
        if not low <= value <= high:
            raise ParameterError(f"0x{spec.index:04X} ({spec.name})", value, f"{spec.data_type.name} [{low}, {high}]")
        sdo.write_int(spec.index, spec.subindex, spec.data_type, value)

    # ------------------------------------------------------------------ cyclic hot path

    def read_inputs(self) -> CyclicInputs:
        """Send SYNC, wait for this cycle's TPDOs (<= tpdo_timeout s) and decode them; raise on fault/timeout."""
        return self._cycle_inputs(self.connected().events, self._own_cycle())

    def _own_cycle(self) -> SyncCycle:
        """The cycle this drive runs; DriveError where it shares one with other drives (their master runs it)."""
        if self.cycle.shared:
            raise DriveError(self.name, "this drive shares a SYNC with other drives: its cycles run there "
                                        "(drives.canopen.axes)")
        return self.cycle

    def _bind_cycle(self) -> DriveCycle:
        """The cycle's read bound to this connection's events and to the drive's own cycle, the bus read
        in this thread from here; its write sends the controller's heartbeat when one is due
        (:meth:`_phase_duties`)."""
        events = self.connected().events
        cycle = self._own_cycle()
        cycle.begin()
        return DriveCycle(self.name, functools.partial(self._cycle_inputs, events, cycle), self.clamp,
                          self._send_and_beat)

    def _phase_duties(self) -> contextlib.AbstractContextManager[None]:
        """The cyclic phase sends the controller's heartbeat from the cycle, its thread silenced
        (:meth:`~drives.canopen.heartbeat.HeartbeatProducer.from_cycle`).  The bus stays read
        directly when it ends (the next SDO access gives it back to canopen's notifier): stopping
        that notifier again for the disabling walk would hold the drive's RPDOs up by its receive
        timeout, against an RPDO deadline of a few periods."""
        return self.heartbeat.from_cycle(self.period)

    def _send_and_beat(self, target_torque: int) -> None:
        """The cycle's outputs (:meth:`_send_torque`), then the heartbeat if one is due."""
        self._send_torque(target_torque)
        self.heartbeat.tick()

    def _cycle_inputs(self, events: DriveEvents, cycle: SyncCycle) -> CyclicInputs:
        """One cycle's inputs (:meth:`read_inputs`) from ``cycle``, the bus read in this thread again
        only where an SDO access gave it back to canopen's notifier."""
        try:
            if not self.link.direct:
                cycle.begin()
            cycle.drain()
            check = events.check if self._tripped is None else None
            [found] = cycle.sync_and_collect(check)  # the frames before the SYNC, handed on after it, checked then
            if check is not None:  # and those that came while the TPDOs were awaited
                check()
        except DriveError as error:
            raise self.trip(error) from error.__cause__
        return self.take_inputs(found, cycle.timeout)

    def take_inputs(self, found: CyclicInputs | None, timeout: float) -> CyclicInputs:
        """This drive's inputs of a cycle that collected ``found`` (None: one of its TPDOs did not arrive
        within ``timeout`` s): accepted (:meth:`accept_inputs`), or its last inputs again with ``age``
        counting the cycles missed in a row; at ``max_missed_tpdos`` of them the drive trips and the
        DriveTimeout is raised."""
        if found is not None:
            self._missed_in_row = 0
            return self.accept_inputs(found)
        self.stats.missed_tpdos += 1
        self._missed_in_row += 1
        if self._missed_in_row >= self.max_missed_tpdos:
            cobs = ", ".join(f"0x{cob:03X}" for cob in self.exchange.tpdo_cobs)
            zeroed = "; torque set to zero" if self._armed else ""  # before the enable there was none to zero
            dropped = self.stats.dropped_frames
            wrong = (f"; {dropped} frame{'s' if dropped > 1 else ''} on these COB-IDs had another length than the "
                     f"mapping commissioned and {'were' if dropped > 1 else 'was'} dropped") if dropped else ""
            raise self.trip(DriveTimeout(self.name, f"no TPDO (COB-ID {cobs}) for {self._missed_in_row} consecutive "
                                                    f"cycles (timeout {timeout * 1e3:g} ms each){wrong}{zeroed}"))
        last = self.last_inputs if self.last_inputs is not None else CyclicInputs(0, 0)
        return dataclasses.replace(last, age=self._missed_in_row)

    def _fault_detail(self) -> tuple[str, int | None]:
        return self.connection.events.fault_detail() if self.connection is not None else ("", None)

    def _send_outputs(self, controlword: int, target_torque: int) -> None:
        try:
            self.exchange.send_rpdo(controlword, target_torque)
        except DriveError as error:
            raise self.trip(error) from error.__cause__

    def _send_safe_outputs(self) -> None:
        """Zero torque with DISABLE VOLTAGE, then one SYNC so that a synchronous drive applies it; on a
        shared cycle no SYNC (its master sends one after every drive's safe outputs)."""
        if self.cycle.shared:
            self.exchange.send_safe()
        else:
            self.cycle.send_safe()

    # ------------------------------------------------------------------ state machine

    def _command(self, controlword: int) -> int:
        """One exchange for the state machine: SYNC/TPDO, then RPDO(controlword, 0); the statusword."""
        [inputs] = self._own_cycle().command([controlword])
        self.last_inputs = inputs
        return inputs.statusword

    def state(self) -> State | None:
        """The drive's CiA-402 state: one SYNC/TPDO exchange, answered with the held controlword and zero torque."""
        self.connected()
        return decode_statusword(self._command(self.hold_word()))

    def mark_enabled(self) -> None:
        """OPERATION ENABLED: hold ENABLE OPERATION; a fault bit, an EMCY or a heartbeat loss now trips."""
        super().mark_enabled()
        self.connected().events.armed = True

    def mark_disabled(self) -> None:
        """Hold DISABLE VOLTAGE; EMCYs and NMT changes are news, no longer trips."""
        super().mark_disabled()
        if self.connection is not None:
            self.connection.events.armed = False

    def disable(self) -> None:
        """Zero torque, DISABLE VOLTAGE, and check the drive reaches SWITCH ON DISABLED (or sits in FAULT)."""
        if self.connection is None:
            return
        super().disable()

    def fault_reset(self) -> None:
        """Rising edge of controlword bit 7, then back to 0; check the drive leaves FAULT."""
        if self.connection is not None:
            self.connection.events.armed = False
        super().fault_reset()

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        """Safe outputs and NMT pre-operational if connected, then release the node and (if owned) the bus."""
        if self._closed:
            return
        self._closed = True
        connection, self.connection = self.connection, None
        if connection is None:
            self._release(None, None)
            return
        try:
            self.exchange.send_rpdo(SAFE_CONTROLWORD, 0)
            self._send_safe_outputs()
            connection.node.nmt.send_command(NmtCommand.ENTER_PRE_OPERATIONAL)
            if self.safety.master_node_id is not None and connection.commissioned.inventory.has(CONSUMER_HEARTBEAT_TIME, 1):
                connection.sdo.write_int(CONSUMER_HEARTBEAT_TIME, 1, DataType.UNSIGNED32, 0)  # a clean goodbye
        except Exception as exc:  # a best-effort goodbye: whatever fails here, the bus is released below
            # INFO (-v): a goodbye that fails follows the error that ended the run (a drive gone, its bus
            # gone), which is the command's one line; the drive's heartbeat consumer stops it either way
            logger.info("%s: could not send the closing frames: %s", self.name,
                        exc.message if isinstance(exc, DriveError) else exc)
        self._release(connection.node, connection.events)

    def _release(self, node: canopen.RemoteNode | None, events: DriveEvents | None) -> None:
        """Stop the heartbeat (unless shared), leave the cyclic phase, drop ``events``' subscriptions and
        ``node`` from the network, close the link (unless shared); nothing is sent to the drive."""
        network = self.link.network
        try:
            if not self.heartbeat.shared:
                self.heartbeat.stop()
            self.cycle.end()
            self.exchange.release()
            if events is not None:
                events.release()
            if network is not None and node is not None and network.nodes.get(self.node_id) is node:
                del network[self.node_id]
        except DriveError as exc:
            logger.warning("%s: closing: %s", self.name, exc)
        finally:
            if not self.link.shared:
                self.link.close()

    def __repr__(self) -> str:
        return f"CanopenDrive(node_id={self.node_id}, period={self.period})"
