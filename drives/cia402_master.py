"""What every CiA-402 master does the same way, whatever the fieldbus.

Mode selection, the state-machine walk and the fault reset, and the cyclic safety state both
masters keep: the trip (after which every output is the safe one), the torque clamp
(:class:`~drives.base.TorqueClamp`, at 0x6072), the fault-bit check, the merge of the drive's scaling with the caller's, and the
counters.  A fieldbus master subclasses :class:`Cia402Master` and provides the primitives:

- :meth:`~Cia402Master._command`: send a controlword (zero torque) and return the statusword
  that answers it (CANopen: one SYNC/RPDO/TPDO exchange; Modbus: a register write and read);
- :meth:`~Cia402Master._send_outputs`: put one cycle's controlword and torque on the wire;
- :meth:`~Cia402Master._send_safe_outputs`: one attempt to put zero torque with DISABLE
  VOLTAGE on the wire, never raising (the error being raised matters more);
- :meth:`~Cia402Master.read_object` / :meth:`~Cia402Master.write_object`: acyclic access.
"""

from __future__ import annotations

import abc
import logging
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from drives.base import (
    SCALING_FIELDS,
    SCALING_UNITS,
    CyclicInputs,
    Drive,
    DriveScaling,
    ScalingFactor,
    ScalingReading,
    ScalingReport,
    TorqueClamp,
)
from drives.cia402 import (
    ERROR_CODE,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    SAFE_CONTROLWORD,
    STATE_STATUS_BITS,
    STATUSWORD,
    SUPPORTED_DRIVE_MODES,
    SW_FAULT,
    SW_FOLLOWS_COMMAND,
    SW_STATE_MASK,
    Command,
    ObjectSpec,
    OperationMode,
    State,
    decode_statusword,
    state_name,
    supports,
)
from drives.errors import DriveError, DriveFault, DriveProtocolError, ParameterError
from drives.fault_reset import clear_fault, error_code_text
from drives.ranges import real_in_range
from drives.state_walk import StateWalk

logger = logging.getLogger(__name__)

_ENABLED_BITS = STATE_STATUS_BITS[State.OPERATION_ENABLED]  # statusword & SW_STATE_MASK in that state


@dataclass(slots=True)
class CyclicStats:
    """Counters every master keeps (since construction)."""

    cycles: int = 0  # read_inputs calls that returned inputs
    saturated_outputs: int = 0  # targets the drive's TorqueClamp clamped (at 0x6072, or a caller's lower limit)
    suppressed_outputs: int = 0  # write_outputs replaced by the safe outputs while tripped
    safe_stops: int = 0


Found = tuple[float | int, str] | Sequence[ScalingReading]
REL_FLOOR = 1e-9  # relative: what any two exact sources may differ by (decimal profile values, float derivations)
REAL32_ROUNDING = 2.0**-24  # relative: a REAL32 object's rounding


def _readings(item: Found) -> tuple[ScalingReading, ...]:
    """A drive's readings of one field: a ``(value, source)`` pair (exact) or readings as they are."""
    if isinstance(item, tuple) and len(item) == 2 and isinstance(item[1], str):
        return (ScalingReading(item[0], item[1]),)
    return tuple(item)


def _check_reading(node: str, name: str, reading: ScalingReading) -> None:
    value = reading.value
    if name == "max_torque_permille":
        if not (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 0xFFFF):
            raise DriveProtocolError(node, f"scaling {name} = {value!r} (from {reading.source}); must be a whole "
                                           "number in 1..65535")
        return
    try:
        real_in_range(name, value, 0.0, math.inf, low_inclusive=False)
    except ParameterError as error:
        raise DriveProtocolError(node, f"scaling {name} = {value!r} (from {reading.source}); must be "
                                       f"{error.allowed}") from None


