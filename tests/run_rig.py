"""In-process rigs for the tests of ``haptic-bus run`` (issue 11): not a test module.

- :func:`simulated_drive` starts the simulated drive in this process on a real link, a CANopen
  slave on the lock-step bus (:mod:`drives.lockstep_bus`, a channel no other test uses: the
  drive answers each frame in the sender's thread, so a virtual-time run costs no thread
  hand-offs) or a Modbus TCP server on 127.0.0.1 (a free port), from the same profile file the
  run is given, and records every CiA-402 state the drive enters; :attr:`DriveUnderTest.args`
  are the ``run`` options that reach it, :attr:`DriveUnderTest.bus` the CAN bus's python-can
  keywords.
- :func:`run_cli` runs the real command line (:func:`haptic_bus.app.cli.main`) in this process
  and gives back its exit status, stdout and stderr; it puts back the SIGINT/SIGTERM handlers
  the run installs, so pytest keeps its own Ctrl-C.
- :func:`profile_variant` writes a shipped profile with literal edits and extra tables into a
  test's folder: the run and the simulated drive read the same file.
- :func:`enabled_drive` is the simulated drive alone, no bus, enabled in CST.
- :func:`late_clock` is a test double of the virtual clock that reports chosen cycles as late
  (the supervisor's input), for a deterministic lateness in a lock-step run.

Every wait here is bounded in time.
"""

from __future__ import annotations

import csv
import json
import os
import pathlib
import signal
import time
import uuid
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from drives.cia402 import Command, OperationMode, State
from haptic_bus.app.cli import main
from haptic_bus.app.profiles import resolve_profile
from haptic_bus.control.clock import VirtualClock
from sim_drive.device import SimulatedDrive
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import read_simulated_device

NODE = 5  # the simulated drive's CANopen node id
CAN_INTERFACE = "lockstep"  # the CAN bus of simulated_drive("canopen")
TRANSPORTS = ("canopen", "modbus")
RECORD_FILES = ("record.csv", "timeline.png", "force_position.png", "region.png", "run.json")  # Modbus, in the order written


def record_files(transport: str, plots: bool = True) -> tuple[str, ...]:
    """What a run on ``transport`` writes, in the order its "wrote" line names them (CANopen: the bus log too;
    the pictures unless ``--no-plots``)."""
    files = RECORD_FILES if plots else (RECORD_FILES[0], RECORD_FILES[-1])
    return (files[0], "bus.asc", *files[1:]) if transport == "canopen" else files


@dataclass
class DriveUnderTest:
    """The simulated drive a run talks to: the ``run`` options that reach it, its hardware, the
    CiA-402 states it entered (in order), the virtual-bus channel and the fault injections that
    make the next TPDO one byte short and put the drive into FAULT with an error code (CANopen only)."""

    transport: str
    args: list[str]
    drive: SimulatedDrive
    states: list[State] = field(default_factory=list)
    channel: str | None = None
    stop: Callable[[], None] = lambda: None
    short_next_tpdo: Callable[[], None] | None = None
    enter_fault: Callable[[int], None] | None = None

    @property
    def bus(self) -> dict[str, Any]:
        """The python-can keywords of the drive's CAN bus (CANopen only)."""
        return {"interface": CAN_INTERFACE, "channel": self.channel}

    @property
    def was_enabled(self) -> bool:
        """True once the drive entered OPERATION ENABLED."""
        return State.OPERATION_ENABLED in self.states


@contextmanager
def simulated_drive(transport: str, profile: pathlib.Path | str, hand_needs_power: bool = False) -> Iterator[DriveUnderTest]:
    """The simulated drive of ``profile`` in this process, on ``transport`` ("canopen": the
    lock-step bus, node 5; "modbus": TCP on 127.0.0.1), its hand as ``hand_needs_power`` says
    (:class:`~sim_drive.device.SimulatedDrive`); stopped on exit (``stop`` may end it earlier)."""
    truth, operator = read_simulated_device(profile).one_axis()
    if transport == "canopen":
        from sim_drive.canopen.slave import CanopenSimDrive

        channel = f"run-test-{os.getpid()}-{uuid.uuid4().hex[:10]}"
        slave = CanopenSimDrive({"interface": CAN_INTERFACE, "channel": channel}, NODE, timing=truth.timing,
                                parameters=truth.parameters, operator=operator, hand_needs_power=hand_needs_power)
        under = DriveUnderTest(transport, ["--interface", CAN_INTERFACE, "--channel", channel, "--node-id", str(NODE)],
                               slave.drive, channel=channel, stop=slave.stop, short_next_tpdo=slave.short_next_tpdo,
                               enter_fault=slave.enter_fault)
        slave.drive.state_listeners.append(lambda old, new, number: under.states.append(new))
        slave.start()
    elif transport == "modbus":
        from sim_drive.modbus.server import ModbusSimServer

        server = ModbusSimServer("127.0.0.1", 0, timing=truth.timing, parameters=truth.parameters, operator=operator,
                                 hand_needs_power=hand_needs_power)
        under = DriveUnderTest(transport, [], server.drive, stop=server.stop)
        server.drive.state_listeners.append(lambda old, new, number: under.states.append(new))
        server.start()
        under.args = ["--modbus", server.url]
    else:
        raise ValueError(transport)
    try:
        yield under
    finally:
        under.stop()


