"""Bus-independent core of the simulated CiA-402 torque drive around the exact plant.

Any bus front end (CANopen slave, Modbus server) writes the drive's objects with
:meth:`SimulatedDrive.write_object`, reads them with :meth:`SimulatedDrive.read_object`, and
calls :meth:`SimulatedDrive.sync` once per SYNC.  Nothing here touches a bus.

Physics (:mod:`sim_drive.handle`): the handle obeys ``m dv/dt + b v = w(t) + F - Fc sgn(v)``
with ``w`` the operator's force, ``F`` the motor force at the handle, ``F = torque_permille *
rated_torque / 1000 * force_per_torque`` N, and ``Fc`` the hidden Coulomb friction; in the
seed's convention the wall force is ``u = -F``.  Each SYNC advances the plant by exactly ``T``
(virtual time).  The sensor (:mod:`sim_drive.sensor`) then samples 0x606C by the drive's
velocity model (point, average, window, lowpass), adds its hidden noise, and quantises
velocity and position.

Timing (see :class:`~sim_drive.parameters.Timing`): the first SYNC (number 0, t = 0) only
samples.  At SYNC k >= 1 the plant first advances over [t_{k-1}, t_k) with the torque that
applies to that interval, then velocity/position are sampled.  ``CIA402`` applies the torque
latched at SYNC k-1 (written during cycle k-2); ``IDEAL`` applies the target present at SYNC k
(written during cycle k-1, i.e. in answer to sample k-1); ``RECEPTION`` holds the target that
acted before for the first ``reception_delay`` of the interval and the target present at SYNC
k after it (the target written in answer to sample k-1 counts as received ``reception_delay
* T`` after SYNC k-1).

Hidden departures (:class:`~sim_drive.parameters.DeviceParameters`, never served to the master):
``extra_delay`` ``e`` samples puts every target on a delay line, so the force the timing would
switch to at ``s`` within an interval (0, or ``reception_delay``) switches at ``s + e`` instead:
``n = floor(s + e)`` intervals later, ``frac(s + e)`` into the interval (0x6077 still reports the
timing's torque); ``transmission`` moves a :class:`~sim_drive.transmission.TwoMassHandle`, whose
motor side the encoder reads and the torque pushes.

Torque is applied only in OPERATION ENABLED with mode CST (0x6061 = 10) and halt (controlword
bit 8) clear; otherwise 0.  State changes take effect per interval: an interval closed by a
SYNC at which the drive is not enabled carries no torque.  0x6071 saturates at +-0x6072, and
statusword bit 11 (internal limit active) shows it.  0x6060 accepts only 0 and the modes
0x6502 announces.

Quick stop (transition 11) removes the torque; with quick stop option code 0..4 the stop
completes at the next SYNC (transition 12 to SWITCH ON DISABLED), with 5..8 the drive stays
in QUICK STOP ACTIVE and transition 16 is allowed.  Faults pass FAULT REACTION ACTIVE at once
(torque removal is the whole reaction) and land in FAULT.  A lost connection
(:meth:`SimulatedDrive.connection_lost`) with the power stage on does what 0x6007 says.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from drives.cia402 import (
    CW_HALT,
    OBJECTS,
    STATE_STATUS_BITS,
    SW_FOLLOWS_COMMAND,
    SW_INTERNAL_LIMIT_ACTIVE,
    SW_REMOTE,
    SW_VOLTAGE_ENABLED,
    TRANSITION_FAULT,
    TRANSITION_FAULT_REACTION_DONE,
    AbortConnectionOption,
    Command,
    OperationMode,
    State,
    supports,
    transitions,
)
from haptic_bus.errors import HapticBusError
from sim_drive.handle import Handle
from sim_drive.operator import OperatorModel
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.sensor import Sensor, saturate

if TYPE_CHECKING:
    from sim_drive.transmission import TwoMassHandle

logger = logging.getLogger(__name__)

SUPPORTED_DRIVE_MODES = 1 << OperationMode.CYCLIC_SYNCHRONOUS_TORQUE.supported_bit
TRANSITION_QUICK_STOP_DONE = 12
_OPERATION_ENABLED = State.OPERATION_ENABLED  # module constants: enum member lookups are slow
_QUICK_STOP_ACTIVE = State.QUICK_STOP_ACTIVE
_CST = int(OperationMode.CYCLIC_SYNCHRONOUS_TORQUE)
_RANGES = {index: spec.data_type.range for index, spec in OBJECTS.items()}
_VOLTAGE_STATES = frozenset(
    {State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE}
)
POWER_STAGE_ON = frozenset({State.SWITCHED_ON, State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE})
_REACTION_WORDS = {
    AbortConnectionOption.DISABLE_VOLTAGE: Command.DISABLE_VOLTAGE.word,
    AbortConnectionOption.QUICK_STOP: Command.QUICK_STOP.word,
}

StateListener = Callable[[State, State, "int | None"], None]

__all__ = ["ObjectAccessError", "SimulatedDrive", "saturate"]


class ObjectAccessError(HapticBusError):
    """A read or write of a drive object the drive refuses.

    ``reason`` is one of ``"unknown"`` (no such object), ``"read-only"``, ``"range"``
    (value outside the object's data type or allowed values).
    """

    def __init__(self, index: int, reason: str, detail: str = "") -> None:
        self.index = index
        self.reason = reason
        super().__init__(f"object 0x{index:04X}: {reason}" + (f" ({detail})" if detail else ""))


class SimulatedDrive:
    """A CiA-402 cyclic-synchronous-torque drive whose hardware is the exact ``m``/``b`` handle.

    ``parameters``: plant and scaling (:class:`DeviceParameters`, also the power-on values a
    reset restores); ``timing``: when a written torque acts; ``operator``: the hand on the
    handle; ``name`` prefixes log lines.  ``hand_needs_power`` (False: the operator's force acts
    on the plant whatever the drive does, the physics the tests of the plant check): True, the hand
    takes the handle only while the torque is on and lets go of an unpowered one, as ``haptic-bus
    sim`` serves it (a constant push would otherwise carry the handle through a wall during a
    controller's pre-flight, and the controller refuses to enable it there).
    """

    def __init__(
        self,
        parameters: DeviceParameters | None = None,
        timing: Timing | str = Timing.CIA402,
        operator: OperatorModel | None = None,
        *,
        name: str = "sim drive",
        hand_needs_power: bool = False,
    ) -> None:
        self.name = name
        self.parameters = parameters if parameters is not None else DeviceParameters()
        self.power_on_parameters = self.parameters
        self.state = State.SWITCH_ON_DISABLED
        self.state_listeners: list[StateListener] = []
        self.controlword = 0
        self.mode = 0
        self.mode_display = 0
        self.target_torque = 0
        self.quick_stop_option_code = 2
        self.abort_connection_option_code = int(AbortConnectionOption.FAULT)
        self.error_code = 0
        self.sync_count = 0
        self.hand_needs_power = hand_needs_power
        self._interval: float | None = None  # the closing interval's length, s (None: T)
        self._latched = 0  # per mille: cia402, latched at the last SYNC; reception, acting since the last switch
        self._newton_per_permille = self.parameters.rated_torque_mnm / 1e6 * self.parameters.force_per_torque
        self.sensor = Sensor(self.parameters)
        self.handle: Handle | TwoMassHandle = Handle(self.parameters, operator)
        self._line: deque[float] | None = None  # the extra delay's forces (N), oldest first
        self._timing = Timing.CIA402
        self._apply_timing(Timing(timing))  # configures the sensor and the handle for the timing
        self._readers: dict[int, Callable[[], int]] = {
            0x6007: lambda: self.abort_connection_option_code,
            0x603F: lambda: self.error_code,
            0x6040: lambda: self.controlword,
            0x6041: lambda: self.statusword,
            0x605A: lambda: self.quick_stop_option_code,
            0x6060: lambda: self.mode,
            0x6061: lambda: self.mode_display,
            0x6064: lambda: self.sensor.position_counts,
            0x606C: lambda: self.sensor.velocity_counts,
            0x6071: lambda: self.target_torque,
            0x6072: lambda: self.parameters.max_torque_permille,
            0x6076: lambda: self.parameters.rated_torque_mnm,
            0x6077: lambda: self.torque_actual,
            0x6502: lambda: SUPPORTED_DRIVE_MODES,
        }
        self._writers: dict[int, Callable[[int], None]] = {
            0x6007: self._write_abort_connection_option_code,
            0x6040: self.write_controlword,
            0x605A: self._write_quick_stop_option_code,
            0x6060: self._write_mode,
            0x6071: self._write_target_torque,
            0x6072: lambda v: self.reconfigure(max_torque_permille=v),
            0x6076: lambda v: self.reconfigure(rated_torque=v / 1000.0),
        }

    # ----------------------------------------------------------------- the handle
    @property
    def timing(self) -> Timing:
        """When a written torque acts (see :class:`Timing`); may be changed between SYNCs.

        The torque acting at the change becomes the latched one: ``cia402`` applies it over one
        more interval, ``reception`` until the next target's reception.
        """
        return self._timing

    @timing.setter
    def timing(self, timing: Timing | str) -> None:
        new = Timing(timing)
        self._latched = self.torque_actual
        self._apply_timing(new)

    def _apply_timing(self, timing: Timing) -> None:
        """Select the per-timing interval step and the handle's force switch (no state carried)."""
        self._timing = timing
        self._close_interval = {
            Timing.CIA402: self._close_cia402,
            Timing.IDEAL: self._close_ideal,
            Timing.RECEPTION: self._close_reception,
        }[timing]
        self._latch_at_sync = timing is Timing.CIA402
        self._configure(self.parameters)

    @property
    def loop_delay(self) -> float:
        """The loop delay ``D`` in samples this drive closes: 1, 0, or its ``reception_delay``."""
        return self._timing.loop_delay(self.parameters.reception_delay)

    @property
    def operator(self) -> OperatorModel:
        """The hand on the handle."""
        return self.handle.operator

    def set_operator(self, operator: OperatorModel) -> None:
        """Replace the operator model from the next plant sub-step on."""
        self.handle.operator = operator

    @property
    def velocity(self) -> float:
        """The handle's true velocity in m/s (not quantised)."""
        return self.handle.velocity

    @property
    def position(self) -> float:
        """The handle's true position in m (not quantised)."""
        return self.handle.position

    @property
    def time(self) -> float:
        """Virtual time in s since the first SYNC."""
        return self.handle.time

    @property
    def operator_energy(self) -> float:
        """Work the operator has done on the handle, J (exact)."""
        return self.handle.operator_energy

    @property
    def wall_energy(self) -> float:
        """Work the motor has taken out of the handle, J (exact)."""
        return self.handle.wall_energy

    @property
    def friction_energy(self) -> float:
        """Energy the Coulomb friction has dissipated, J (exact)."""
        return self.handle.friction_energy

    @property
    def viscous_energy(self) -> float:
        """Energy the viscous friction ``b`` has dissipated, J (exact)."""
        return self.handle.viscous_energy

    @property
    def velocity_counts(self) -> int:
        """0x606C as sampled at the last SYNC."""
        return self.sensor.velocity_counts

    @property
    def position_counts(self) -> int:
        """0x6064 as sampled at the last SYNC."""
        return self.sensor.position_counts

    def reconfigure(self, **changes: object) -> None:
        """Change :class:`DeviceParameters` fields (validated first; nothing half-applied).

        The handle keeps its velocity and position, a low-pass velocity filter its state; a new
        ``period`` acts from the next SYNC.
        """
        self._configure(dataclasses.replace(self.parameters, **changes))  # type: ignore[arg-type]

    def _configure(self, parameters: DeviceParameters) -> None:
        self.parameters = parameters
        self._mechanism(parameters)
        self.sensor.configure(parameters, self.handle.velocity)
        switch = parameters.reception_delay if self._timing is Timing.RECEPTION else 0.0
        if parameters.extra_delay:
            late = switch + parameters.extra_delay
            switch = late - math.floor(late)
            length = math.floor(late) + 2
            if self._line is None or self._line.maxlen != length:
                self._line = deque([0.0] * length, maxlen=length)
        else:
            self._line = None
        self.handle.configure(parameters, self.sensor.meter, switch)
        self._newton_per_permille = parameters.rated_torque_mnm / 1e6 * parameters.force_per_torque

    def _mechanism(self, parameters: DeviceParameters) -> None:
        """A rigid handle, or the motor and handle of ``parameters.coupling``: taken over moving as the old one did."""
        old, coupling = self.handle, parameters.coupling
        if coupling is None if isinstance(old, Handle) else old.transmission == coupling:
            return
        new: Handle | TwoMassHandle
        if coupling is None:
            new = Handle(parameters, old.operator)
            new.velocity, new.position = old.velocity, old.position
        else:
            from sim_drive.transmission import TwoMassHandle  # numpy with it: only a drive with a transmission needs it

            new = TwoMassHandle(coupling, old.operator)
            new.place(old.velocity, old.position)
        new.time = old.time
        new.operator_energy, new.wall_energy = old.operator_energy, old.wall_energy
        new.friction_energy, new.viscous_energy = old.friction_energy, old.viscous_energy
        self.handle = new

    # ----------------------------------------------------------------- objects
    def read_object(self, index: int) -> int:
        """The value of CiA-402 object ``index`` (sub-index 0) in its drive units."""
        return self.reader(index)()

    def reader(self, index: int) -> Callable[[], int]:
        """A callable returning object ``index`` (for precompiled cyclic encoders)."""
        reader = self._readers.get(index)
        if reader is None:
            raise ObjectAccessError(index, "unknown")
        return reader

    def write_object(self, index: int, value: int) -> None:
        """Write CiA-402 object ``index`` (sub-index 0); raise :class:`ObjectAccessError` if refused."""
        writer = self._writers.get(index)
        if writer is None:
            raise ObjectAccessError(index, "unknown" if index not in self._readers else "read-only")
        low, high = _RANGES[index]
        if not low <= value <= high:
            raise ObjectAccessError(index, "range", f"{value} not in [{low}, {high}]")
        try:
            writer(value)
        except ObjectAccessError:
            raise
        except HapticBusError as exc:
            raise ObjectAccessError(index, "range", str(exc)) from exc

    def readable_objects(self) -> frozenset[int]:
        """Indices :meth:`read_object` serves."""
        return frozenset(self._readers)

    def writable_objects(self) -> frozenset[int]:
        """Indices :meth:`write_object` accepts."""
        return frozenset(self._writers)

    @property
    def statusword(self) -> int:
        """0x6041: the state bits, voltage enabled, remote, bit 11 while the torque is clamped
        at 0x6072, and bit 12 while following in CST."""
        word = STATE_STATUS_BITS[self.state] | SW_REMOTE
        if self.state in _VOLTAGE_STATES:
            word |= SW_VOLTAGE_ENABLED
        if self.torque_enabled:
            word |= SW_FOLLOWS_COMMAND
            if abs(self.target_torque) > self.parameters.max_torque_permille:
                word |= SW_INTERNAL_LIMIT_ACTIVE
        return word

    @property
    def torque_actual(self) -> int:
        """0x6077 in per mille of rated torque: the torque acting from the latest SYNC on (with
        ``reception`` timing: from the latest target's reception on)."""
        if self._latch_at_sync:
            return self._latched if self.torque_enabled else 0
        return self._effective_target()

    def write_controlword(self, word: int) -> None:
        """0x6040: run the state machine on ``word`` (fault reset on the rising edge of bit 7)."""
        steps = transitions(self.state, word, self.controlword, quick_stop_option_code=self.quick_stop_option_code)
        self.controlword = word
        for new, number in steps:
            self._enter(new, number)

    def _write_mode(self, mode: int) -> None:
        if mode != 0:
            try:
                known = OperationMode(mode)
            except ValueError:
                raise ObjectAccessError(0x6060, "range", f"{mode} is no CiA-402 mode") from None
            if not supports(SUPPORTED_DRIVE_MODES, known):
                raise ObjectAccessError(0x6060, "range", f"{known.name} ({mode}) not in 0x6502")
        self.mode = self.mode_display = mode

    def _write_target_torque(self, permille: int) -> None:
        self.target_torque = permille

    def _write_quick_stop_option_code(self, code: int) -> None:
        if not 0 <= code <= 8:
            raise ObjectAccessError(0x605A, "range", f"{code} not in [0, 8]")
        self.quick_stop_option_code = code

    def _write_abort_connection_option_code(self, code: int) -> None:
        if code not in {int(option) for option in AbortConnectionOption}:
            raise ObjectAccessError(0x6007, "range", f"{code} not in [0, 3]")
        self.abort_connection_option_code = code

    # ----------------------------------------------------------------- state machine
    def reset_application(self) -> None:
        """NMT reset node: the drive's power-on values (the handle itself keeps moving)."""
        if self.state is not State.SWITCH_ON_DISABLED:
            self._enter(State.SWITCH_ON_DISABLED, None)
        self.controlword = self.mode = self.mode_display = self.target_torque = 0
        self.quick_stop_option_code = 2
        self.abort_connection_option_code = int(AbortConnectionOption.FAULT)
        self.error_code = 0
        self._latched = 0
        self._configure(self.power_on_parameters)

    def fault(self, code: int) -> None:
        """A fault with CiA error ``code`` (0x603F): transitions 13 and 14, torque off at once."""
        if self.state is not State.FAULT:
            self.error_code = code
            self._enter(State.FAULT_REACTION_ACTIVE, TRANSITION_FAULT)
            self._enter(State.FAULT, TRANSITION_FAULT_REACTION_DONE)

    def connection_lost(self, code: int) -> bool:
        """The master is gone (heartbeat, RPDO deadline, NMT): 0x6007's reaction if the power
        stage is on; True if the drive faulted with ``code``, False if it did anything else."""
        if self.state not in POWER_STAGE_ON:
            return False
        option = self.abort_connection_option_code
        logger.warning("%s: connection lost (0x%04X) in %s, 0x6007 = %d", self.name, code, self.state.value, option)
        if option == AbortConnectionOption.FAULT:
            self.fault(code)
            return True
        word = _REACTION_WORDS.get(AbortConnectionOption(option))
        if word is not None:
            self.write_controlword(word)
        return False

    def _enter(self, new: State, number: int | None) -> None:
        old = self.state
        self.state = new
        if old is _OPERATION_ENABLED:
            self._latched = 0
        if old is State.FAULT:
            self.error_code = 0
        logger.info("%s: %s -> %s (transition %s) at t = %.6f s", self.name, old.value, new.value, number, self.time)
        for listener in self.state_listeners:
            listener(old, new, number)

    @property
    def torque_enabled(self) -> bool:
        """Whether a written torque acts: OPERATION ENABLED, cyclic synchronous torque, no halt."""
        return self.state is _OPERATION_ENABLED and self.mode_display == _CST and not self.controlword & CW_HALT

    def _effective_target(self) -> int:
        """0x6071 saturated at +-0x6072 while torque is enabled, else 0 (per mille)."""
        if not self.torque_enabled:
            return 0
        target, limit = self.target_torque, self.parameters.max_torque_permille
        return target if -limit <= target <= limit else saturate(target, -limit, limit)

    # ----------------------------------------------------------------- the cycle
    def sync(self, interval: float | None = None) -> None:
        """One SYNC: advance the plant over the closing interval (if any), then sample.

        ``interval``: how long that interval was, s (None: exactly the period ``T``, virtual
        time; a real-time drive passes the time since the last SYNC, so a late SYNC holds the
        latched torque that much longer, as a real drive does)."""
        self._interval = interval
        if self.sync_count:
            self._close_interval()
        if self.state is _QUICK_STOP_ACTIVE and not 5 <= self.quick_stop_option_code <= 8:
            self._enter(State.SWITCH_ON_DISABLED, TRANSITION_QUICK_STOP_DONE)
        if self._latch_at_sync:
            self._latched = self._effective_target()
        self.sensor.sample(self.handle)
        self.sync_count += 1

    def _advance(self, before: float, now: float) -> None:
        """The plant over the closing interval: ``before`` N until the switch, ``now`` N after it; the
        operator's hand on the handle only while the torque is on (it takes a powered handle, and lets
        go of one whose drive is off: a push through an unpowered wall is no contact)."""
        self.handle.hand_on = self.torque_enabled or not self.hand_needs_power
        line = self._line
        if line is not None:  # the hidden extra delay: this interval's forces come off the line
            if not self.torque_enabled and any(line):  # once: a drive switched off flushes what was on its way
                line.extend([0.0] * len(line))
            line.append(now if self.torque_enabled else 0.0)
            before, now = line[0], line[1]
        interval = self._interval
        if interval is None:
            self.handle.advance(before, now)
        elif interval > 0.0:
            self.handle.advance_for(interval, before, now)

    def _close_cia402(self) -> None:
        """The closing interval under the torque latched at the SYNC before."""
        force = (self._latched if self.torque_enabled else 0) * self._newton_per_permille
        self._advance(force, force)

    def _close_ideal(self) -> None:
        """The closing interval under the target present now."""
        force = self._effective_target() * self._newton_per_permille
        self._advance(force, force)

    def _close_reception(self) -> None:
        """The closing interval: the torque acting before for ``reception_delay``, the target present now after."""
        before = self._latched if self.torque_enabled else 0
        self._latched = self._effective_target()
        self._advance(before * self._newton_per_permille, self._latched * self._newton_per_permille)
