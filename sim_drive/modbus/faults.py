"""Faults the simulated Modbus server injects into its next requests (busy, exception, delay, drop)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

from pymodbus.constants import ExcCodes

from haptic_bus.errors import ParameterError

__all__ = ["Fault", "FaultInjector"]


@dataclass
class Fault:
    """One armed fault: ``kind`` is "exception" (answer ``code``), "delay" (answer ``seconds`` s late)
    or "drop" (close the connection); ``count`` requests are still to meet it."""

    kind: str
    count: int
    code: int = 0
    seconds: float = 0.0


class FaultInjector:
    """Faults for the next requests, consumed one per request (thread-safe to arm).

    ``busy(n)``: answer 0x06 SERVER DEVICE BUSY; ``exception(code, n)``: any exception code;
    ``delay(seconds, n)``: answer late; ``drop()``: close the connection instead of answering.
    Nothing of a faulted request is applied (a delayed one is applied after the delay).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._queue: list[Fault] = []
        self.injected = 0  # faults taken by requests so far

    def busy(self, count: int = 1) -> None:
        """The next ``count`` requests answer exception 0x06 (server busy)."""
        self.exception(ExcCodes.DEVICE_BUSY, count)

    def exception(self, code: int, count: int = 1) -> None:
        """The next ``count`` requests answer Modbus exception ``code`` (one of pymodbus' ``ExcCodes``)."""
        try:
            code = ExcCodes(code)
        except ValueError:
            raise ParameterError("code", code, ", ".join(f"0x{c:02X}" for c in ExcCodes), "FaultInjector.exception") from None
        with self._lock:
            self._queue.append(Fault("exception", count, code=code))

    def delay(self, seconds: float, count: int = 1) -> None:
        """The next ``count`` requests are answered ``seconds`` (s) late."""
        with self._lock:
            self._queue.append(Fault("delay", count, seconds=seconds))

    def drop(self) -> None:
        """The next request closes its connection (no answer)."""
        with self._lock:
            self._queue.append(Fault("drop", 1))

    def clear(self) -> None:
        """Forget armed faults."""
        with self._lock:
            self._queue.clear()

    def take(self) -> Fault | None:
        """The fault for the request being served, if any (counts it as met)."""
        with self._lock:
            if not self._queue:
                return None
            fault = self._queue[0]
            fault.count -= 1
            if fault.count <= 0:
                self._queue.pop(0)
            self.injected += 1
            return fault
