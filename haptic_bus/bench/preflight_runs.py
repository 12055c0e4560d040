"""Benchmark 11: pre-flight as a user meets it -- ``haptic-bus run cia402-handle`` in real time against
a fresh ``haptic-bus sim``, again and again (issue 26: 20 of 20 runs pass pre-flight and judge the
wall at 1.5 samples or less, on an idle machine).

Each run starts a simulated drive of its own (:func:`~haptic_bus.bench.processes.canopen_simulator`:
its own udp_multicast group and port, the profile's operator), then the command line as a process
of its own, as a user types it (real time, the default scheduling, ``--no-plots``, a run of
:data:`DURATION` s after pre-flight), and reads pre-flight's verdict from the run's ``run.json``:
whether this machine held ``T`` (else the refusal, naming the period it held), the start
lateness p99 of its 500 cycles (2000 where it looked again), the p99 of the delay each cycle adds (what the judged delay adds to
the gate's: :func:`haptic_bus.app.preflight.delay_added`), and the loop delay the gate judged the wall at.  The count is
20 runs (full), 5 (``--quick``) and 1 (``--smoke``: the path runs).  A run that never reached
pre-flight is one of the count too, with what ended it: its error (a drive error, a crash's last
line on stderr), no exit within :data:`RUN_WAIT` s (killed), or a simulated drive that did not start.
A Ctrl-C keeps the runs that finished as the section (:class:`~haptic_bus.bench.interrupts.SectionInterrupted`).
"""

from __future__ import annotations

import contextlib
import statistics
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from haptic_bus.app.preflight import PREFLIGHT_CYCLES
from haptic_bus.bench.size import Size

PROFILE, NODE_ID = "cia402-handle", 5
DURATION = 0.2  # s of cycles after pre-flight: the run completes, its run.json whole
DELAY_TARGET = 1.5  # samples: the largest loop delay issue 26 lets pre-flight judge at
RUN_WAIT = 120.0  # s: one run's command, its imports and pre-flight included (3-6 s here, three sessions running beside it)


def one_run(bus: dict[str, Any]) -> dict[str, Any]:
    """``haptic-bus run`` of :data:`PROFILE` against the drive on ``bus``: its exit status (None: no exit
    within :data:`RUN_WAIT` s, killed), what ended it, and pre-flight's figures (None where it never ran)."""
    from haptic_bus.app.run_json import read_document
    from haptic_bus.bench.startup import haptic_bus_command

    with tempfile.TemporaryDirectory() as out:
        folder = Path(out) / "run"
        try:
            done = subprocess.run([*haptic_bus_command(), "run", PROFILE, "--interface", bus["interface"], "--channel",
                                   bus["channel"], "--bus-option", f"port={bus['port']}", "--node-id", str(NODE_ID),
                                   "--duration", str(DURATION), "--no-plots", "-q", "--out", str(folder)],
                                  capture_output=True, text=True, timeout=RUN_WAIT, check=False)
            status: int | None = done.returncode
            ending = (done.stderr.strip().splitlines() or [""])[-1]
        except subprocess.TimeoutExpired:
            status, ending = None, f"no exit within {RUN_WAIT:g} s: killed"
        document = read_document(folder)
    preflight = document.get("preflight") or {}
    return {"exit": status, "exit_reason": document.get("exit_reason") or (None if status is not None else "timed out"),
            "error": document.get("error") or ending,
            "held": bool(preflight.get("holdable")), "judged_delay": preflight.get("observed_delay"),
            "lateness_p99_s": (preflight.get("lateness") or {}).get("p99"),
            "delay_added_p99_s": preflight.get("delay_added_p99"), "reason": preflight.get("reason"),
            "cycles": preflight.get("cycles")}


def fresh_run() -> dict[str, Any]:
    """:func:`one_run` against a simulated drive of its own; a simulator that does not start is the run's outcome."""
    from haptic_bus.bench.processes import canopen_simulator

    with contextlib.ExitStack() as stack:
        try:
            bus, _ = stack.enter_context(canopen_simulator(PROFILE, (NODE_ID,)))
        except RuntimeError as error:  # no heartbeat, or it exited: no run was started
            return {"exit": None, "exit_reason": "no simulator", "error": f"the simulated drive did not start: {error}",
                    "held": False, "judged_delay": None, "lateness_p99_s": None, "delay_added_p99_s": None,
                    "reason": None, "cycles": None}
        return one_run(bus)


def reached(entry: dict[str, Any]) -> bool:
    """Whether a run reached pre-flight's verdict (held ``T`` or refused it)."""
    return entry.get("held", False) or entry.get("reason") is not None


def within(entry: dict[str, Any]) -> bool:
    """Whether a run passed pre-flight, judged the wall at :data:`DELAY_TARGET` samples or less, and ended 0."""
    delay = entry.get("judged_delay")
    return entry.get("exit") == 0 and entry.get("held", False) and delay is not None and delay <= DELAY_TARGET


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 11; returns its section of ``bench.json``."""
    count = size.pick(1, 5, 20)
    runs: list[dict[str, Any]] = []
    try:
        for k in range(count):
            runs.append(fresh_run())
            tick(f"pre-flight: run {k + 1} of {count}")
    except KeyboardInterrupt:  # Ctrl-C: the runs that finished are the section
        if not runs:
            raise
        from haptic_bus.bench.interrupts import SectionInterrupted

        raise SectionInterrupted(section(runs, count)) from None
    return section(runs, count)


def section(runs: list[dict[str, Any]], planned: int) -> dict:
    """Section 11 of ``bench.json`` for ``runs`` of the ``planned`` (fewer: interrupted by Ctrl-C)."""
    delays = [r["judged_delay"] for r in runs if r["held"] and r["judged_delay"] is not None]
    count = len(runs)
    done = (f"{count} run{'' if count == 1 else 's'}" if count == planned else
            f"{count} of {planned} runs (interrupted: Ctrl-C)")
    return {
        "description": f"haptic-bus run {PROFILE} (real time, {DURATION:g} s after pre-flight) against a fresh "
                       f"haptic-bus sim each time: {done}, one after another",
        "count": count, "planned": planned, "interrupted": count < planned, "runs": runs, "delay_target": DELAY_TARGET,
        "held": sum(r["held"] for r in runs), "within": sum(within(r) for r in runs),
        "looked_again": sum((r.get("cycles") or 0) > PREFLIGHT_CYCLES for r in runs),  # the second look's (preflight)
        "refused": sum(reached(r) and not r["held"] for r in runs), "not_reached": sum(not reached(r) for r in runs),
        "judged_delay": ({"median": statistics.median(delays), "min": min(delays), "max": max(delays)}
                         if delays else None),
    }
