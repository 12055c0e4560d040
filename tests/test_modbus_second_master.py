"""A second master on a Modbus device already driven is refused without writing to any unit.

Seen: ``haptic-bus run gantry-3d --modbus URL --unit-ids 1,2,3`` started beside a running one
was refused ("Modbus unit 1 ... another master drives it"), but closing its links to units 2
and 3 wrote their safe outputs: those two units of the running run went to SWITCH ON DISABLED.
"""

from __future__ import annotations

import time

from haptic_bus.app.profiles import load_profile

AFTER = 50  # cycles of the first run on every unit after the second's refusal
AFTER_WAIT = 30.0  # s of wall clock: a bound on a hang, not a pace


def test_a_refused_second_master_leaves_every_unit_to_the_first(haptic_sim, haptic_controller):
    device = haptic_sim("gantry-3d", interface="modbus")
    profile = load_profile("gantry-3d")  # one profile object for both runs
    first = haptic_controller(profile, device, duration=600.0, plots=False)
    first.wait_cycling()
    second = haptic_controller(profile, device, duration=0.1, plots=False).wait()
    assert second.exit_reason == "drive error"
    assert "another master drives it" in second.error
    # A unit the refused master disabled would end the first run ("drive error") at the first cycle that reads its
    # statusword; the first run goes on for AFTER cycles more on every unit (each cycle reads every unit's), then is
    # stopped, where it used to run out its 4 s (2 000 cycles, most of them after the refusal).
    units = device.served_units()
    since = [unit.bank.cycles for unit in units]
    deadline = time.monotonic() + AFTER_WAIT

    def after() -> int:
        """The fewest cycles any unit has closed since the refusal."""
        return min(unit.bank.cycles - start for unit, start in zip(units, since))

    while first.running and time.monotonic() < deadline and after() < AFTER:
        time.sleep(0.01)
    done = first.stop()
    # every unit stayed enabled under the first master: a unit disabled under it would have ended its run, which
    # cycled on after the refusal (a run stalled since, stopped at the deadline, shows nothing of the units)
    assert done.exit_reason == "stopped", done.error
    assert after() >= AFTER, (after(), AFTER)
    cycles = [len(record["time_s"]) for record in done.records.values()]
    assert len(set(cycles)) == 1 and cycles[0] >= AFTER  # every axis recorded every cycle
