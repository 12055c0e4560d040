"""A user's misuse of the public API and the pytest plugin (found by a user-level break round, break17):
each refused before anything is touched, in one line naming the thing and what it takes, or handled."""
from __future__ import annotations

import dataclasses
import logging
import math
import pathlib
import re
from collections.abc import Callable
from typing import Any

import can
import pytest

import haptic_bus as hb
from drives.canopen.link import ReceiveErrors
from haptic_bus.app.profiles import read_profile
from haptic_bus.profile.files import resolve_profile


def test_a_shut_down_bus_is_refused_before_any_file(tmp_path: pathlib.Path) -> None:
    """hb.run on a can.BusABC the caller already shut down: one ParameterError naming the bus, no run
    folder (it was a flood of receive errors on stderr, then python-can's CanOperationError raw and a
    run.json saying "crashed")."""
    bus = can.Bus(interface="virtual", channel="break17-closed")
    bus.shutdown()
    out = tmp_path / "run"
    with pytest.raises(hb.ParameterError, match=r"^run: bus = .* is invalid; allowed: an open can.BusABC "
                                                r"\(this one is shut down\)$"):
        hb.run(hb.load_profile("cia402-handle"), bus, hb.RunOptions(duration=0.1, pacing="virtual", out_dir=out),
               node_id=5)
    assert not out.exists()


@pytest.mark.parametrize(("name", "change", "field"), [
    ("cia402-handle", lambda p: dataclasses.replace(p, force_limit=-5.0), "limits.force_limit = -5.0"),
    ("cia402-handle", lambda p: dataclasses.replace(p, force_limit=math.nan), "limits.force_limit = nan"),
    ("cia402-handle", lambda p: dataclasses.replace(p, force_limit=1e5), "limits.force_limit = 100000.0"),
    ("gantry-3d", lambda p: dataclasses.replace(p, axes=(dataclasses.replace(p.axes[0], force_limit=-1.0), *p.axes[1:])),
     "axes[0].force_limit = -1.0"),
])
def test_a_force_limit_a_program_set_is_checked_before_any_file(tmp_path: pathlib.Path, name: str,
                                                                 change: Any, field: str) -> None:
    """A profile a program built (``dataclasses.replace``) skipped the reader's checks: a negative force limit
    was refused only after commissioning, naming the drive's ``torque_limit = -312``, its run.json "crashed".
    Now one ParameterError naming the field and the range, before any folder or bus."""
    out = tmp_path / "run"
    profile = change(read_profile(resolve_profile(name)))  # read, not judged: the gate is not what is tested
    with pytest.raises(hb.ParameterError, match=rf"^run: {re.escape(field)} is invalid; allowed: "):
        hb.run(profile, {"interface": "virtual", "channel": f"force-limit-{tmp_path.name}"},
               hb.RunOptions(duration=0.1, pacing="virtual", out_dir=out), **({"node_id": 5} if name != "gantry-3d" else {}))
    assert not out.exists()


def test_a_run_folder_refused_from_python_names_out_dir(tmp_path: pathlib.Path) -> None:
    """From Python the run folder is ``RunOptions.out_dir``, and its refusal says so (it named the command
    line's ``--out``, which a program never typed); the command line still says ``--out``."""
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    with pytest.raises(hb.ParameterError, match=r"^run: out_dir = '.*a-file/out' is invalid; allowed: a folder "):
        hb.run(hb.load_profile("cia402-handle"), {"interface": "virtual", "channel": f"out-dir-{tmp_path.name}"},
               hb.RunOptions(duration=0.1, pacing="virtual", out_dir=blocked / "out"), node_id=5)


def test_receive_errors_are_all_counted_but_logged_by_decades(caplog: pytest.LogCaptureFixture) -> None:
    """A notifier whose bus fails every receive: the first error kept, every one counted, the log
    lines at the 1st, 10th and 100th error, not one per error."""
    listener = ReceiveErrors("node 5")
    errors = [can.CanOperationError(f"closed {i}") for i in range(150)]
    with caplog.at_level(logging.WARNING, logger="drives.canopen.link"):
        for error in errors:
            listener.on_error(error)
    assert listener.count == 150
    assert listener.error is errors[0]
    lines = [record.getMessage() for record in caplog.records]
    assert lines == ["node 5: CAN receive failed: CanOperationError('closed 0')",
                     "node 5: CAN receive failed: CanOperationError('closed 9') (10 receive errors so far)",
                     "node 5: CAN receive failed: CanOperationError('closed 99') (100 receive errors so far)"]


