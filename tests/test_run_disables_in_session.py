"""A wall-paced run disables its drives at its end while its control thread still holds the real-time
session (breaker11a: undoing SCHED_FIFO, mlockall and the frozen gc first took 11 ms idle and 75 ms
beside CPU-bound work, longer than gantry-3d's 60 ms RPDO deadline while the drives held their last
torque: all three drives of a run that said "completed" were left in FAULT, EMCY 0x8250)."""

from __future__ import annotations

import dataclasses
import os
import pathlib
from collections.abc import Callable
from typing import Any

import pytest

import haptic_bus as hb
from drives.axes_master import AxesMaster
from drives.canopen.drive import CanopenDrive
from haptic_bus.testing.run_files import read_run_folder

RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0)  # the session asks for it beside SCHED_FIFO


@pytest.mark.parametrize(("profile", "master"), [("cia402-handle", CanopenDrive), ("gantry-3d", AxesMaster)])
def test_the_end_of_a_run_disables_under_the_run_s_scheduling(
        haptic_sim: Callable[..., Any], tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
        profile: str, master: type) -> None:
    policies: list[int] = []
    disable = master.disable

    def disable_and_say_how(self: Any) -> None:  # the real disable, its thread's policy noted first
        policies.append(os.sched_getscheduler(0) & ~RESET_ON_FORK)
        disable(self)

    monkeypatch.setattr(master, "disable", disable_and_say_how)
    still = {} if profile == "gantry-3d" else {"operator": {"model": "constant", "level": 0.0}}  # gantry's hand waits
    drive = haptic_sim(profile, interface="lockstep", **still)  # for every axis enabled; the handle's would push now
    options = hb.RunOptions(duration=0.05, pacing="wall", out_dir=tmp_path, start_in_contact="ramp", live=False,
                            bus_log=False, plots=False, preflight_cycles=2)
    loaded = hb.load_profile(profile)
    if isinstance(loaded, hb.AxesProfile):  # its drives and deadlines, without the ball: pre-flight judges the scene
        # at the delay it measured, and a sphere's direction search took 1.3 s of CPU there, 1400 cycles run meanwhile
        loaded = dataclasses.replace(loaded, space=tuple(obj for obj in loaded.space if obj.name != "ball"))
    result = hb.run(loaded, drive.bus, options, **drive.run_kwargs())
    if result.exit_reason == "refused" and "this machine holds T >=" in (result.error or ""):
        # two pre-flight cycles allow none busy longer than T; the lock-step bus answers in the sender's thread
        pytest.skip(f"this machine cannot hold the loop now, and the run said so at pre-flight: {result.error}")
    assert result.exit_reason == "completed", result.error
    got = read_run_folder(result.folder).document["realtime"]["got"]
    assert policies, "the run never disabled its drive(s)"
    if "SCHED_FIFO" not in got:
        pytest.skip(f"the OS did not grant SCHED_FIFO here ({got}): the run's policy is the thread's own")
    assert policies[-1] == os.SCHED_FIFO
    assert os.sched_getscheduler(0) & ~RESET_ON_FORK != os.SCHED_FIFO  # and the session was undone after it


def test_a_drive_that_faults_as_the_run_ends_makes_it_a_drive_error(
        haptic_sim: Callable[..., Any], tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The disable walk accepts FAULT as an end (a drive that faulted is as safe as a disabled one), so a
    drive that faulted between the last cycle and the disable (its RPDO deadline, EMCY 0x8250) left the
    run "completed", exit 0, and the next run refused for the fault.  The run now reads each drive's
    state after the walk: a drive error naming the drive and its error code."""
    drive = haptic_sim("cia402-handle", interface="lockstep", operator={"model": "constant", "level": 0.0})
    disable = CanopenDrive.disable

    def fault_then_disable(self: CanopenDrive) -> None:  # what a 60 ms stall after the last cycle did
        drive.sim.enter_fault(0x8250)
        disable(self)

    monkeypatch.setattr(CanopenDrive, "disable", fault_then_disable)
    options = hb.RunOptions(duration=0.05, pacing="virtual", out_dir=tmp_path, live=False, bus_log=False, plots=False)
    result = hb.run(hb.load_profile("cia402-handle"), drive.bus, options, **drive.run_kwargs())
    assert result.exit_reason == "drive error" and result.summary is not None and result.summary.cycles == 50
    assert result.error is not None and result.error.startswith("CANopen node 5: in FAULT after the run's last cycle: "
                                                                 "drive is in FAULT (statusword 0x"), result.error
    assert "0x8250" in result.error
    assert read_run_folder(result.folder).document["exit_reason"] == "drive error"
