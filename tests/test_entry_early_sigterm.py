"""A SIGTERM that reaches ``haptic-bus run`` while the console script still imports the command line
(0.1-0.5 s after the start under load) ends it in one line, exit 0, as one during the profile's
read does; it used to kill the process silently (status -15, 143 in a shell)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

from haptic_bus.app.early_stop import STOPPED_BEFORE_START

# A child that runs the console script's main for `haptic-bus run gantry-3d ...` and sends itself
# SIGTERM as soon as main has installed its handler, before the command line is imported; the
# child says first whether the command line's run (haptic_bus.app.cli._run, which installs the
# handler too) was still undefined when it sent the signal.
_CHILD = textwrap.dedent("""
    import os, signal, sys, threading, time
    from haptic_bus.app.early_stop import note_stop
    from haptic_bus.app.entry import main

    def kill_early():
        deadline = time.monotonic() + 30.0
        while signal.getsignal(signal.SIGTERM) is not note_stop and time.monotonic() < deadline:
            time.sleep(1e-4)
        cli = sys.modules.get("haptic_bus.app.cli")  # there from the start of its import, _run defined late in it
        os.write(1, f"early {getattr(cli, '_run', None) is None}\\n".encode())
        os.kill(os.getpid(), signal.SIGTERM)

    sys.argv = ["haptic-bus", "run", "gantry-3d", "--interface", "virtual", "--channel", "early-sigterm",
                "--virtual-time", "--duration", "1"]
    threading.Thread(target=kill_early, daemon=True).start()
    sys.exit(main())
""")


def test_sigterm_while_the_command_line_is_imported_ends_the_run_in_one_line() -> None:
    done = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, timeout=120,
                          env=os.environ | {"PYTHONWARNINGS": "error"})
    assert (done.returncode, done.stderr) == (0, "")
    assert done.stdout.splitlines() == ["early True", STOPPED_BEFORE_START]
