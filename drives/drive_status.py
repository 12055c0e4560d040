"""A drive's state as ``haptic-bus status`` reports it: each object read, with its meaning in words.

Bus-neutral: :meth:`StatusObject.read` reads one object through any
:class:`~drives.object_access.ObjectAccess`; an object the drive lacks (or refuses) becomes a
:class:`Reading` that says so (``missing``), never an exception; silence (a
:class:`~drives.errors.DriveTimeout`) still raises.  :func:`read_readings` reads what every
CiA-402 drive is asked for, in the order they are shown, with the fieldbus' own readings in their
places (:mod:`drives.canopen.service`, :mod:`drives.modbus.service`).  :func:`describe_value`
says what a standard object's value means, for ``haptic-bus sdo``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from drives.cia301 import ERROR_REGISTER, PRE_DEFINED_ERROR_FIELD, describe_emcy_code, describe_error_register, sdo_abort_text
from drives.cia402 import (
    ABORT_CONNECTION_OPTION_CODE,
    ERROR_CODE,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL,
    STATUSWORD,
    VELOCITY_ACTUAL,
    DataType,
    ObjectSpec,
    State,
    decode_statusword,
    describe_abort_option,
    describe_mode,
)
from drives.errors import DriveProtocolError, DriveRefusal
from drives.fault_reset import error_code_meaning, error_code_text, state_text
from drives.object_access import ObjectAccess, is_absent

DEFAULT_LISTEN = 0.5  # s: how long CANopen status listens (five heartbeats at the usual 100 ms)
DEFAULT_ANSWER_TIMEOUT = 0.5  # s: each SDO answer or Modbus request of status and fault-reset
LABEL_WIDTH = 20  # characters of the label column in :meth:`DriveStatus.lines`
TEXT_WIDTH = 44  # characters of the meaning column


@dataclass(frozen=True)
class Reading:
    """One thing status read: ``key`` (its JSON name), ``label`` (its line's name), ``source``
    (the object or register), ``value`` (drive units; None if there is none) and ``text``
    (its meaning, or why there is no value); ``missing``: "absent", "not readable", or None.
    ``details``: structured entries of a multi-valued object (an error history, consumer list)."""

    key: str
    label: str
    source: str
    value: int | None
    text: str
    missing: str | None = None
    details: tuple[dict[str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        found: dict[str, Any] = {"source": self.source, "value": self.value, "text": self.text, "missing": self.missing}
        if self.details:
            found["details"] = list(self.details)
        return found

    def line(self) -> str:
        """``label  meaning  source``: one line of the status table."""
        text = f"{self.missing} ({self.text})" if self.missing else self.text
        if len(text) > TEXT_WIDTH:
            return f"  {self.label:<{LABEL_WIDTH}} {self.source}: {text}"
        return f"  {self.label:<{LABEL_WIDTH}} {text:<{TEXT_WIDTH}} {self.source}"


def missing_reading(key: str, label: str, source: str, error: DriveProtocolError) -> Reading:
    """The Reading of an object the drive refused: "absent" or "not readable", with its reason
    (an SDO abort as its code and meaning)."""
    if isinstance(error, DriveRefusal):
        reason = f"SDO abort 0x{error.code:08X} {sdo_abort_text(error.code)}"
    else:
        reason = error.message
    return Reading(key, label, source, None, reason, "absent" if is_absent(error) else "not readable")


@dataclass(frozen=True)
class StatusObject:
    """One object status reads: its JSON key, its line's label, the object and how its value reads."""

    key: str
    label: str
    spec: ObjectSpec
    describe: Callable[[int], str]

    def read(self, access: ObjectAccess) -> Reading:
        """This object from ``access`` as a :class:`Reading`, or one that says why the drive gave
        none (:func:`missing_reading`); DriveTimeout (silence) is raised."""
        try:
            value = access.read(self.spec)
        except DriveProtocolError as exc:
            return missing_reading(self.key, self.label, access.source(self.spec), exc)
        return Reading(self.key, self.label, access.source(self.spec), value, self.describe(value))


STATE = StatusObject("cia402_state", "CiA-402 state", STATUSWORD, lambda v: f"{state_text(v)} (statusword 0x{v:04X})")
MODE = StatusObject("mode_of_operation", "mode of operation", MODES_OF_OPERATION_DISPLAY, lambda v: f"{v}: {describe_mode(v)}")
ERROR = StatusObject("error_code", "error code", ERROR_CODE, error_code_text)
POSITION = StatusObject("position", "position", POSITION_ACTUAL, lambda v: f"{v} increments")
VELOCITY = StatusObject("velocity", "velocity", VELOCITY_ACTUAL, lambda v: f"{v} velocity units")
ABORT_OPTION = StatusObject("abort_connection_option", "on connection loss", ABORT_CONNECTION_OPTION_CODE,
                            lambda v: f"{v}: {describe_abort_option(v)}")
ERROR_REGISTER_OBJECT = StatusObject("error_register", "error register",
                                     ObjectSpec(ERROR_REGISTER, "Error register", DataType.UNSIGNED8, "ro"),
                                     lambda v: f"0x{v:02X}: {describe_error_register(v)}")
AccessT = TypeVar("AccessT", bound=ObjectAccess)


def read_readings(access: AccessT, errors: Sequence[Callable[[AccessT], Reading]],
                  watchdogs: Sequence[Callable[[AccessT], Reading]]) -> list[Reading]:
    """Every reading status shows, in order: the CiA-402 state, mode and error code, then the
    fieldbus' own error records (``errors``, each read from ``access``); position and velocity; the
    fieldbus' watchdogs (``watchdogs``) and 0x6007, what the drive does when one expires."""
    return [STATE.read(access), MODE.read(access), ERROR.read(access), *(read(access) for read in errors),
            POSITION.read(access), VELOCITY.read(access), *(read(access) for read in watchdogs),
            ABORT_OPTION.read(access)]


_MEANINGS: dict[int, Callable[[int], str]] = {
    STATUSWORD.index: state_text,
    ERROR_CODE.index: error_code_meaning,
    MODES_OF_OPERATION.index: describe_mode,
    MODES_OF_OPERATION_DISPLAY.index: describe_mode,
    ABORT_CONNECTION_OPTION_CODE.index: describe_abort_option,
    ERROR_REGISTER: describe_error_register,
}


def describe_value(index: int, subindex: int, value: int) -> str | None:
    """What the value of a standard object means in words (the CiA-402 state of a statusword, an
    error code's text, a mode's name...), or None for an object without such a table."""
    if index == PRE_DEFINED_ERROR_FIELD and subindex:
        return describe_emcy_code(value & 0xFFFF)
    meaning = _MEANINGS.get(index) if subindex == 0 else None
    return None if meaning is None else meaning(value)


@dataclass
class DriveStatus:
    """What status found: the drive, its protocol, the readings in order, and (CANopen) what the
    listening heard in ``listen_s`` s: the NMT state, heartbeats, SYNC frames, EMCYs."""

    drive: str
    protocol: str
    readings: list[Reading]
    listen_s: float = 0.0
    nmt_state: str | None = None
    heartbeats: int = 0
    sync_frames: int = 0
    emcys: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def reading(self, key: str) -> Reading | None:
        """The reading named ``key``, or None."""
        return next((r for r in self.readings if r.key == key), None)

    @property
    def state(self) -> State | None:
        """The CiA-402 state, where 0x6041 was read."""
        found = self.reading(STATE.key)
        return None if found is None or found.value is None else decode_statusword(found.value)

    @property
    def faulted(self) -> bool:
        """True in FAULT or FAULT REACTION ACTIVE."""
        return self.state in (State.FAULT, State.FAULT_REACTION_ACTIVE)

    def headline(self) -> str:
        """``CANopen node 5: NMT OPERATIONAL, FAULT (error code 0x8250 RPDO timeout)``."""
        parts = [] if self.protocol != "canopen" else [f"NMT {self.nmt_state or 'not heard'}"]
        state = self.reading(STATE.key)
        parts.append(state_text(state.value) if state is not None and state.value is not None else "CiA-402 state unknown")
        error = self.reading(ERROR.key)
        if self.faulted and error is not None:
            parts[-1] += f" (error code {error.text})"
        return f"{self.drive}: {', '.join(parts)}"

    def lines(self) -> list[str]:
        """The headline, one line per reading, the EMCYs heard and the notes."""
        lines = [self.headline()]
        if self.protocol == "canopen":
            heard = f"{self.heartbeats} heartbeat(s) in {self.listen_s:.2g} s"
            lines.append(f"  {'NMT state':<{LABEL_WIDTH}} {(self.nmt_state or 'none heard') + ' (' + heard + ')':<{TEXT_WIDTH}} "
                         "heartbeat")
        lines += [reading.line() for reading in self.readings]
        if self.protocol == "canopen":
            if not self.emcys:
                lines.append(f"  {'EMCY':<{LABEL_WIDTH}} none heard in {self.listen_s:.2g} s")
            for emcy in self.emcys:
                lines.append(f"  {'EMCY':<{LABEL_WIDTH}} 0x{emcy['code']:04X} {emcy['text']}, error register "
                             f"0x{emcy['error_register']:02X}, {emcy['age_s']:.2g} s ago")
            if self.sync_frames:
                lines.append(f"  {'SYNC':<{LABEL_WIDTH}} {self.sync_frames} frame(s) in {self.listen_s:.2g} s: "
                             "a master is cycling")
        lines += [f"  note: {note}" for note in self.notes]
        return lines

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every reading by key, and the listening's findings."""
        state = self.state
        document: dict[str, Any] = {
            "drive": self.drive,
            "protocol": self.protocol,
            "cia402_state": None if state is None else state.value,
            "faulted": self.faulted,
        }
        if self.protocol == "canopen":
            document.update({"nmt_state": self.nmt_state, "heartbeats": self.heartbeats, "listen_s": self.listen_s,
                             "sync_frames": self.sync_frames, "emcy": self.emcys})
        document["readings"] = {reading.key: reading.to_dict() for reading in self.readings}
        document["notes"] = list(self.notes)
        return document
