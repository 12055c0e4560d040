"""A second master on a Modbus device already driven is refused without writing to any unit.

Seen: ``haptic-bus run gantry-3d --modbus URL --unit-ids 1,2,3`` started beside a running one
was refused ("Modbus unit 1 ... another master drives it"), but closing its links to units 2
and 3 wrote their safe outputs: those two units of the running run went to SWITCH ON DISABLED.
"""

from __future__ import annotations


def test_a_refused_second_master_leaves_every_unit_to_the_first(haptic_sim, haptic_controller):
    device = haptic_sim("gantry-3d", interface="modbus")
    first = haptic_controller("gantry-3d", device, duration=4.0, plots=False)
    first.wait_cycling()
    second = haptic_controller("gantry-3d", device, duration=0.1, plots=False).wait()
    assert second.exit_reason == "drive error"
    assert "another master drives it" in second.error
    done = first.wait()
    # every unit stayed enabled under the first master: a unit disabled under it now ends its run
    assert done.exit_reason == "completed", done.error
    assert all(len(record["time_s"]) == 2000 for record in done.records.values())  # 4 s at T = 2 ms
