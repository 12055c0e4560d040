"""Issue 11, records that are always kept: ``runs/<UTC>-<profile>/`` (or ``--out``) is made and
shown writable before any bus is touched, and whatever ends the run it receives ``record.csv``,
``run.json`` and the plots; the run says where it wrote them.

The real command line runs in this process against the simulated drive on a real link (a
CANopen slave on python-can's ``virtual`` bus, or a Modbus TCP server on 127.0.0.1).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import logging
import os
import pathlib
import re
import socket
import threading
import time

import can
import pytest

import haptic_bus
from drives.safety import VIRTUAL_TIME_CANOPEN_PATIENCE
from haptic_bus.app.profiles import resolve_profile
from haptic_bus.control.record import COLUMNS
from tests.run_rig import NODE, TRANSPORTS, read_record, read_run, record_files, run_cli, simulated_drive

PNG = b"\x89PNG\r\n\x1a\n"


def test_the_default_folder_is_runs_utc_profile_and_holds_every_record(
        tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    before = dt.datetime.now(dt.UTC).replace(microsecond=0)
    with simulated_drive("canopen", "cia402-handle") as drive:
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.2", "--no-live")
    after = dt.datetime.now(dt.UTC)
    assert result.code == 0, result.err
    (folder,) = (tmp_path / "runs").iterdir()
    match = re.fullmatch(r"(\d{8}T\d{6}Z)-cia402-handle", folder.name)
    assert match is not None, folder.name
    stamp = dt.datetime.strptime(match.group(1), "%Y%m%dT%H%M%SZ").replace(tzinfo=dt.UTC)
    assert before <= stamp <= after
    relative = pathlib.Path("runs") / folder.name
    files = record_files("canopen")
    assert f"ended: completed; wrote {', '.join(str(relative / name) for name in files)}" in result.out
    for name in files:
        assert (folder / name).stat().st_size > 0, name
    assert all((folder / name).read_bytes()[:8] == PNG for name in ("timeline.png", "force_position.png", "region.png"))
    header, record = read_record(folder)
    assert tuple(header) == COLUMNS and record["time_s"].size == 200

    document = read_run(folder)
    assert document["software"]["haptic_bus"] == haptic_bus.__version__
    (counts,) = document["drive_counts"].values()  # the drive's counters: every cycle's TPDO in, none dropped or late
    assert counts["cycles"] >= 200 and counts["dropped_frames"] == counts["missed_tpdos"] == counts["stale_tpdos"] == 0
    assert {"python", "numpy", "scipy", "python-can", "canopen", "pymodbus", "matplotlib"} <= set(document["software"])
    shipped = resolve_profile("cia402-handle")
    assert document["profile"] == {"name": "cia402-handle", "path": str(shipped),
                                   "sha256": hashlib.sha256(shipped.read_bytes()).hexdigest()}
    assert document["settings"]["device"]["mass"] == 1.0 and document["settings"]["device"]["friction"] == 20.0
    # what the drive was given: virtual time lifts the profile's watchdogs (default [safety]: 30 periods, 90 ms,
    # 60 ms) to 2 s of wall clock (drives.safety.VIRTUAL_TIME_DEADLINE), 2000 periods of T = 1 ms
    assert document["settings"]["safety"] == {"heartbeat_ms": 20, "consumer_ms": 2000, "rpdo_deadline_periods": 2000,
                                              "abort_option": 1, "strict": False, "modbus_watchdog_ms": 2000}
    assert document["loop"] == {"period": 0.001, "timing": "cia402", "delay_assumed": 1, "delay_observed": 1.0}
    assert document["link"]["kind"] == "canopen" and document["link"]["node_id"] == NODE
    assert document["link"]["bus"]["interface"] == "lockstep" and document["link"]["bus"]["channel"] == drive.channel
    assert document["link"]["controller_node_id"] == 127
    # SYNC 55 + TPDO1 (6 bytes) 115 + TPDO2 (4 bytes) 95 + RPDO1 (4 bytes) 95 = 360 bit times per 1 ms at 1 Mbit/s
    assert (document["link"]["bitrate_checked"], document["link"]["bus_load"]["bits"]) == (1e6, 360)
    assert document["link"]["bus_load"]["load"] == pytest.approx(0.36, rel=1e-12)
    assert {"values", "sources"} <= set(document["scaling"])
    assert document["scaling"]["values"]["velocity_per_count"] == pytest.approx(1.1984224905356573e-07, rel=1e-15)
    (scene,) = document["scenes"]
    assert scene["scene_id"] == 0 and scene["origin"] == "profile"
    assert scene["objects"] == [{"name": "end-stop", "kind": "wall", "position": 0.003, "normal": -1, "stiffness": 1500.0,
                                 "damping": 10.0}]
    (wall,) = scene["walls"]
    assert (wall["K"], wall["B"]) == (1500.0, 10.0) and wall["margin"] == pytest.approx(11.09, abs=0.01)  # the profile's
    assert document["summary"]["exit_reason"] == document["exit_reason"] == "completed" and document["error"] is None
    assert document["summary"]["cycles"] == 200 and document["events"] == [] and document["events_dropped"] == 0
    assert document["files"] == [str(relative / name) for name in files]
    assert document["status"] == "completed" and document["ended"] is True
    assert document["gate_loop"] == {"m": 1.0, "b": 20.0, "T": 0.001, "delay": 1, "velocity": "average"}
    assert document["record"] == {"rows_written": 200, "rows_lost": 0} and document["bus_log"]["frames"] > 3 * 200
    assert dt.datetime.fromisoformat(document["started_utc"]) <= dt.datetime.fromisoformat(document["ended_utc"])


def _in_the_way(tmp_path: pathlib.Path, how: str) -> pathlib.Path:
    """An ``--out`` that cannot be written: a file in its place, a file where its parent should
    be, or a folder without write permission."""
    if how == "file":
        path = tmp_path / "out"
        path.write_text("not a folder")
        return path
    if how == "under-a-file":
        (tmp_path / "file").write_text("not a folder")
        return tmp_path / "file" / "out"
    if os.geteuid() == 0:
        pytest.skip("root writes into a read-only folder: no permission to withhold here")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    return locked / "out"


@pytest.mark.parametrize("how", ["file", "under-a-file", "read-only"])
@pytest.mark.parametrize("transport", TRANSPORTS)
def test_an_out_that_cannot_be_written_is_exit_2_before_the_bus_is_touched(
        transport: str, how: str, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _in_the_way(tmp_path, how)
    if transport == "canopen":
        with simulated_drive("canopen", "cia402-handle") as drive, \
                can.Bus(**drive.bus) as sniffer:
            result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--out", str(out))
            heard = {message.arbitration_id for message in iter(lambda: sniffer.recv(0.05), None)}
            assert heard <= {0x700 + NODE}, [hex(i) for i in heard]  # only the drive's own heartbeat
            assert drive.states == []
    else:  # a bare listening socket: whoever connects would be queued there
        with socket.create_server(("127.0.0.1", 0)) as listener:
            port = listener.getsockname()[1]
            result = run_cli(capsys, "run", "cia402-handle", "--modbus", f"tcp://127.0.0.1:{port}", "--virtual-time",
                             "--out", str(out))
            listener.setblocking(False)
            with pytest.raises(BlockingIOError):
                listener.accept()  # nobody connected
    assert result.code == 2 and result.out == ""
    (line,) = result.err_lines
    assert line.startswith(f"haptic-bus run: error: --out = '{out}' is invalid; allowed: a folder this user can create "
                           "and write (")
    assert "Traceback" not in result.err


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_drive_that_dies_mid_run_still_leaves_every_record(
        transport: str, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    # the lock-step bus serves each frame in its sender's thread: a TPDO that comes is in before the SYNC's send
    # returns, so the virtual-time master's wait for one elapses only once the drive is gone: 50 ms, not 0.5 s, each
    # of the three it misses before it names the drive error
    monkeypatch.setitem(VIRTUAL_TIME_CANOPEN_PATIENCE, "tpdo_timeout", 0.05)
    out = tmp_path / "run"
    plots = transport == "canopen"  # the pictures after a drive error once: they are drawn from the files, whatever the link
    # the simulated drive runs in this process: its own warnings (connection lost) are the rig's, not the run's output
    monkeypatch.setattr(logging.getLogger("sim_drive.modbus"), "disabled", True)
    monkeypatch.setattr(logging.getLogger("sim_drive.device"), "disabled", True)
    with simulated_drive(transport, "cia402-handle") as drive:
        def kill_after_300_cycles() -> None:
            deadline = time.monotonic() + 60.0
            while drive.drive.sync_count < 300 and time.monotonic() < deadline:
                time.sleep(0.005)
            drive.stop()  # the drive stops serving: no answer, no heartbeat (CANopen), connection gone (Modbus)

        killer = threading.Thread(target=kill_after_300_cycles, daemon=True)
        killer.start()
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "60", "--out",
                         str(out), "--no-live", *([] if plots else ["--no-plots"]))
        killer.join(timeout=10.0)
    assert result.code == 1, result.err
    (line,) = result.err_lines
    assert line.startswith("haptic-bus run: drive error: ") and "Traceback" not in result.err
    files = record_files(transport, plots)
    assert f"ended: drive error; wrote {', '.join(str(out / name) for name in files)}" in result.out
    for name in files:
        assert (out / name).stat().st_size > 0, name
    assert sorted(path.name for path in out.iterdir()) == sorted(files)
    header, record = read_record(out)
    cycles = record["time_s"].size
    # the drive took 300 SYNCs, up to ten of them before the first cycle (the enable walk's exchanges;
    # Modbus: SYNC 0 at start); every cycle the controller ran is in the record
    assert tuple(header) == COLUMNS and cycles >= 290
    document = read_run(out)
    assert document["exit_reason"] == document["summary"]["exit_reason"] == "drive error"
    assert document["summary"]["cycles"] == cycles
    fault = document["events"][-1]
    assert fault["kind"] == "fault" and fault["message"] == document["error"] == document["summary"]["error"]
    assert fault["time_s"] == pytest.approx(cycles * 1e-3, abs=1e-12)  # the run's clock when it ended
    assert line == f"haptic-bus run: drive error: {document['error']}"
    link = document["link"]  # the bus or the Modbus URL the run used
    if transport == "modbus":
        assert (link["kind"], link["url"], link["unit_id"]) == ("modbus", drive.args[1], 1)
    else:
        assert (link["kind"], link["bus"]["channel"], link["node_id"]) == ("canopen", drive.channel, NODE)
