"""Benchmark 11: pre-flight as a user meets it -- ``haptic-bus run cia402-handle`` in real time against
a fresh ``haptic-bus sim``, again and again (issue 26: 20 of 20 runs pass pre-flight and judge the
wall at 1.5 samples or less, on an idle machine).

Each run starts a simulated drive of its own (:func:`~haptic_bus.bench.processes.canopen_simulator`:
its own udp_multicast group and port, the profile's operator), then the command line as a process
of its own, as a user types it (real time, the default scheduling, ``--no-plots``, a run of
:data:`DURATION` s after pre-flight), and reads pre-flight's verdict from the run's ``run.json``:
whether this machine held ``T`` (else the refusal, naming the period it held), the start
lateness p99 of its 500 cycles, and the loop delay the gate judged the wall at.  The count is
20 runs (full), 5 (``--quick``) and 1 (``--smoke``: the path runs).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from haptic_bus.bench.size import Size

PROFILE, NODE_ID = "cia402-handle", 5
DURATION = 0.2  # s of cycles after pre-flight: the run completes, its run.json whole
DELAY_TARGET = 1.5  # samples: the largest loop delay issue 26 lets pre-flight judge at
RUN_WAIT = 120.0  # s: one run's command, its imports and pre-flight included (3-6 s here, three sessions running beside it)


def one_run(bus: dict[str, Any]) -> dict[str, Any]:
    """``haptic-bus run`` of :data:`PROFILE` against the drive on ``bus``: its exit status and pre-flight's figures."""
    from haptic_bus.bench.startup import haptic_bus_command

    with tempfile.TemporaryDirectory() as out:
        folder = Path(out) / "run"
        done = subprocess.run([*haptic_bus_command(), "run", PROFILE, "--interface", bus["interface"], "--channel",
                               bus["channel"], "--bus-option", f"port={bus['port']}", "--node-id", str(NODE_ID),
                               "--duration", str(DURATION), "--no-plots", "-q", "--out", str(folder)],
                              capture_output=True, text=True, timeout=RUN_WAIT, check=False)
        document = json.loads((folder / "run.json").read_text()) if (folder / "run.json").exists() else {}
    preflight = document.get("preflight") or {}
    return {"exit": done.returncode, "exit_reason": document.get("exit_reason"),
            "error": document.get("error") or (done.stderr.strip().splitlines() or [""])[-1],
            "held": bool(preflight.get("holdable")), "judged_delay": preflight.get("observed_delay"),
            "lateness_p99_s": (preflight.get("lateness") or {}).get("p99"), "reason": preflight.get("reason")}


def within(entry: dict[str, Any]) -> bool:
    """Whether a run passed pre-flight, judged the wall at :data:`DELAY_TARGET` samples or less, and ended 0."""
    delay = entry.get("judged_delay")
    return entry.get("exit") == 0 and entry.get("held", False) and delay is not None and delay <= DELAY_TARGET


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 11; returns its section of ``bench.json``."""
    from haptic_bus.bench.processes import canopen_simulator

    count = size.pick(1, 5, 20)
    runs: list[dict[str, Any]] = []
    for k in range(count):
        with canopen_simulator(PROFILE, (NODE_ID,)) as (bus, _):
            runs.append(one_run(bus))
        tick(f"pre-flight: run {k + 1} of {count}")
    delays = [r["judged_delay"] for r in runs if r["held"] and r["judged_delay"] is not None]
    return {
        "description": f"haptic-bus run {PROFILE} (real time, {DURATION:g} s after pre-flight) against a fresh "
                       f"haptic-bus sim each time: {count} run{'' if count == 1 else 's'}, one after another",
        "count": count, "runs": runs, "delay_target": DELAY_TARGET,
        "held": sum(r["held"] for r in runs), "within": sum(within(r) for r in runs),
        "judged_delay": ({"median": statistics.median(delays), "min": min(delays), "max": max(delays)}
                         if delays else None),
    }
