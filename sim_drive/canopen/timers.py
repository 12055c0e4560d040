"""The slave's clocks: the heartbeat it produces, the master heartbeat it consumes, its RPDO deadlines.

One receive thread keeps all of them (it wakes at the earliest due time), so a thread that
stops also stops the node's heartbeat: a node that can no longer serve never says it is alive.

- Producer (0x1017): the boot-up message counts as the first heartbeat; the next is due one
  period after it (CiA 301 7.2.8.3.2.2).
- Consumer (0x1016 sub 1): armed by the watched node's first heartbeat after configuration;
  a gap longer than the consumer time is a heartbeat event (EMCY 0x8130); the next heartbeat
  re-arms it.
- RPDO deadline (0x1400+n sub 5, the event timer read as a receive deadline, CiA 301
  7.5.2.35): armed by the first reception of RPDO n in OPERATIONAL; a gap longer than the
  event time is an RPDO timeout (EMCY 0x8250); the next reception re-arms it.

Times are ``time.monotonic()`` seconds.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class Watchdog(enum.Enum):
    """What expired."""

    HEARTBEAT = "heartbeat consumer"
    RPDO = "RPDO deadline"


@dataclass(frozen=True)
class Expiry:
    """One watchdog that ran out: which, and for a deadline the RPDO number."""

    watchdog: Watchdog
    rpdo: int = 0


class NodeTimers:
    """Every due time of one slave (see the module docstring)."""

    def __init__(self) -> None:
        self.producer_period = 0.0
        self._producer_due: float | None = None
        self.consumer_node: int | None = None
        self.consumer_period = 0.0
        self._consumer_due: float | None = None
        self._rpdo_periods: dict[int, float] = {}
        self._rpdo_due: dict[int, float] = {}

    # ------------------------------------------------------------------ producer

    def start_producer(self, period: float, now: float) -> None:
        """Produce every ``period`` s (0: not at all); the boot-up just sent counts as the first."""
        self.producer_period = period
        self._producer_due = now + period if period > 0 else None

    def stop_producer(self) -> None:
        """No more heartbeats (a silent node, or one that lost its heartbeat)."""
        self._producer_due = None

    def heartbeat_due(self, now: float) -> bool:
        """True when a heartbeat must go out now (then the next one is scheduled)."""
        due = self._producer_due
        if due is None or now < due:
            return False
        period = self.producer_period
        self._producer_due = due + period if now < due + period else now + period  # never a burst to catch up
        return True

    # ------------------------------------------------------------------ consumer

    def configure_consumer(self, node: int | None, period: float) -> None:
        """Watch ``node``'s heartbeat with consumer time ``period`` s (None or 0: watch nothing)."""
        self.consumer_node = node if node and period > 0 else None
        self.consumer_period = period
        self._consumer_due = None

    def heartbeat_seen(self, node: int, now: float) -> bool:
        """A heartbeat of ``node`` arrived; True if it is the watched one (the consumer re-arms)."""
        if node != self.consumer_node:
            return False
        self._consumer_due = now + self.consumer_period
        return True

    # ------------------------------------------------------------------ RPDO deadlines

    def configure_rpdo(self, number: int, period: float) -> None:
        """RPDO ``number``'s deadline ``period`` s (0: not monitored)."""
        if period > 0:
            self._rpdo_periods[number] = period
        else:
            self._rpdo_periods.pop(number, None)
        self._rpdo_due.pop(number, None)

    def rpdo_seen(self, number: int, now: float) -> None:
        """RPDO ``number`` arrived in OPERATIONAL: its deadline moves on."""
        period = self._rpdo_periods.get(number)
        if period is not None:
            self._rpdo_due[number] = now + period

    def stop_rpdo_monitoring(self) -> None:
        """Leaving OPERATIONAL: no RPDO is expected until the next reception arms it again."""
        self._rpdo_due.clear()

    # ------------------------------------------------------------------ expiry

    def next_due(self) -> float | None:
        """The earliest due time of anything, or None."""
        dues = [d for d in (self._producer_due, self._consumer_due) if d is not None]
        dues += self._rpdo_due.values()
        return min(dues) if dues else None

    def expired(self, now: float) -> list[Expiry]:
        """Watchdogs that ran out by ``now`` (each disarmed until its next heartbeat or RPDO)."""
        found = []
        if self._consumer_due is not None and now > self._consumer_due:
            self._consumer_due = None
            found.append(Expiry(Watchdog.HEARTBEAT))
        for number, due in list(self._rpdo_due.items()):
            if now > due:
                del self._rpdo_due[number]
                found.append(Expiry(Watchdog.RPDO, number))
        return found