@dataclass(frozen=True)
class CliResult:
    """What one command did: exit status, stdout, stderr."""

    code: int
    out: str
    err: str

    @property
    def err_lines(self) -> list[str]:
        """The non-empty lines on stderr."""
        return [line for line in self.err.splitlines() if line.strip()]


def run_cli(capsys: pytest.CaptureFixture[str], *args: str) -> CliResult:
    """``haptic-bus ARGS`` in this process (the real CLI); SIGINT/SIGTERM handlers put back after."""
    capsys.readouterr()  # what came before is not this command's
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = main(list(args))
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    captured = capsys.readouterr()
    return CliResult(code, captured.out, captured.err)


def enabled_drive(parameters: DeviceParameters, timing: Timing = Timing.CIA402) -> SimulatedDrive:
    """The simulated drive alone (no bus) of ``parameters``, in CST and OPERATION ENABLED."""
    drive = SimulatedDrive(parameters, timing)
    drive.write_object(0x6060, int(OperationMode.CYCLIC_SYNCHRONOUS_TORQUE))
    for command in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        drive.write_controlword(command.word)
    return drive


def profile_variant(folder: pathlib.Path, base: str, name: str, edits: Mapping[str, str] | None = None,
                    extra: str = "") -> pathlib.Path:
    """``folder/name.toml``: the shipped profile ``base`` with each literal ``old -> new`` of
    ``edits`` applied (each must occur exactly once) and ``extra`` TOML appended."""
    text = resolve_profile(base).read_text()
    for old, new in (edits or {}).items():
        assert text.count(old) == 1, f"{old!r} occurs {text.count(old)} times in {base}"
        text = text.replace(old, new)
    path = folder / f"{name}.toml"
    path.write_text(text + "\n" + extra)
    return path


def late_clock(lateness: Mapping[int, float]) -> type[VirtualClock]:
    """A :class:`VirtualClock` (lock-step, nothing waits) that reports cycle ``k`` as
    ``lateness[k]`` s late (0 for the others): what the supervisor and the live view see."""

    class LateClock(VirtualClock):
        name = "virtual, with injected lateness (test double)"

        def __init__(self, period: float) -> None:
            super().__init__(period)
            self.reported: list[float] = []

        def wait_next(self, cycle: int) -> float:
            late = lateness.get(cycle, 0.0)
            self.reported.append(late)
            return late

        def lateness(self, last: int | None = None) -> np.ndarray:
            values = np.array(self.reported)
            return values if last is None else values[-last:]

    return LateClock


def read_record(folder: pathlib.Path) -> tuple[list[str], dict[str, np.ndarray]]:
    """``record.csv`` of a run folder: its header, and each column as floats (exact: written with ``repr``)."""
    with (folder / "record.csv").open(newline="") as file:
        rows = list(csv.reader(file))
    header, body = rows[0], np.array(rows[1:], dtype=float)
    return header, {name: body[:, i] for i, name in enumerate(header)}


def read_run(folder: pathlib.Path) -> dict[str, Any]:
    """``run.json`` of a run folder."""
    return json.loads((folder / "run.json").read_text())


def events_of(document: Mapping[str, Any], kind: str) -> list[dict[str, Any]]:
    """The run's events of ``kind``."""
    return [event for event in document.get("events", []) if event["kind"] == kind]


def wait_until(condition: Callable[[], bool], timeout: float = 2.0) -> bool:
    """Poll ``condition`` every 10 ms for at most ``timeout`` s; its last value."""
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()
