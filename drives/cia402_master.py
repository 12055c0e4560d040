"""What every CiA-402 master does the same way, whatever the fieldbus: select the mode of
operation, walk the state machine, reset a fault.

A fieldbus master subclasses :class:`Cia402Master` and provides one primitive,
:meth:`Cia402Master._command`: send a controlword and return the statusword that answers it
(on CANopen one SYNC/RPDO/TPDO exchange, on Modbus a register write and read).
"""

from __future__ import annotations

import abc
import time

from drives.base import Drive, DriveError, DriveTimeout
from drives.cia402 import (
    CW_FAULT_RESET,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    SUPPORTED_DRIVE_MODES,
    Command,
    OperationMode,
    State,
    decode_statusword,
    path_to_operation_enabled,
    supports,
)

SAFE_CONTROLWORD = Command.DISABLE_VOLTAGE.word  # -> SWITCH ON DISABLED: no torque, handle free


class UnsupportedModeError(DriveError):
    """The drive does not announce the requested mode of operation in 0x6502."""


class DriveStateError(DriveTimeout):
    """The CiA-402 state machine did not reach the expected state in time; ``state`` is where it stuck."""

    def __init__(self, node: str, message: str, state: State | None) -> None:
        self.state = state
        super().__init__(node, message)


def state_name(state: State | None) -> str:
    """The state's CiA-402 name, or a phrase for a statusword the standard does not define."""
    return state.value if state is not None else "an undefined state"


class Cia402Master(Drive):
    """Mode selection, state-machine walks and fault reset on top of :meth:`_command`.

    Subclasses set ``name``, ``state_timeout`` (s, per state-machine step) and
    ``max_commands_per_step`` (a bound on the exchanges one step may take besides the time).
    """

    state_timeout: float
    max_commands_per_step: int

    @abc.abstractmethod
    def write_object(self, spec, value: int) -> None:
        """Write one object acyclically (SDO download, register write) in drive units."""

    @abc.abstractmethod
    def _command(self, controlword: int) -> int:
        """Send ``controlword`` (with zero torque) and return the statusword that answers it."""

    def _select_mode(self, mode: OperationMode) -> None:
        """Check 0x6502 announces ``mode`` (CST only, the one this master drives), write 0x6060
        and wait (``state_timeout``) until 0x6061 shows it."""
        mode = OperationMode(mode)
        if mode is not OperationMode.CYCLIC_SYNCHRONOUS_TORQUE:
            raise UnsupportedModeError(
                self.name, f"this master drives only CYCLIC_SYNCHRONOUS_TORQUE (10); {mode.name} ({int(mode)}) was asked"
            )
        supported = self.read_object(SUPPORTED_DRIVE_MODES)
        if not supports(supported, mode):
            raise UnsupportedModeError(
                self.name, f"0x6502 supported drive modes = 0x{supported:08X} lacks {mode.name} (bit {mode.supported_bit})"
            )
        self.write_object(MODES_OF_OPERATION, int(mode))
        deadline = time.monotonic() + self.state_timeout
        while (shown := self.read_object(MODES_OF_OPERATION_DISPLAY)) != int(mode):
            if time.monotonic() > deadline:
                raise DriveStateError(
                    self.name,
                    f"0x6061 modes of operation display = {shown}, still not {int(mode)} ({mode.name}) "
                    f"{self.state_timeout:.3g} s after writing 0x6060",
                    None,
                )

    def _walk(self, goal: State, first_word: int, accept: tuple[State, ...] = ()) -> State:
        """Command the state machine to ``goal`` (or a state in ``accept``), starting with
        ``first_word``; :class:`DriveStateError` if one step stalls for ``state_timeout``."""
        statusword = self._command(first_word)
        state = decode_statusword(statusword)
        step_started = time.monotonic()
        previous_word = first_word
        commands = 0
        while state is not goal and state not in accept:
            if goal is State.SWITCH_ON_DISABLED:
                command: Command | None = Command.DISABLE_VOLTAGE
            elif state is State.FAULT:
                raise DriveStateError(self.name, f"drive is in FAULT (statusword 0x{statusword:04X}); call fault_reset() first", state)
            else:
                path = path_to_operation_enabled(state) if state is not None else ()
                command = path[0] if path else None
            word = command.word if command is not None else previous_word & ~CW_FAULT_RESET
            if time.monotonic() - step_started > self.state_timeout or commands > self.max_commands_per_step:
                sent = f"{command.name} (controlword 0x{word:04X})" if command is not None else f"controlword 0x{word:04X}"
                raise DriveStateError(
                    self.name,
                    f"state machine stuck in {state_name(state)} (statusword 0x{statusword:04X}) for "
                    f"{self.state_timeout:.3g} s while sending {sent} towards {goal.value}",
                    state,
                )
            statusword = self._command(word)
            commands += 1
            previous_word = word
            new_state = decode_statusword(statusword)
            if new_state is not state:
                state = new_state
                step_started = time.monotonic()
                commands = 0
        return state

    def _reset_fault(self) -> None:
        """Controlword bit 7 low, high (the rising edge), low again; wait until the drive leaves
        FAULT (and FAULT REACTION ACTIVE), bounded by ``state_timeout``."""
        statusword = self._command(SAFE_CONTROLWORD)  # bit 7 low: the edge needs a low phase
        state = decode_statusword(statusword)
        deadline = time.monotonic() + self.state_timeout
        while state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            if time.monotonic() > deadline:
                raise DriveStateError(
                    self.name,
                    f"still in {state_name(state)} (statusword 0x{statusword:04X}) {self.state_timeout:.3g} s "
                    f"after the fault reset edge",
                    state,
                )
            statusword = self._command(CW_FAULT_RESET if state is State.FAULT else SAFE_CONTROLWORD)
            state = decode_statusword(statusword)
        self._command(SAFE_CONTROLWORD)  # bit 7 back to 0
