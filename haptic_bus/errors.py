"""Every error the distribution raises on purpose, drawn once.  The two roots, the exit-code
branches and drives' errors import from here; a class marked with a module in parentheses lives
in that module (beside the code that raises it, above this base layer) and imports from there.

Each carries its data from construction; the command line maps the branch to an exit status
(``haptic_bus.app.cli``)::

    HapticBusError                         haptic_bus refused or broke (this module)
     +-- ParameterError (InvalidInput)     invalid input haptic_bus found                        exit 2
     |    +-- ProfileError                 (profile.reader) a profile field: .path, .field
     |    +-- NoSuchObject                 (node.upload) the controller has no such scene object
     +-- GateRefusal                       a passivity gate said no: .decision                    exit 1
     |    +-- ProfileRefusal               (app.profiles) a profile's scene: .path
     |    +-- SpaceGateRefusal             (control.space_gate) a scene in space
     |         +-- AxesProfileRefusal      (app.axes_profile) a multi-axis profile's scene: .path
     +-- AssumptionBroken                  the gate's assumption failed at run time:             exit 3
     |                                     .assumption, .observed, .allowed
     +-- StartRefused                      (app.runner) the handle starts inside an object       exit 1
     +-- UploadRefused                     (node.upload) a controller refused: .abort_code       exit 1
     +-- NotIdentifiable                   (identify.fit) too few usable equations                exit 1
     +-- ObjectAccessError                 (sim_drive.device) the simulated drive refuses an object

    FieldbusError                          drives failed or was misused (drives.errors)
     +-- DriveArgumentError (InvalidInput) an invalid argument to drive code                     exit 2
     +-- DriveError                        a drive or bus failed: .node, .message                 exit 1
          +-- BusConfigError               no usable CAN bus configuration
          +-- DriveTimeout (TimeoutError)  silence: no answer in time
          |    +-- DriveStateError         the CiA-402 state machine stalled: .state
          |    +-- ModbusLinkLost          the Modbus link is gone: call reconnect()
          |    +-- NoController            (node.upload) no controller on that node id
          +-- DriveFault                   the drive reported a fault: .code
          +-- ScalingConflict              two sources of a scaling factor disagree: .field, .first, .second
          +-- DriveProtocolError           an answer or frame the protocol forbids
          |    +-- SdoAbortError           SDO abort: .abort_code, .index, .subindex
          |    +-- ObjectAbsent            no such object on the drive or its map: .index, .subindex
          |    +-- ScalingObjectError      a factor-group/SI-unit object out of range: .index, .subindex, .value
          |    +-- ModbusExceptionError    exception response: .exception_code
          |    +-- PdoLengthError          PDO frame of the wrong length: .expected, .got
          +-- UnsupportedModeError         0x6502 lacks the requested mode
          +-- NotAController               (node.upload) the node answered but is no controller

    InvalidInput (ValueError)              (drives.errors) the shape of both invalid-input errors:
                                           .name, .value, .allowed, .context

Two roots, because ``drives`` is the bottom layer and usable alone (the simulator, the service
commands, a user's own master): its errors cannot derive from :class:`HapticBusError`, and
wrapping every drive error the controller meets would hide what it is (a ``DriveTimeout`` is a
``TimeoutError``, an ``SdoAbortError`` has its abort code).  So ``except HapticBusError`` means
"haptic_bus refused or broke"; ``except ALL_ERRORS`` catches everything raised on purpose,
including a drive failing while the controller runs, in one clause; ``except InvalidInput``
(both ``ParameterError`` and ``DriveArgumentError``) catches every invalid input (exit 2),
whichever layer found it.  The analysis raises only :class:`ParameterError` and imports nothing
of ``drives`` itself; through this module it loads ``drives.errors`` (plain classes) and nothing else.
"""

from __future__ import annotations

from typing import Generic, Protocol, TypeVar

from drives.errors import (
    BusConfigError,
    DriveArgumentError,
    DriveError,
    DriveFault,
    DriveProtocolError,
    DriveStateError,
    DriveTimeout,
    FieldbusError,
    InvalidInput,
    ModbusExceptionError,
    ModbusLinkLost,
    ObjectAbsent,
    PdoLengthError,
    ScalingConflict,
    ScalingObjectError,
    SdoAbortError,
    UnsupportedModeError,
)


class HapticBusError(Exception):
    """Base class of every error haptic_bus (and its simulator) raises on purpose."""


class ParameterError(HapticBusError, InvalidInput):
    """A parameter is outside its allowed range (or not a number at all): ``name``, ``value``,
    ``allowed`` and where it was read, ``context``."""


class Decision(Protocol):
    """What a refusal needs of a gate's decision: one line per reason."""

    @property
    def reasons(self) -> tuple[str, ...]: ...


DecisionT = TypeVar("DecisionT", bound=Decision)


class GateRefusal(HapticBusError, Generic[DecisionT]):
    """A passivity gate refused a change; ``decision`` (the gate's, e.g. a
    :class:`~haptic_bus.control.gate.GateDecision`) holds every reason; ``where`` (e.g.
    ``profile PATH``) prefixes the message."""

    subject = "change"  # what was refused, in the message

    def __init__(self, decision: DecisionT, where: str = "") -> None:
        self.decision = decision
        prefix = f"{where}: " if where else ""
        super().__init__(f"{prefix}passivity gate refused the {self.subject}: " + "; ".join(decision.reasons))


class AssumptionBroken(HapticBusError):
    """An assumption of the gate's verdict failed at run time (exit 3): ``assumption`` says which,
    ``observed`` what was measured, ``allowed`` what the gate assumed."""

    def __init__(self, assumption: str, observed: str, allowed: str) -> None:
        self.assumption = assumption
        self.observed = observed
        self.allowed = allowed
        super().__init__(f"assumption broken: {assumption}: {observed}; the gate assumed {allowed}")


ALL_ERRORS: tuple[type[HapticBusError], type[FieldbusError]] = (HapticBusError, FieldbusError)
"""Every error the distribution raises on purpose: ``except ALL_ERRORS``."""

__all__ = [
    "ALL_ERRORS",
    "AssumptionBroken",
    "BusConfigError",
    "DriveArgumentError",
    "DriveError",
    "DriveFault",
    "DriveProtocolError",
    "DriveStateError",
    "DriveTimeout",
    "FieldbusError",
    "GateRefusal",
    "HapticBusError",
    "InvalidInput",
    "ModbusExceptionError",
    "ModbusLinkLost",
    "ObjectAbsent",
    "ParameterError",
    "PdoLengthError",
    "ScalingConflict",
    "ScalingObjectError",
    "SdoAbortError",
    "UnsupportedModeError",
]
