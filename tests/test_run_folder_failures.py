"""A run whose folder cannot be written any more -- deleted while the run goes on, or a full disk --
stops at the next cycle boundary with its drive disabled, says why in one line ("write error",
exit 1, naming the folder, the file and the system's reason), and keeps what was written before;
a disk already full when the run begins is its ``--out`` refused, exit 2, before the bus.

Both writers are exercised: a CANopen run on the lock-step bus writes from a thread of its own
process, a Modbus run (loopback TCP) from a writer process.  The full disk is a real one: a 256 KiB
tmpfs mounted in a private mount namespace (``unshare -m``, as root or with user namespaces) for
a child process that runs the real command line against the simulated drive.  Where no such
mount can be made the test is skipped, saying so: a file size limit (``RLIMIT_FSIZE``) is no
stand-in, since it also caps the run's shared-memory rings (``ftruncate`` of a segment larger than
the limit fails before the run starts).
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess
import sys
import threading
from typing import Any

import pytest

from drives.cia402 import State
from haptic_bus.app.folder_lock import LOCK_NAME
from tests.run_rig import TRANSPORTS, run_cli, simulated_drive, wait_until

REPO = pathlib.Path(__file__).resolve().parents[1]
TMPFS_BYTES = 256 * 1024  # a record of about 1000 cycles at most (about 250 bytes a row): full long before 60 s
CHILD_WAIT = 120.0  # s: the child imports the stack, fills the disk and stops (a few s idle)

CHILD = """
import contextlib, io, json, os, sys
from haptic_bus.app.cli import main
from haptic_bus.control.record import read_record
from tests.run_rig import simulated_drive

transport = sys.argv[1]
for out, full in zip(sys.argv[2::2], (mode == "full" for mode in sys.argv[3::2])):  # each run on a disk of its own
    if full:  # the disk full before the run: one file takes every block there is
        with open(f"{out}-filler", "wb", buffering=0) as filler:
            try:
                for _ in range(1000):
                    filler.write(bytes(4096))
            except OSError:
                pass
    stdout, stderr = io.StringIO(), io.StringIO()
    with simulated_drive(transport, "cia402-handle") as drive:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            code = main(["run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "60", "--no-live", "--no-plots",
                         "--out", out])
        states = [state.name for state in drive.states]
    kept = {"rows": read_record(f"{out}/record.csv").cycles, "status": json.load(open(f"{out}/run.json"))["status"]} \
        if not full else {"files": sorted(os.listdir(out))}
    print(json.dumps({"code": code, "out": stdout.getvalue(), "err": stderr.getvalue(), "states": states, "kept": kept}))
