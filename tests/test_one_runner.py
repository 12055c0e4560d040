"""One runner for any axis count: ``hb.run`` drives the one-axis ``cia402-handle`` and the
three-axis ``gantry-3d`` through the same session (:func:`haptic_bus.app.runner._session`), in
virtual time on the lock-step bus against the simulated drive(s) in this process.

Numbers: a run of ``d`` s at ``T`` has ``round(d / T)`` cycles exactly (virtual time: a cycle per
SYNC, none lost); the port's least energy is at or above zero (the passivity layer's guard keeps
it so; the profiles' walls are judged passive); one record per axis, ``record.csv`` for one axis
and ``record-x|y|z.csv`` for three, each with a row per cycle.  The bus load is the bit-time model
of :mod:`haptic_bus.analysis.can_timing` (``55 + 10 n`` bit times a frame of ``n`` bytes), exact
integers: one axis with its position mapped is a SYNC (55), TPDO1 (6 bytes, 115), TPDO2 (4 bytes,
95) and RPDO1 (4 bytes, 95), 360 bit times a cycle; three are 55 + 3 x 305 = 970.
"""

from __future__ import annotations

import csv
import json
import pathlib
import re
from typing import Any

import can
import pytest

import haptic_bus as hb
from drives.bus_config import open_bus
from drives.cia402 import State
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
    ("gantry-3d", "tcp://127.0.0.1:5020", None, "unit_ids"),  # Modbus axes: the profile names node ids, no unit ids
    ("gantry-3d", ["tcp://127.0.0.1:5020"] * 2, None, "bus"),  # one URL for every axis, or one per axis: not two
    ("gantry-3d", {"interface": "lockstep", "channel": "x"}, 5, "node_id"),
    ("cia402-handle", {"interface": "lockstep", "channel": "x"}, None, "node_id"),
])
def test_a_call_that_names_no_drive_is_refused_before_anything_is_touched(
        profile: str, bus: Any, node_id: int | None, named: str, tmp_path: pathlib.Path) -> None:
    options = hb.RunOptions(DURATION, pacing="virtual", out_dir=tmp_path / "run", live=False)
    with pytest.raises(hb.ParameterError, match=f"^run: {named} "):
        hb.run(hb.load_profile(profile), bus, options, node_id=node_id)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(("profile", "bus", "ids", "named"), [
    ("cia402-handle", "tcp://127.0.0.1:5020", {"node_id": 5}, "node_id"),  # a Modbus drive is its unit id
    ("cia402-handle", {"interface": "lockstep", "channel": "x"}, {"node_id": 5, "unit_id": 2}, "unit_id"),
    ("gantry-3d", "tcp://127.0.0.1:5020", {"unit_id": 2}, "unit_id"),  # several: unit_ids
    ("gantry-3d", {"interface": "lockstep", "channel": "x"}, {"unit_ids": [1, 2, 3]}, "unit_ids"),
])
def test_a_drive_id_that_names_nothing_on_its_link_is_refused_not_ignored(
        profile: str, bus: Any, ids: dict[str, Any], named: str, tmp_path: pathlib.Path) -> None:
    options = hb.RunOptions(DURATION, pacing="virtual", out_dir=tmp_path / "run", live=False)
    with pytest.raises(hb.ParameterError, match=f"^run: {named} = .* is invalid; allowed: none: "):
        hb.run(hb.load_profile(profile), bus, options, **ids)
    assert not (tmp_path / "run").exists()


def test_one_axis_refuses_a_bus_that_cannot_carry_its_cycle_before_any_sync(haptic_sim, tmp_path: pathlib.Path) -> None:
    """360 bit times every 1 ms on 500 kbit/s is 72.0 % of the bus, above the 70 % ceiling: refused,
    naming the smallest T that fits, 360 / (0.7 x 500 000) s = 1.029 ms; no SYNC sent, nothing enabled."""
    drive = haptic_sim("cia402-handle", interface="lockstep", node_id=5)
    assert drive.sim is not None  # in this process: its SYNCs and state are read directly
    options = hb.RunOptions(DURATION, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False)
    result = hb.run(hb.load_profile("cia402-handle"), {**drive.bus, "bitrate": 500_000}, options, node_id=5)
    assert result.exit_reason == "refused" and result.summary is None and result.error is not None
    assert "bus load 72.0 % of 500 kbit/s at T = 1 ms (1 axis, 360 bits per cycle" in result.error
    assert "T >= 1.029 ms" in result.error
    assert (drive.sim.drive.sync_count, drive.sim.drive.state) == (0, State.SWITCH_ON_DISABLED)
    document = json.loads((tmp_path / "run" / "run.json").read_text())
    assert document["exit_reason"] == "refused" and document["link"]["bitrate_checked"] == 500_000


@pytest.mark.parametrize(("profile", "node_id", "controller", "allowed"), [
    ("cia402-handle", 5, 5, "a node id other than the drive's (5)"),
    ("gantry-3d", None, 6, "a node id none of the axes has ([5, 6, 7])"),
])
def test_the_controller_node_is_none_of_the_drives_named_as_runs_argument(
        profile: str, node_id: int | None, controller: int, allowed: str, tmp_path: pathlib.Path) -> None:
    """Refused before any file or bus (exit 2 at the command line, which names --controller-node-id)."""
    options = hb.RunOptions(DURATION, pacing="virtual", out_dir=tmp_path / "run", live=False)
    bus = {"interface": "lockstep", "channel": f"nobody-{tmp_path.name}"}
    with pytest.raises(hb.ParameterError, match=f"^run: controller_node_id = {controller} is invalid; allowed: "
                                                 f"{re.escape(allowed)}$"):
        hb.run(hb.load_profile(profile), bus, options, node_id=node_id, controller_node_id=controller)
    assert not (tmp_path / "run").exists()


def test_several_axes_take_an_open_bus_and_leave_it_open(tmp_path: pathlib.Path) -> None:
    """gantry-3d on a lock-step bus handle the caller opened: 0.5 s at T = 2 ms is 250 cycles, every
    axis' record a row each; the run leaves the handle open; the load is 970 bit times per 2 ms at the
    profile's 1 Mbit/s (an open bus states no bitrate), 48.5 %."""
    three = hb.load_profile("gantry-3d")
    config = {"interface": "lockstep", "channel": f"open-{tmp_path.name}"}
    sim = simulated_axes_device(three, config).start()
    bus = open_bus(**config)
    try:
        options = hb.RunOptions(DURATION, pacing="virtual", out_dir=tmp_path / "run", live=False, plots=False)
        result = hb.run(three, bus, options)
        assert result.exit_reason == "completed", result.error
        assert result.summary is not None and result.summary.cycles == 250
        assert [rows(tmp_path / "run" / f"record-{axis}.csv") for axis in "xyz"] == [250] * 3
        link = json.loads((tmp_path / "run" / "run.json").read_text())["link"]
        assert (link["node_ids"], link["bus"]["interface"]) == ([5, 6, 7], type(bus).__name__)
        assert link["bus_load"]["bits"] == 970 and link["bus_load"]["load"] == pytest.approx(0.485, rel=1e-12)
        bus.send(can.Message(arbitration_id=0x080, is_extended_id=False))  # still open: the caller's to close
    finally:
        bus.shutdown()
        sim.stop()
