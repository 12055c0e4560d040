"""``haptic-bus`` as another process, for the tests that need one: not a test module.

- :func:`cli_process` starts ``python -m haptic_bus ARGS`` in the repository with this
  tree leading ``PYTHONPATH`` (the process imports the code under test), stdout and stderr piped
  as text.
- :func:`reaped` kills and reaps, on leaving its block, a process that still runs (a failed
  assertion or a timeout must not leave it behind).
- :func:`terminated` ends a process with SIGTERM, as a user's ``kill`` does, and gives back its
  output; a process that does not exit in time is killed.
- :func:`skip_if_refused_at_preflight` skips a test whose real-time run ended refused at pre-flight:
  this machine could not hold the loop then (the suite's own load), and the run said so.

Every wait here is bounded in time.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
KILL_WAIT = 10.0  # s: the longest a killed process is waited for


def cli_process(*args: str) -> subprocess.Popen[str]:
    """``haptic-bus ARGS`` as a subprocess (stdout and stderr piped, text)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.Popen([sys.executable, "-m", "haptic_bus", *args], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@contextmanager
def reaped(process: subprocess.Popen[str]) -> Iterator[subprocess.Popen[str]]:
    """``process``; killed and reaped on exit if it still runs."""
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate(timeout=KILL_WAIT)


def terminated(process: subprocess.Popen[str], timeout: float) -> tuple[str, str]:
    """SIGTERM to ``process``, then its stdout and stderr within ``timeout`` s (killed if it takes longer)."""
    process.send_signal(signal.SIGTERM)
    try:
        return process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.communicate(timeout=KILL_WAIT)


def skip_if_refused_at_preflight(run: subprocess.Popen[str], what: str = "the loop") -> None:
    """A run that ended with exit 1: skip the test if pre-flight refused it, naming the period this
    machine holds (the right answer under load, but no run to test); else fail with its stderr."""
    if run.poll() != 1 or run.stderr is None:
        return
    error = run.communicate(timeout=KILL_WAIT)[1]  # it has exited: its pipes read to the end and closed
    if "this machine holds T >=" in error or "reaches the drive's watchdog" in error:
        pytest.skip(f"this machine cannot hold {what} now, and the run said so at pre-flight: {error.strip()}")
    raise AssertionError(error)