def _agree(node: str, name: str, used: ScalingReading, other: ScalingReading) -> None:
    """DriveError (a scaling conflict naming both sources) unless ``other`` equals ``used`` within the larger
    rounding of the two (at least REL_FLOOR)."""
    scale = max(abs(used.value), abs(other.value))
    relative = abs(used.value - other.value) / scale if scale else 0.0
    tolerance = max(REL_FLOOR, used.tolerance, other.tolerance)
    if relative > tolerance:
        unit = f" {SCALING_UNITS[name]}" if SCALING_UNITS.get(name) else ""
        raise DriveError(
            node,
            f"scaling conflict for {name}: {used.value:.12g}{unit} from {used.source} but {other.value:.12g}{unit} from "
            f"{other.source} (relative difference {relative:.3g}, more than the {tolerance:.3g} the objects' rounding "
            f"allows); correct the profile or the drive's objects, the drive is not enabled",
        )


def merge_scaling(
    node: str, given: DriveScaling | None, found: Mapping[str, Found], given_source: str = "caller",
    notes: Sequence[str] = (),
) -> tuple[DriveScaling, ScalingReport]:
    """The drive's scaling: per field, the first of the drive's readings (``found``: field ->
    readings in order of precedence, or one ``(value, source)`` pair), else the caller's
    (``given``, labelled ``given_source``).

    Every other reading of a field must agree with the one used within the larger of their
    roundings (a :class:`DriveError` names both).  :class:`DriveProtocolError` names a field
    no one gives, or a value the drive reports that cannot be a scaling factor.  Returns the
    scaling and the :class:`ScalingReport` of where each factor came from (``notes`` appended).
    """
    factors = []
    missing = []
    for name in SCALING_FIELDS:
        readings = _readings(found[name]) if name in found else ()
        for reading in readings:
            _check_reading(node, name, reading)
        if given is not None:
            readings += (ScalingReading(getattr(given, name), given_source),)
        if not readings:
            missing.append(name)
            continue
        used, others = readings[0], readings[1:]
        for other in others:
            _agree(node, name, used, other)
        factors.append(ScalingFactor(name, used, others))
    if missing:
        raise DriveProtocolError(
            node, f"scaling unknown for {', '.join(missing)}: the drive has no objects for them; pass scaling=DriveScaling(...)"
        )
    scaling = DriveScaling(**{f.name: f.used.value for f in factors})  # type: ignore[arg-type]
    return scaling, ScalingReport(tuple(factors), tuple(notes))


ConnectionT = TypeVar("ConnectionT")


