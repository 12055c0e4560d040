"""Every error the distribution raises on purpose, drawn once: one class for each thing a caller
catches differently (python-can has five); a detail a caller needs is an attribute, not a class.
Every class is importable from here but ``ObjectAccessError``, which lives in ``sim_drive.device``;
the root, ``ParameterError`` and the ``DriveError`` branch are defined in ``drives.errors``.  The
command line maps each branch to its exit status (``haptic_bus.app.cli``)::

    HapticBusError                       everything raised on purpose
     +-- ParameterError (ValueError)     invalid input, found before anything moved:            exit 2
     |                                   .name, .value, .allowed, .context
     +-- Refusal                         haptic_bus said no and changed nothing: a passivity     exit 1
     |                                   gate (.decision), a start inside an object, a
     |                                   controller refusing an upload, a fit without data:
     |                                   .reasons
     +-- AssumptionBroken                the gate's assumption failed at run time:              exit 3
     |                                   .assumption, .observed, .allowed
     +-- ObjectAccessError               the simulated drive refuses an object (it answers
     |                                   an SDO abort or a Modbus exception): .index, .reason
     +-- DriveError                      a drive or its bus failed (bus configuration, mode,    exit 1
          |                              scaling, not a controller): .node, .message
          +-- DriveTimeout (TimeoutError)  silence: no answer in time
          +-- ModbusLinkLost             the link is gone until the master reconnects
          +-- DriveFault                 in FAULT, or a CiA-402 step stalled: .code, .state
          +-- DriveProtocolError         an answer or a frame that cannot be used
               +-- DriveRefusal          the drive refused one request (SDO abort, Modbus
                                         exception, object not mapped): .code, .index, .subindex

One root, defined in ``drives`` because ``drives`` is the bottom layer and usable alone (the
simulator, the service commands, a user's own master): ``except HapticBusError`` catches every
error raised on purpose, a drive failing while the controller runs included; ``except
ParameterError`` every invalid input (exit 2), whichever layer found it; ``except DriveError``
every failure of a drive or its bus, which is never a misuse.  A :class:`DriveTimeout` is a
``TimeoutError`` and nothing else is: a drive in FAULT is a :class:`DriveFault`, a lost link a
:class:`ModbusLinkLost`.  The analysis raises only :class:`ParameterError`; through this module
it loads ``drives.errors`` (plain classes) and nothing else.
"""

from __future__ import annotations

from typing import Protocol

from drives.errors import (
    DriveError,
    DriveFault,
    DriveProtocolError,
    DriveRefusal,
    DriveTimeout,
    HapticBusError,
    ModbusLinkLost,
    ParameterError,
)

NAMES_SHOWN = 3
"""How many items a message shows of a list (a refusal's objects and reasons, the names a check allows):
the first few and the count of the rest (:func:`haptic_bus.validation.some_names`), so that a scene of
3 000 walls is one short line, not 3 000 names."""


class Decision(Protocol):
    """What a refusal needs of a gate's decision: one line per reason."""

    @property
    def reasons(self) -> tuple[str, ...]: ...


class Refusal(HapticBusError):
    """haptic_bus refused and changed nothing (exit 1): a passivity gate refused a scene or a change,
    the handle starts inside an object, a controller refused an upload, a record cannot identify the
    plant.  ``reasons`` holds every reason in the refuser's own words, one line each (the message
    when none are given); ``decision`` is the gate's (e.g. a
    :class:`~haptic_bus.control.gate.GateDecision`) when a gate refused, else None."""

    def __init__(self, message: str, reasons: tuple[str, ...] = (), decision: Decision | None = None) -> None:
        self.reasons = reasons or (message,)
        self.decision = decision
        super().__init__(message)

    @classmethod
    def by_gate(cls, decision: Decision, where: str = "", subject: str = "change") -> Refusal:
        """A gate's refusal of ``subject`` (the ``change``, the ``scene``); ``where`` (e.g. ``profile PATH``)
        prefixes the message, which says the first :data:`NAMES_SHOWN` reasons and the count of the rest
        (``reasons`` holds every one)."""
        prefix = f"{where}: " if where else ""
        said = "; ".join(decision.reasons[:NAMES_SHOWN])
        rest = len(decision.reasons) - NAMES_SHOWN
        more = f"; and {rest} more" if rest > 0 else ""
        return cls(f"{prefix}passivity gate refused the {subject}: {said}{more}", decision.reasons, decision)


class AssumptionBroken(HapticBusError):
    """An assumption of the gate's verdict failed at run time (exit 3): ``assumption`` says which,
    ``observed`` what was measured, ``allowed`` what the gate assumed."""

    def __init__(self, assumption: str, observed: str, allowed: str) -> None:
        self.assumption = assumption
        self.observed = observed
        self.allowed = allowed
        super().__init__(f"assumption broken: {assumption}: {observed}; the gate assumed {allowed}")


__all__ = [
    "AssumptionBroken",
    "Decision",
    "DriveError",
    "DriveFault",
    "DriveProtocolError",
    "DriveRefusal",
    "DriveTimeout",
    "HapticBusError",
    "ModbusLinkLost",
    "ParameterError",
    "Refusal",
]
