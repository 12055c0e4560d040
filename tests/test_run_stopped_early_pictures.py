"""A run asked to stop before its first cycle ends at once: no pictures of a run that never moved.

Breaker10: a one-axis run stopped by Ctrl-C before its drive was enabled took 3.5-8.6 s to exit on a
loaded machine, drawing region.png (its passive region: 60 ``passive_set`` evaluations).  Now such a
run writes run.json ("stopped") and the bus log, no picture; ``haptic-bus plot`` draws them later.
Here the stop request is set before the run starts (SIGTERM's path: ``StopRequest.event``), in
virtual time against the simulated drive on the lock-step bus, in this process.
"""

from __future__ import annotations

import pathlib

import haptic_bus as hb
from haptic_bus.app.run_options import StopRequest
from tests.run_rig import read_run, simulated_drive


def test_a_run_stopped_before_its_first_cycle_draws_nothing(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "run"
    stop = StopRequest()
    stop.event.set()  # SIGTERM before the run began
    with simulated_drive("canopen", "cia402-handle") as drive:
        options = hb.RunOptions(duration=1.0, pacing="virtual", out_dir=out, live=False, stop=stop)  # pictures asked
        result = hb.run(hb.load_profile("cia402-handle"), drive.bus, options, node_id=5)
        assert not drive.was_enabled
    assert result.exit_reason == "stopped" and read_run(out)["status"] == "stopped"
    assert sorted(path.name for path in out.iterdir() if path.suffix == ".png") == []
    assert (out / "record.csv").is_file() and (out / "bus.asc").is_file()
