"""The machine's own preemption: how often, and for how long, a thread that never yields loses its CPU.

On a virtual machine the host runs other work on the physical CPUs behind the guest's virtual ones;
a guest thread then stops for as long as its virtual CPU is not run, whatever its priority (steal
time), and the guest's own interrupts take it for a few microseconds.  Nothing a guest process does
avoids these gaps, so they bound what any real-time loop here can show.  A run's cycle meets the gaps
of two CPUs (its own, and the simulated drive's, which must answer the SYNC), the bare clock only
those of its own: measured here (2-CPU Firecracker guest, idle, both CPUs in polling idle) a SYNC's
wake-up of the drive's thread took 2.1 ms once in 10 s, its CPU not run by the host meanwhile.

It runs as ``python -m haptic_bus.bench.host_gaps CPU SECONDS [PARENT]`` (:func:`host_gaps` starts one per
CPU, all at once): the process pins itself to ``CPU``, asks for ``SCHED_FIFO`` at the control thread's
priority (where the OS grants it; ordinary otherwise, said in its figures), spins on
``time.perf_counter_ns`` for ``SECONDS`` in all and prints one JSON object: the gaps between two
readings longer than :data:`GAP`, their count, their sum and the longest (s).  It spins in bursts of
:data:`BURST` with :data:`REST` between them (not watched): the kernel runs real-time threads at most
0.95 s of every second (``sched_rt_runtime_us``), and a spin longer than that was stopped for the
rest of the second (gaps of 26 and 46 ms, the kernel's, not the host's); under another limit
the bursts and rests are the kernel's own (:func:`schedule`).  The module imports the standard
library only; a probe still starts in about 0.14 s here, half of it the ``haptic_bus.bench``
package's own imports, and each spins its own ``SECONDS`` from its start.

A probe never outlives the bench, whose CPUs it takes: :func:`host_gaps` kills and reaps every
probe still running when it ends in any way (Ctrl-C, an error, a timeout), and a probe asks the kernel
to kill it when the thread that started it ends (``PR_SET_PDEATHSIG``, as the bench's CPU hogs do), so
a killed bench leaves none behind either.  A probe has a process group of its own: the Ctrl-C the
terminal sends the bench's group reaches the bench alone, which stops its probes and ends with its
one line (a probe in the bench's group died with a traceback each, or printed one into a closed pipe).
"""

from __future__ import annotations

import ctypes
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from haptic_bus.bench.interrupts import sigint_after

GAP = 50e-6  # s: a pause of the spin longer than this is a gap (a reading takes ~0.1 us; a timer tick a few us)
LONG_GAP = 1e-3  # s: a gap as long as a period at T = 1 ms, counted apart
BURST = 0.5  # s: one spin, watched, at most
REST = 0.1  # s: between two bursts, at least (a burst and a rest fit below the kernel's 0.95 s of real-time threads a second)
RT_LIMIT = ("/proc/sys/kernel/sched_rt_runtime_us", "/proc/sys/kernel/sched_rt_period_us")  # the kernel's real-time limit
FIFO_PRIORITY = 80  # haptic_bus.app.realtime.FIFO_PRIORITY (not imported: the probe loads the standard library only)


def schedule(runtime_us: int, period_us: int) -> tuple[float, float]:
    """A burst and the rest after it (s) that keep a spin below the kernel's real-time limit, ``runtime_us``
    of real-time threads in every ``period_us`` (``sched_rt_runtime_us``, -1: none).  A burst and its
    rest fit in one period, so any window of a period holds a rest's length of rest at least; a rest of
    1.2 times the period's share left to other threads then keeps the spin below the limit.  950000 in
    1000000 (the kernel's default) gives :data:`BURST` and :data:`REST`, fixed before, which a runtime of
    0.5 s a second (or a period under 0.6 s) throttled."""
    if runtime_us < 0 or runtime_us >= period_us:  # no limit: rests for the other threads all the same
        return BURST, REST
    period, runtime = period_us * 1e-6, runtime_us * 1e-6
    rest = max(min(REST, period / 10), 1.2 * (period - runtime))
    if period - rest <= 0:  # a runtime under a sixth of the period: one short burst a period
        return runtime / 2, period
    return min(BURST, period - rest), rest


