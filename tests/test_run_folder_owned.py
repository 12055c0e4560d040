"""A run owns its folder (:mod:`haptic_bus.app.folder_lock`): a second run into the same ``--out``
is refused, exit 2, one line naming the folder and the other run's process id, before its bus or
the folder's files are touched; the lock goes with the process that held it, ``kill -9`` too.

Real components: the simulated drive in this process on a lock-step bus, the real command line,
a real run through the Python API in a thread, a real child process holding the lock.
"""

from __future__ import annotations

import json
import logging
import os
import pathlib
import signal
import subprocess
import sys
import threading

import can
import pytest

import haptic_bus as hb
from drives.canopen.drive import CanopenDrive
from haptic_bus.app.folder_lock import LOCK_NAME
from haptic_bus.app.run_folder import read_run_folder
from haptic_bus.app.run_options import StopRequest
from haptic_bus.app.run_plots import title_of
from tests.run_rig import CAN_INTERFACE, read_run, run_cli, simulated_drive, wait_until

REPO = pathlib.Path(__file__).resolve().parents[1]
MASTER_FRAMES = {0x000, 0x080, 0x605, 0x77F}  # NMT, SYNC, SDO to node 5, the controller node's heartbeat
HOLD_LOCK = ("import pathlib, sys; from haptic_bus.app.folder_lock import own_folder; "
             "lock = own_folder(pathlib.Path(sys.argv[1])); print('locked', flush=True); sys.stdin.read()")


def settled_names(folder: pathlib.Path) -> list[str]:
    """The folder's file names, less the temporary of an atomic ``run.json`` write the running
    run may be making at that instant (:func:`haptic_bus.app.run_json.write_json`)."""
    return sorted(p.name for p in folder.iterdir() if not (p.name.startswith(".") and p.name.endswith(".tmp")))


def refused_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_a_second_run_into_a_running_runs_folder_is_refused_before_its_bus(tmp_path: pathlib.Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "shared"
    with simulated_drive("canopen", "cia402-handle") as first, simulated_drive("canopen", "cia402-handle") as second:
        stop = StopRequest()
        options = hb.RunOptions(duration=60.0, pacing="virtual", out_dir=folder, live=False, stop=stop, plots=False)
        results: list[hb.RunResult] = []
        profile = hb.load_profile("cia402-handle")
        running = threading.Thread(target=lambda: results.append(hb.run(profile, first.bus, options, node_id=5)), daemon=True)
        running.start()
        try:
            assert wait_until(lambda: first.was_enabled, 30.0)  # the first run is cycling
            names, started = settled_names(folder), read_run(folder)["started_utc"]
            with can.Bus(interface=CAN_INTERFACE, channel=second.channel) as sniffer:
                result = run_cli(capsys, "run", "cia402-handle", *second.args, "--virtual-time", "--duration", "0.2",
                                 "-q", "--no-plots", "--out", str(folder))
                sent = [m.arbitration_id for m in (sniffer.recv(0.0) for _ in range(10_000)) if m is not None]
            assert not set(sent) & MASTER_FRAMES, sent  # the second drive's bus: its own heartbeats, nothing of a master
            assert second.states == []
            assert settled_names(folder) == names and read_run(folder)["started_utc"] == started
        finally:
            stop.event.set()
            running.join(30.0)
    assert result.code == 2 and result.out == ""
    line = refused_line(result.err)
    assert line.startswith(f"haptic-bus run: error: --out = '{folder}' is invalid; allowed: a folder no other run")
    assert f"the run of process {os.getpid()} holds {folder / LOCK_NAME}" in line
    (done,) = results
    assert done.exit_reason == "stopped" and read_run(folder)["status"] == "stopped"


def test_the_lock_goes_with_a_killed_process(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(folder)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        with simulated_drive("canopen", "cia402-handle") as drive:
            refused = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.1", "-q",
                              "--no-plots", "--out", str(folder))
            assert drive.states == [] and sorted(p.name for p in folder.iterdir()) == [LOCK_NAME]
            holder.send_signal(signal.SIGKILL)
            holder.wait(10.0)
            ran = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.1", "-q",
                          "--no-plots", "--out", str(folder))
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.wait(10.0)
        if holder.stdout is not None:
            holder.stdout.close()
        if holder.stdin is not None:
            holder.stdin.close()
    assert refused.code == 2
    assert f"the run of process {holder.pid} holds" in refused_line(refused.err)
    assert ran.code == 0, ran.err
    assert read_run(folder)["status"] == "completed"
    assert not (folder / LOCK_NAME).exists()  # the killed holder's file, taken over and removed by the run that ended


