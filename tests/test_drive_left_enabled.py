"""A drive that leaves OPERATION ENABLED without a fault ends the run, as a fault does.

Seen over Modbus: a second master, refused, disabled two of a running three-axis run's units
(their statusword 0x0240, SWITCH ON DISABLED, no fault bit); the run cycled on for 87 cycles
with no wall on those axes and ended "completed", exit 0.  Only the fault bit tripped a master.
Here the drive's own panel, as it were: its controlword DISABLE VOLTAGE while the run cycles.
"""

from __future__ import annotations

from drives.cia402 import Command


def test_a_drive_disabled_under_the_run_stops_it(haptic_sim, haptic_controller):
    drive = haptic_sim("cia402-handle", interface="lockstep", operator={"model": "none"})
    run = haptic_controller("cia402-handle", drive, duration=5.0, plots=False)
    run.wait_cycling()
    drive.sim.drive.write_controlword(Command.DISABLE_VOLTAGE.word)  # not this master's doing
    result = run.wait()
    assert result.exit_reason == "drive error"
    assert "left OPERATION ENABLED without a fault: statusword 0x0240 (SWITCH ON DISABLED)" in result.error
    assert len(result.record["time_s"]) < 5000  # it stopped, where it used to run its 5 s out