def _rt_limit() -> tuple[int, int]:
    """The kernel's real-time limit (``runtime_us``, ``period_us``); its default where it cannot be read."""
    try:
        runtime, period = (int(Path(path).read_text()) for path in RT_LIMIT)
    except (OSError, ValueError):
        return 950_000, 1_000_000
    return runtime, period


def spin(cpu: int, seconds: float) -> dict[str, Any]:
    """Spin on ``cpu`` for ``seconds`` s; the gaps seen (module docstring)."""
    os.sched_setaffinity(0, {cpu})
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
        policy = f"SCHED_FIFO {FIFO_PRIORITY}"
    except (PermissionError, AttributeError):
        policy = "SCHED_OTHER (SCHED_FIFO not granted)"
    burst, rest = schedule(*_rt_limit())
    gap_ns, long_ns = round(GAP * 1e9), round(LONG_GAP * 1e9)
    gaps = long = lost = longest = watched = 0
    clock = time.perf_counter_ns
    left = round(seconds * 1e9)
    while left > 0:
        previous = start = clock()
        end = start + min(left, round(burst * 1e9))
        while previous < end:
            now = clock()
            step = now - previous
            if step > gap_ns:
                gaps += 1
                long += step > long_ns
                lost += step
                longest = max(longest, step)
            previous = now
        watched += previous - start
        left -= previous - start
        if left > 0:
            time.sleep(rest)
    return {"cpu": cpu, "policy": policy, "seconds": watched * 1e-9, "gaps": gaps, "gaps_over_1ms": long,
            "lost_s": lost * 1e-9, "longest_s": longest * 1e-9}


def unprivileged(figures: list[dict[str, Any]]) -> bool:
    """Whether a probe of ``figures`` spun without ``SCHED_FIFO``: then every process of its CPU took
    turns with it, and its gaps are theirs as much as the machine's."""
    return any(not g["policy"].startswith("SCHED_FIFO") for g in figures)


def host_gaps(seconds: float) -> list[dict[str, Any]]:
    """One spinning process per CPU this process may run on, all at once for ``seconds`` s; each one's figures."""
    cpus = sorted(os.sched_getaffinity(0))
    probes: list[subprocess.Popen[str]] = []
    try:
        for cpu in cpus:
            with sigint_after():  # a probe started is one the finally knows of
                probes.append(subprocess.Popen([sys.executable, "-m", __name__, str(cpu), repr(seconds),
                                                str(os.getpid())], stdout=subprocess.PIPE, text=True, process_group=0))
        figures = []
        for probe in probes:
            out, _ = probe.communicate(timeout=seconds + 60.0)
            if probe.returncode != 0:
                raise RuntimeError(f"the host gap probe ended with status {probe.returncode}")
            figures.append(json.loads(out))
        return figures
    finally:  # none outlives this call (module docstring)
        for probe in probes:
            if probe.poll() is None:
                probe.kill()
        for probe in probes:
            probe.wait()  # SIGKILL: at once, whatever its priority
            if probe.stdout is not None:
                probe.stdout.close()


def _bound_to(parent: int) -> None:
    """Die with the thread that started this probe (module docstring); exit at once if ``parent`` is
    already gone."""
    ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # 1 = PR_SET_PDEATHSIG
    if os.getppid() != parent:  # it ended before the prctl: nobody reads the figures
        sys.exit(1)


if __name__ == "__main__":
    if len(sys.argv) > 3:  # started by host_gaps
        _bound_to(int(sys.argv[3]))
    print(json.dumps(spin(int(sys.argv[1]), float(sys.argv[2]))))
