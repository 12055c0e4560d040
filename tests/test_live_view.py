"""Issues 11 and 20, the live view: cycles, the run's elapsed and remaining time, position, force,
contact (in or out, which objects), the K and B in effect, the scene (and the start ramp),
lateness p99, overruns, the observer's energy and the whole last event; a rich panel on a
terminal with every log line printed above it (never through it), plain lines otherwise, none
with ``-q``.

No test here waits on the wall clock: the view's fields are read from a controller stepped over
the simulated drive (lock-step CANopen bus, in process), its wall-clock time comes from a fake
clock, and views are drawn with ``LiveView.update``; the command-line tests run in virtual time
and read the view drawn when the run ends.  The terminal test reads what the view wrote to a
pseudo-terminal through pyte, a terminal emulator, and checks the screen a user would see.
"""

from __future__ import annotations

import fcntl
import io
import logging
import os
import pathlib
import re
import struct
import termios
import threading

import pyte
import pytest

from haptic_bus.app.live import LiveView, status_fields
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.control.controller import WallController, encoder_origin
from tests.run_rig import run_cli, simulated_drive

TITLE = "haptic-bus run cia402-handle"
LONG_EVENT = ("upload accepted as scene 1 after the operator asked for a stiffer end stop while the handle rested "
              "against it; the gate judged the summed wall at the loop delay the profile declares and found a margin "
              "of 6.5 N s/m, so nothing here is cut short")


class FakeClock:
    """Seconds that pass only when the test says so."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_quiet_runs_show_no_view(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    with simulated_drive("canopen", "cia402-handle") as drive:
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.3",
                         "--out", str(tmp_path / "run"), "-q", "--no-plots")
    assert result.code == 0, result.err
    assert result.err == "" and TITLE not in result.out


def test_the_fields_show_time_contact_k_b_and_the_whole_last_event() -> None:
    profile = load_profile("cia402-handle")
    with simulated_canopen(profile) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive), supervisor=profile.supervisor, ramp_time=0.5)
        for _ in range(10):
            controller.step()
        row = controller.record.latest()
        assert row is not None
        fields = status_fields(controller, wall_elapsed=65.0, duration=10.0)
        assert fields == {"cycles": "10", "time": "0.0 s of 10.0 s (wall clock 1:05.0)", "remaining": "10.0 s",
                          "position": f"{row['position_m'] * 1e3:+.3f} mm", "force": "+0.000 N",
                          "contact": "out (free)", "K, B": "0 N/m, 0 N s/m", "scene": "0 (ramp 2%)",
                          "port energy": f"{row['energy_j'] * 1e3:+.4g} mJ",
                          "passivity layer": "guard, lowered 0 targets", "overruns": "0"}  # virtual time: no lateness
        while controller.record.latest()["position_m"] < 0.004 and controller.cycles < 2000:  # type: ignore[index]
            controller.step()  # the operator pushes the handle 1 mm into the end stop (at 3 mm)
        controller.events.add(controller.now(), "upload", LONG_EVENT)
        fields = status_fields(controller)
        scale = controller.record.latest()["scale"]  # type: ignore[index]
    assert "time" not in fields and fields["contact"] == "in end-stop"
    assert fields["K, B"] == f"{scale * 1500:g} N/m, {scale * 10:g} N s/m" and 0 < scale < 1  # the ramp scales both
    assert fields["last event"] == f"{controller.now():.3f} s upload: {LONG_EVENT}"  # whole


def test_a_fake_clock_drives_the_plain_view_without_waiting() -> None:
    profile = load_profile("cia402-handle")
    clock = FakeClock()
    stream = io.StringIO()
    with simulated_canopen(profile) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive))
        with LiveView(controller, "view", stream=stream, duration=2.0, clock=clock, refresh=None) as view:
            for _ in range(500):
                controller.step()
            clock.now += 5.0
            view.update()
            for _ in range(1000):
                controller.step()
            clock.now += 2.5
            view.update()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2  # two updates, two lines: none added at the end (a failed run's stderr keeps its one line)
    assert re.fullmatch(r"view: cycles 500; time 0\.5 s of 2\.0 s \(wall clock 5\.0 s\); remaining 1\.5 s; "
                        r"position \+\d\.\d{3} mm; force \+\d\.\d{3} N; contact (in end-stop|out \(free\)); "
                        r"K, B \d+ N/m, \d+ N s/m; scene 0; port energy [+-][0-9.e+-]+ mJ; "
                        r"passivity layer guard, lowered 0 targets; overruns 0", lines[0]), lines[0]
    assert lines[1].startswith("view: cycles 1500; time 1.5 s of 2.0 s (wall clock 7.5 s); remaining 0.5 s; ")


def _terminal(columns: int, rows: int) -> tuple[int, io.TextIOWrapper]:
    """A pseudo-terminal of that size: (the reading end, the writing end as a text stream)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))
    return master, os.fdopen(slave, "w")


def test_on_a_terminal_log_lines_go_above_one_whole_panel() -> None:
    columns, rows = 100, 60
    master, terminal = _terminal(columns, rows)
    shown = bytearray()
    reader = threading.Thread(target=lambda: _drain(master, shown), daemon=True)
    reader.start()
    root = logging.getLogger()
    handler = logging.StreamHandler(terminal)  # what the command line's logging set-up puts on stderr
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    saved = root.level, root.handlers[:]  # earlier command-line tests leave theirs (on streams pytest has closed)
    root.handlers = [handler]
    root.setLevel(logging.WARNING)  # as the command line sets it
    clock = FakeClock()
    profile = load_profile("cia402-handle")
    try:
        with simulated_canopen(profile) as (_, drive):
            controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                        origin=encoder_origin(drive))
            with LiveView(controller, "panel title", stream=terminal, duration=1.0, clock=clock, refresh=None) as view:
                for number in range(5):
                    for _ in range(100):
                        controller.step()
                    logging.getLogger("haptic_bus.test").warning("warning %d while the panel is up", number)
                    clock.now += 1.0
                    view.update()
                controller.events.add(controller.now(), "upload", LONG_EVENT)
            assert root.handlers.count(handler) == 1  # the terminal's handler is back
    finally:
        root.setLevel(saved[0])
        root.handlers = saved[1]
        terminal.close()
        reader.join(timeout=5.0)
        os.close(master)
    screen = pyte.Screen(columns, rows)
    pyte.ByteStream(screen).feed(bytes(shown))
    lines = [line.rstrip() for line in screen.display]
    tops = [i for i, line in enumerate(lines) if "panel title" in line]
    assert len(tops) == 1, "\n".join(lines)  # one panel: none stacked, none torn
    warnings = [i for i, line in enumerate(lines) if "while the panel is up" in line]
    assert [lines[i] for i in warnings] == [f"WARNING haptic_bus.test: warning {n} while the panel is up" for n in range(5)]
    assert max(warnings) < tops[0]  # every log line above the panel
    panel = " ".join(" ".join(line.strip("│ ") for line in lines[tops[0]:] if line).split())
    assert "cycles 500 time 0.5 s of 1.0 s (wall clock 5.0 s) remaining 0.5 s" in panel
    assert f"upload: {LONG_EVENT}" in panel  # the whole event, wrapped over lines


def _drain(fd: int, into: bytearray) -> None:
    """Read the terminal until its writing end is closed (a pty's buffer is small: the writer must not block)."""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except OSError:
            return
        if not chunk:
            return
        into += chunk