@pytest.mark.parametrize("argument", [5, None, b"cia402-handle", ["cia402-handle"]])
def test_load_profile_refuses_what_is_neither_a_name_nor_a_path(argument: object) -> None:
    """hb.load_profile(5) was pathlib's TypeError; the docs promise a ParameterError naming the field (None: the
    field is missing, ParameterError's rule for a value not given)."""
    said = "is missing" if argument is None else "= .* is invalid"
    where = "" if argument is None else "profile .*: "  # None: no 'profile None:' before it (break17b)
    with pytest.raises(hb.ParameterError, match=rf"^{where}profile {said}; allowed: a shipped profile "
                                                r"name or a TOML file's path \(str or pathlib.Path\)$"):
        hb.load_profile(argument)  # type: ignore[arg-type]  # what a user may pass


def test_haptic_controller_refuses_a_one_axis_drive_for_gantry(haptic_sim: Any, haptic_controller: Any) -> None:
    """A user's test gives haptic_controller the 3-axis gantry-3d against a one-axis simulated drive: a
    ParameterError naming the profile and the axes, where hb.run's refusal named a ``node_id = 5`` the
    test never gave."""
    from haptic_bus.app.profiles import read_profile

    drive = haptic_sim("cia402-handle")
    with pytest.raises(hb.ParameterError) as error:  # read, not judged: the coupled gate on a sphere takes a second
        haptic_controller(read_profile("gantry-3d"), drive)
    assert str(error.value) == ("haptic_controller: profile = 'gantry-3d' is invalid; allowed: a one-axis "
                                "profile, as the simulated drive has (this one has 3 axes)")


def test_haptic_controller_refuses_a_one_axis_profile_for_three_drives(haptic_sim: Any,
                                                                       haptic_controller: Any) -> None:
    """The reverse: a one-axis profile against the simulated gantry's three drives."""
    drive = haptic_sim("gantry-3d", interface="lockstep")
    with pytest.raises(hb.ParameterError) as error:
        haptic_controller("cia402-handle", drive)
    assert str(error.value) == ("haptic_controller: profile = 'cia402-handle' is invalid; allowed: a profile "
                                "of 3 [[axes]], as the simulated drive has (this one has 1 axes)")


