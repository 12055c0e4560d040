"""Issues 11, 20 and 26, the live view, drawn in the run's writer process from the record rings:
cycles, the run's elapsed and remaining time, position and force (per axis for several, with
each axis' energy), the scene (and the start ramp), the port's energy (the sum over the axes),
lateness p99, late cycles, the targets the passivity layer lowered and the whole last event; a
rich panel on a terminal, plain lines otherwise, none with ``-q``.

No test here waits on the wall clock: the view's fields are read from the ring of a controller
stepped over the simulated drive (lock-step CANopen bus, in process) or from rings filled with
known rows, its wall-clock time comes from a fake clock, and views are drawn with
``LiveView.update``; the command-line tests run in virtual time
and read the view drawn when the run ends.  The terminal test reads what the view wrote to a
pseudo-terminal through pyte, a terminal emulator, and checks the screen a user would see.
"""

from __future__ import annotations

import fcntl
import io
import os
import pathlib
import re
import struct
import termios
import threading

import pyte
import pytest

from haptic_bus.app.live import LiveView
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.control.controller import WallController
from haptic_bus.control.joints import encoder_origin
from haptic_bus.control.record import RunRecord
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


def test_the_fields_show_time_position_force_scene_energy_and_the_whole_last_event() -> None:
    profile = load_profile("cia402-handle")
    clock = FakeClock()
    with simulated_canopen(profile) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive), supervisor=profile.supervisor, ramp_time=0.5)
        event: dict[str, object] | None = None
        with LiveView([("", controller.record)], "view", controller.period, io.StringIO(), duration=10.0, clock=clock,
                      last_event=lambda: event) as view:
            for _ in range(10):
                controller.step()
            clock.now += 65.0
            row = controller.record.latest()
            assert row is not None
            fields = view.fields()
            assert fields == {"cycles": "10", "time": "0.0 s of 10.0 s (wall clock 1:05.0)", "remaining": "10.0 s",
                              "position": f"{row['position_m'] * 1e3:+.3f} mm", "force": "+0.000 N",
                              "scene": "0 (ramp 2%)", "port energy": f"{row['energy_j'] * 1e3:+.4g} mJ",
                              "late cycles": "0", "passivity layer": "lowered 0 targets"}  # virtual time: no lateness
            while controller.record.latest()["position_m"] < 0.004 and controller.cycles < 2000:  # type: ignore[index]
                controller.step()  # the operator pushes the handle 1 mm into the end stop (at 3 mm)
            event = controller.events.add(controller.now(), "upload", LONG_EVENT).to_dict()
            fields = view.fields()
    row = controller.record.latest()
    assert row is not None and 0 < row["scale"] < 1 and row["force_n"] != 0.0
    assert fields["cycles"] == str(controller.cycles) and fields["force"] == f"{row['force_n']:+.3f} N"
    assert fields["scene"] == f"0 (ramp {row['scale']:.0%})"
    assert fields["last event"] == f"{controller.now():.3f} s upload: {LONG_EVENT}"  # whole


def test_a_fake_clock_drives_the_plain_view_without_waiting() -> None:
    profile = load_profile("cia402-handle")
    clock = FakeClock()
    stream = io.StringIO()
    with simulated_canopen(profile) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    origin=encoder_origin(drive))
        with LiveView([("", controller.record)], "view", controller.period, stream, duration=2.0, clock=clock) as view:
            assert view.fields()["cycles"] == "0 (not enabled yet: start-up, pre-flight)"  # no cycle recorded yet
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
                        r"position \+\d\.\d{3} mm; force [+-]\d+\.\d{3} N; scene 0; port energy [+-][0-9.e+-]+ mJ; "
                        r"late cycles 0; passivity layer lowered 0 targets", lines[0]), lines[0]
    assert lines[1].startswith("view: cycles 1500; time 1.5 s of 2.0 s (wall clock 7.5 s); remaining 0.5 s; ")


def _row(t: float, x: float, force: float, energy: float, late: bool, lateness: float, removed: float) -> tuple[float, ...]:
    """One record row (COLUMNS order) with the fields the view reads set, the rest plausible."""
    return (t, 1e9 + t, t, lateness, 0x1237, 0, 0, x, 0.0, force, 0, energy, 1, 1.0, late, 1e-6, removed)


def test_several_axes_show_each_axis_and_the_whole_port() -> None:
    records = [(name, RunRecord(100)) for name in "xyz"]
    for k in range(50):  # 50 cycles at T = 1 ms; axis i at (i + 1) mm, i N, E_i = (i + 1) mJ; y late every 10th cycle
        for i, (_, record) in enumerate(records):
            record.append(*_row(k * 1e-3, (i + 1) * 1e-3, float(i), (i + 1) * 1e-3, i == 0 and k % 10 == 0,
                                1e-4 * (k % 5), 0.5 if k == 49 else 0.0))
    clock = FakeClock()
    with LiveView(records, "3 axes", 1e-3, io.StringIO(), duration=1.0, clock=clock) as view:
        clock.now += 2.0
        fields = view.fields()
    assert fields == {
        "cycles": "50", "time": "0.0 s of 1.0 s (wall clock 2.0 s)", "remaining": "1.0 s",
        "x: position": "+1.000 mm", "x: force": "+0.000 N", "x: energy": "+1 mJ",
        "y: position": "+2.000 mm", "y: force": "+1.000 N", "y: energy": "+2 mJ",
        "z: position": "+3.000 mm", "z: force": "+2.000 N", "z: energy": "+3 mJ",
        "scene": "1", "port energy": "+6 mJ (sum over the axes)",
        "lateness p99": "400 us",  # 0..0.4 ms in equal shares: p99 by linear interpolation is 0.4 ms
        "late cycles": "5", "passivity layer": "lowered 3 targets"}  # the last cycle, on each of the 3 axes


def _terminal(columns: int, rows: int) -> tuple[int, io.TextIOWrapper]:
    """A pseudo-terminal of that size: (the reading end, the writing end as a text stream)."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))
    return master, os.fdopen(slave, "w")


def test_on_a_terminal_one_whole_panel_is_left_showing_the_end() -> None:
    columns, rows = 100, 40
    master, terminal = _terminal(columns, rows)
    shown = bytearray()
    reader = threading.Thread(target=lambda: _drain(master, shown), daemon=True)
    reader.start()
    clock = FakeClock()
    profile = load_profile("cia402-handle")
    event: dict[str, object] | None = None
    try:
        with simulated_canopen(profile) as (_, drive):
            controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                        origin=encoder_origin(drive))
            with LiveView([("", controller.record)], "panel title", controller.period, terminal, duration=1.0,
                          clock=clock, last_event=lambda: event) as view:
                for _ in range(5):
                    for _ in range(100):
                        controller.step()
                    clock.now += 1.0
                    view.update()
                event = controller.events.add(controller.now(), "upload", LONG_EVENT).to_dict()
    finally:
        terminal.close()
        reader.join(timeout=5.0)
        os.close(master)
    screen = pyte.Screen(columns, rows)
    pyte.ByteStream(screen).feed(bytes(shown))
    lines = [line.rstrip() for line in screen.display]
    tops = [i for i, line in enumerate(lines) if "panel title" in line]
    assert len(tops) == 1, "\n".join(lines)  # one panel: none stacked, none torn
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