"""


def can_mount_tmpfs() -> bool:
    """Whether ``unshare -m`` gives this user a mount namespace where a tmpfs can be mounted."""
    if shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                           capture_output=True, timeout=30)
    if probe.returncode == 0:
        return True
    return subprocess.run(["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
                          capture_output=True, timeout=30).returncode == 0


def one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def on_small_disks(folder: pathlib.Path, transport: str, *fulls: bool) -> list[tuple[pathlib.Path, dict[str, Any]]]:
    """One child's 60 s runs, one after another, each into ``--out`` on a fresh 256 KiB tmpfs of its own
    (``full``: filled first): each run's folder, and what the child reports for it (exit status, stdout,
    stderr, the drive's states, what was kept).  One child for several runs: its interpreter's start and
    the stack's imports (0.6 s of CPU) once."""
    if not can_mount_tmpfs():
        pytest.skip("no tmpfs can be mounted here (unshare -m / -rm refused): no full disk to run into")
    mounts = [folder / f"small{k}" for k in range(len(fulls))]
    runs: list[str] = []
    for mount, full in zip(mounts, fulls):
        mount.mkdir()
        runs += [str(mount / "run"), "full" if full else "empty"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = [sys.executable, "-c", CHILD, transport, *runs]
    unshare = ["unshare", "-m"] if os.geteuid() == 0 else ["unshare", "-rm"]
    script = (f'n=$1; shift; while [ "$n" -gt 0 ]; do mount -t tmpfs -o size={TMPFS_BYTES} tmpfs "$1" || exit 1; '
              'shift; n=$((n - 1)); done; exec "$@"')
    done = subprocess.run([*unshare, "sh", "-c", script, "sh", str(len(mounts)), *map(str, mounts), *child],
                          capture_output=True, text=True, env=env, cwd=REPO, timeout=CHILD_WAIT * len(fulls))
    assert done.returncode == 0, done.stderr[-3000:]
    reports = done.stdout.splitlines()[-len(fulls):]
    return [(mount / "run", json.loads(report)) for mount, report in zip(mounts, reports)]


@pytest.fixture(scope="module")
def canopen_disks(tmp_path_factory: pytest.TempPathFactory) -> dict[bool, tuple[pathlib.Path, dict[str, Any]]]:
    """The CANopen runs on a disk that fills (False) and on one full before the run (True), in one child."""
    return dict(zip((False, True), on_small_disks(tmp_path_factory.mktemp("disks"), "canopen", False, True)))


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_full_disk_stops_the_run_with_one_line_and_keeps_the_record(transport: str, tmp_path: pathlib.Path,
                                                                      request: pytest.FixtureRequest) -> None:
    if transport == "canopen":
        out, result = request.getfixturevalue("canopen_disks")[False]
    else:
        ((out, result),) = on_small_disks(tmp_path, transport, False)
    assert result["code"] == 1, result
    line = one_line(result["err"])
    assert line.startswith(f"haptic-bus run: write error: run folder {out}: No space left on device writing "), line
    assert "; the run stopped after " in line and "every drive disabled; the folder keeps what was written before" in line
    assert f"ended: write error; wrote {out / 'record.csv'}, " in result["out"]
    assert result["states"][-1] == "SWITCH_ON_DISABLED" and "OPERATION_ENABLED" in result["states"]
    cycles = int(line.split("the run stopped after ")[1].split(" cycles")[0])
    kept = result["kept"]
    assert kept["status"] == "running"  # run.json's last whole version, from before the disk was full
    # the run's files filled the disk: a cycle writes under 450 bytes (a record row, 17 numbers' repr, about
    # 180 bytes; on CANopen bus.asc's SYNC, TPDOs and RPDO, about 60 bytes a line), so 256 KiB less run.json's
    # few KiB held more than 500 rows, each a cycle the run made; and the run stopped long before its 60 s
    assert 500 < kept["rows"] <= cycles < 60_000, (kept, cycles)


def test_a_disk_full_before_the_run_is_exit_2_before_the_bus(
        canopen_disks: dict[bool, tuple[pathlib.Path, dict[str, Any]]]) -> None:
    out, result = canopen_disks[True]
    assert result["code"] == 2 and result["out"] == "" and result["states"] == [], result  # the drive never reached
    line = one_line(result["err"])
    assert line == (f"haptic-bus run: error: --out = '{out}' is invalid; allowed: a folder this run can write "
                    f"({out / LOCK_NAME}: No space left on device)")
    assert result["kept"] == {"files": []}  # nothing left behind, not even the lock file


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_folder_deleted_while_the_run_goes_on_stops_it_with_one_line(transport: str, tmp_path: pathlib.Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    with simulated_drive(transport, "cia402-handle") as drive:
        def delete_once_cycling() -> None:
            if wait_until(lambda: drive.was_enabled and drive.drive.sync_count > 200, 30.0):
                gone = out.rename(tmp_path / "gone")  # at once: an rmtree of the live folder races the writer's next file
                shutil.rmtree(gone)

        deleter = threading.Thread(target=delete_once_cycling, daemon=True)
        deleter.start()
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "60", "--no-live",
                         "--no-plots", "--out", str(out))
        deleter.join(35.0)
        assert drive.states[-1] is State.SWITCH_ON_DISABLED and State.OPERATION_ENABLED in drive.states
    assert result.code == 1, result.err
    line = one_line(result.err)
    assert line.startswith(f"haptic-bus run: write error: run folder {out}: deleted or replaced while the run wrote it; "
                           "the run stopped after "), line
    assert line.endswith("every drive disabled; the folder keeps what was written before")
    assert "ended: write error; wrote \n" in result.out or result.out.rstrip().endswith("ended: write error; wrote")
    assert not out.exists()  # nothing made again: the user deleted it
