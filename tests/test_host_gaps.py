"""The bench's host gap probes (haptic_bus.bench.host_gaps) never outlive the code that started them, and a
Ctrl-C reaches that code alone: each probe spins at SCHED_FIFO on its CPU, so one left behind takes the CPU
from everything else for the rest of its seconds.

Each test starts a caller of ``host_gaps(60.0)`` restricted to one CPU (one probe, spinning until it is
killed: under a second of one CPU here), interrupts it once its probe exists, and looks at the probe once
the caller has ended.  The figures themselves: tests/test_bench.py (smoke run)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from haptic_bus.bench.interrupts import sigint_after

REPO = Path(__file__).resolve().parents[1]
WAIT = 30.0  # s: bound of every wait here (the caller runs only in the probe's rests, 0.1 s in 0.6 s, if it shares the CPU)
CALLER = """
import os, sys
os.sched_setaffinity(0, {%d})
from haptic_bus.bench.host_gaps import host_gaps
try:
    host_gaps(60.0)
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)
"""


def _caller() -> subprocess.Popen[str]:
    cpu = max(os.sched_getaffinity(0))
    return subprocess.Popen([sys.executable, "-c", CALLER % cpu], cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)},
                            stderr=subprocess.PIPE, text=True, process_group=0)


def _catches_sigint(pid: int) -> bool:
    """Whether Python runs in process ``pid`` with its SIGINT handler (a SIGINT there is a KeyboardInterrupt)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    caught = next(int(line.split()[1], 16) for line in status.splitlines() if line.startswith("SigCgt:"))
    return bool(caught >> (signal.SIGINT - 1) & 1)


def _probe_of(caller: subprocess.Popen[str]) -> int:
    """The pid of ``caller``'s probe, once Python runs in it (before, a SIGINT ends it silently)."""
    deadline = time.monotonic() + WAIT
    while time.monotonic() < deadline:
        assert caller.poll() is None, f"the caller ended first: {caller.stderr.read() if caller.stderr else ''}"
        children = Path(f"/proc/{caller.pid}/task/{caller.pid}/children").read_text().split()
        if children and _catches_sigint(int(children[0])):
            return int(children[0])
        time.sleep(0.02)
    raise AssertionError(f"no probe started within {WAIT} s")


