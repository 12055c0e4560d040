"""What a real-time run asks of the OS for its control thread, and what it got.

:func:`realtime_session` is one context manager around the cyclic phase of a run (entered
after set-up, in the control thread, so threads started before it keep their own settings):

always asked (``haptic-bus run`` in real time)
    the thread's timer slack to 1 ns (``prctl(PR_SET_TIMERSLACK)``: a sleep then wakes within
    the scheduler's latency instead of up to 50 us late, so the clock's final spin can be
    short); ``gc.freeze()`` (everything built in set-up leaves the collector's view; only the
    young generation is collected first, a full collection between the drive's enable and the
    first cycle could outlast its RPDO deadline) and the automatic collector off (the real clock
    collects in the slack before a deadline instead, :mod:`haptic_bus.control.clock`);
    ``sys.setswitchinterval`` lowered, so a helper thread that takes the GIL gives it back
    within tens of microseconds instead of 5 ms;
    ``SCHED_FIFO`` at :data:`FIFO_PRIORITY`, and the process's other threads at
    :data:`GIL_PRIORITY` (the GIL has no priority inheritance: a thread holding it, preempted by
    an ordinary process for a scheduler slice, held the cycle up 6 ms beside two CPU hogs, 36
    overruns in 1000 cycles; with them above ordinary processes, none), each with
    ``SCHED_RESET_ON_FORK``: a process or thread started from them, the upload judge importing
    numpy and scipy for a second among them, starts as an ordinary one (inheriting SCHED_FIFO 80
    it starved the simulated drive during pre-flight: 9 of 10 runs refused on an idle machine,
    2 of 6 after); and
    ``mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT)``: no page the loop has touched is ever
    paged out, and entering takes milliseconds (without ``MCL_ONFAULT``, on kernels before 4.4,
    every mapped page is faulted in first: ~50 ms and the whole address space resident); and
    a CPU wake-up latency of 0 (``/dev/cpu_dma_latency``, the kernel's PM QoS, as ``cyclictest``
    asks by default): while the file is held open no CPU enters an idle state it wakes from late,
    so the sleep before each deadline ends on time.  On this project's virtual machine (cpuidle
    ``haltpoll``) a 1 ms sleep-then-spin clock under SCHED_FIFO had a start lateness p99 of
    45-175 us without it and 1.6-23 us with it (the p99.9, the host's own preemption, stays).
    It holds every CPU of the machine out of its deep idle states for the run's length: more power
    drawn while the run goes.

Without real-time scheduling no Python loop holds a 1 ms period beside other work: measured on
this project's 2-core machine, idle, its start lateness p99 was 15 times the bare clock's (0.70
against 0.047 ms) and the loop delay seen 1.7 samples; with it, 1.07 times and 1.06 samples
(:mod:`haptic_bus.bench.thread_tuning`).  So it is asked for by default, as ``ros2_control``'s
controller manager does: a process that may have it (root, ``CAP_SYS_NICE``, an
``RLIMIT_RTPRIO``) gets it; one that may not runs on, the items it could not get logged at
info level.  ``haptic-bus run --realtime`` insists: each item it cannot get is a warning, and
once SCHED_FIFO is got the control thread is pinned to one CPU (the last it may run on; not by
default: two runs on one machine would both pin to it, and one's clock spin holds the other up;
an ordinary thread is never pinned, it could not move off a busy CPU).
``--no-realtime`` asks only for the unprivileged items (beside another real-time process that
must keep the CPU).

Each item asked for is either got or reported missing with the reason and what would grant
it (in the log, and :class:`RealtimeReport` in ``run.json``); nothing missing stops the run.
On exit every setting is put back as it was found.  Linux only for the
``prctl``/``mlockall`` items (elsewhere they are reported missing).
"""

from __future__ import annotations

import ctypes
import dataclasses
import errno
import gc
import logging
import os
import resource
import struct
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager, suppress

from haptic_bus.control.clock import PR_GET_TIMERSLACK, libc

logger = logging.getLogger(__name__)

