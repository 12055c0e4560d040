"""A SIGTERM once ``run`` has ended changes nothing: the exit status stays the one the run said.

With a Python handler installed, the interpreter puts the default action back while it finalizes,
and a SIGTERM then killed the process (status -15) after it had printed "drive error" (found by the
fuzz test, whose SIGTERM came while the run's process exited on its own)."""

from __future__ import annotations

import os
import pathlib
import signal

import pytest

from haptic_bus.app.cli import main
from tests.run_rig import simulated_drive


def test_sigterm_is_ignored_once_the_run_has_ended(tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with simulated_drive("canopen", "cia402-handle") as drive:
            code = main(["run", "cia402-handle", *drive.args, "--virtual-time", "--duration", "0.05", "-q", "--no-plots",
                         "--out", str(tmp_path / "run")])
        assert code == 0, capsys.readouterr().err
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN  # kept through the interpreter's exit
        os.kill(os.getpid(), signal.SIGTERM)  # delivered, and nothing happens
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
