"""A SIGTERM while the ``haptic-bus`` process exits changes nothing: the exit status stays the command's.

With a Python handler installed (``run``'s stop request), the interpreter puts the default action
back while it finalizes, and a SIGTERM then killed the process (status -15) after it had printed
"drive error" (found by the fuzz test, whose SIGTERM came while the run's process exited on its own).
The command line called from a program (:func:`haptic_bus.app.cli.main`) leaves the signals as they were."""

from __future__ import annotations

import os
import signal
import sys

import pytest

from haptic_bus.app import entry


def test_the_console_script_ignores_sigterm_once_its_command_has_ended(monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    saved = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(sys, "argv", ["haptic-bus", "profiles", "show", "cia402-handle"])
    try:
        assert entry.main() == 0
        assert "cia402-handle" in capsys.readouterr().out
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN  # kept through the interpreter's exit
        os.kill(os.getpid(), signal.SIGTERM)  # delivered, and nothing happens
    finally:
        signal.signal(signal.SIGTERM, saved)