def test_plot_of_a_folder_a_run_still_writes_is_refused_there_and_says_so_elsewhere(tmp_path: pathlib.Path,
                                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``haptic-bus plot`` of a folder a live run holds drew its pictures into it (the run's own replaced them
    at its end) and called the run "killed or crashed" (break18).  Into that folder: refused as a second run
    is; elsewhere (``--out``): drawn, the note naming the run still writing it; once that run is gone
    (``kill -9``): "did not end cleanly", as before."""
    folder = tmp_path / "live"
    assert run_cli(capsys, "demo", "--duration", "0.1", "--no-plots", "--out", str(folder)).code == 0
    document = json.loads((folder / "run.json").read_text())
    (folder / "run.json").write_text(json.dumps({**document, "status": "running", "ended": False}))  # as while it runs
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(folder)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        into = run_cli(capsys, "plot", str(folder))
        drawn_into = sorted(p.name for p in folder.glob("*.png"))
        elsewhere = run_cli(capsys, "plot", str(folder), "--out", str(tmp_path / "snapshot"))
        live_title = title_of(read_run_folder(folder), "timeline")  # the snapshot's timeline.png said killed or crashed
        holder.send_signal(signal.SIGKILL)
        holder.wait(10.0)
        after = run_cli(capsys, "plot", str(folder))
        killed_title = title_of(read_run_folder(folder), "timeline")
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.wait(10.0)
        for stream in (holder.stdout, holder.stdin):
            if stream is not None:
                stream.close()
    assert into.code == 2 and f"the run of process {holder.pid} holds" in refused_line(into.err) and drawn_into == []
    assert elsewhere.code == 0, elsewhere.err
    assert elsewhere.out.splitlines()[0] == f"note: {folder}: the run of process {holder.pid} is still writing it; so far " \
                                            "record.csv holds 100 cycles"
    assert (tmp_path / "snapshot" / "timeline.png").is_file()
    assert (" ".join(live_title[0].split()), live_title[1]) == (
        f"cia402-handle: timeline; still running (process {holder.pid}): drawn from the cycles written so far", "tab:red")
    assert killed_title[0].startswith("cia402-handle: timeline; did NOT end cleanly") and killed_title[1] == "tab:red"
    assert after.code == 0 and "the run did not end cleanly" in after.out.splitlines()[0]
    assert (folder / "timeline.png").is_file() and not (folder / LOCK_NAME).exists()


def test_a_run_into_an_earlier_runs_folder_replaces_that_run_and_keeps_the_users_files(
        tmp_path: pathlib.Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    """A folder given again held the earlier run's record.csv and pictures beside the new run.json
    (``plot`` then drew the old record under the new run's end).  The new run clears what a run
    writes, before its bus, and says so in one warning; other files stay.  Nobody answers on the bus:
    the master's three waits for a drive (its statusword, the boot-up, an SDO probe) take 0.1 s each, not
    the default 1 s, the run ending as it does at any length of them."""
    monkeypatch.setitem(CanopenDrive.__init__.__kwdefaults__, "boot_timeout", 0.1)
    caplog.set_level(logging.WARNING, logger="haptic_bus.app.run_folder")  # whatever an earlier CLI test set the root to
    folder = tmp_path / "run"
    folder.mkdir()
    earlier = ["record.csv", "record-x.csv", "bus.asc", "timeline.png", "region.png", "validate.json"]
    for name in [*earlier, "notes.txt", "mine.png", "record-mine.csv"]:  # record-mine.csv: no axis of that run
        (folder / name).write_text("an earlier run's\n")
    (folder / "run.json").write_text(json.dumps({"settings": {"axes": [{"name": "x"}]}}))
    options = hb.RunOptions(0.01, pacing="virtual", out_dir=folder, live=False, plots=False)
    result = hb.run(hb.load_profile("cia402-handle"), {"interface": CAN_INTERFACE, "channel": f"nobody-{tmp_path.name}"},
                    options, node_id=5)  # nobody answers: the run ends at commissioning, having written run.json
    assert result.exit_reason == "drive error"
    left = sorted(path.name for path in folder.iterdir() if not path.name.startswith("."))
    assert left == ["bus.asc", "mine.png", "notes.txt", "record-mine.csv", "run.json"]  # bus.asc and run.json: this run's
    assert read_run(folder)["exit_reason"] == "drive error" and "an earlier run's" not in (folder / "bus.asc").read_text()
    assert (folder / "notes.txt").read_text() == (folder / "mine.png").read_text() == "an earlier run's\n"
    (said,) = [r.getMessage() for r in caplog.records if r.name == "haptic_bus.app.run_folder"]
    assert said == (f"run folder {folder}: this run replaces the earlier run's run.json, record.csv, bus.asc, "
                    "timeline.png, region.png, validate.json, record-x.csv")
