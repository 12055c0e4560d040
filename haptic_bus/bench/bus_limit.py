"""Benchmark 5: the CAN bus against its physical limit (worst-case bit-time model).

Bits per cycle come from :mod:`haptic_bus.analysis.can_timing` (``55 + 10 n`` bit times for a standard
frame with ``n`` data bytes, worst-case stuffing and inter-frame space included); objects are
packed into frames by the master's own :func:`drives.canopen.drive.split_into_frames`.

* **minimal mapping** (what the controller configures): TPDO = statusword 0x6041 + velocity
  actual 0x606C (6 bytes), RPDO = controlword 0x6040 + target torque 0x6071 (4 bytes);
* **naive full mapping** (everything a CST drive commonly maps "just in case"): TPDOs =
  statusword 0x6041, position actual 0x6064, torque actual 0x6077, velocity actual 0x606C,
  modes display 0x6061, error code 0x603F (15 bytes, 2 frames); RPDOs = controlword 0x6040,
  target torque 0x6071, modes of operation 0x6060, max torque 0x6072 (7 bytes, 1 frame).

One SYNC (0 bytes) per cycle serves every axis.  An axis fits when the cycle's bits stay under
``LOAD_CEILING`` of the bus's capacity in one period.  Latency per cycle: the cycle's frames
sent back to back (no arbitration losses, no processing time).  A short in-process run with
:class:`sim_drive.bus_timing.BusLoadMeter` attached to the simulated drive checks the model's
bookkeeping against the frames actually exchanged.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from drives.canopen.drive import split_into_frames
from drives.cia402 import (
    CONTROLWORD,
    ERROR_CODE,
    MAX_TORQUE,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL,
    STATUSWORD,
    TARGET_TORQUE,
    TORQUE_ACTUAL,
    VELOCITY_ACTUAL,
    ObjectSpec,
)
from haptic_bus.analysis.can_timing import LOAD_CEILING, axes_that_fit, cycle_bits, frame_bits
from haptic_bus.app.rig import BusLoadMeter
from haptic_bus.bench.size import Size

BITRATES = (125_000, 500_000, 1_000_000)
PERIOD = 1e-3
MAPPINGS: dict[str, dict[str, tuple[ObjectSpec, ...]]] = {
    "minimal": {"tpdo": (STATUSWORD, VELOCITY_ACTUAL), "rpdo": (CONTROLWORD, TARGET_TORQUE)},
    "naive_full": {"tpdo": (STATUSWORD, POSITION_ACTUAL, TORQUE_ACTUAL, VELOCITY_ACTUAL, MODES_OF_OPERATION_DISPLAY,
                            ERROR_CODE),
                   "rpdo": (CONTROLWORD, TARGET_TORQUE, MODES_OF_OPERATION, MAX_TORQUE)},
}


def _frame_bytes(objects: Sequence[ObjectSpec]) -> list[int]:
    return [sum(spec.data_type.size for spec in frame) for frame in split_into_frames(objects)]


def mapping_budget(name: str) -> dict[str, Any]:
    """Frames, bytes and worst-case bits per axis per cycle of one mapping."""
    mapping = MAPPINGS[name]
    tpdo, rpdo = _frame_bytes(mapping["tpdo"]), _frame_bytes(mapping["rpdo"])
    per_axis = cycle_bits(tpdo + rpdo)
    return {
        "tpdo_objects": [f"0x{s.index:04X} {s.name}" for s in mapping["tpdo"]],
        "rpdo_objects": [f"0x{s.index:04X} {s.name}" for s in mapping["rpdo"]],
        "tpdo_frame_bytes": tpdo, "rpdo_frame_bytes": rpdo,
        "bits_per_axis": per_axis, "sync_bits": frame_bits(0),
        "bits_one_axis_cycle": frame_bits(0) + per_axis,
    }


def measured_bits_per_cycle(tpdo_objects: Sequence[ObjectSpec], cycles: int = 200) -> float:
    """Median bits per SYNC cycle the BusLoadMeter counts on the lock-step bus (in-process run)."""
    from drives.canopen.drive import CanopenDrive
    from drives.safety import SafetySettings
    from haptic_bus.app.rig import CanopenSimDrive, eds_path
    from haptic_bus.bench.hot_path import bench_closed_loop

    channel = f"bench-bus-{uuid.uuid4().hex[:12]}"
    meter = BusLoadMeter(1_000_000, PERIOD)
    sim = CanopenSimDrive({"interface": "lockstep", "channel": channel}, 5, bus_meter=meter).start()
    drive = CanopenDrive(5, interface="lockstep", channel=channel, period=PERIOD, tpdo_objects=tpdo_objects, eds=eds_path(),
                         safety=SafetySettings().for_virtual_time(PERIOD))
    try:
        drive.connect()
        drive.enable()
        first = len(meter.cycle_bit_counts)
        bench_closed_loop(drive, cycles)
        counts = meter.cycle_bit_counts[first + 2:]
    finally:
        drive.close()
        sim.stop()
    return float(np.median(counts))


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 5; returns its section of ``bench.json``."""
    mappings = {name: mapping_budget(name) for name in MAPPINGS}
    table = []
    for bitrate in BITRATES:
        row: dict[str, Any] = {"bitrate": bitrate}
        for name, budget in mappings.items():
            one = budget["bits_one_axis_cycle"]
            row[name] = {
                "load_one_axis": one / (bitrate * PERIOD),
                "axes_fit": axes_that_fit(budget["bits_per_axis"], bitrate, PERIOD),
                "latency_one_axis_s": one / bitrate,
                "min_period_one_axis_s": one / (LOAD_CEILING * bitrate),
            }
        table.append(row)
    tick("bus: model")
    measured: dict[str, Any] = {}
    try:
        from drives.canopen.drive import DEFAULT_TPDO, DEFAULT_TPDO_WITH_POSITION

        for label, objects in (("minimal (0x6041 + 0x606C)", DEFAULT_TPDO),
                               ("with position (0x6041 + 0x606C + 0x6064)", DEFAULT_TPDO_WITH_POSITION)):
            tpdo = _frame_bytes(objects)
            measured[label] = {"model_bits": frame_bits(0) + cycle_bits(tpdo + _frame_bytes(MAPPINGS["minimal"]["rpdo"])),
                               "meter_bits_median": measured_bits_per_cycle(objects, size.pick(20, 100, 1000))}
    except Exception as exc:
        measured = {"available": False, "reason": f"{type(exc).__name__}: {exc}"}
    tick("bus: measured")
    ratio = mappings["naive_full"]["bits_per_axis"] / mappings["minimal"]["bits_per_axis"]
    return {
        "description": "worst-case bits per cycle per axis (55 + 10 n per frame), bus load at T = 1 ms and axes that "
                       f"fit under a {LOAD_CEILING:.0%} load ceiling",
        "period_s": PERIOD, "load_ceiling": LOAD_CEILING,
        "mappings": mappings, "bitrates": table,
        "naive_over_minimal_bits": ratio,
        "measured_on_lockstep_bus": measured,
    }
