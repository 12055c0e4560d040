"""A CANopen node stopped by NMT answers no SDO (CiA 301): the timeout says what its heartbeat shows."""

from __future__ import annotations

import time

import can
import pytest

from drives.canopen.drive import CanopenDrive
from drives.errors import DriveTimeout
from drives.safety import SafetySettings
from haptic_bus.app.profiles import load_profile


def test_a_stopped_node_that_answers_no_sdo_is_said_to_be_stopped(haptic_sim):
    """A node stopped by NMT answers no SDO (CiA 301); the timeout names what its heartbeat shows (break14b: an NMT
    stop during gantry-3d's commissioning read as a bare "no SDO answer", heartbeats showing STOPPED on the bus)."""
    sim = haptic_sim("cia402-handle", operator={"model": "none"})
    spec = sim.spec
    drive = CanopenDrive(5, **spec.drive_kwargs(), period=0.001, scaling=load_profile("cia402-handle").scaling(),
                         sdo_timeout=0.2, heartbeat_consumer_ms=0,
                         safety=SafetySettings(master_node_id=None, rpdo_deadline_periods=0))
    spy = can.Bus(**spec.config())
    try:
        drive.connect()
        spy.send(can.Message(arbitration_id=0x000, data=[0x02, 5], is_extended_id=False))  # NMT stop node 5
        deadline, stopped = time.monotonic() + 2.0, False
        while not stopped and time.monotonic() < deadline:  # bounded: its next heartbeat, 0.1 s apart
            msg = spy.recv(0.1)
            stopped = msg is not None and msg.arbitration_id == 0x705 and msg.data[:1] == b"\x04"
        assert stopped, "no heartbeat showing STOPPED"
        with pytest.raises(DriveTimeout, match=r"no SDO answer reading 0x1000:00 .* its heartbeat shows NMT STOPPED, "
                                               r"where a node answers no SDO"):
            drive.sdo_read(0x1000)
        with pytest.raises(DriveTimeout, match=r"no SDO answer writing 0x6060:00 .*NMT STOPPED, where a node answers no "
                                               r"SDO \(.*reset it\)$"):  # dropped by the node: nothing more to say
            drive.sdo_write(0x6060, 0, bytes([10]))
    finally:
        spy.shutdown()
        drive.close()


def test_a_write_that_met_no_answer_may_still_be_applied_and_the_line_says_so(canopen_rig) -> None:
    """A drive that takes a write but answers late (SIGSTOPped, starved) applies it all the same (break16: ``sdo
    write`` to a stopped process exited 1, and after SIGCONT 0x6060 was 10): the timeout's line says so."""
    with canopen_rig("virtual", "ideal", sdo_timeout=0.2) as rig:
        with rig.sim.paused(), pytest.raises(DriveTimeout, match=r"no SDO answer writing 0x6060:00 \(Modes of "
                                                                   r"operation\) within 0.2 s: .*; the request went "
                                                                   r"out, so a drive that answers late may still apply it$"):
            rig.drive.sdo_write(0x6060, 0, bytes([10]))
        deadline = time.monotonic() + 2.0  # bounded: the request waits on the bus for the receive thread
        while rig.sim.drive.mode != 10 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert rig.sim.drive.mode == 10  # applied late, as the line warned
