"""Benchmark of the Modbus cycle over loopback TCP in virtual time (a helper, not a test).

    python -m haptic_bus.bench.modbus_poll [--cycles N] [--url tcp://HOST:PORT] [--mode split|fc23|both]

Without ``--url`` it starts the simulated drive as a subprocess
(``python -m sim_drive --modbus tcp://127.0.0.1:0 --timing ideal``), reads the bound port from
its log line, and stops it with SIGTERM afterwards.  For each cycle mode it connects a
:class:`~drives.modbus.drive.ModbusDrive`, enables it, and runs ``N`` closed-loop cycles of a
wall law (K = 200 N/m, B = 100 N s/m) as fast as the link allows, reporting cycles/s, requests
per cycle and the round-trip percentiles of :func:`drives.modbus.timing.measure_poll`-style
timing.  Target: >= 2000 cycles/s.
"""

from __future__ import annotations

import argparse
import re
import signal
import subprocess
import sys
import time
from collections.abc import Sequence

from drives.modbus.drive import CYCLE_MODES, ModbusDrive
from drives.modbus.timing import PollTiming, time_cycles
from haptic_bus.app.rig import simulator_command

_BOUND = re.compile(r"serving Modbus TCP on (tcp://\S+)")


def start_simulator(timing: str = "ideal", timeout: float = 10.0, profile: str | None = None) -> tuple[subprocess.Popen, str]:
    """Start ``python -m sim_drive --modbus tcp://127.0.0.1:0`` (the device of ``profile``, if given);
    return the process and its URL."""
    process = subprocess.Popen(
        simulator_command("--modbus", "tcp://127.0.0.1:0", "--timing", timing, *(("--profile", profile) if profile else ())),
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
    )
    deadline = time.monotonic() + timeout
    lines: list[str] = []
    while time.monotonic() < deadline and process.stderr is not None:
        line = process.stderr.readline()
        if not line:
            break
        lines.append(line)
        match = _BOUND.search(line)
        if match:
            return process, match.group(1)
    process.kill()
    process.wait(5)
    raise RuntimeError("the simulator did not report its port:\n" + "".join(lines))


def stop_simulator(process: subprocess.Popen, timeout: float = 10.0) -> int:
    """SIGTERM, wait; the exit status."""
    process.send_signal(signal.SIGTERM)
    try:
        return process.wait(timeout)
    finally:
        if process.stderr is not None:
            process.stderr.close()


def bench_cycle(url: str, cycle: str, cycles: int, *, time_limit: float = 30.0) -> PollTiming:
    """``cycles`` wall-law cycles over ``url`` with ``cycle`` mode; the timing of each cycle."""
    K, B, T = 200.0, 100.0, 1e-3
    drive = ModbusDrive.from_url(url, cycle=cycle)
    with drive:
        drive.connect()
        drive.enable()
        scaling = drive.scaling
        per_count = scaling.velocity_per_count
        read, write, torque_of = drive.read_inputs, drive.write_outputs, scaling.torque_permille
        x = 0.0

        def wall_cycle() -> None:
            nonlocal x
            v = read().velocity * per_count
            x += T * v
            write(torque_of(-(K * x + B * v)) if x > 0 else 0)

        timing = time_cycles(drive, wall_cycle, cycles, time_limit)
        drive.disable()
    return timing


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark; print one line per cycle mode."""
    parser = argparse.ArgumentParser(prog="python -m haptic_bus.bench.modbus_poll", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--url", help="an already running server (default: start the simulator)")
    parser.add_argument("--mode", choices=[*CYCLE_MODES, "both"], default="both")
    args = parser.parse_args(argv)
    process = None
    url = args.url
    if url is None:
        process, url = start_simulator()
    try:
        modes = CYCLE_MODES if args.mode == "both" else (args.mode,)
        for mode in modes:
            result = bench_cycle(url, mode, args.cycles)
            print(result.summary(), flush=True)
    finally:
        if process is not None:
            status = stop_simulator(process)
            print(f"simulator stopped with exit status {status}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
