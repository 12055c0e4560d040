"""``haptic-bus sim --clock wall``: a reset restarts the SYNC clock, so the idle time before a run is not stepped through.

Each run resets the drive's communication, then sends its first SYNC.  Before, that SYNC closed
an interval as long as the time since the last run's last SYNC, and the plant stepped through it
in period-long pieces (about 4 ms of the simulator per idle second): after 45 s idle it answered
174 ms late and the next run's pre-flight failed ("no TPDO ... for 3 consecutive cycles").
"""

from __future__ import annotations

import time

import can

from drives.bus_config import open_bus
from sim_drive.canopen.slave import CanopenSimDrive
from sim_drive.sync_clock import IDLE as IDLE_BOUND
from sim_drive.sync_clock import WallSyncClock

CHANNEL = "test_sim_wall_clock_reset"
NODE = 5
IDLE = 0.3  # s between SYNCs: far above a period (1 ms), far below the 5 s each wait is bounded by


def _sync_and_wait(bus: can.BusABC, sim: CanopenSimDrive) -> float:
    """One SYNC; the simulated handle's time once the drive has taken it (s)."""
    before = sim.drive.sync_count
    bus.send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
    deadline = time.monotonic() + 5.0
    while sim.drive.sync_count == before:
        assert time.monotonic() < deadline, "the simulated drive took no SYNC within 5 s"
        time.sleep(0.001)
    return sim.drive.handle.time


def test_the_first_sync_after_a_reset_closes_one_period_not_the_idle_time() -> None:
    sim = CanopenSimDrive({"interface": "virtual", "channel": CHANNEL}, NODE, sync_clock=WallSyncClock()).start()
    bus = open_bus(interface="virtual", channel=CHANNEL)
    try:
        period = sim.drive.parameters.period
        first = _sync_and_wait(bus, sim)
        time.sleep(IDLE)
        idle = _sync_and_wait(bus, sim) - first
        assert idle > IDLE - 0.05  # the wall clock: the time between the SYNCs' receptions (sleep never short)
        time.sleep(IDLE)
        bus.send(can.Message(arbitration_id=0x000, data=bytes([0x82, NODE]), is_extended_id=False))  # reset communication
        deadline = time.monotonic() + 5.0
        while (boot := bus.recv(0.1)) is None or (boot.arbitration_id, bytes(boot.data)) != (0x700 + NODE, b"\x00"):
            assert time.monotonic() < deadline, "no boot-up within 5 s of the reset"
        before = sim.drive.handle.time
        after = _sync_and_wait(bus, sim)
        assert abs((after - before) - period) < 1e-12  # one period, as the very first SYNC closes
    finally:
        bus.shutdown()
        sim.stop()


def test_an_interval_longer_than_the_idle_bound_closes_one_period() -> None:
    """A Modbus master's first cycle after idle time (no reset on that bus): one period, not the idle time."""
    clock = WallSyncClock()
    assert clock(100.0) is None  # the first: one period
    assert clock(100.001) == 0.001  # then the time between them, to the microsecond
    assert clock(100.001 + IDLE_BOUND) == IDLE_BOUND  # at the bound: still stepped
    assert clock(100.001 + 2 * IDLE_BOUND + 1e-3) is None  # beyond it: one period
    assert clock(100.003 + 2 * IDLE_BOUND + 1e-3) == 0.002
