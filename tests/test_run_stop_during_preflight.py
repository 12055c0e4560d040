"""A stop asked while a wall-paced run measures its pre-flight ends the run "stopped" (SIGTERM; Ctrl-C:
"interrupted"), its drive never enabled, whatever the measurement's verdict: it used to finish the
pre-flight and end "refused" (exit 1) when this machine could not hold the period.  Over Modbus TCP on
loopback: on CAN the bus-load check refuses such a period before any pre-flight (one axis' 360 bit
times a cycle need T >= 0.514 ms at 70 % of 1 Mbit/s)."""

from __future__ import annotations

import pathlib

import haptic_bus as hb
import profiles
from haptic_bus.app.run_options import RealtimeSettings

SHIPPED = pathlib.Path(profiles.__file__).parent / "cia402-handle.toml"
UNHOLDABLE_PERIOD = "period = 0.0001"  # s: 0.1 ms, less than a Modbus poll's round trip in Python takes anywhere


def test_a_stop_during_the_preflight_is_a_stop_not_a_refusal(haptic_sim, recorded_run, tmp_path: pathlib.Path) -> None:
    text = SHIPPED.read_text()
    assert text.count("\nperiod = 0.001 ") == 1
    profile_path = tmp_path / "fast.toml"
    profile_path.write_text(text.replace("\nperiod = 0.001 ", f"\n{UNHOLDABLE_PERIOD} "))
    drive = haptic_sim(str(profile_path), interface="modbus")
    options = hb.RunOptions(1.0, out_dir=tmp_path / "run", live=False, plots=False, start_in_contact="ramp",
                            scheduling=RealtimeSettings.unprivileged())
    options.stop.event.set()  # SIGTERM as soon as the run began: the pre-flight still measures, then it stops
    result = hb.run(hb.load_profile(profile_path), drive.bus, options)
    assert (result.exit_reason, result.error, result.summary) == ("stopped", None, None)
    run = recorded_run(result.folder)
    assert run.exit_reason == "stopped"
    assert "preflight" not in run.document  # stopped before its verdict was taken
