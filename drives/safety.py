"""What a master sets up so that the drive stops on its own when the master is gone (DESIGN 4.1).

Bus-neutral data: the CANopen master writes it to the drive at commissioning
(:mod:`drives.canopen.commissioning`), the Modbus master to its watchdog register.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from drives.cia301 import NODE_ID_RANGE, NODE_IDS
from drives.cia402 import AbortConnectionOption
from drives.errors import ParameterError
from drives.ranges import real_in_range

DEFAULT_TPDO_WAIT = 0.05  # s: a cycle's wait for the drives' TPDOs where their watchdogs allow as much
VIRTUAL_TIME_DEADLINE = 2.0  # s: the drive watchdogs' floor (RPDO deadline, consumer, Modbus) when nothing paces the loop
VIRTUAL_TIME_WAIT = 0.5
"""s: how long a master waits for one answer of the drive (a TPDO, a Modbus reply) when nothing paces
the loop.  Only a dead drive should trip it, not a machine busy elsewhere: beside two CPU-bound jobs
and five test sessions a simulated drive's process went 250 ms without a turn (measured), and three
waits missed in a row (1.5 s) still end before the drive's own :data:`VIRTUAL_TIME_DEADLINE`."""
VIRTUAL_TIME_CANOPEN_PATIENCE: dict[str, Any] = {"tpdo_timeout": VIRTUAL_TIME_WAIT,
                                                 "heartbeat_consumer_ms": round(VIRTUAL_TIME_DEADLINE * 1000)}
"""A CANopen master's waits when nothing paces the loop (keyword arguments of
:class:`~drives.canopen.drive.CanopenDrive` and :class:`~drives.canopen.axes.CanopenAxes`): one
TPDO, and the drives' heartbeats, which helper threads send that a loop running flat out lets
have the interpreter only at its switch interval."""
VIRTUAL_TIME_MODBUS_PATIENCE: dict[str, Any] = {"timeout": VIRTUAL_TIME_WAIT}
"""A Modbus master's wait for one reply when nothing paces the loop (of :class:`~drives.modbus.drive.ModbusDrive`)."""


def patient(wall_paced: bool, waits: dict[str, Any]) -> dict[str, Any]:
    """A master's keyword arguments for its waits: ``waits`` (:data:`VIRTUAL_TIME_CANOPEN_PATIENCE` or
    :data:`VIRTUAL_TIME_MODBUS_PATIENCE`) when nothing paces the loop, none (the real-time defaults) when
    the wall clock does."""
    return {} if wall_paced else dict(waits)
ABORT_OPTIONS = {"none": 0, "fault": 1, "disable-voltage": 2, "quick-stop": 3}  # 0x6007 by name


