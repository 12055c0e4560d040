"""One runner for any axis count: ``hb.run`` drives the one-axis ``cia402-handle`` and the
three-axis ``gantry-3d`` through the same session (:func:`haptic_bus.app.runner._session`), in
virtual time on the lock-step bus against the simulated drive(s) in this process.

Numbers: a run of ``d`` s at ``T`` has ``round(d / T)`` cycles exactly (virtual time: a cycle per
SYNC, none lost); the port's least energy is at or above zero (the passivity layer's guard keeps
it so; the profiles' walls are judged passive); one record per axis, ``record.csv`` for one axis
and ``record-x|y|z.csv`` for three, each with a row per cycle.
"""

from __future__ import annotations

import csv
import json
import pathlib
from typing import Any

import pytest

import haptic_bus as hb
from haptic_bus.app import runner
from haptic_bus.app.rig import simulated_axes_device
from haptic_bus.app.run_kinds import AxesRun, OneAxisRun

DURATION = 0.5  # s of virtual time


@pytest.fixture
def sessions(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The kind of each run that went through the one session, by class name."""
    seen: list[str] = []
    session = runner._session

    def recorded(kind: Any, rig: Any, options: Any) -> runner.RunResult:
        seen.append(type(kind).__name__)
        return session(kind, rig, options)

    monkeypatch.setattr(runner, "_session", recorded)
    return seen


def rows(path: pathlib.Path) -> int:
    with path.open() as file:
        return sum(1 for _ in csv.DictReader(file))


def test_one_call_runs_one_axis_and_three_through_one_session(haptic_sim, sessions: list[str],
                                                              tmp_path: pathlib.Path) -> None:
    options = {"pacing": "virtual", "live": False, "plots": False, "bus_log": False}
    one = hb.load_profile("cia402-handle")
    drive = haptic_sim("cia402-handle", interface="lockstep", node_id=5)
    single = hb.run(one, drive.bus, hb.RunOptions(DURATION, out_dir=tmp_path / "one", **options), node_id=5)

    three = hb.load_profile("gantry-3d")
    bus = {"interface": "lockstep", "channel": f"three-{tmp_path.name}"}
    sim = simulated_axes_device(three, bus).start()
    try:
        triple = hb.run(three, bus, hb.RunOptions(DURATION, out_dir=tmp_path / "three", **options))
    finally:
        sim.stop()

    assert sessions == [OneAxisRun.__name__, AxesRun.__name__]
    for result, period, files in ((single, one.loop.period, ["record.csv"]),
                                  (triple, three.period, ["record-x.csv", "record-y.csv", "record-z.csv"])):
        assert result.exit_reason == "completed", result.error
        cycles = round(DURATION / period)
        assert result.summary is not None and result.summary.cycles == cycles
        assert result.summary.least_energy >= 0.0
        assert [path.name for path in result.files if path.suffix == ".csv"] == files
        assert [rows(result.folder / name) for name in files] == [cycles] * len(files)
        document = json.loads((result.folder / "run.json").read_text())
        assert document["status"] == "completed" and document["ended"] is True
    assert triple.controller is not None and len(triple.controller.names) == 3


@pytest.mark.parametrize(("profile", "bus", "node_id", "named"), [
    ("gantry-3d", "tcp://127.0.0.1:5020", None, "--unit-ids"),  # Modbus axes: the profile names node ids, no unit ids
    ("gantry-3d", {"interface": "lockstep", "channel": "x"}, 5, "node_id"),
    ("cia402-handle", {"interface": "lockstep", "channel": "x"}, None, "node_id"),
])
def test_a_call_that_names_no_drive_is_refused_before_anything_is_touched(
        profile: str, bus: Any, node_id: int | None, named: str, tmp_path: pathlib.Path) -> None:
    options = hb.RunOptions(DURATION, pacing="virtual", out_dir=tmp_path / "run", live=False)
    with pytest.raises(hb.ParameterError, match=f"^run: {named} "):
        hb.run(hb.load_profile(profile), bus, options, node_id=node_id)
    assert not (tmp_path / "run").exists()
