"""Benchmark 8 (``haptic-bus bench --soak [CYCLES]``): a long virtual-time run on the lock-step bus.

The ``cia402-handle`` profile's controller against the in-process simulated drive
(:func:`haptic_bus.app.rig.simulated_canopen`, lock-step bus), an operator pushing a sinusoid
(2 N + 5 N at 2 Hz: the handle keeps going in and out of the wall), 10^7 cycles with ``--soak``
(a shorter default in every run: :data:`QUICK_CYCLES`, :data:`FULL_CYCLES`), in :data:`SAMPLES`
chunks.  Checked at the end:

* the position's integer sum is exact: the controller's sum of 0x606C counts equals a sum
  taken independently of every input it was given (Python integers), and the position it
  rendered last is ``origin + T * velocity_per_count * sum`` with one rounding; beside it, how
  far a float accumulator ``x += T v`` would have drifted;
* memory is flat: the resident set after each chunk (``/proc/self/statm``) and its least-squares
  slope over the second half of the run (the first chunks touch the controller's record, at
  most a tenth of the run long, and the allocator's pools for the summaries' temporaries);
  flat when that slope, over the whole run, adds at most :data:`FLAT_BYTES`.  A leak of one
  small Python object per cycle is >= 28 bytes a cycle: 280 MB over 10^7 cycles.

Progress: a tick at each tenth of the run, and between ticks the count at least every
:data:`PROGRESS_SECONDS` of wall time (``--soak 1e9`` is hours; ten ticks left an hour between
them): the cycles run in pieces sized from the rate measured so far, each ending at a cycle
boundary, never past the next memory sample; the report is made between pieces, never in a cycle.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from typing import Protocol

import numpy as np

from drives.base import CyclicInputs, Drive, DriveCycle
from haptic_bus.app.profiles import load_profile, one_axis_only
from haptic_bus.control.controller import WallController

PROFILE = "cia402-handle"
CYCLES = 10_000_000  # --soak without a number
QUICK_CYCLES = 50_000  # the soak of every --quick run
FULL_CYCLES = 1_000_000  # the soak of every full run
SAMPLES = 100  # resident-set samples over a run
RECORD_ROWS = 200_000  # the controller's record (haptic-bus run's default), at most a tenth of a shorter run
FLAT_BYTES = 2 * 2**20  # memory is flat if the second half's slope adds at most this over the whole run
OPERATOR = {"model": "sinusoid", "amplitude": 5.0, "frequency": 2.0, "offset": 2.0}
PROGRESS_SECONDS = 10.0  # between ticks, the count reported at least this often (s of wall time)
FIRST_PIECE = 1_000  # cycles run before the rate is known (tens of ms)


class Tick(Protocol):
    """The progress the soak reports: ``label`` shown; ``advance`` False: the bar not advanced (a report
    between its ten ticks)."""

    def __call__(self, label: str, *, advance: bool = True) -> None: ...


def no_progress(label: str, *, advance: bool = True) -> None:
    """A :class:`Tick` that shows nothing."""


def piece_cycles(done: int, seconds: float, left: int) -> int:
    """How many cycles the next piece runs: what takes half of :data:`PROGRESS_SECONDS` at the rate of
    ``done`` cycles in ``seconds`` (:data:`FIRST_PIECE` before any), at least 1 and at most ``left``."""
    planned = int(done / seconds * PROGRESS_SECONDS / 2) if done and seconds > 0 else FIRST_PIECE
    return max(1, min(planned, left))


def observe_inputs(drive: Drive, each: Callable[[CyclicInputs], None]) -> None:
    """From now on every cyclic phase of ``drive`` (:meth:`~drives.base.Drive.cyclic`, where a
    controller reads its inputs) also hands each input it reads to ``each``: a tally taken apart
    from the controller."""
    cyclic = drive.cyclic

    @contextlib.contextmanager
    def observed(torque_limit: int | None = None) -> Iterator[DriveCycle]:
        with cyclic(torque_limit) as cycle:
            read = cycle.read

            def counted() -> CyclicInputs:
                inputs = read()
                each(inputs)
                return inputs
            yield DriveCycle(drive.name, counted, cycle.saturate, cycle.write)  # the phase's checks stay in cycle

    drive.cyclic = observed  # type: ignore[method-assign]


def resident_bytes() -> int:
    """This process's resident set now (bytes)."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def run(cycles: int = CYCLES, tick: Tick = no_progress) -> dict:
    """The soak; returns its section of ``bench.json``; ``tick`` reports its progress (module docstring)."""
    from haptic_bus.app.rig import operator_from_table, simulated_canopen

    profile = one_axis_only(load_profile(PROFILE), "bench")
    chunk = max(1, cycles // SAMPLES)
    with simulated_canopen(profile, operator=operator_from_table(OPERATOR)) as (_, drive):
        controller = WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                                    record_capacity=max(1, min(RECORD_ROWS, cycles // 10)))
        step = controller.integrators[0].step
        tally = {"counts": 0, "float_position": 0.0}  # the float sum from the origin the first cycle sets

        def add(inputs: CyclicInputs) -> None:  # every input the controller gets, summed apart from it
            tally["counts"] += inputs.velocity
            tally["float_position"] += step * inputs.velocity

        observe_inputs(drive, add)
        resident, at, started, done = [resident_bytes()], [0], time.perf_counter(), 0
        reported, tenths = started, 0
        while done < cycles:
            sample = min(len(at) * chunk, cycles)  # the cycle count of the next memory sample
            summary = controller.run(piece_cycles(done, time.perf_counter() - started, sample - done))
            done = controller.cycles
            if done >= sample:
                resident.append(resident_bytes())
                at.append(done)
            now = time.perf_counter()
            if done * 10 // cycles > tenths or now - reported >= PROGRESS_SECONDS:
                tick(f"soak: {done:,} of {cycles:,} cycles", advance=done * 10 // cycles > tenths)
                reported, tenths = now, done * 10 // cycles
            if summary.error:
                break
        seconds = time.perf_counter() - started
    counts = tally["counts"]
    exact_position = controller.integrators[0].origin + step * counts
    last = controller.record.latest() or {}
    half = len(resident) // 2
    second_half = resident[half:]
    slope = float(np.polyfit(at[half:], second_half, 1)[0]) if len(second_half) >= 3 else 0.0  # bytes per cycle
    growth = max(slope, 0.0) * cycles
    return {
        "description": f"{cycles:,} cycles of the {PROFILE} loop in virtual time on the lock-step bus, operator "
                       f"{OPERATOR}",
        "cycles_asked": cycles, "cycles": done, "seconds": seconds, "cycles_per_s": done / seconds if seconds else None,
        "exit_reason": summary.exit_reason, "error": summary.error,
        "integer_sum": {"controller": controller.integrators[0].counts, "independent": counts,
                        "exact": controller.integrators[0].counts == counts,
                        "position_exact": last.get("position_m") == exact_position,
                        "float_accumulator_drift_m": abs(controller.integrators[0].origin + tally["float_position"]
                                                         - exact_position)},
        "memory": {"resident_bytes": resident, "at_cycles": at, "chunk_cycles": chunk,
                   "second_half_spread_bytes": max(second_half) - min(second_half),
                   "slope_bytes_per_cycle": slope, "growth_bytes": growth, "flat_bytes": FLAT_BYTES,
                   "flat": growth <= FLAT_BYTES},
    }