FIFO_PRIORITY = 80  # SCHED_FIFO priority of the control thread (1..99)
GIL_PRIORITY = 1  # SCHED_FIFO priority of the process's other threads while the control thread has FIFO_PRIORITY
_RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0)  # a child (the judge, a writer) starts as an ordinary process
_PR_SET_TIMERSLACK = 29
CPU_LATENCY = "/dev/cpu_dma_latency"  # the kernel's PM QoS request: an int32 in us, held while the file is open
_MCL_CURRENT, _MCL_FUTURE, _MCL_ONFAULT = 1, 2, 4


@dataclasses.dataclass(frozen=True)
class RealtimeSettings:
    """What to ask for (None or False: leave it as it is).

    ``timer_slack_ns``: the thread's timer slack; ``switch_interval`` (s): the interpreter's
    GIL switch interval while running; ``freeze_gc``: ``gc.freeze()`` and the automatic
    collector off; ``spin`` (s): the real clock's final spin (None: its default);
    ``fifo_priority``: ``SCHED_FIFO`` at this priority; ``cpu``: once SCHED_FIFO is got, pin the
    thread to this CPU (-1: the last CPU it may run on); ``lock_memory``: ``mlockall``;
    ``cpu_latency_us``: the CPUs' wake-up latency asked of the kernel's PM QoS (0: never idle
    deeper than polling); ``insist``: an item not got is a warning (else an info line: the process
    may not have it).
    """

    timer_slack_ns: int | None = 1
    switch_interval: float | None = 50e-6
    freeze_gc: bool = True
    spin: float | None = None
    fifo_priority: int | None = FIFO_PRIORITY
    cpu: int | None = None
    lock_memory: bool = True
    cpu_latency_us: int | None = 0
    insist: bool = False

    @classmethod
    def insisting(cls) -> RealtimeSettings:
        """``--realtime``: the default's items, each one not got a warning, and the thread pinned to the last CPU."""
        return cls(cpu=-1, insist=True)

    @classmethod
    def unprivileged(cls) -> RealtimeSettings:
        """``--no-realtime``: timer slack, switch interval and the frozen collector only."""
        return cls(fifo_priority=None, cpu=None, lock_memory=False, cpu_latency_us=None)

    @classmethod
    def untuned(cls) -> RealtimeSettings:
        """Nothing asked: the OS defaults, and the clock's 200 us spin of before issue 14 (the bench's baseline)."""
        return cls(timer_slack_ns=None, switch_interval=None, freeze_gc=False, spin=200e-6, fifo_priority=None,
                   cpu=None, lock_memory=False, cpu_latency_us=None)


@dataclasses.dataclass
class RealtimeReport:
    """What a session got (item -> what) and could not get (item -> why, and what would grant it)."""

    got: dict[str, str] = dataclasses.field(default_factory=dict)
    missing: dict[str, str] = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict[str, dict[str, str]]:
        """JSON-ready."""
        return {"got": dict(self.got), "missing": dict(self.missing)}

    def summary(self) -> str:
        """One line: what was got, and what was not and why."""
        parts = [f"got {', '.join(f'{k} ({v})' for k, v in self.got.items()) or 'nothing'}"]
        parts += [f"could NOT get {k}: {why}" for k, why in self.missing.items()]
        return "real time: " + "; ".join(parts)


def _os_error(text: str) -> OSError:
    code = ctypes.get_errno()
    return OSError(code, f"{text}: {os.strerror(code)}")


