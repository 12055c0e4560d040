"""The real-time clock's accounting and the real-time session (haptic_bus.app.realtime): what it
sets, that it puts everything back, and that it says what it could not get and why."""

from __future__ import annotations

import gc
import json
import os
import pathlib
import shutil
import struct
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from haptic_bus.app.realtime import FIFO_PRIORITY, GIL_PRIORITY, RealtimeSettings, realtime_session
from haptic_bus.control.clock import RealClock, timer_slack

PERIOD = 2e-3  # s
LINUX = sys.platform.startswith("linux")


def _state() -> tuple:
    return (timer_slack(), sys.getswitchinterval(), gc.isenabled(), gc.get_freeze_count(),
            os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0))


# ----------------------------------------------------------------------------- the clock

def test_lateness_overruns_and_cpu_are_accounted_per_cycle() -> None:
    clock = RealClock(PERIOD, capacity=3)
    assert clock.wait_next(0) == 0.0  # the first cycle defines the schedule: never late
    time.sleep(5 * PERIOD)  # miss cycle 1 by about four periods: an overrun
    late = clock.wait_next(1)
    assert late >= 4 * PERIOD and clock.overruns == 1
    busy = time.process_time()
    while time.process_time() - busy < PERIOD:  # burn CPU inside the cycle
        pass
    clock.wait_next(20)  # far ahead: the clock waits for its deadline
    clock.wait_next(21)  # beyond the capacity: counted (if an overrun) but not kept
    kept = clock.lateness()
    assert kept.size == 3 and kept[1] == late
    # an overrun is a start later than deadline + T, whatever a loaded machine did to cycles 20 and 21
    assert clock.overruns >= int((kept > PERIOD).sum()) >= 1
    wall, cpu = clock.usage()
    # cycle 0 to cycle 20 is 20 periods plus the difference of their lateness, exactly
    assert wall == pytest.approx(20 * PERIOD + kept[2] - kept[0], rel=1e-9)
    assert cpu >= PERIOD  # at least the CPU burnt in the cycle (every thread of the process counts)
    assert clock.usage(1, 1) == (0.0, 0.0)


def test_the_clock_collects_in_the_slack_only_when_the_collector_is_off() -> None:
    clock = RealClock(10 * PERIOD)
    clock.wait_next(0)
    was = gc.isenabled()
    gc.disable()
    try:
        young = [[i] for i in range(5 * gc.get_threshold()[0])]  # the young generation over its threshold
        clock.wait_next(1)  # 20 ms ahead: room for a collection before the deadline
        assert clock.slack_collections == 1 and gc.get_count()[0] < gc.get_threshold()[0]
        del young
    finally:
        if was:
            gc.enable()
    clock.wait_next(2)
    assert clock.slack_collections == 1  # the automatic collector is on again: the clock leaves it alone


# ----------------------------------------------------------------------------- the session

@pytest.mark.skipif(not LINUX, reason="timer slack is Linux only")
def test_the_session_sets_and_restores_slack_switch_interval_and_the_collector() -> None:
    before = _state()
    with realtime_session(RealtimeSettings.unprivileged()) as report:
        assert set(report.got) == {"timer slack", "switch interval", "gc frozen"} and not report.missing
        assert timer_slack() == pytest.approx(1e-9)
        assert sys.getswitchinterval() == pytest.approx(50e-6)
        assert not gc.isenabled() and gc.get_freeze_count() > 0
    assert _state() == before


def test_an_untuned_session_asks_for_nothing() -> None:
    before = _state()
    with realtime_session(RealtimeSettings.untuned()) as report:
        assert report.got == {} and report.missing == {}
        assert _state() == before
    assert "got nothing" in report.summary()