def test_identify_says_a_profile_it_cannot_write_in_one_line(haptic_sim: Any, tmp_path: pathlib.Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``identify --write-profile /proc/x.toml`` (a folder that os.access calls writable for root, or one
    gone during the run): the estimates printed, one line naming the file and why, exit 1; it was
    FileNotFoundError's traceback after the whole measurement, the estimates never printed."""
    folder = tmp_path / "gone"
    folder.mkdir()
    target = folder / "identified.toml"
    status, out, err = _identify_while(haptic_sim, target, folder.rmdir, capsys)  # the folder went while it measured
    assert status == 1
    assert "mass m" in out and "verdict: supported" in out
    assert err == (f"haptic-bus identify: write error: --write-profile {target}: No such file or directory; "
                   "nothing written, the estimates are the ones above\n")
    assert not target.exists()


def test_identify_leaves_a_profile_that_appeared_while_it_measured(haptic_sim: Any, tmp_path: pathlib.Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``--write-profile FILE`` (no file there when identify started, no --force) and a file made there by
    another program during the measurement: it was overwritten silently (exit 0); it is now left as it
    was (an exclusive create), the estimates printed, one line naming the file, exit 1."""
    target = tmp_path / "identified.toml"
    status, out, err = _identify_while(haptic_sim, target, lambda: target.write_text("# someone else's\n"), capsys)
    assert status == 1
    assert "mass m" in out and "verdict: supported" in out and "wrote" not in out
    assert err == (f"haptic-bus identify: write error: --write-profile {target}: a file appeared there during the "
                   "measurement (--force replaces one); nothing written, the estimates are the ones above\n")
    assert target.read_text() == "# someone else's\n"
    status, out, err = _identify_while(haptic_sim, target, lambda: None, capsys, "--force")  # asked: replaced
    assert status == 0 and f"wrote {target}" in out and err == ""
    assert "[identification]" in target.read_text()


def _identify_while(haptic_sim: Any, target: pathlib.Path, meanwhile: Callable[[], object],
                    capsys: pytest.CaptureFixture[str], *options: str) -> tuple[int, str, str]:
    """``identify --write-profile target [options]`` against a simulated drive, ``meanwhile`` done after the
    command's checks and the measurement, just before the profile is written; (exit status, stdout, stderr)."""
    from haptic_bus.app import identify_profile
    from haptic_bus.app.cli import main

    drive = haptic_sim("cia402-handle", operator={"model": "none"})
    made = identify_profile.identified_profile

    def measured_then(*args: Any) -> str:
        meanwhile()
        return made(*args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(identify_profile, "identified_profile", measured_then)
        status = main(["identify", "--profile", "cia402-handle", *drive.run_args(), "--virtual-time",
                       "--duration", "1", "--write-profile", str(target), *options])
    out, err = capsys.readouterr()
    return status, out, err


def test_a_modbus_stall_names_a_drive_that_kept_the_cycle_waiting_too() -> None:
    """A Modbus server stopped with SIGSTOP for 1 s during a real-time gantry-3d run: the request waited 402 ms,
    the drive's 60 ms watchdog faulted it, and the run's line said only "this process did not run for that
    long".  Over Modbus a cycle can wait that long for an answer, so the line names both; on CANopen (whose
    TPDO wait is at most half the stall) it stays as it was."""
    import types

    import numpy as np

    from haptic_bus.app.runner import _stall_before
    from haptic_bus.control.clock import RealClock

    class HeldClock(RealClock):
        def lateness(self, last: int | None = None) -> np.ndarray:
            return np.array([0.0, 0.4019, 0.0])

    controller: Any = types.SimpleNamespace(clock=HeldClock(2e-3), error_cycle_s=0.0)
    assert _stall_before(controller, 0.06, answers_wait=True) == (
        " (a cycle just before was held 401.9 ms late, past the 60 ms the drive's watchdog allows: this process did "
        "not run for that long, stopped or starved of CPU, or it waited that long for a drive's answer (a drive or "
        "server that stalled))")
    assert _stall_before(controller, 0.06) == (
        " (a cycle just before was held 401.9 ms late, past the 60 ms the drive's watchdog allows: this process did "
        "not run for that long, stopped or starved of CPU)")
    assert _stall_before(controller, 0.5, answers_wait=True) == ""


def test_recorded_run_names_a_folder_that_is_no_run(recorded_run: Any, tmp_path: pathlib.Path) -> None:
    """recorded_run(folder) of an empty or missing folder: a ParameterError naming the folder and what it
    takes; it was FileNotFoundError naming ``run.json``."""
    for folder in (tmp_path, tmp_path / "nope"):
        with pytest.raises(hb.ParameterError) as error:
            recorded_run(folder)
        assert str(error.value) == (f"recorded_run: folder = '{folder}' is invalid; allowed: a run folder, one "
                                    "holding run.json (haptic-bus run --out, haptic-bus demo, hb.run's folder)")


def test_a_simulated_drive_the_test_killed_is_no_teardown_failure(haptic_sim: Any) -> None:
    """A test that kills its udp_multicast drive on purpose (``drive.process.stop(signal.SIGKILL)``, a drive
    dying mid-run) got teardown's "did not exit cleanly on SIGTERM (status -9)" though teardown sent no
    SIGTERM; one that exits on its own still fails the test, saying it had exited before teardown."""
    import signal

    from haptic_bus.testing import _stop_cleanly

    killed = haptic_sim("cia402-handle", interface="udp_multicast")
    status, _ = killed.process.stop(signal.SIGKILL)
    assert status == -signal.SIGKILL
    _stop_cleanly(killed)  # the test's own stop: no failure

    crashed = haptic_sim("cia402-handle", interface="udp_multicast")
    crashed.process.process.kill()  # as if it died on its own: not through its stop()
    crashed.process.process.wait(10)
    with pytest.raises(AssertionError, match=r"^simulated drive node 5 had exited before the test's teardown "
                                             r"\(status -9; a test that ends it on purpose: "
                                             r"drive.process.stop\(signal.SIGKILL\)\): "):
        _stop_cleanly(crashed)


def test_run_refuses_a_start_from_a_spawned_processes_import(tmp_path: pathlib.Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """A script without ``if __name__ == "__main__":`` whose top level catches hb.run's errors: the spawned
    worker ran that top level again, and its hb.run wrote a second run folder, "crashed" with
    multiprocessing's RuntimeError, beside the real run.  hb.run now refuses first, as multiprocessing
    refuses to start a process there, naming the idiom; no folder."""
    import multiprocessing

    monkeypatch.setattr(multiprocessing.current_process(), "_inheriting", True, raising=False)
    out = tmp_path / "run"
    with pytest.raises(hb.HapticBusError, match=r"^hb.run was called while a process of a run started .*"
                                                r"if __name__ == '__main__':"):
        hb.run(hb.load_profile("cia402-handle"), {"interface": "virtual", "channel": "break17-spawned"},
               hb.RunOptions(duration=0.1, pacing="virtual", out_dir=out), node_id=5)
    assert not out.exists()


@pytest.mark.parametrize(("given", "line"), [
    ({"timing": "fast"}, "simulated drive: timing = 'fast' is invalid; allowed: one of 'ideal', 'cia402', 'reception', "
                         "or None (the profile's)"),
    ({"operator": "constant:3"}, "simulated drive: operator = 'constant:3' is invalid; allowed: a mapping, the "
                                 "profile's [operator_model] table, e.g. {'model': 'constant', 'level': 3.0}"),
    ({"interface": "modbus", "unit_id": 0}, "simulated drive: unit_id = 0 is invalid; allowed: Modbus unit ids 1..247"),
    ({"interface": "modbus", "unit_id": 300}, "simulated drive: unit_id = 300 is invalid; allowed: Modbus unit ids 1..247"),
    ({"interface": "modbus", "unit_id": True}, "simulated drive: unit_id = True is invalid; allowed: Modbus unit ids 1..247"),
])
def test_haptic_sim_names_a_bad_timing_operator_or_unit(haptic_sim: Any, given: dict[str, Any], line: str) -> None:
    """haptic_sim's timing and operator were the simulator's ValueError and dict()'s TypeError-like ValueError,
    and a unit id took the server's 0..255 (with no context) where hb.run and haptic-bus sim take 1..247."""
    with pytest.raises(hb.ParameterError) as error:
        haptic_sim("cia402-handle", **given)
    assert str(error.value) == line


def test_runs_started_in_one_second_get_folders_of_their_own(tmp_path: pathlib.Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Two hb.run calls in two threads at once, no out_dir: both named runs/<UTC>-cia402-handle (each found it
    free), and one was refused with "--out ... a folder this user can create and write (No such file or
    directory)".  The folder is now claimed by creating it; a name another run took in the meantime (exists()
    said free) moves on to -2."""
    from haptic_bus.app import run_folder

    monkeypatch.setattr(run_folder, "_utc_now", lambda: run_folder.dt.datetime(2026, 12, 7, 20, 43, 41,
                                                                              tzinfo=run_folder.dt.UTC))
    first = run_folder.prepare_run_folder(None, "cia402-handle", root=tmp_path)
    monkeypatch.setattr(pathlib.Path, "exists", lambda self: False)  # the other run made it after we looked
    second = run_folder.prepare_run_folder(None, "cia402-handle", root=tmp_path)
    assert (first.name, second.name) == ("20261207T204341Z-cia402-handle", "20261207T204341Z-cia402-handle-2")


def test_folders_probed_at_once_are_all_writable(tmp_path: pathlib.Path) -> None:
    """writable_folder's probe file had one name for everyone: two commands probing one folder at once unlinked
    each other's, and one was refused 'No such file or directory'.  Two threads, 300 probes each."""
    import threading

    from haptic_bus.validation import writable_folder

    failures: list[BaseException] = []

    def probe() -> None:
        try:
            for _ in range(300):
                writable_folder("--out", tmp_path)
        except BaseException as error:  # what the other thread must see
            failures.append(error)

    threads = [threading.Thread(target=probe) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert failures == []
    assert list(tmp_path.iterdir()) == []


def test_the_trajectory_legend_leaves_the_section_label_readable() -> None:
    """trajectory.png of a run that moved along one axis (a short, wide equal-aspect section): the legend
    (handle, start, end) sat on the section's x-axis label.  Laid out as trajectory_figure lays it out, the two
    no longer overlap."""
    import matplotlib.pyplot as plt
    import numpy as np

    from haptic_bus.app.trajectory_plot import _draw_sections

    t = np.linspace(0.0, 1.0, 200)
    x = np.column_stack([np.zeros_like(t), -0.022 * (1 - np.exp(-5 * t)), np.zeros_like(t)])  # y alone moves
    fig = plt.figure(figsize=(13, 6.2))
    try:
        grid = fig.add_gridspec(2, 2, width_ratios=(1.1, 1))
        section = fig.add_subplot(grid[:, 0])
        _draw_sections(section, ["x", "y", "z"], [], x)
        fig.add_subplot(grid[0, 1]).plot(t, t)
        fig.add_subplot(grid[1, 1]).plot(t, t)
        fig.tight_layout()
        fig.canvas.draw()  # where each artist lands (the legend's box before a draw is not where it is drawn)
        renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]  # Agg's
        legend, label = section.get_legend(), section.xaxis.label
        assert legend is not None
        legend_box, label_box = legend.get_window_extent(renderer), label.get_window_extent(renderer)
        assert not legend_box.overlaps(label_box), (legend_box, label_box)
        assert legend_box.y1 < label_box.y0  # below it
    finally:
        plt.close(fig)


def test_a_controller_wait_that_bounds_nothing_is_refused(haptic_sim: Any, haptic_controller: Any) -> None:
    """run.wait(timeout=-1) returned at once and failed the test "did not end within -1 s of wall clock"; a
    timeout that bounds no wait is one line naming it, the run left to its own end."""
    run = haptic_controller("cia402-handle", haptic_sim("cia402-handle"), duration=0.05)
    for timeout in (-1, 0, float("nan"), float("inf"), "10", 1e6):
        for wait in (run.wait, run.stop, run.wait_cycling):
            with pytest.raises(hb.ParameterError, match=r"^haptic_controller run: timeout = .* is invalid; allowed: "
                                                        r"a finite real in \(0, 86400\] s$"):  # validation's words
                wait(timeout=timeout)
    assert run.wait().exit_reason == "completed"


def test_options_that_stopped_a_run_run_again(haptic_sim: Any, tmp_path: pathlib.Path) -> None:
    """The same hb.RunOptions for a second run after a stop ended the first: the second ended "stopped" before
    its first cycle, nothing said, because the first run's stop request was still set."""
    import threading
    import time

    drive = haptic_sim("cia402-handle", operator={"model": "none"})  # nobody pushes it into the wall between runs
    options = hb.RunOptions(duration=1000.0, pacing="virtual", plots=False, live=False, out_dir=tmp_path / "a")
    profile = hb.load_profile("cia402-handle")
    def stop_once_cycling() -> None:  # bounded: 30 s of wall clock, then stopped anyway
        deadline = time.monotonic() + 30
        while drive.sim.drive.sync_count < 200 and time.monotonic() < deadline:
            time.sleep(0.01)
        options.stop.event.set()

    stopper = threading.Thread(target=stop_once_cycling)
    stopper.start()
    first = hb.run(profile, drive.bus, options, **drive.run_kwargs())
    stopper.join(30)
    assert first.exit_reason == "stopped" and first.summary is not None and first.summary.cycles > 0
    again = dataclasses.replace(options, duration=0.05, out_dir=tmp_path / "b")
    second = hb.run(profile, drive.bus, again, **drive.run_kwargs())
    assert second.exit_reason == "completed"
    assert second.summary is not None and second.summary.cycles == 50


def test_a_program_without_logging_sees_the_libraries_lines_not_ours() -> None:
    """docs/errors.md, "Log lines beside the errors": in a program that configures no logging a bus library's
    ERROR (canopen's SDO abort) reaches stderr through logging.lastResort, Python's rule, and the one line
    the page gives silences it; the records of our three packages (haptic_bus, drives, sim_drive) do not (a
    NullHandler on each top-level logger, the logging HOWTO's rule for a library), and propagate to a
    program's handler as before."""
    import importlib
    import subprocess
    import sys

    ours = ("haptic_bus.control.controller", "drives.canopen.drive", "sim_drive.device")
    program = "\n".join([
        "import logging, haptic_bus, drives, sim_drive",
        *(f"logging.getLogger({name!r}).warning('unconfigured')" for name in ours),
        "logging.getLogger('canopen.sdo.client').error('Transfer aborted by client with code 0x05040000')",
        "logging.getLogger('canopen').setLevel(logging.CRITICAL)",
        "logging.getLogger('canopen.sdo.client').error('silenced')",
        "logging.basicConfig(format='%(name)s: %(message)s')",
        *(f"logging.getLogger({name!r}).warning('configured')" for name in ours)])
    tree = pathlib.Path(__file__).resolve().parents[1]  # this tree's packages, not installed ones
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120, cwd=tree)
    assert done.returncode == 0 and done.stdout == ""
    assert done.stderr == "Transfer aborted by client with code 0x05040000\n" + "".join(
        f"{name}: configured\n" for name in ours), done.stderr
    for package in ("haptic_bus", "drives", "sim_drive"):
        importlib.import_module(package)
        assert any(isinstance(h, logging.NullHandler) for h in logging.getLogger(package).handlers), package
