"""Signals before a run has begun: the stop handling is the first thing ``run`` does, and a Ctrl-C
while the console script imports the command line is one line and exit 130, no traceback.

Each signal is a real one the process sends itself at the moment under test (while ``run`` reads
its profile; while the console script imports the command line), in a subprocess, so that a
signal nobody handles ends that process (exit -15), not the suite.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib

from tests.cli_process import REPO

WAIT = 60.0  # s: a subprocess that imports the command line and reads a profile, on a loaded machine

# ``run`` with the profile's reading wrapped so that the process gets SIG first: the real reading then runs.
_DURING_PROFILE = """
import os, signal, sys
import haptic_bus.app.profiles as profiles
from haptic_bus.app.cli import main
real = profiles.load_profile
def load_profile(*args, **kwargs):
    os.kill(os.getpid(), signal.SIG)
    return real(*args, **kwargs)
profiles.load_profile = load_profile
sys.exit(main(["run", "cia402-handle", "--interface", "udp_multicast", "--channel", "239.74.164.9",
               "--bus-option", "port=46009", "--node-id", "5", "--virtual-time", "--no-live"]))
"""

# The console script as pip writes it (``from MODULE import FUNCTION``), for pyproject's target,
# with a Ctrl-C arriving as the command line's module is looked up.
_DURING_IMPORT = """
import importlib.abc, os, signal, sys
class CtrlC(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "haptic_bus.app.cli":
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, CtrlC())
from MODULE import FUNCTION
sys.exit(FUNCTION())
"""


def python(script: str) -> subprocess.CompletedProcess[str]:
    """``python -c script`` with this tree first on ``PYTHONPATH``; its output as text."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-c", script], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=WAIT, check=False)


def test_sigterm_while_the_profile_is_read_stops_the_run_with_exit_0() -> None:
    done = python(_DURING_PROFILE.replace("SIG)", "SIGTERM)"))
    assert (done.returncode, done.stderr) == (0, "")
    assert "ended: stopped before the run began" in done.stdout


def test_ctrl_c_while_the_profile_is_read_is_one_line_and_exit_130() -> None:
    done = python(_DURING_PROFILE.replace("SIG)", "SIGINT)"))
    assert (done.returncode, done.stderr) == (130, "haptic-bus: interrupted\n")  # at once: the profile is left unread


def test_ctrl_c_while_the_console_script_imports_is_one_line_and_exit_130() -> None:
    target = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]["haptic-bus"]
    module, _, function = target.partition(":")
    done = python(_DURING_IMPORT.replace("MODULE", module).replace("FUNCTION", function))
    assert (done.returncode, done.stderr) == (130, "haptic-bus: interrupted\n")
