"""Several CiA-402 drives on one CAN bus, one SYNC per cycle: the master of a multi-axis device.

Each axis is a :class:`~drives.canopen.drive.CanopenDrive`, commissioned exactly as a single
drive is: its own NMT, PDO mapping, scaling and its own safety chain -- the heartbeat consumer
0x1016 (watching this controller's one heartbeat), the RPDO deadline 0x1400:05 and 0x6007,
written to each node and read back.  They share one SYNC cycle on one link (one bus, one
canopen network) and one heartbeat producer, which this object owns (the heartbeat sent by the
cycle itself in the cyclic phase, :mod:`~drives.canopen.heartbeat`).  What it adds:

* **one SYNC per cycle** (:class:`~drives.canopen.sync_cycle.SyncCycle`, the one a single drive
  runs too, here of every axis' exchange): every axis' TPDOs (status, velocity, position) are
  collected before any RPDO goes out.  The cycle waits for the last axis, up to
  ``tpdo_timeout`` (never more than half the shortest stall that faults a drive: a silent axis
  must not hold the others' RPDOs past their deadline,
  :meth:`~drives.safety.SafetySettings.longest_tpdo_wait`): an axis whose TPDO missed it hands
  out its last input again with ``age`` counting up
  (:meth:`~drives.canopen.drive.CanopenDrive.take_inputs`), so the cycle is as late as its
  oldest input, and ``max_missed_tpdos`` in a row is a :class:`~drives.errors.DriveTimeout`.
  The axes run no cycle of their own and send no SYNC;
* **one fate**: whatever error any axis meets (its EMCY, its heartbeat lost, its fault bit, its
  TPDOs missing, a send that failed), every axis is tripped in that same cycle -- each gets zero
  torque with DISABLE VOLTAGE, then one SYNC, at which every drive latches it -- and the error
  is raised.  From then on every output is the safe one until :meth:`enable`;
* **one cyclic phase** (:meth:`CanopenAxes.cyclic`, an :class:`~drives.base.AxesDriveCycle` of
  the shape of one drive's): each axis' target saturated by its own drive's clamp, at its own
  limit, counted once in its own ``stats.saturated_outputs``;
* **the state machine walked together** (:class:`~drives.axes_master.AxesMaster`, what the Modbus
  master does alike): one SYNC per step serves every axis' walk
  (:class:`~drives.state_walk.StateWalk`), so no axis is left without SYNC or RPDO while
  another is being enabled, and every drive is enabled (or disabled) in the same cycle.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from typing import Any

import can
from canopen import objectdictionary as od

from drives.axes_master import MAX_AXES, AxesMaster, trip_together
from drives.base import AxesDriveCycle, CyclicInputs, DriveScaling
from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION, CanopenDrive
from drives.canopen.heartbeat import HeartbeatProducer
from drives.canopen.link import NetworkLink
from drives.canopen.sync_cycle import SyncCycle
from drives.errors import DriveError, DriveTimeout, ParameterError
from drives.safety import DEFAULT_SAFETY, SafetySettings


class CanopenAxes(AxesMaster[CanopenDrive]):
    """The drives ``node_ids`` (one per axis, in axis order) on one bus, one SYNC per cycle.

    The bus: an open ``bus`` the caller owns (closing leaves it open, :mod:`~drives.canopen.link`), or
    ``interface``/``channel``/``bitrate``/``bus_kwargs`` as :class:`CanopenDrive` takes them
    (python-can's configuration chain fills the gaps); ``scalings`` one per axis (None: the
    drive's own objects must give it), labelled ``scaling_source``.  One axis is N = 1: its cycle
    serves that one drive and is not ``shared``, so the drive (``drives[0]``) also runs it itself,
    on its scalar path (:meth:`CanopenDrive.cyclic <drives.base.Drive.cyclic>`), which a one-axis
    controller takes.  ``period`` (s), ``tpdo_objects``,
    ``eds``, ``safety`` (``master_node_id`` is this controller's node: one heartbeat for all),
    ``tpdo_timeout`` (s), ``max_missed_tpdos`` and ``heartbeat_consumer_ms`` apply to every axis.
    """

    def __init__(
        self,
        node_ids: Sequence[int],
        *,
        scalings: Sequence[DriveScaling | None],
        bus: can.BusABC | None = None,
        interface: str | None = None,
        channel: Any = None,
        bitrate: int | None = None,
        bus_kwargs: dict[str, Any] | None = None,
        period: float = 0.001,
        tpdo_objects: Sequence[Any] = DEFAULT_TPDO_WITH_POSITION,
        eds: str | os.PathLike[str] | od.ObjectDictionary | None = None,
        scaling_source: str = "caller",
        safety: SafetySettings = DEFAULT_SAFETY,
        tpdo_timeout: float | None = None,
        max_missed_tpdos: int = 3,
        heartbeat_consumer_ms: int | None = None,
    ) -> None:
        nodes = list(node_ids)
        if not 1 <= len(nodes) <= MAX_AXES or len(set(nodes)) != len(nodes):
            raise ParameterError("node_ids", nodes, f"1 to {MAX_AXES} distinct node ids, one per axis", "CANopen axes")
        if len(scalings) != len(nodes):
            raise ParameterError("scalings", len(scalings), f"one per axis ({len(nodes)})", "CANopen axes")
        self.name = "CANopen nodes " + ", ".join(map(str, nodes))
        self.link = NetworkLink(self.name, bus=bus, bus_args=(interface, channel, bitrate, dict(bus_kwargs or {})),
                                shared=True)
        master = safety.master_node_id
        self.heartbeat = HeartbeatProducer(master or 0, safety.heartbeat_ms / 1000.0 if master is not None else 0.0,
                                           shared=True)
        self.cycle = SyncCycle(self.name, self.link, safety.longest_tpdo_wait(period, tpdo_timeout), shared=len(nodes) > 1)
        self.drives = tuple(  # each joins the cycle, in axis order
            CanopenDrive(node, cycle=self.cycle, heartbeat=self.heartbeat, period=period, tpdo_objects=tpdo_objects,
                         scaling=scaling, scaling_source=scaling_source, eds=eds, safety=safety,
                         max_missed_tpdos=max_missed_tpdos, heartbeat_consumer_ms=heartbeat_consumer_ms)
            for node, scaling in zip(nodes, scalings))

    @property
    def node_ids(self) -> tuple[int, ...]:
        """The axes' node ids, in axis order."""
        return tuple(drive.node_id for drive in self.drives)

    # ------------------------------------------------------------------ connection

    def _reach(self) -> None:
        """Open the bus, start this controller's heartbeat and commission every drive in turn."""
        self.link.open()
        for drive in self.drives:
            drive.connect()  # the first starts the shared heartbeat (its boot-up before any drive is touched)

    # ------------------------------------------------------------------ state machine

    def _before_walk(self) -> None:
        """The bus read by canopen's notifier again (mode selection is SDO)."""
        self.cycle.end()

    def _command(self, words: list[int]) -> list[int]:
        """One exchange for the state machines: SYNC, every TPDO, then each drive's RPDO(word, 0)."""
        received = self.cycle.command(words)
        for drive, inputs in zip(self.drives, received):
            drive.last_inputs = inputs
        return [inputs.statusword for inputs in received]

    # ------------------------------------------------------------------ cyclic

    @contextlib.contextmanager
    def cyclic(self, torque_limits: Sequence[int | None] | None = None) -> Iterator[AxesDriveCycle]:
        """The cyclic phase of every axis: an :class:`~drives.base.AxesDriveCycle` bound once (the bus
        read in this thread from here), each axis' clamp -- the one place its target is saturated --
        held within its ``torque_limits`` entry (per mille; None: its drive's own 0x6072) until the
        phase ends."""
        self._require_connected()
        limits = self._axis_limits(torque_limits)
        with contextlib.ExitStack() as stack:
            clamps = tuple(stack.enter_context(drive.clamp.lowered(limit, drive.name))
                           for drive, limit in zip(self.drives, limits))
            stack.enter_context(self.heartbeat.from_cycle(self.drives[0].period))  # the cycle sends it (_send_torques)
            self.cycle.begin()
            yield AxesDriveCycle(self._cycle_inputs, clamps, self._send_torques)

    def read_inputs(self) -> tuple[CyclicInputs, ...]:
        """One SYNC and every axis' inputs of this cycle (an axis whose TPDO missed: its last ones,
        ``age`` counting up); any axis' error trips every axis (module docstring) and is raised."""
        self._require_connected()
        return self._cycle_inputs()

    def _check_events(self) -> None:
        """Every drive not tripped: what its EMCY and heartbeat frames said (a DriveError, the first)."""
        for drive in self.drives:
            if drive.tripped is None:
                drive.connected().events.check()

    def _cycle_inputs(self) -> tuple[CyclicInputs, ...]:
        """One cycle's inputs (:meth:`read_inputs`), the bus read in this thread again only where an
        SDO access gave it back to canopen's notifier."""
        cycle = self.cycle
        drives = self.drives
        try:
            if not self.link.direct:
                cycle.begin()
            cycle.drain()
            collected = cycle.sync_and_collect(self._check_events)  # the frames before the SYNC, checked after it
            self._check_events()  # and those that came while the TPDOs were awaited
            timeout = cycle.timeout
            taken: list[CyclicInputs] = []
            silent: list[DriveTimeout] = []
            for drive, found in zip(drives, collected):
                try:
                    taken.append(drive.take_inputs(found, timeout))
                except DriveTimeout as error:  # every drive silent as long is named, not only the first
                    silent.append(error)
            if silent:
                first, *others = silent
                raise first if not others else DriveTimeout(first.node, f"{first.message} (nor from "
                                                                         f"{', '.join(e.node for e in others)})")
            return tuple(taken)
        except DriveError as error:
            raise self._trip_all(error) from error.__cause__

    def write_outputs(self, torques: Sequence[int]) -> None:
        """Every axis' target torque (0x6071, per mille, in axis order), each saturated by its drive's
        clamp; the safe outputs on every axis once any tripped.  A send that fails trips every axis.
        ParameterError for a count other than one per axis, then DriveError before :meth:`connect` or
        after :meth:`close` (nothing sent)."""
        self._one_per_axis("torques", len(torques))
        self._require_connected()
        self._send_torques([drive.clamp(torque) for drive, torque in zip(self.drives, torques)])

    def _send_torques(self, torques: Sequence[int]) -> None:
        """Every axis' saturated target torque (per mille) with its held controlword (:meth:`write_outputs`),
        then this controller's heartbeat when one is due (in the cyclic phase: the cycle sends it)."""
        try:
            for drive, torque in zip(self.drives, torques):
                drive._send_torque(torque)
        except DriveError as error:
            raise self._trip_all(error) from error.__cause__
        self.heartbeat.tick()

    def _trip_all(self, error: DriveError) -> DriveError:
        """Zero torque with DISABLE VOLTAGE on every axis, then one SYNC: every drive latches it at that SYNC."""
        trip_together(self.drives, error)
        self.cycle.send_safe()
        return error

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        """Safe outputs and one SYNC, then every drive's goodbye (NMT pre-operational, 0x1016 off),
        the heartbeat stopped and the bus released (one axis: its drive's goodbye sends its safe outputs
        and their SYNC).  Never raises for a bus that is gone."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._connected and self.link.network is not None and self.cycle.shared:
                self.cycle.send_safe()
        finally:
            for drive in self.drives:
                drive.close()
            self.heartbeat.stop()
            self.link.close()
            self._connected = False
