"""Several CiA-402 drives over Modbus, polled in one cycle: the master of a multi-axis device over Modbus.

Each axis is a :class:`~drives.modbus.drive.ModbusDrive` (its own unit id and its own connection,
to one server that serves every unit or to a server per axis), commissioned exactly as a single
drive is: identity, scaling, 0x6007 and the communication watchdog, each read back.  What this
adds is what :class:`drives.canopen.axes.CanopenAxes` adds on one SYNC:

* **one poll per cycle** (:meth:`ModbusAxes.cyclic`, an :class:`~drives.base.AxesDriveCycle`):
  every axis' input block is read, in axis order, before any output goes out; then every axis'
  outputs are written.  Modbus has no SYNC: each drive samples when its read arrives, and its
  torque lands with its write, so the force answering an axis' sample lands at most one whole
  cycle's round trip later -- the loop delay :mod:`drives.modbus.timing` bounds for every axis
  from the whole cycle's measured round trip;
* **one fate**: whatever error any axis meets (a timeout, a dropped connection, an exception
  response, its fault bit), every axis is tripped in that same cycle
  (:func:`~drives.axes_master.trip_together`: each writes its safe outputs, zero torque with
  DISABLE VOLTAGE) and the error is raised;
* **the state machines walked together** (:class:`~drives.axes_master.AxesMaster`,
  :func:`~drives.axes_master.walk_together`): each step one controlword write and statusword
  read per drive, so no drive's watchdog starves while another is being enabled;
* **a unit that does not answer is named**: a server that answers "gateway target failed to
  respond" (0x0B) or "gateway path unavailable" (0x0A) for a unit id is one :class:`DriveError`
  naming the unit and the address, raised at :meth:`ModbusAxes.connect` before anything is written.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence

from drives.axes_master import MAX_AXES, AxesMaster, trip_together
from drives.base import AxesDriveCycle, CyclicInputs, DriveCycle
from drives.errors import DriveError, DriveRefusal, ParameterError
from drives.modbus.drive import ModbusDrive
from drives.modbus.register_map import NO_UNIT_CODES


class _CycleRequests:
    """The cyclic requests of every axis, summed (what :func:`drives.modbus.timing.time_cycles` counts)."""

    def __init__(self, drives: Sequence[ModbusDrive]) -> None:
        self._drives = tuple(drives)

    @property
    def cyclic_requests(self) -> int:
        """Cyclic requests sent to every axis so far."""
        return sum(drive.stats.cyclic_requests for drive in self._drives)


class ModbusAxes(AxesMaster[ModbusDrive]):
    """The Modbus drives ``drives`` (one per axis, in axis order), polled in one cycle; it owns them
    (:meth:`close` closes every one).  Every drive has the same ``cycle`` mode ("split" or "fc23")."""

    def __init__(self, drives: Sequence[ModbusDrive]) -> None:
        axes = tuple(drives)
        if not 1 <= len(axes) <= MAX_AXES:
            raise ParameterError("drives", len(axes), f"1 to {MAX_AXES} Modbus drives, one per axis", "Modbus axes")
        places = [(drive.address, drive.unit_id) for drive in axes]
        if len(set(places)) != len(places):
            raise ParameterError("unit_ids", [unit for _, unit in places], "one unit per axis: no unit id twice at one "
                                 "address", "Modbus axes")
        modes = {drive.cycle for drive in axes}
        if len(modes) != 1:
            raise ParameterError("cycle", sorted(modes), "one cycle mode for every axis", "Modbus axes")
        self.drives = axes
        self.cycle = modes.pop()
        self.stats = _CycleRequests(axes)
        addresses = {drive.address for drive in axes}
        units = ", ".join(str(drive.unit_id) if len(addresses) == 1 else f"{drive.unit_id} at {drive.address}"
                          for drive in axes)
        self.name = f"Modbus units {units}" + (f" at {axes[0].address}" if len(addresses) == 1 else "")

    @property
    def simulated(self) -> bool:
        """True when every axis is the simulated drive (each then states its own loop delay)."""
        return all(drive.simulated_delay is not None for drive in self.drives)

    # ------------------------------------------------------------------ connection

    def _reach(self) -> None:
        """Reach every drive in turn (reads only: identity, scaling, timing), a unit nobody answers for named."""
        for drive in self.drives:
            _reach(drive, several=len(self.drives) > 1)

    # ------------------------------------------------------------------ state machine

    def _command(self, words: list[int]) -> list[int]:
        """Each drive's controlword written (zero torque) and its statusword read, in axis order."""
        return [drive._command(word) for drive, word in zip(self.drives, words)]

    # ------------------------------------------------------------------ cyclic

    @contextlib.contextmanager
    def cyclic(self, torque_limits: Sequence[int | None] | None = None) -> Iterator[AxesDriveCycle]:
        """The cyclic phase of every axis: an :class:`~drives.base.AxesDriveCycle` bound once, each
        axis' clamp held within its ``torque_limits`` entry (per mille; None: its drive's own 0x6072)."""
        self._require_connected()
        limits = self._axis_limits(torque_limits)
        with contextlib.ExitStack() as stack:
            cycles = tuple(stack.enter_context(drive.cyclic(limit)) for drive, limit in zip(self.drives, limits))
            yield AxesDriveCycle(lambda: self._read(cycles), tuple(cycle.saturate for cycle in cycles),
                                 lambda torques: self._write(cycles, torques))

    def read_inputs(self) -> tuple[CyclicInputs, ...]:
        """One poll of every axis' inputs, in axis order (outside a cyclic phase: each drive's
        :meth:`~drives.modbus.drive.ModbusDrive.read_inputs`); any axis' error trips every axis and is raised."""
        self._require_connected()
        try:
            return tuple(drive.read_inputs() for drive in self.drives)
        except DriveError as error:
            raise trip_together(self.drives, error) from error.__cause__

    def write_outputs(self, torques: Sequence[int]) -> None:
        """Every axis' target torque (0x6071, per mille, in axis order), each saturated by its drive's
        clamp; a write that fails trips every axis.  ParameterError for a count other than one per axis,
        then DriveError before :meth:`connect` or after :meth:`close` (nothing written)."""
        self._one_per_axis("torques", len(torques))
        self._require_connected()
        try:
            for drive, torque in zip(self.drives, torques):
                drive.write_outputs(torque)
        except DriveError as error:
            raise trip_together(self.drives, error) from error.__cause__

    def _read(self, cycles: tuple[DriveCycle, ...]) -> tuple[CyclicInputs, ...]:
        """One cycle's inputs of every axis; any axis' error trips every axis and is raised."""
        try:
            return tuple(cycle.read() for cycle in cycles)
        except DriveError as error:
            raise trip_together(self.drives, error) from error.__cause__

    def _write(self, cycles: tuple[DriveCycle, ...], torques: Sequence[int]) -> None:
        """Every axis' saturated target (per mille); a write that fails trips every axis."""
        try:
            for cycle, torque in zip(cycles, torques):
                cycle.write(torque)
        except DriveError as error:
            raise trip_together(self.drives, error) from error.__cause__

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        """Every drive's safe outputs (one attempt each, where its link is up) and its link closed."""
        if self._closed:
            return
        self._closed = True
        self._connected = False
        for drive in self.drives:
            drive.close()


def _reach(drive: ModbusDrive, several: bool) -> None:
    """``drive.connect()``; a unit id the server answers for with a gateway exception is named as such,
    with where that id comes from: one axis' ``--unit-id``, or several axes' ``--unit-ids`` or profile."""
    try:
        drive.connect()
    except DriveRefusal as exc:
        if exc.code not in NO_UNIT_CODES:
            raise
        where = "the unit ids (--unit-ids, or the profile's [[axes]] unit_id)" if several else "the unit id (--unit-id)"
        raise DriveError(drive.name, f"no unit {drive.unit_id} answers at {drive.address} (exception 0x{exc.code:02X}): "
                                     f"check {where}") from exc