@dataclass(frozen=True)
class SafetySettings:
    """What makes the drive stop on its own when the master is gone (DESIGN 4.1).

    ``master_node_id``: the node id whose heartbeat the master produces every ``heartbeat_ms``
    (boot-up first) and the drive consumes with consumer time ``consumer_ms`` (0x1016 sub 1);
    None: neither.  ``rpdo_deadline_periods``: the RPDO event timer 0x1400:05 as a receive
    deadline, in cycle periods (0: none).  ``abort_option``: 0x6007 (0 nothing, 1 fault,
    2 disable voltage, 3 quick stop).  ``strict``: refuse a drive that lacks one of these
    objects (otherwise a warning names what is missing).

    The defaults are a trade (README, "Safety"): the drive stops within about 30 ms of the
    controller's death at T = 1 ms (the RPDO deadline fires first; 60 ms over Modbus), well
    inside 100 ms, while a desktop machine that stalls a thread for up to 20 ms (measured here:
    a few ms idle, more beside CPU-bound work) keeps the drive running; a longer deadline also
    lengthens what the ``bound`` passivity layer must budget per target.
    """

    master_node_id: int | None = 127
    heartbeat_ms: int = 20
    consumer_ms: int = 90
    rpdo_deadline_periods: int = 30
    abort_option: int = int(AbortConnectionOption.FAULT)
    strict: bool = False
    modbus_watchdog_ms: int = 60

    def __post_init__(self) -> None:
        def check(name: str, ok: bool, allowed: str) -> None:
            if not ok:
                raise ParameterError(name, getattr(self, name), allowed, "CANopen safety settings")

        def whole(value: object) -> bool:
            return isinstance(value, int) and not isinstance(value, bool)

        node = self.master_node_id
        low, high = NODE_ID_RANGE
        check("master_node_id", node is None or (whole(node) and low <= node <= high), f"{NODE_IDS}, or None (no heartbeat)")
        check("heartbeat_ms", whole(self.heartbeat_ms) and 1 <= self.heartbeat_ms <= 0xFFFF, "1..65535 ms")
        check("consumer_ms", whole(self.consumer_ms) and self.heartbeat_ms < self.consumer_ms <= 0xFFFF,
              f"{self.heartbeat_ms + 1}..65535 ms (longer than the heartbeat period {self.heartbeat_ms} ms)")
        check("rpdo_deadline_periods", whole(self.rpdo_deadline_periods) and 0 <= self.rpdo_deadline_periods <= 10_000,
              "0 (none) .. 10000 cycle periods")
        check("abort_option", whole(self.abort_option) and 0 <= self.abort_option <= 3,
              "0 (nothing), 1 (fault), 2 (disable voltage), 3 (quick stop)")
        check("modbus_watchdog_ms", whole(self.modbus_watchdog_ms) and 0 <= self.modbus_watchdog_ms <= 0xFFFF,
              "0 (off) .. 65535 ms")

    def for_virtual_time(self, period: float) -> SafetySettings:
        """These settings for a loop nothing paces (virtual time, cycle period ``period`` s): the
        RPDO deadline, the drive's heartbeat consumer time and the Modbus watchdog of at least
        :data:`VIRTUAL_TIME_DEADLINE` s of wall clock, so that they guard against a dead master,
        not a busy machine that paused a lock-step run or the master's heartbeat thread."""
        floor_ms = round(VIRTUAL_TIME_DEADLINE * 1000)
        periods = self.rpdo_deadline_periods
        if periods:
            periods = min(10_000, max(periods, math.ceil(VIRTUAL_TIME_DEADLINE / period)))
        watchdog = max(self.modbus_watchdog_ms, floor_ms) if self.modbus_watchdog_ms else 0
        return dataclasses.replace(self, rpdo_deadline_periods=periods, modbus_watchdog_ms=watchdog,
                                   consumer_ms=max(self.consumer_ms, floor_ms))

    def canopen_stall(self, period: float) -> float:
        """The shortest stall of the master (s) that faults a CANopen drive with these settings at cycle
        period ``period`` s: its RPDO deadline, or the slack its heartbeat consumer leaves over the
        master's heartbeat (inf: neither is set)."""
        deadline = self.rpdo_deadline_ms(period) / 1000.0 if self.rpdo_deadline_periods else math.inf
        slack = (self.consumer_ms - self.heartbeat_ms) / 1000.0 if self.master_node_id is not None else math.inf
        return min(deadline, slack)

    def longest_tpdo_wait(self, period: float, wanted: float | None) -> float:
        """How long (s) one cycle may wait for the drives' TPDOs at period ``period`` s: ``wanted``, or
        (None) :data:`DEFAULT_TPDO_WAIT`, at most half of :meth:`canopen_stall` -- a cycle that waits
        for a silent drive sends every drive its RPDO and the heartbeat that much later, and a wait as
        long as the stall would fault the drives that answered.  ParameterError naming ``tpdo_timeout``
        for a ``wanted`` that is not a finite real in (0, that half] s (neither watchdog set)."""
        most = self.canopen_stall(period) / 2.0
        if wanted is None:
            return min(DEFAULT_TPDO_WAIT, most)
        try:
            return real_in_range("tpdo_timeout", wanted, 0.0, most, low_inclusive=False, unit="s")
        except ParameterError as error:
            deadline = f"{self.rpdo_deadline_ms(period)} ms" if self.rpdo_deadline_periods else "none"
            slack = f"{self.consumer_ms - self.heartbeat_ms} ms" if self.master_node_id is not None else "none (no heartbeat)"
            why = "half the shortest stall that faults the drive" if math.isfinite(most) else "no stall faults the drive"
            raise ParameterError(error.name, wanted, f"{error.allowed}: {why} at T = {period * 1e3:.4g} ms (RPDO deadline "
                                 f"{deadline}, heartbeat consumer slack {slack})", "CANopen master") from None

    def rpdo_deadline_ms(self, period: float) -> int:
        """The RPDO event timer for cycle period ``period`` s, ms (0: none; at least 1 otherwise)."""
        if not self.rpdo_deadline_periods:
            return 0
        return min(0xFFFF, max(1, round(self.rpdo_deadline_periods * period * 1000.0)))


DEFAULT_SAFETY = SafetySettings()  # frozen: the one shared default of every master
