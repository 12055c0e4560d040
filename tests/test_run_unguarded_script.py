"""A script that calls ``hb.run`` at its top level, without ``if __name__ == "__main__":``: the judge
worker, started by spawn, runs the script again and dies.  The run says so in one exception naming
the rule, and its ``run.json`` says "crashed" with it; it used to raise BrokenProcessPool and
record the run as "completed" (the worker's own second run too)."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

SCRIPT = """\
import pathlib
import haptic_bus as hb

out = pathlib.Path({out!r}) / str(len(list(pathlib.Path({out!r}).iterdir())))  # the worker's run: a folder of its own
hb.run(hb.load_profile("cia402-handle"), {bus!r},
       hb.RunOptions(duration=0.2, pacing="virtual", out_dir=out, start_in_contact="ramp", live=False, plots=False),
       node_id={node_id})
"""


def test_an_unguarded_script_is_told_the_rule_and_its_run_is_not_completed(multicast: tuple[str, int],
                                                                             tmp_path: pathlib.Path) -> None:
    """The script is the process that matters; the simulated drive it talks to over udp_multicast runs in this
    one (as ``haptic-bus sim --profile cia402-handle`` builds it), which costs no second interpreter's imports."""
    from sim_drive.canopen.slave import CanopenSimDrive
    from sim_drive.profile import read_simulated_device

    group, port = multicast
    bus = {"interface": "udp_multicast", "channel": group, "port": port}
    truth, operator = read_simulated_device("cia402-handle").one_axis()
    runs = tmp_path / "runs"
    runs.mkdir()
    script = tmp_path / "unguarded.py"
    script.write_text(SCRIPT.format(out=str(runs), bus=bus, node_id=5))
    sim = CanopenSimDrive(bus, 5, timing=truth.timing, parameters=truth.parameters, operator=operator).start()
    try:
        done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                              env=os.environ | {"PYTHONWARNINGS": "ignore"})  # the crash's resource_tracker warning
    finally:
        sim.stop()
    assert done.returncode == 1, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("drives.errors.HapticBusError: the judge worker process died while it started")
    assert "if __name__ == '__main__':" in last
    statuses = {folder.name: json.loads((folder / "run.json").read_text())["status"] for folder in runs.iterdir()}
    assert statuses["0"] == "crashed"  # the script's run; the worker's own ("1", if it got that far) crashed too
    assert set(statuses.values()) == {"crashed"}