def _running(pid: int) -> bool:
    """Whether process ``pid`` still runs (neither gone nor a zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _end(caller: subprocess.Popen[str], probe: int, how: int) -> tuple[int, str]:
    """Send SIGINT to the caller (``how`` 0) or to its process group (a terminal's Ctrl-C, ``how`` 1); the
    caller's status and stderr, and whether the probe still runs after it ended (killed then, by pid)."""
    try:
        if how:
            os.killpg(caller.pid, signal.SIGINT)
        else:
            os.kill(caller.pid, signal.SIGINT)
        _, err = caller.communicate(timeout=WAIT)
        left = _running(probe)
    finally:
        if caller.poll() is None:
            caller.kill()
            caller.wait(WAIT)
        if _running(probe):
            os.kill(probe, signal.SIGKILL)
    assert not left, "the probe outlived its caller"
    return caller.returncode, err


def test_a_probe_does_not_outlive_an_interrupted_caller() -> None:
    """SIGINT to the caller alone (the bench's own Ctrl-C handling, or ``kill -INT``): it stops its probe
    before it ends (the probe ran on, orphaned, at SCHED_FIFO, and printed into a closed pipe)."""
    caller = _caller()
    status, err = _end(caller, _probe_of(caller), 0)
    assert (status, err) == (130, "interrupted\n")


def test_a_ctrl_c_reaches_the_caller_alone() -> None:
    """A terminal's Ctrl-C (SIGINT to the foreground process group): one line from the caller, no
    probe's traceback (each probe died of it with one)."""
    caller = _caller()
    status, err = _end(caller, _probe_of(caller), 1)
    assert (status, err) == (130, "interrupted\n")


def test_a_probe_dies_with_a_killed_caller() -> None:
    """SIGKILL to the caller (no finally runs): the kernel ends the probe (PR_SET_PDEATHSIG), or the probe
    ends itself (its parent gone before it asked)."""
    caller = _caller()
    probe = _probe_of(caller)
    try:
        caller.kill()  # whenever: a probe that asks for PR_SET_PDEATHSIG after this sees its parent gone and exits
        caller.communicate(timeout=WAIT)
        deadline = time.monotonic() + WAIT
        while _running(probe) and time.monotonic() < deadline:  # the kernel's SIGKILL: at once
            time.sleep(0.02)
        left = _running(probe)
    finally:
        if _running(probe):
            os.kill(probe, signal.SIGKILL)
    assert not left, "the probe outlived its killed caller"


def _gaps(policy: str) -> list[dict]:
    """Two CPUs' figures as the probes print them, at ``policy``."""
    return [{"cpu": cpu, "policy": policy, "seconds": 1.0, "gaps": 3, "gaps_over_1ms": 1, "lost_s": 4e-3,
             "longest_s": 2e-3} for cpu in (0, 1)]


@pytest.mark.parametrize("fifo", [True, False])
def test_the_report_calls_gaps_the_machines_own_only_at_sched_fifo(fifo: bool) -> None:
    """Not granted SCHED_FIFO (no CAP_SYS_NICE, RLIMIT_RTPRIO below 80), a probe takes turns with every
    process of its CPU (gaps of 99 ms measured so): issue 26's lateness rows and the section's paragraph
    called them the machine's own, "which no process here avoids"."""
    from haptic_bus.bench.report import host_gaps_paragraph
    from haptic_bus.bench.targets import issue_26

    gaps = _gaps("SCHED_FIFO 80" if fifo else "SCHED_OTHER (SCHED_FIFO not granted)")
    figures = {"core_ratio_target": 1.5, "lateness_ratio_target": 2.0, "overrun_target": 0.005, "delay_target": 1.5,
               "quiet": {"lateness_p99_ratio": 1.2, "floor_lateness_p99_ratio": 1.1}}
    rows = issue_26({"realtime": {"host_gaps": gaps, "issue_26": figures}})
    (note,) = [r["note"] for r in rows if r["what"] == "start lateness p99 / the bare clock's, quiet"]
    assert note.startswith("python-can's floor on the same cycle: 1.1 x; ")
    assert note.endswith(" > 1 ms a second, per CPU: 1, 1 (longest 2 ms)")
    assert ("the machine's gaps" in note) == fifo and ("not granted SCHED_FIFO" in note) != fifo
    paragraph = host_gaps_paragraph(gaps)
    assert ("which no process here avoids" in paragraph) == fifo and ("not the machine's own" in paragraph) != fifo
    assert "CPU 0: 3 in 1 s, 1 over 1 ms" in paragraph and "CPU 1: 3 in 1 s" in paragraph and gaps[0]["policy"] in paragraph


def test_gaps_that_could_not_be_measured_leave_the_lateness_rows_their_floor() -> None:
    """A probe that failed (the section keeps why, a str, and runs on): the rows say the floor's figure and
    nothing of gaps."""
    from haptic_bus.bench.targets import issue_26

    figures = {"core_ratio_target": 1.5, "lateness_ratio_target": 2.0, "overrun_target": 0.005, "delay_target": 1.5,
               "quiet": {"lateness_p99_ratio": 1.2, "floor_lateness_p99_ratio": 1.1}}
    rows = issue_26({"realtime": {"host_gaps": "RuntimeError: the host gap probe ended with status 1",
                                  "issue_26": figures}})
    (note,) = [r["note"] for r in rows if r["what"] == "start lateness p99 / the bare clock's, quiet"]
    assert note == "python-can's floor on the same cycle: 1.1 x"


def _most_spun(burst: float, rest: float, period: float) -> float:
    """The most time a spin of ``burst`` s on, ``rest`` s off spends on in any window of ``period`` s (the
    window's start taken at every point where the on-time can peak: a burst's start, or the window's end
    at a burst's end, over two cycles; the pattern repeats)."""
    cycle = burst + rest

    def spun(start: float) -> float:
        first = int(start // cycle) - 1
        return sum(max(0.0, min(start + period, k * cycle + burst) - max(start, k * cycle))
                   for k in range(first, first + int(period // cycle) + 3))

    starts = [k * cycle + shift for k in range(2) for shift in (0.0, burst - period % cycle, burst)]
    return max(spun(start) for start in starts)


@pytest.mark.parametrize(("runtime_us", "period_us"), [(950_000, 1_000_000), (800_000, 1_000_000), (500_000, 1_000_000),
                                                       (100_000, 1_000_000), (95_000, 100_000), (475_000, 500_000),
                                                       (999_999, 1_000_000)])
def test_the_probe_spins_below_the_kernels_real_time_limit(runtime_us: int, period_us: int) -> None:
    """The kernel lets real-time threads run ``sched_rt_runtime_us`` of every ``sched_rt_period_us`` and
    stops them for the rest of the period (a throttled spin's gap, 49 ms here, would be counted as the
    machine's): the probe's bursts and rests keep it below whatever the limit is, not the default alone
    (0.5 s on, 0.1 s off is 0.9 s of a second: throttled under 500000 us or a period of 0.5 s)."""
    from haptic_bus.bench.host_gaps import BURST, REST, schedule

    burst, rest = schedule(runtime_us, period_us)
    assert 0 < burst <= BURST and rest > 0
    assert _most_spun(burst, rest, period_us * 1e-6) < runtime_us * 1e-6
    if (runtime_us, period_us) == (950_000, 1_000_000):  # the kernel's default: the schedule measured here
        assert (burst, rest) == (BURST, REST)


@pytest.mark.parametrize("limit", [(-1, 1_000_000), (1_000_000, 1_000_000)])
def test_without_a_limit_the_probe_still_rests(limit: tuple[int, int]) -> None:
    from haptic_bus.bench.host_gaps import BURST, REST, schedule

    assert schedule(*limit) == (BURST, REST)


def test_a_ctrl_c_while_a_child_is_started_acts_once_it_is_in_the_list() -> None:
    """The window the test above can hit only by chance: a SIGINT inside ``Popen`` (or before the append)
    raised KeyboardInterrupt there, and the child it had started was in no list a ``finally`` stops.  Inside
    :func:`sigint_after` the signal waits; at its end it acts through the handler that was there."""
    children: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        with sigint_after():
            signal.raise_signal(signal.SIGINT)  # the Ctrl-C, in the middle of the start
            children.append("started")
    assert children == ["started"]
    with sigint_after():  # none came: nothing acts after it
        children.append("again")
    assert children == ["started", "again"] and signal.getsignal(signal.SIGINT) is signal.default_int_handler
