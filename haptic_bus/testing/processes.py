"""The simulated drive as another process: ``python -m sim_drive ARGS``, stopped within bounded time.

The process runs the same interpreter and imports the same installation of haptic_bus as the
test (the folder that holds the imported ``haptic_bus`` leads its ``PYTHONPATH``); its log
(stderr) goes to an unlinked file, which cannot fill up as a pipe can.  Stopping sends a signal
(SIGTERM), waits at most :data:`STOP_WAIT` s, then kills it (SIGKILL) and fails the test.
"""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import tempfile
import time

import pytest

STOP_WAIT = 10.0  # s: the longest a simulator subprocess is given to exit on a signal, and again after SIGKILL
POLL_INTERVAL = 0.02  # s: how often a wait looks at the log


def installation_root() -> pathlib.Path:
    """The folder holding the ``haptic_bus`` (and so ``sim_drive``) this process imported."""
    return pathlib.Path(__file__).resolve().parents[2]  # haptic_bus/testing/processes.py


class SimProcess:
    """``python -m sim_drive ARGS`` as a subprocess, its log (stderr) in a file that cannot fill up."""

    def __init__(self, *args: str) -> None:
        from haptic_bus.app.rig import simulator_command

        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(installation_root()), env.get("PYTHONPATH")]))
        self.args = simulator_command(*args)
        self._log, path = tempfile.mkstemp(prefix="sim_drive-", suffix=".log")  # a file, not a pipe: it cannot fill up
        os.unlink(path)  # the descriptor keeps it; nothing is left behind
        self.process = subprocess.Popen(self.args, env=env, stdout=subprocess.DEVNULL, stderr=self._log)
        self.sent: signal.Signals | None = None  # the signal stop() sent, the last time it sent one

    def log(self) -> str:
        """Everything the process wrote to stderr so far (``pread``: the shared file offset does not move)."""
        return os.pread(self._log, os.fstat(self._log).st_size, 0).decode(errors="replace")

    def wait_for_line(self, text: str, timeout: float) -> str:
        """Block until the log contains ``text`` (bounded by ``timeout`` s); the log so far."""
        deadline = time.monotonic() + timeout
        while True:
            log = self.log()
            if text in log:
                return log
            if self.process.poll() is not None:
                raise AssertionError(f"simulator exited ({self.process.returncode}) before {text!r}: {log[-2000:]}")
            if time.monotonic() >= deadline:
                raise AssertionError(f"no {text!r} from the simulator within {timeout} s: {log[-2000:]}")
            time.sleep(POLL_INTERVAL)

    def stop(self, sig: signal.Signals = signal.SIGTERM, timeout: float = STOP_WAIT) -> tuple[int, str]:
        """Send ``sig``, wait at most ``timeout`` s; the exit status and the log.  A process still
        running then is killed (SIGKILL) and the test fails."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
            self.sent = sig
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=timeout)
            pytest.fail(f"simulated drive did not stop on {sig.name} within {timeout} s")
        return self.process.returncode, self.log()

    def close(self) -> None:
        """Kill the process if it still runs (bounded wait) and drop the log."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=STOP_WAIT)
        if self._log >= 0:
            os.close(self._log)
            self._log = -1


def stop_all(started: list[SimProcess]) -> None:
    """Stop (SIGTERM, bounded, then SIGKILL) every process of ``started`` still running, then close them all."""
    try:
        for process in started:
            if process.process.poll() is None:
                process.stop()
    finally:
        for process in started:
            process.close()