class _Session:
    """The items of one session; each ``ask_*`` records into ``report`` and pushes its undo on ``undo``."""

    def __init__(self, report: RealtimeReport, undo: ExitStack) -> None:
        self.report = report
        self.undo = undo
        self.libc = libc()

    def ask(self, item: str, get: Callable[[], str], remedy: str) -> None:
        """Run ``get`` (returns what was got); an OSError or ValueError makes ``item`` missing."""
        try:
            self.report.got[item] = get()
        except (OSError, ValueError, AttributeError) as exc:
            denied = isinstance(exc, OSError) and exc.errno in (errno.EPERM, errno.EACCES, errno.ENOMEM)
            self.report.missing[item] = f"{exc}" + (f" ({remedy})" if denied else "")

    def timer_slack(self, ns: int) -> str:
        c = self.libc
        if c is None:
            raise OSError(errno.ENOSYS, "prctl(PR_SET_TIMERSLACK) is Linux only")
        zero = ctypes.c_ulong(0)
        before = c.prctl(PR_GET_TIMERSLACK, zero, zero, zero, zero)
        if c.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), zero, zero, zero) != 0:
            raise _os_error("prctl(PR_SET_TIMERSLACK)")
        self.undo.callback(c.prctl, _PR_SET_TIMERSLACK, ctypes.c_ulong(max(before, 1)), zero, zero, zero)
        return f"{ns} ns, was {before} ns"

    def switch_interval(self, seconds: float) -> str:
        before = sys.getswitchinterval()
        sys.setswitchinterval(seconds)
        self.undo.callback(sys.setswitchinterval, before)
        return f"{seconds * 1e6:g} us, was {before * 1e6:g} us"

    def freeze_gc(self) -> str:
        enabled = gc.isenabled()
        gc.collect(0)  # the young generation only: a full collection here could take longer than the RPDO deadline
        gc.freeze()
        gc.disable()
        self.undo.callback(gc.unfreeze)
        if enabled:
            self.undo.callback(gc.enable)
        return f"{gc.get_freeze_count()} set-up objects frozen; collections only in the clock's slack"

    def fifo(self, priority: int) -> str:
        self._fifo(0, priority)
        others = 0
        for task in _other_threads():  # a GIL holder preempted by an ordinary process would hold the cycle up
            with suppress(OSError):  # a thread that ended meanwhile
                self._fifo(task, GIL_PRIORITY)
                others += 1
        return f"priority {priority}; the process's {others} other threads at {GIL_PRIORITY}"

    def _fifo(self, tid: int, priority: int) -> None:
        before = os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority
        os.sched_setscheduler(tid, os.SCHED_FIFO | _RESET_ON_FORK, os.sched_param(priority))
        self.undo.callback(_restore_policy, tid, before[0], before[1])

    def pin(self, cpu: int) -> str:
        before = os.sched_getaffinity(0)
        chosen = max(before) if cpu < 0 else cpu
        os.sched_setaffinity(0, {chosen})
        self.undo.callback(os.sched_setaffinity, 0, before)
        return f"CPU {chosen} of {sorted(before)}"

    def lock_memory(self) -> str:
        c = self.libc
        if c is None:
            raise OSError(errno.ENOSYS, "mlockall is Linux only")
        if c.mlockall(_MCL_CURRENT | _MCL_FUTURE | _MCL_ONFAULT) == 0:
            self.undo.callback(c.munlockall)
            return "current and future pages, each locked once touched (MCL_ONFAULT)"
        if ctypes.get_errno() != errno.EINVAL or c.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:  # EINVAL: a kernel before 4.4
            raise _os_error("mlockall")
        self.undo.callback(c.munlockall)
        return "current and future pages"

    def cpu_latency(self, microseconds: int) -> str:
        fd = os.open(CPU_LATENCY, os.O_WRONLY | os.O_CLOEXEC)
        self.undo.callback(os.close, fd)  # closing it withdraws the request
        os.write(fd, struct.pack("i", microseconds))
        return f"{microseconds} us on every CPU, while the run goes"


