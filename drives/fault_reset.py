"""Clearing a CiA-402 fault: the controlword's fault-reset edge, and what the drive says after it.

CiA-402 (transition 15): in FAULT, a rising edge of controlword bit 7 takes the drive to
SWITCH ON DISABLED, if the cause of the fault is gone; a drive whose cause persists stays in
FAULT (or faults again at once).  :func:`clear_fault` sends the sequence through any
``command`` primitive (write a controlword, return the statusword that follows): the CANopen
master's cyclic exchange, or an acyclic write and read (:func:`reset_drive_fault`, for
``haptic-bus fault-reset`` and ``run --reset-fault``).

The sequence: bit 7 low (an edge needs a low phase), then high while the drive shows FAULT
(held, for drives that sample it), until it leaves FAULT or ``timeout`` s pass, then low
again.  FAULT REACTION ACTIVE is waited out with bit 7 low.  Nothing else is written: a drive
found outside FAULT is left as it is.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from drives.cia301 import describe_emcy_code
from drives.cia402 import CONTROLWORD, CW_FAULT_RESET, ERROR_CODE, STATUSWORD, Command, State, decode_statusword
from drives.errors import DriveProtocolError
from drives.object_access import ObjectAccess

BIT_7_LOW = Command.DISABLE_VOLTAGE.word  # controlword 0: no command a faulted drive acts on, no torque
DEFAULT_WAIT = 1.0  # s: the longest a fault reset waits for SWITCH ON DISABLED
POLL_PAUSE = 0.005  # s: between two acyclic writes/reads of a waiting reset (a bus is shared)
_FAULTED = (State.FAULT, State.FAULT_REACTION_ACTIVE)


def clear_fault(command: Callable[[int], int], timeout: float, pause: float = 0.0) -> int:
    """Send the fault-reset sequence through ``command`` (controlword -> statusword); the
    statusword after bit 7 went low again.  It still shows FAULT (or FAULT REACTION ACTIVE)
    if the drive did not leave it within ``timeout`` s.  ``pause`` (s) between two commands."""
    statusword = command(BIT_7_LOW)
    state = decode_statusword(statusword)
    deadline = time.monotonic() + timeout
    while state in _FAULTED and time.monotonic() <= deadline:
        if pause:
            time.sleep(pause)
        statusword = command(CW_FAULT_RESET if state is State.FAULT else BIT_7_LOW)
        state = decode_statusword(statusword)
    return command(BIT_7_LOW)


def state_text(statusword: int) -> str:
    """``"FAULT"``, or ``"an undefined state"`` for a statusword CiA-402 does not define."""
    state = decode_statusword(statusword)
    return state.value if state is not None else "an undefined state"


def error_code_text(code: int | None) -> str:
    """``"0x8250 RPDO timeout"``, ``"0x0000 no error"``; ``"unknown"`` where 0x603F could not be read."""
    return "unknown" if code is None else f"0x{code:04X} {error_code_meaning(code)}"


def error_code_meaning(code: int) -> str:
    """What 0x603F (an EMCY code) says: ``"RPDO timeout"``, ``"no error"`` for 0."""
    return describe_emcy_code(code) if code else "no error"


@dataclass(frozen=True)
class FaultResetOutcome:
    """What a fault reset found and left: the statuswords and 0x603F before and after, whether
    the reset edge was sent (only to a drive in FAULT) and whether the drive is now out of it."""

    drive: str
    statusword_before: int
    error_code_before: int | None
    statusword_after: int
    error_code_after: int | None
    reset_sent: bool
    elapsed_s: float

    @property
    def state_before(self) -> str:
        """The CiA-402 state the drive was found in."""
        return state_text(self.statusword_before)

    @property
    def state_after(self) -> str:
        """The CiA-402 state the drive was left in."""
        return state_text(self.statusword_after)

    @property
    def cleared(self) -> bool:
        """True if the drive is in SWITCH ON DISABLED after the reset (or was out of FAULT already)."""
        after = decode_statusword(self.statusword_after)
        return after is State.SWITCH_ON_DISABLED if self.reset_sent else after not in _FAULTED

    def message(self) -> str:
        """One line: the drive, what was done and where it is now."""
        return f"{self.drive}: {self.detail()}"

    def detail(self) -> str:
        """What was done and where the drive is now (without the drive's name)."""
        if not self.reset_sent:
            if self.cleared:
                return f"in {self.state_before}, not in FAULT: nothing to reset"
            return (f"still in {self.state_after} (statusword 0x{self.statusword_after:04X}) {self.elapsed_s:.3g} s after "
                    f"it was found there; error code {error_code_text(self.error_code_after)}")
        before = f"FAULT (error code {error_code_text(self.error_code_before)})"
        if self.cleared:
            return (f"{before} reset: now {self.state_after} (statusword 0x{self.statusword_after:04X}) "
                    f"after {self.elapsed_s:.3g} s")
        return (f"{before}: the cause persists, the drive is still in {self.state_after} (statusword "
                f"0x{self.statusword_after:04X}, error code {error_code_text(self.error_code_after)}) "
                f"{self.elapsed_s:.3g} s after the reset edge; remove the cause, then reset again")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: numbers as numbers, the states and codes also in words."""
        return {
            "drive": self.drive,
            "state_before": self.state_before,
            "statusword_before": self.statusword_before,
            "error_code_before": self.error_code_before,
            "error_code_before_text": None if self.error_code_before is None else describe_emcy_code(self.error_code_before),
            "reset_sent": self.reset_sent,
            "state_after": self.state_after,
            "statusword_after": self.statusword_after,
            "error_code_after": self.error_code_after,
            "cleared": self.cleared,
            "elapsed_s": self.elapsed_s,
        }


def _error_code(access: ObjectAccess) -> int | None:
    """0x603F, or None where the drive has none (or refuses it)."""
    try:
        return access.read(ERROR_CODE)
    except DriveProtocolError:
        return None


def reset_drive_fault(access: ObjectAccess, wait: float = DEFAULT_WAIT) -> FaultResetOutcome:
    """Reset ``access``'s drive if it is in FAULT, and wait (at most ``wait`` s) for SWITCH ON
    DISABLED; a drive in FAULT REACTION ACTIVE is first waited for, one in any other state is
    left alone.  DriveError if the drive cannot be read or written."""
    started = time.monotonic()
    deadline = started + wait
    before = access.read(STATUSWORD)
    while decode_statusword(before) is State.FAULT_REACTION_ACTIVE and time.monotonic() <= deadline:
        time.sleep(POLL_PAUSE)
        before = access.read(STATUSWORD)
    if decode_statusword(before) is not State.FAULT:
        code = _error_code(access) if decode_statusword(before) in _FAULTED else None
        return FaultResetOutcome(access.name, before, code, before, code, False, time.monotonic() - started)
    code_before = _error_code(access)

    def command(word: int) -> int:
        access.write(CONTROLWORD, word)
        return access.read(STATUSWORD)

    after = clear_fault(command, max(0.0, deadline - time.monotonic()), POLL_PAUSE)
    while decode_statusword(after) not in (*_FAULTED, State.SWITCH_ON_DISABLED) and time.monotonic() <= deadline:
        time.sleep(POLL_PAUSE)  # a drive passing through another state on its way (NOT READY TO SWITCH ON)
        after = access.read(STATUSWORD)
    code_after = _error_code(access) if decode_statusword(after) in _FAULTED else None
    return FaultResetOutcome(access.name, before, code_before, after, code_after, True, time.monotonic() - started)
