"""A stop asked while a wall-paced run measures its pre-flight ends the run "stopped" (SIGTERM; Ctrl-C:
"interrupted"), its drive never enabled, whatever the measurement's verdict: it used to finish the
pre-flight and end "refused" (exit 1) when this machine could not hold the period.  Over Modbus TCP on
loopback: on CAN the bus-load check refuses such a period before any pre-flight (one axis' 360 bit
times a cycle need T >= 0.514 ms at 70 % of 1 Mbit/s)."""

from __future__ import annotations

import pathlib
import threading

import pytest

import haptic_bus as hb
import profiles
from drives.cia402 import State
from haptic_bus.app import run_options
from haptic_bus.app.run_options import RealtimeSettings
from tests.run_rig import read_run, run_cli, simulated_drive

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
    assert result.preflight_stopped == 0  # the stop was there before pre-flight's first cycle
    run = recorded_run(result.folder)
    assert run.exit_reason == "stopped"
    assert "preflight" not in run.document  # stopped before its verdict was taken
    assert run.document["preflight_stopped"] == {"cycles": 0}


MEASURED = 37  # pre-flight's cycles before the stop: fewer than its first look's 500


class _SetAfter(threading.Event):
    """An event that reads set from its ``checks + 1``-th ``is_set()`` on: the run checks it once at each
    pre-flight cycle's start (and nowhere before), so the stop lands after ``checks`` cycles, whatever the clock."""

    def __init__(self, checks: int) -> None:
        super().__init__()
        self.checks = checks

    def is_set(self) -> bool:
        self.checks -= 1
        return self.checks < 0 or super().is_set()


@pytest.mark.parametrize(("interrupted", "code", "reason", "err"), [
    (False, 0, "stopped", ""),  # SIGTERM: no error, nothing on stderr (docs/commands.md)
    (True, 130, "interrupted", "haptic-bus run: interrupted (Ctrl-C) during pre-flight, before enabling (37 cycles "
                               "measured)\n"),
], ids=["SIGTERM", "Ctrl-C"])
def test_a_stop_during_the_preflight_says_so_and_how_many_cycles_it_measured(
        interrupted: bool, code: int, reason: str, err: str, monkeypatch: pytest.MonkeyPatch,
        tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The end line said only "ended: stopped" (break18b): now where, and what pre-flight had measured."""

    class StopInPreflight(run_options.StopRequest):  # as SIGTERM (or SIGINT) would ask, after MEASURED cycles
        def __init__(self) -> None:
            super().__init__()
            self.event = _SetAfter(MEASURED)
            self.interrupted = interrupted

    monkeypatch.setattr(run_options, "StopRequest", StopInPreflight)
    with simulated_drive("modbus", "cia402-handle") as drive:
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--no-realtime", "--no-live", "--no-plots",
                         "--out", str(tmp_path))
        assert State.OPERATION_ENABLED not in drive.states
    assert (result.code, result.err) == (code, err)
    assert f"ended: {reason} during pre-flight, before enabling ({MEASURED} cycles measured); wrote " in result.out
    document = read_run(tmp_path)
    assert (document["exit_reason"], document["preflight_stopped"]) == (reason, {"cycles": MEASURED})
    assert "preflight" not in document and "summary" not in document