class HelperPlacement:
    """Where a helper thread the calling thread starts runs: where the session put the process's other
    threads, at ``SCHED_FIFO`` :data:`GIL_PRIORITY` when the caller has SCHED_FIFO (else nothing).
    ``SCHED_RESET_ON_FORK`` starts such a thread as an ordinary one, and an ordinary thread holding the
    GIL is preempted by any ordinary process for a scheduler slice while the control thread waits for
    the GIL: pre-flight's judge thread, started after the session, held gantry-3d's cycle up 80-173 ms
    on a loaded 2-CPU machine (its RPDO deadline 60 ms at T = 2 ms: every node logged "RPDO1 missed its
    deadline" before the enable).

    The helper calls :meth:`place` first; the caller calls :meth:`release` once it stops waiting for the
    helper.  Whichever comes second sees the other: a release before the helper placed itself (a stop
    while the new thread waited for a CPU) leaves it ordinary, where its late placement had put it back
    at SCHED_FIFO (seen on a loaded machine)."""

    def __init__(self) -> None:
        self._fifo = hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) & ~_RESET_ON_FORK == os.SCHED_FIFO
        self._lock = threading.Lock()
        self._released = False

    def place(self) -> None:
        """In the helper thread, first: SCHED_FIFO :data:`GIL_PRIORITY` beside a SCHED_FIFO caller, unless released."""
        with self._lock:
            if self._fifo and not self._released:
                with suppress(OSError):  # refused: it stays an ordinary thread, as before
                    os.sched_setscheduler(0, os.SCHED_FIFO | _RESET_ON_FORK, os.sched_param(GIL_PRIORITY))

    def release(self, thread: threading.Thread) -> None:
        """``thread``, the helper, back to an ordinary one, now and if it places itself later: a helper whose
        caller has stopped waiting for it (a run stopped while pre-flight's judge still judges) works on until
        its call returns, and should not do so above every ordinary process, the run's own shutdown among them
        once the session has put the control thread back."""
        with self._lock:
            self._released = True
            if thread.native_id is not None and hasattr(os, "sched_setscheduler"):
                with suppress(OSError):  # it ended meanwhile
                    os.sched_setscheduler(thread.native_id, os.SCHED_OTHER, os.sched_param(0))


def _other_threads() -> list[int]:
    """The kernel thread ids of this process' threads but the calling one (none where /proc is not)."""
    try:
        tasks = [int(name) for name in os.listdir("/proc/self/task")]
    except OSError:
        return []
    return [task for task in tasks if task != threading.get_native_id()]


def _restore_policy(tid: int, policy: int, priority: int) -> None:
    with suppress(OSError):  # a thread that ended meanwhile
        os.sched_setscheduler(tid, policy, os.sched_param(priority))


def _memlock_limit() -> str:
    soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    return "unlimited" if soft == resource.RLIM_INFINITY else f"{soft // 1024} KiB"


@contextmanager
def realtime_session(settings: RealtimeSettings) -> Iterator[RealtimeReport]:
    """Apply ``settings`` to the calling thread (and the interpreter) until the block ends; yield
    the :class:`RealtimeReport` (each missing item is also logged: a warning if ``settings.insist``, else info)."""
    report = RealtimeReport()
    with ExitStack() as undo:
        session = _Session(report, undo)
        slack, interval = settings.timer_slack_ns, settings.switch_interval
        if slack is not None:
            session.ask("timer slack", lambda: session.timer_slack(slack), "")
        if interval is not None:
            session.ask("switch interval", lambda: session.switch_interval(interval), "")
        if settings.freeze_gc:
            session.ask("gc frozen", session.freeze_gc, "")
        if settings.fifo_priority is not None:
            priority = settings.fifo_priority
            session.ask("SCHED_FIFO", lambda: session.fifo(priority),
                        f"needs CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least {priority}: e.g. "
                        f"'ulimit -r {priority}' or an rtprio entry in /etc/security/limits.conf")
        if settings.cpu is not None:
            cpu = settings.cpu
            if "SCHED_FIFO" in report.got or settings.fifo_priority is None:
                session.ask("CPU affinity", lambda: session.pin(cpu), "")
            else:
                report.missing["CPU affinity"] = ("not pinned without SCHED_FIFO (an ordinary thread pinned to one CPU "
                                                  "could not move off it when it is busy)")
        if settings.lock_memory:
            session.ask("mlockall", session.lock_memory,
                        f"RLIMIT_MEMLOCK is {_memlock_limit()}: needs CAP_IPC_LOCK or 'ulimit -l unlimited'")
        if settings.cpu_latency_us is not None:
            latency = settings.cpu_latency_us
            session.ask("CPU wake-up latency", lambda: session.cpu_latency(latency),
                        f"needs write access to {CPU_LATENCY}: root, or a udev rule giving the user's group it")
        level = logging.WARNING if settings.insist else logging.INFO
        for item, why in report.missing.items():
            logger.log(level, "real time: could not get %s: %s", item, why)
        if report.got:
            logger.info("real time: got %s", ", ".join(f"{k} ({v})" for k, v in report.got.items()))
        yield report