@pytest.mark.skipif(not LINUX, reason="SCHED_FIFO, affinity and mlockall are Linux only here")
def test_the_privileged_items_are_each_got_or_reported_and_all_restored() -> None:
    """With SCHED_FIFO got, the process's other threads run at GIL_PRIORITY (a GIL holder is not
    preempted by ordinary processes) until the session ends, and are put back then."""
    before = _state()
    release = threading.Event()
    other = threading.Thread(target=release.wait, args=(30.0,), name="other")  # bounded: the session ends first
    other.start()
    try:
        assert other.native_id is not None
        other_before = os.sched_getscheduler(other.native_id)
        with realtime_session(RealtimeSettings.insisting()) as report:
            asked = {"timer slack", "switch interval", "gc frozen", "SCHED_FIFO", "CPU affinity", "mlockall",
                     "CPU wake-up latency"}
            assert set(report.got) | set(report.missing) == asked and not set(report.got) & set(report.missing)
            if "CPU wake-up latency" in report.got:  # the kernel's aggregate request, read back: 0 us while held
                assert _cpu_latency_request() == 0 and _holds_latency_request()
            if "SCHED_FIFO" in report.got:
                fifo_resetting = os.SCHED_FIFO | os.SCHED_RESET_ON_FORK  # what they start stays ordinary
                assert os.sched_getscheduler(0) == fifo_resetting and os.sched_getparam(0).sched_priority == FIFO_PRIORITY
                assert os.sched_getscheduler(other.native_id) == fifo_resetting
                assert os.sched_getparam(other.native_id).sched_priority == GIL_PRIORITY
            if "CPU affinity" in report.got:
                assert os.sched_getaffinity(0) == {max(before[-1])}
        assert os.sched_getscheduler(other.native_id) == other_before
        if "CPU wake-up latency" in report.got:  # withdrawn with the session: the aggregate is then the kernel's
            assert not _holds_latency_request()  # default or another process' (a run beside this test asks 0 too)
    finally:
        release.set()
        other.join(30.0)
    assert _state() == before


def _cpu_latency_request() -> int:
    """The CPUs' wake-up latency the kernel's PM QoS grants now, us (reading the file gives the aggregate)."""
    from haptic_bus.app.realtime import CPU_LATENCY

    with open(CPU_LATENCY, "rb") as request:
        return int(struct.unpack("i", request.read(4))[0])


def _holds_latency_request() -> bool:
    """Whether this process holds a PM QoS request open (a file descriptor on the CPU latency device)."""
    from haptic_bus.app.realtime import CPU_LATENCY

    descriptors = pathlib.Path("/proc/self/fd")
    return any(os.path.realpath(fd) == os.path.realpath(CPU_LATENCY) for fd in descriptors.iterdir())


_UNPRIVILEGED = textwrap.dedent("""
    import json, logging, resource, sys
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, format="%(message)s")
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))          # no real-time priority without the capability
    resource.setrlimit(resource.RLIMIT_MEMLOCK, (65536, 65536))  # far less than the interpreter's pages
    from haptic_bus.app.realtime import RealtimeSettings, realtime_session
    with realtime_session(RealtimeSettings.insisting() if sys.argv[1] == "insist" else RealtimeSettings()) as report:
        print(json.dumps(report.to_dict()))
""")


def _unprivileged_command(insist: bool) -> list[str] | None:
    """Python without CAP_SYS_NICE and CAP_IPC_LOCK: as is for an ordinary user; for root, with
    both dropped from the bounding set (root's capabilities after exec) by setpriv."""
    command = [sys.executable, "-c", _UNPRIVILEGED, "insist" if insist else "ask"]
    if os.geteuid() != 0:
        return command
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        return None
    return [setpriv, "--bounding-set", "-sys_nice,-ipc_lock", "--inh-caps", "-sys_nice,-ipc_lock", *command]


@pytest.mark.skipif(not LINUX, reason="SCHED_FIFO and mlockall are Linux only here")
@pytest.mark.parametrize("insist", [False, True], ids=["by default", "--realtime"])
def test_without_privileges_it_says_what_it_could_not_get_and_why(insist: bool) -> None:
    command = _unprivileged_command(insist)
    if command is None:
        pytest.skip("running as root and no setpriv to drop CAP_SYS_NICE/CAP_IPC_LOCK")
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    latency = "CPU wake-up latency"  # root keeps the file's permission without CAP_SYS_NICE; a user has none
    assert set(report["missing"]) - {latency} == {"SCHED_FIFO", "mlockall"} | ({"CPU affinity"} if insist else set())
    assert latency in report["got"] or "/dev/cpu_dma_latency" in report["missing"][latency]
    assert "CAP_SYS_NICE" in report["missing"]["SCHED_FIFO"] and "ulimit -r" in report["missing"]["SCHED_FIFO"]
    assert "RLIMIT_MEMLOCK" in report["missing"]["mlockall"] and "CAP_IPC_LOCK" in report["missing"]["mlockall"]
    assert not insist or "not pinned without SCHED_FIFO" in report["missing"]["CPU affinity"]
    assert {"timer slack", "switch interval", "gc frozen"} <= set(report["got"])  # the run goes on
    warned = "could not get SCHED_FIFO" in done.stderr and "could not get mlockall" in done.stderr
    assert warned == insist  # asked by default, a process that may not have it is not warned at
