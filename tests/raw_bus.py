"""Helpers for tests that handle python-can buses themselves: not a test module.

- :func:`queued` takes every frame a bus has queued now (a sniffer's view of what was sent).
- :class:`FailingBus` is python-can's ``virtual`` bus whose receive raises
  ``can.CanOperationError`` when the test says so, as a bad udp_multicast datagram or a lost
  interface does.
"""

from __future__ import annotations

from collections.abc import Callable

import can

MAX_QUEUED = 100_000  # frames: the bound of one drain


def queued(bus: can.BusABC) -> list[can.Message]:
    """Every frame queued on ``bus`` now, in order (bounded by :data:`MAX_QUEUED`)."""
    frames = []
    for _ in range(MAX_QUEUED):
        message = bus.recv(0.0)
        if message is None:
            break
        frames.append(message)
    return frames


class FailingBus(can.BusABC):
    """A virtual bus on ``channel`` whose receive raises ``can.CanOperationError(reason)`` on each
    call ``n`` (1, 2, ...) for which ``fails(n)`` is true; ``raised`` counts them."""

    def __init__(self, channel: str, fails: Callable[[int], bool], reason: str) -> None:
        self.inner = can.Bus(interface="virtual", channel=channel)
        self.fails = fails
        self.reason = reason
        self.calls = 0
        self.raised = 0
        super().__init__(channel=channel)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self.calls += 1
        if self.fails(self.calls):
            self.raised += 1
            raise can.CanOperationError(self.reason)
        return self.inner.recv(timeout), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)

    def shutdown(self) -> None:
        self.inner.shutdown()
        super().shutdown()
