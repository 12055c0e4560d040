"""Issue 11, the live view: once a second while a run goes on, the cycles, position, force,
the scene in effect (and the start ramp), lateness p99 and overruns, the observer's energy
and the last event; a rich panel on a terminal, plain lines otherwise, none with ``-q``.

The command-line tests run in real time (the view's pace is the wall clock's, so a lock-step
run would print as many lines as this machine's speed allows), in this process, against the
simulated drive on python-can's ``virtual`` bus; their profile runs at T = 5 ms and only
warns when late (a loaded machine must not stop them: lateness is not what they test), with
the drive's watchdogs at 2 s.
"""

from __future__ import annotations

import io
import os
import pathlib
import re
import select
import time

import pytest

from haptic_bus.app.live import LiveView, status_fields
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.control.controller import WallController, encoder_origin
from tests.run_rig import profile_variant, run_cli, simulated_drive

TITLE = "haptic-bus run cia402-handle"
LINE = re.compile(rf"{TITLE}: cycles (\d+); position [+-]\d+\.\d{{3}} mm; force [+-]\d+\.\d{{3}} N; scene 0; "
                  r"observer [+-][0-9.e+-]+ mJ; lateness p99 \d+ us; overruns \d+(; last event \d+\.\d{3} s \w+: .+)?$")


@pytest.mark.parametrize("quiet, seconds", [(False, 3.5), (True, 1.5)], ids=["plain-lines", "quiet"])
def test_the_live_view_prints_a_plain_line_a_second_unless_quiet(
        quiet: bool, seconds: float, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    profile = profile_variant(tmp_path, "cia402-handle", "relaxed", {
        "period = 0.001 ": "period = 0.005 ", 'bandwidth = "strict"': 'bandwidth = "warn"'},
        '[supervisor]\non_late = "warn"\n[safety]\nconsumer_ms = 2000\nrpdo_deadline_periods = 400\n')
    with simulated_drive("canopen", profile) as drive:
        started = time.monotonic()
        result = run_cli(capsys, "run", str(profile), *drive.args, "--duration", str(seconds), "--out", str(tmp_path / "run"),
                         *(["-q"] if quiet else []))
        elapsed = time.monotonic() - started
    assert result.code == 0, result.err
    assert elapsed >= seconds  # real time: the run lasted its duration of wall clock
    live = [line for line in (result.out + result.err).splitlines() if line.startswith(TITLE)]
    if quiet:
        assert live == [] and result.err == ""
        return
    assert all(line in result.err.splitlines() for line in live)  # on stderr: stdout keeps the summary
    assert 2 <= len(live) <= 4, live  # at about 1, 2 and 3 s of a 3.5 s run
    cycles = []
    for line in live:
        match = LINE.match(line)
        assert match is not None, line
        cycles.append(int(match.group(1)))
    assert cycles == sorted(cycles) and cycles[0] > 0 and cycles[-1] <= round(seconds / 0.005)


def _stepped(controller: WallController, seconds: float) -> None:
    """Step the controller for ``seconds`` of wall clock (at most 200 000 cycles)."""
    end = time.monotonic() + seconds
    for _ in range(200_000):
        if time.monotonic() >= end:
            return
        controller.step()


def test_the_view_shows_the_ramp_and_the_last_event_from_the_controller_itself() -> None:
    """LiveView on a controller over the simulated drive (lock-step CANopen bus, in process):
    the fields as the record has them, the start ramp's scale, the newest event."""
    profile = load_profile("cia402-handle")
    with simulated_canopen(profile) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive), supervisor=profile.supervisor, ramp_time=0.1)
        for _ in range(10):
            controller.step()
        row = controller.record.latest()
        assert row is not None
        fields = status_fields(controller)
        assert fields == {"cycles": "10", "position": f"{row['position_m'] * 1e3:+.3f} mm",
                          "force": f"{row['force_n']:+.3f} N", "scene": "0 (ramp 10%)",  # 10 of 100 ramp cycles
                          "observer": f"{row['energy_j'] * 1e3:+.4g} mJ", "overruns": "0"}  # virtual time: no lateness
        controller.events.add(controller.now(), "upload", "upload accepted as scene 1")
        stream = io.StringIO()
        with LiveView(controller, "view", stream=stream):
            _stepped(controller, 1.4)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1, lines  # one a second, and the view stopped with the block
    assert lines[0].startswith("view: cycles ") and lines[0].endswith("; last event 0.010 s upload: upload accepted as scene 1")
    assert "; scene 0; " in lines[0]  # the ramp (0.1 s) is over by then


def test_on_a_terminal_the_view_is_a_rich_panel() -> None:
    profile = load_profile("cia402-handle")
    master, slave = os.openpty()
    terminal = os.fdopen(slave, "w")
    try:
        with simulated_canopen(profile) as (_, drive):
            controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                        origin=encoder_origin(drive))
            with LiveView(controller, "panel title", stream=terminal):
                _stepped(controller, 0.3)
        terminal.flush()
        shown = b""
        while select.select([master], [], [], 0.5)[0] and len(shown) < 1_000_000:
            shown += os.read(master, 65536)
    finally:
        terminal.close()
        os.close(master)
    text = shown.decode(errors="replace")
    assert "panel title" in text and "cycles" in text and "observer" in text
    assert "\x1b[" in text and any(corner in text for corner in "╭┌+")  # drawn with terminal control codes, boxed
