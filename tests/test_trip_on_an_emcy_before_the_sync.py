"""A fault the drain read before the SYNC trips the drive without waiting out the TPDO timeout (found by hand by
a session trying to break 5aedf65, break14b; both tests failed before the mend).

A drive that reports a fault by EMCY and leaves NMT OPERATIONAL (an NMT stop here: the simulated drive
sends EMCY 0x8100 and answers no SYNC) must trip at the next cycle as before 5aedf65, when the event
check ran before the SYNC: not after the collect has waited its whole ``tpdo_timeout`` for TPDOs the
stopped drive will not send.  ``tpdo_timeout`` is 2 s here so that the two behaviours are apart by
orders of magnitude: the trip takes milliseconds; waiting out the collect takes 2 s.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import can
import pytest

from drives.base import DriveScaling
from drives.canopen.drive import CanopenDrive
from drives.errors import DriveFault
from drives.safety import SafetySettings

TPDO_TIMEOUT = 2.0  # s: no watchdog set (below), so the cycle may wait this long for a silent drive
SCALING = DriveScaling(1.1984224905356573e-07, 1.1984224905356573e-07, 0.32, 50.0, 2000)  # profile cia402-handle [device]
TRIP_BOUND = 1.0  # s: half of TPDO_TIMEOUT; the trip itself takes a few ms (0.5-1.2 ms on udp_multicast)


def _stop_and_trip(spy: can.BusABC, node: int, read_inputs: Callable[[], object], cycle: Callable[[], object]) -> None:
    """After 20 cycles (``cycle``), an NMT stop of ``node``, its EMCY 0x8100 seen on the bus, then the next
    ``read_inputs`` trips on it within :data:`TRIP_BOUND` (not after the collect's :data:`TPDO_TIMEOUT`)."""
    for _ in range(20):
        cycle()
    while spy.recv(0.0) is not None:  # bounded: the frames of 20 cycles
        pass
    spy.send(can.Message(arbitration_id=0x000, data=[0x02, node], is_extended_id=False))  # NMT stop
    deadline = time.monotonic() + 2.0
    emcy = None
    while emcy is None and time.monotonic() < deadline:
        msg = spy.recv(0.1)
        if msg is not None and msg.arbitration_id == 0x080 + node:
            emcy = msg
    assert emcy is not None and emcy.data[:2] == bytes([0x00, 0x81]), "the stopped drive sent no EMCY 0x8100"
    started = time.perf_counter()
    with pytest.raises(DriveFault, match=f"node {node}: EMCY 0x8100"):
        read_inputs()
    elapsed = time.perf_counter() - started
    assert elapsed < TRIP_BOUND, (f"the trip waited {elapsed:.3f} s: the collect waited out its {TPDO_TIMEOUT} s "
                                  "for a drive whose EMCY was already read")


def test_an_emcy_read_before_the_sync_trips_without_waiting_for_the_stopped_drives_tpdos(haptic_sim):
    sim = haptic_sim("cia402-handle", operator={"model": "none"})
    spec = sim.spec
    drive = CanopenDrive(5, **spec.drive_kwargs(), period=0.001, scaling=SCALING, tpdo_timeout=TPDO_TIMEOUT,
                         heartbeat_consumer_ms=0, safety=SafetySettings(master_node_id=None, rpdo_deadline_periods=0))
    spy = can.Bus(**spec.config())
    try:
        drive.connect()
        drive.enable()
        _stop_and_trip(spy, 5, drive.read_inputs, lambda: (drive.read_inputs(), drive.write_outputs(0)))
    finally:
        spy.shutdown()
        drive.close()


def test_an_axis_emcy_read_before_the_sync_trips_every_axis_without_waiting_for_its_tpdos(haptic_sim):
    """The same on three axes (gantry-3d): node 6 stops; nodes 5 and 7 must not hold their last torque while
    the collect waits out ``tpdo_timeout`` for node 6 (on the wire, before 5aedf65: safe outputs 1.2 ms after
    the NMT stop; after it: 31 ms at the default 30 ms wait, T = 2 ms)."""
    from drives.canopen.axes import CanopenAxes
    from haptic_bus.app.profiles import load_profile

    profile = load_profile("gantry-3d")
    sim = haptic_sim("gantry-3d")
    spec = sim.spec
    axes = CanopenAxes([5, 6, 7], scalings=profile.scalings(), **spec.drive_kwargs(), period=0.002,
                       tpdo_timeout=TPDO_TIMEOUT, heartbeat_consumer_ms=0,
                       safety=SafetySettings(master_node_id=None, rpdo_deadline_periods=0))
    spy = can.Bus(**spec.config())
    try:
        axes.connect()
        axes.enable()
        _stop_and_trip(spy, 6, axes.read_inputs, lambda: (axes.read_inputs(), axes.write_outputs([0, 0, 0])))
    finally:
        spy.shutdown()
        axes.close()
