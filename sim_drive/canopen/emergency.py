"""The slave's EMCY producer and its error register 0x1001 (CiA 301 7.2.7 and 7.5.2.2).

The EMCY's error-register byte is always 0x1001 as it reads at that moment:

- bit 0 (generic) whenever any error is present: the drive in FAULT or a communication error
  active (a watchdog that expired and has not recovered);
- bit 4 (communication) while a communication error is active, or the drive's fault code is
  of the communication class (0x81xx / 0x82xx).

An EMCY goes out when the drive enters FAULT (code 0x603F), when a communication error
starts, and an error-reset EMCY (code 0x0000) when the last error is gone (fault reset, a
watchdog recovered, or right after a one-off event such as a late PDO).  Nothing is sent while
the node is STOPPED, silent, or its EMCY is invalidated (0x1014 bit 31); frames go through
canopen's :class:`~canopen.emcy.EmcyProducer`.
"""

from __future__ import annotations

from collections.abc import Callable

from canopen.emcy import EmcyProducer

from drives.cia301 import ERROR_REGISTER_COMMUNICATION, ERROR_REGISTER_GENERIC
from drives.cia402 import State
from sim_drive.device import SimulatedDrive


def is_communication_code(code: int) -> bool:
    """True for EMCY/0x603F codes of the communication class (0x8100..0x82FF)."""
    return 0x8100 <= code <= 0x82FF


class Emergency:
    """Error register and EMCY of one slave; ``may_send()`` says whether the node may transmit one."""

    def __init__(self, producer: EmcyProducer, drive: SimulatedDrive, may_send: Callable[[], bool]) -> None:
        self.producer = producer
        self.drive = drive
        self.may_send = may_send
        self.enabled = True  # 0x1014 bit 31 clear
        self.active: set[int] = set()  # communication errors not yet recovered
        drive.state_listeners.append(self._on_state)

    @property
    def register(self) -> int:
        """0x1001 now."""
        faulted = self.drive.state in (State.FAULT, State.FAULT_REACTION_ACTIVE)
        register = ERROR_REGISTER_GENERIC if faulted or self.active else 0
        if self.active or (faulted and is_communication_code(self.drive.error_code)):
            register |= ERROR_REGISTER_COMMUNICATION
        return register

    def send(self, code: int, data: bytes = b"") -> None:
        """One EMCY with ``code``, the current register and ``data`` (up to 5 manufacturer bytes)."""
        if self.enabled and self.may_send():
            self.producer.send(code, self.register, data[:5])

    def communication_error(self, code: int, announce: bool = True) -> None:
        """A communication error starts (``announce``: send its EMCY here, not through a fault)."""
        self.active.add(code)
        if announce:
            self.send(code)

    def communication_event(self, code: int) -> None:
        """A communication error that is over as it happens (a late or short PDO, a bad SYNC):
        its EMCY with bit 4 set, then the error reset if nothing else is left."""
        was_active = code in self.active
        self.communication_error(code)
        if not was_active:
            self.communication_recovered(code)

    def communication_recovered(self, code: int) -> None:
        """A communication error is over; error-reset EMCY when nothing is left."""
        if code in self.active:
            self.active.discard(code)
            if not self.register:
                self.send(0)

    def _on_state(self, old: State, new: State, number: int | None) -> None:
        if new is State.FAULT:
            self.send(self.drive.error_code)
        elif old is State.FAULT:
            self.active.clear()
            self.send(0)
