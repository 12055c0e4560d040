"""How a signal ends ``haptic-bus run`` while its drive is enabled (the exit table, README and
docs/commands.md): SIGTERM, a service manager's stop, is no error -- "stopped", exit 0, nothing on
stderr; SIGINT (Ctrl-C) is "interrupted", exit 130, one line.  Either way the drive is disabled
and the folder completed.

A real signal to this process, caught by the handler the real command line installs
(:class:`~haptic_bus.app.run_options.StopRequest`), sent once the simulated drive (in this process,
lock-step bus) is enabled; the run is 60 s of virtual time, so only the signal can end it.
"""

from __future__ import annotations

import os
import pathlib
import signal
import threading

import pytest

from drives.cia402 import State
from tests.run_rig import read_record, read_run, run_cli, simulated_drive, wait_until

CYCLES_BEFORE_SIGNAL = 100  # SYNCs the enabled drive sees before the signal is sent


@pytest.mark.parametrize(("sig", "code", "reason"), [(signal.SIGTERM, 0, "stopped"), (signal.SIGINT, 130, "interrupted")],
                         ids=["SIGTERM", "SIGINT"])
def test_a_signal_ends_an_enabled_run_disabled_and_recorded_with_its_exit_status(
        sig: signal.Signals, code: int, reason: str, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    with simulated_drive("canopen", "cia402-handle") as drive:
        def signal_once_enabled() -> None:
            if not wait_until(lambda: drive.was_enabled, 30.0):
                return
            enabled_at = drive.drive.sync_count  # SYNCs before it were commissioning's and the enable handshake's
            if wait_until(lambda: drive.drive.sync_count >= enabled_at + CYCLES_BEFORE_SIGNAL, 30.0):
                os.kill(os.getpid(), sig)  # the run's handler is installed: it was enabled after it

        sender = threading.Thread(target=signal_once_enabled, daemon=True)
        sender.start()
        result = run_cli(capsys, "run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "60", "--no-live",
                         "--no-plots", "--out", str(tmp_path))
        sender.join(35.0)
        assert drive.states[-1] is State.SWITCH_ON_DISABLED  # disabled by the run, not left enabled or faulted
    assert result.code == code, result.err
    assert f"ended: {reason}; wrote " in result.out
    if reason == "stopped":
        assert result.err == ""
    else:
        assert result.err_lines == ["haptic-bus run: interrupted (Ctrl-C)"]
    document = read_run(tmp_path)
    assert (document["status"], document["ended"], document["summary"]["exit_reason"]) == (reason, True, reason)
    _, record = read_record(tmp_path)
    # cycled, and ended long before its 60 s: every SYNC after the drive enabled is a recorded cycle,
    # but the master sees the enabled statusword one cycle late, so one may be missing
    assert CYCLES_BEFORE_SIGNAL - 1 <= record["time_s"].size < 60_000