class Cia402Master(Drive, Generic[ConnectionT]):
    """Mode selection, state-machine walks, fault reset, the cyclic safety state, and the connection's life.

    Subclasses call :meth:`_init_master` from their constructor, set ``state_timeout``
    (s, per state-machine step) and ``max_commands_per_step`` (a bound on the exchanges one
    step may take besides the time), and implement ``_establish`` (reach and configure the drive
    over their bus: the ``ConnectionT`` that :meth:`connect` keeps as ``connection`` until
    their ``close()``).
    """

    state_timeout: float
    max_commands_per_step: int
    stats: CyclicStats
    connection: ConnectionT | None  # what connect() built, until close()

    def _init_master(self, name: str, stats: CyclicStats, scaling: DriveScaling | None,
                     scaling_source: str = "caller") -> None:
        self.name = name
        self.stats = stats
        self._given_scaling = (scaling, scaling_source)  # the caller's, and its label in the report
        self.scaling = scaling  # type: ignore[assignment]  # complete after connect()
        self.scaling_report: ScalingReport | None = None  # where each factor came from, after connect()
        self.clamp = TorqueClamp(0x7FFF, stats)  # 0x6072 once the scaling is known
        self.last_inputs: CyclicInputs | None = None
        self._controlword = SAFE_CONTROLWORD
        self._armed = False  # OPERATION ENABLED reached: the fault bit raises
        self._tripped: DriveError | None = None
        self._selected: OperationMode | None = None  # select_mode()'s, for the next enable only
        self._follows = False  # statusword bit 12 set when enabled: its clearing trips
        self.connection = None
        self._closed = False

    # ------------------------------------------------------------------ connection

    def connect(self) -> ConnectionT:
        """Reach the drive and configure it over its bus (``_establish``); raise DriveTimeout.  Returns the
        connection (the same one again while connected); DriveError once the drive object is closed."""
        if self._closed:
            raise DriveError(self.name, "the drive object is closed; create a new one")
        if self.connection is None:
            self.connection = self._establish()
        return self.connection

    @abc.abstractmethod
    def _establish(self) -> ConnectionT:
        """Reach and configure the drive over the bus; the new connection (on failure: raise, nothing left open)."""

    def connected(self) -> ConnectionT:
        """The connection; DriveError if there is none (before connect(); after close(), saying so)."""
        connection = self.connection
        if connection is None:
            if self._closed:
                raise DriveError(self.name, "the drive object is closed; create a new one")
            raise DriveError(self.name, "not connected; call connect() first")
        return connection

    # ------------------------------------------------------------------ primitives

    @abc.abstractmethod
    def write_object(self, spec: ObjectSpec | int, value: int) -> None:
        """Write one object acyclically (SDO download, register write) in drive units."""

    @abc.abstractmethod
    def _command(self, controlword: int) -> int:
        """Send ``controlword`` (with zero torque) and return the statusword that answers it."""

    @abc.abstractmethod
    def _send_outputs(self, controlword: int, target_torque: int) -> None:
        """Put one cycle's controlword and target torque on the wire."""

    @abc.abstractmethod
    def _send_safe_outputs(self) -> None:
        """One attempt to put zero torque with DISABLE VOLTAGE on the wire; never raises."""

    def _clear_events(self) -> None:
        """Forget events seen before an enable or a fault reset (subclass hook)."""

    def _before_enable(self) -> None:
        """Bus-specific preparation after the mode is set and before the walk (subclass hook)."""

    # ------------------------------------------------------------------ safety state

    @property
    def tripped(self) -> DriveError | None:
        """The error that made the master send the safe outputs, or None."""
        return self._tripped

    @property
    def scaling_sources(self) -> dict[str, str]:
        """Field -> where its value came from (empty before connect())."""
        return self.scaling_report.sources if self.scaling_report is not None else {}

    def _adopt_scaling(self, found: Mapping[str, Found], notes: Sequence[str] = ()) -> None:
        """Merge the drive's scaling readings with the caller's (:func:`merge_scaling`) and log where each came from."""
        given, source = self._given_scaling
        self.scaling, self.scaling_report = merge_scaling(self.name, given, found, source, notes)
        self.clamp.limit = min(int(self.scaling.max_torque_permille), 0x7FFF)
        for line in self.scaling_report.lines():
            logger.info("%s: scaling %s", self.name, line)

    def trip(self, error: DriveError) -> DriveError:
        """Safe outputs now, every later output safe too (until :meth:`enable` or
        :meth:`fault_reset`); returns ``error`` for ``raise``.  A master of several drives on one
        SYNC trips every drive when one faults."""
        self._controlword = SAFE_CONTROLWORD
        self._armed = False
        self.stats.safe_stops += 1
        self._send_safe_outputs()
        self._tripped = error
        return error

    def accept_inputs(self, inputs: CyclicInputs) -> CyclicInputs:
        """Count a cycle's inputs; once the drive was enabled, trip on the fault bit, and on any
        state but OPERATION ENABLED without it (another master's disable, the drive's own quick
        stop or STO: a run would otherwise go on, and end "completed", with no wall on that axis)
        (the inputs of a cycle this master, or a master of several drives, received)."""
        self.last_inputs = inputs
        self.stats.cycles += 1
        statusword = inputs.statusword
        if self._armed and not statusword & SW_FAULT and (statusword & SW_STATE_MASK) != _ENABLED_BITS:
            state = decode_statusword(statusword)
            raise self.trip(DriveFault(
                self.name,
                f"left OPERATION ENABLED without a fault: statusword 0x{statusword:04X} ({state_name(state)}): "
                "disabled by another master, or stopped by the drive itself (quick stop, STO, its panel); "
                "torque set to zero",
                state=state,
            ))
        if self._follows and self._armed and not statusword & (SW_FOLLOWS_COMMAND | SW_FAULT):
            raise self.trip(DriveFault(
                self.name,
                f"statusword 0x{statusword:04X}: bit 12 cleared, the drive no longer follows the target torque "
                "(its mode changed by another master, 0x6060, or halted); torque set to zero",
                state=decode_statusword(statusword),
            ))
        if statusword & SW_FAULT and self._armed:
            detail, code = self._fault_detail()
            raise self.trip(DriveFault(
                self.name,
                f"fault bit set in statusword 0x{statusword:04X} ({state_name(decode_statusword(statusword))})"
                f"{detail}; torque set to zero",
                code=code,
            ))
        return inputs

    def _fault_detail(self) -> tuple[str, int | None]:
        """Text to append to a fault-bit message and the drive's error code, where known (hook)."""
        return "", None

    def _send_torque(self, target_torque: int) -> None:
        """Send the held controlword and ``target_torque`` (per mille, already saturated by
        ``clamp``); the safe outputs instead while tripped."""
        if self._tripped is not None:
            self.stats.suppressed_outputs += 1
            self._send_outputs(SAFE_CONTROLWORD, 0)
            return
        self._send_outputs(self._controlword, target_torque)

    # ------------------------------------------------------------------ state machine

    def enable(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """Check 0x6502, write 0x6060, await 0x6061, walk to OPERATION ENABLED (timeouts per step)."""
        self.prepare_enable(mode)
        self._walk(State.OPERATION_ENABLED, self.hold_word())
        self.mark_enabled()

    def prepare_enable(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """What :meth:`enable` does before the state-machine walk: check 0x6502, write 0x6060, await
        0x6061, forget the last trip and the events seen.  A master walking several drives on one
        SYNC calls it per drive, walks them together (:func:`~drives.axes_master.walk_together`), then :meth:`mark_enabled`."""
        mode = self._torque_mode(mode)
        self.connected()
        if self._selected is not mode:
            self._select_mode(mode)
        elif (shown := self.read_object(MODES_OF_OPERATION_DISPLAY)) != int(mode):  # one SDO: still the mode selected?
            self._selected = None
            raise DriveFault(self.name, f"0x6061 modes of operation display = {shown}, not {int(mode)} ({mode.name}) "
                                        "selected by select_mode(): the mode was changed meanwhile (another master?)")
        self._selected = None  # a later enable selects it again
        self._before_enable()
        self._tripped = None
        self._clear_events()

    def mark_enabled(self) -> None:
        """The drive reached OPERATION ENABLED: hold ENABLE OPERATION, and a fault bit now trips (so does
        statusword bit 12 cleared, where the drive showed it set: it no longer follows the target torque)."""
        self._controlword = Command.ENABLE_OPERATION.word
        self._armed = True
        last = self.last_inputs
        self._follows = last is not None and bool(last.statusword & SW_FOLLOWS_COMMAND)

    def mark_disabled(self) -> None:
        """From now on DISABLE VOLTAGE is held and the fault bit no longer trips (before a walk to SWITCH ON DISABLED)."""
        self._armed = False
        self._controlword = SAFE_CONTROLWORD

    def disable(self) -> None:
        """Zero torque, DISABLE VOLTAGE, and check the drive reaches SWITCH ON DISABLED (or sits in FAULT)."""
        self.mark_disabled()
        self._walk(State.SWITCH_ON_DISABLED, SAFE_CONTROLWORD, accept=(State.FAULT,))

    def fault_reset(self) -> None:
        """Rising edge of controlword bit 7, then back to 0; check the drive leaves FAULT."""
        self.connected()
        self._armed = False
        self._clear_events()
        self._reset_fault()
        self._controlword = SAFE_CONTROLWORD
        self._tripped = None

    def refuse_fault(self) -> None:
        """:meth:`in_fault` if the drive sits in FAULT now (0x6041 read acyclically): what a run
        checks as soon as the drive is reached, so that a faulted drive is its first and only news."""
        statusword = self.read_object(STATUSWORD)
        if decode_statusword(statusword) is State.FAULT:
            raise self.in_fault(statusword)

    def in_fault(self, statusword: int) -> DriveFault:
        """The error of a drive found in FAULT with ``statusword``: its name, the statusword and its
        error code (0x603F, read now), and that it needs a fault reset."""
        return DriveFault(self.name, f"drive is in FAULT (statusword 0x{statusword:04X}, error code "
                                     f"{error_code_text(self._error_code())}): it needs a fault reset first",
                          state=State.FAULT)

    def _error_code(self) -> int | None:
        """0x603F, or None where it cannot be read."""
        try:
            return self.read_object(ERROR_CODE)
        except DriveError:
            return None

    def hold_word(self) -> int:
        """The controlword this master holds (DISABLE VOLTAGE once tripped)."""
        return self._controlword if self._tripped is None else SAFE_CONTROLWORD

    def select_mode(self, mode: OperationMode = OperationMode.CYCLIC_SYNCHRONOUS_TORQUE) -> None:
        """:meth:`enable`'s first step ahead of it, for the next enable only, which then reads 0x6061
        once to see the mode still selected: a run selects the mode before pre-flight, so that the
        round trips of 0x6502, 0x6060 and 0x6061 (23 ms in all at T = 1 ms over udp_multicast) do
        not lie between pre-flight's last RPDO and the walk's first (the RPDO deadline: 30 periods)."""
        mode = self._torque_mode(mode)  # an invalid mode: said before the drive is asked anything
        self.connected()
        self._select_mode(mode)
        self._selected = mode

    def _torque_mode(self, mode: OperationMode) -> OperationMode:
        """``mode`` (0x6060's code) if it is cyclic synchronous torque, the one mode this master drives;
        said before the drive is asked anything, connected or not: a code that is no mode is a
        :class:`~drives.errors.ParameterError` naming the codes, another mode (7, 8, 9: the cyclic
        position and velocity modes) a :class:`~drives.errors.DriveError`."""
        mode = OperationMode.of(mode)
        if mode is not OperationMode.CYCLIC_SYNCHRONOUS_TORQUE:
            raise DriveError(
                self.name, f"this master drives only CYCLIC_SYNCHRONOUS_TORQUE (10); {mode.name} ({int(mode)}) was asked"
            )
        return mode

    def _select_mode(self, mode: OperationMode) -> None:
        """Check 0x6502 announces ``mode`` (CST only, the one this master drives), write 0x6060
        and wait (``state_timeout``) until 0x6061 shows it."""
        supported = self.read_object(SUPPORTED_DRIVE_MODES)
        if not supports(supported, mode):
            raise DriveError(
                self.name, f"0x6502 supported drive modes = 0x{supported:08X} lacks {mode.name} (bit {mode.supported_bit})"
            )
        self.write_object(MODES_OF_OPERATION, int(mode))
        deadline = time.monotonic() + self.state_timeout
        while (shown := self.read_object(MODES_OF_OPERATION_DISPLAY)) != int(mode):
            if time.monotonic() > deadline:
                raise DriveFault(
                    self.name,
                    f"0x6061 modes of operation display = {shown}, still not {int(mode)} ({mode.name}) "
                    f"{self.state_timeout:.3g} s after writing 0x6060",
                )

    def _walk(self, goal: State, first_word: int, accept: tuple[State, ...] = ()) -> State:
        """Command the state machine to ``goal`` (or a state in ``accept``), starting with
        ``first_word``; :class:`DriveFault` if one step stalls for ``state_timeout``."""
        walk = StateWalk(self, goal, first_word, accept)
        word: int | None = first_word
        while word is not None:
            word = walk.next_word(self._command(word))
        state = walk.state
        assert state is not None  # a walk ends only in a state it arrived at
        return state

    def _reset_fault(self) -> None:
        """The fault-reset sequence (:func:`drives.fault_reset.clear_fault`); DriveFault if the
        drive is still in FAULT (or FAULT REACTION ACTIVE) ``state_timeout`` s after the edge."""
        statusword = clear_fault(self._command, self.state_timeout)
        state = decode_statusword(statusword)
        if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            detail, _ = self._fault_detail()
            raise DriveFault(
                self.name,
                f"still in {state_name(state)} (statusword 0x{statusword:04X}{detail}) {self.state_timeout:.3g} s "
                f"after the fault reset edge: the cause of the fault persists",
                state=state,
            )
