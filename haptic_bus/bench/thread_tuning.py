"""Benchmark 6: real time, ``T = 1 ms``, the controller and the simulated drive in two processes.

``haptic-bus run``'s own session (:func:`haptic_bus.app.runner.run_canopen`, the ``cia402-handle``
profile, supervisor, heartbeat and SDO server included) against ``python -m sim_drive`` on
udp_multicast (one simulator for every run of the section: an operator's hand, a spring towards
1.5 mm inside the wall, takes the handle once each run enables it), in three set-ups of
the control thread (:mod:`haptic_bus.app.realtime`):

* **untuned** -- as before issue 14: the OS defaults (timer slack 50 us, GIL switch interval
  5 ms, the collector on) and a 200 us final spin;
* **--no-realtime** -- what the OS grants any process: timer slack 1 ns, a 60 us spin, the
  collector frozen and kept to the clock's slack, switch interval 50 us;
* **default** -- what ``haptic-bus run`` does: those plus SCHED_FIFO 80, one CPU and ``mlockall``
  where the OS grants them (said in the output when it does not);

each once on a quiet machine and once beside a CPU hog (one busy process per CPU); ``--smoke``
runs untuned and default quiet and default beside one hog, 0.15 s each after a 200-cycle pre-flight
(``--quick`` 1 s, full 15 s, after the product's 500), and the three axes quiet on ``gantry-3d`` without its ball
(:func:`axes_profile`).  The
simulated drive stands in for hardware: its threads run under SCHED_FIFO where the OS grants it
(:mod:`sim_drive.scheduling`, the policy said in the output), so that the hog slows the
controller, not the drive's answers.

Per run: the share of a core the controller process used (every thread, from the clock's CPU
time at each cycle start) and the start lateness, each over :data:`SEGMENTS` consecutive
stretches of the run (median, min-max), the whole run's lateness percentiles and overruns, and
whether it started without a stall (the first 50 cycles' lateness within the run's p99).  Beside
them the bare clock (no drive, no controller) in each set-up: what the clock itself costs; and
python-can's floor for the default set-up (:mod:`~haptic_bus.bench.can_floor`: the same frames
with python-can alone), its lateness too.  The default set-up's core share over the floor's, and its
lateness over the bare clock's, are each the median of :data:`~haptic_bus.bench.pairs.PAIRS` pairs, each a run, the floor and
the bare clock right after it (:mod:`~haptic_bus.bench.pairs`): on this virtual machine one pair's core ratio
moved from 1.14 to 2.07 between two bench runs, the floor's own share from 0.14 to 0.24 of a core,
and one stall of the host (1.5-6 ms, a few times a minute) decides a 1 s run's p99.9.  Before the runs, the machine's own gaps
(:mod:`~haptic_bus.bench.host_gaps`): how often a spinning real-time thread lost its CPU, which
bounds every lateness figure of the section from below.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager, nullcontext
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from haptic_bus.app.profiles import AxesProfile, Profile, admit, load_profile, one_axis_only, read_profile
from haptic_bus.app.realtime import RealtimeSettings, realtime_session
from haptic_bus.app.run_json import read_document
from haptic_bus.bench.pairs import PAIRS, axes_figures, issue_26_figures, measure_pair, paired_runs
from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import Spread
from haptic_bus.control.clock import RealClock
from haptic_bus.control.space_scene import Sphere

if TYPE_CHECKING:
    from haptic_bus.control.controller import WallController

PROFILE = "cia402-handle"
NODE_ID = 5
AXES_PROFILE = "gantry-3d"  # three axes on one SYNC, at the profile's own T (2 ms: at 1 Mbit/s its frames take 48.5 % of it)
AXES_NODE_IDS = (5, 6, 7)
SEGMENTS = 5
FIRST_CYCLES = 50
FLOOR_START_WAIT = 60.0  # s: the floor process imports numpy and python-can before it says it is ready
FLOOR_TPDOS = 2  # TPDO1 (0x6041 + 0x606C) and TPDO2 (0x6064): the run maps the position for its port observer
CORE_TARGET = 0.12  # issue 14: the controller at T = 1 ms within 0.12 of a core
SETUPS = {"untuned": RealtimeSettings.untuned(), "--no-realtime": RealtimeSettings.unprivileged(),
          "default": RealtimeSettings()}
RUNS = {"quiet": tuple(SETUPS), "CPU hog": tuple(SETUPS)}  # load -> the set-ups run under it
SMOKE_RUNS = {"quiet": ("untuned", "default"), "CPU hog": ("default",)}  # what the targets need, and one hogged run
SMOKE_PREFLIGHT_CYCLES = 200  # pre-flight cycles of a smoke run (:func:`preflight_cycles`)
HAND = "hand:300,5,0.0045"  # the simulated operator: a hand spring (N/m, N s/m) towards 4.5 mm, 1.5 mm inside the wall,
# holding a powered handle (haptic-bus sim's hand lets go of an unpowered one)
_POLICIES = {getattr(os, n): n for n in ("SCHED_OTHER", "SCHED_FIFO", "SCHED_RR", "SCHED_BATCH", "SCHED_IDLE")
             if hasattr(os, n)}


def percentiles(values: np.ndarray) -> dict[str, float]:
    """p50, p99, p99.9 and max (s) of ``values`` (empty dict for none)."""
    if values.size == 0:
        return {}
    p50, p99, p999 = np.percentile(values, [50, 99, 99.9])
    return {"p50": float(p50), "p99": float(p99), "p99.9": float(p999), "max": float(np.max(values))}


def scheduler_info() -> dict:
    """OS scheduling policy, nice, CPU affinity and timer slack (ns) of this thread, where readable."""
    from haptic_bus.control.clock import timer_slack

    info: dict = {}
    try:
        info["policy"] = _POLICIES.get(os.sched_getscheduler(0), str(os.sched_getscheduler(0)))
        info["nice"] = os.nice(0)
        info["affinity"] = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        pass
    info["timer_slack_ns"] = round(timer_slack() * 1e9)
    return info


def clock_figures(clock: RealClock, segments: int = SEGMENTS) -> dict:
    """Core share and lateness of a finished run, per stretch (spreads) and whole (percentiles)."""
    late = clock.lateness()
    if late.size < 2 * segments:
        return {"cycles": int(late.size), "overruns": clock.overruns}
    bounds = np.linspace(0, late.size - 1, segments + 1).astype(int)
    shares, p50, p99, worst = [], [], [], []
    for first, last in itertools.pairwise(bounds):
        wall, cpu = clock.usage(int(first), int(last))
        if wall > 0:
            shares.append(cpu / wall)
        stretch = late[first:last]
        p50.append(float(np.median(stretch)))
        p99.append(float(np.percentile(stretch, 99)))
        worst.append(float(np.max(stretch)))
    whole = percentiles(late)
    first_max = float(np.max(late[:FIRST_CYCLES])) if late.size else 0.0
    return {
        "cycles": int(late.size), "core_share": Spread.of(shares).to_dict(),
        "lateness_p50_s": Spread.of(p50).to_dict(), "lateness_p99_s": Spread.of(p99).to_dict(),
        "lateness_max_s": Spread.of(worst).to_dict(), "lateness_s": whole, "overruns": clock.overruns,
        "first_cycles_max_late_s": first_max, "no_startup_stall": first_max <= whole.get("p99", 0.0),
        "slack_collections": clock.slack_collections,
    }


def bare_clock(settings: RealtimeSettings, period: float, cycles: int) -> dict:
    """The clock alone (no drive, no controller) in ``settings``: its core share and lateness."""
    clock = RealClock(period, capacity=cycles + 1, spin=settings.spin)
    with realtime_session(settings):
        for k in range(cycles):
            clock.wait_next(k)
    return clock_figures(clock)


WRITER = "writer process"  # by_name's key for the run's writer process (a child, not a thread)
ENDED = "threads ended meanwhile"  # by_name's key for the threads that started and ended within the block


class ThreadCpu:
    """CPU seconds of each thread of this process (by name) over the block, read from ``/proc`` as it
    starts and ends, and of the threads that started and ended within it together (:data:`ENDED`:
    the process's CPU less its living threads').  Nothing runs meanwhile: a sampling thread in the
    control process would itself take the interpreter from the cycle (beside CPU hogs, one
    preempted while it held it made the cycle wait)."""

    def __init__(self) -> None:
        self._start: dict[int, tuple[str, float]] = {}
        self._end: dict[int, tuple[str, float]] = {}
        self._process_start = self._process_end = 0.0  # the whole process's CPU (s)

    def __enter__(self) -> ThreadCpu:
        self._start = _threads_cpu()
        self._process_start = time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self._end = _threads_cpu()
        self._process_end = time.process_time()

    def by_name(self) -> dict[str, float]:
        """CPU seconds per thread name over the block (threads of one name summed), and :data:`ENDED`."""
        out: dict[str, float] = {}
        for tid, (name, used) in self._end.items():
            key = "canopen notifier" if name.startswith("Notifier") else name
            out[key] = out.get(key, 0.0) + used - self._start.get(tid, (name, 0.0))[1]
        out[ENDED] = max(0.0, self._process_end - self._process_start - sum(out.values()))
        return {k: round(v, 3) for k, v in sorted(out.items(), key=lambda kv: -kv[1])}


def _threads_cpu() -> dict[int, tuple[str, float]]:
    """Each living thread's name and CPU seconds, by native id (``/proc``'s ``schedstat``: the time on a
    CPU, in ns, where ``stat``'s user and system times count 10 ms ticks)."""
    found: dict[int, tuple[str, float]] = {}
    for thread in threading.enumerate():
        try:
            on_cpu = int(Path(f"/proc/self/task/{thread.native_id}/schedstat").read_text().split()[0])
        except (OSError, IndexError, ValueError):
            continue
        found[thread.native_id or 0] = (thread.name, on_cpu * 1e-9)
    return found


@contextmanager
def can_floor(bus: dict, node_ids: tuple[int, ...], tpdos: int, period: float, duration: float) -> Iterator[Callable[[], dict]]:
    """python-can's floor for the same cycle (:mod:`~haptic_bus.bench.can_floor`) in a process of its own,
    started now and waited for until it has imported (a second of a core, which beside the hogged run
    kept the hog spinning as long); the block's function measures it and gives its figures, once per call
    (one process for every run of the cycle on ``bus``: quiet and beside the hogs; it idles between them,
    blocked on its stdin).  A floor that fails or does not answer is reported, and so is each later call."""
    from haptic_bus.bench.can_floor import READY, FloorConfig

    config = {"bus": bus, "node_ids": list(node_ids), "tpdos": tpdos, "period": period, "duration": duration}
    FloorConfig.from_json(json.dumps(config))  # a configuration the child reads, checked here
    process = subprocess.Popen([sys.executable, "-m", "haptic_bus.bench.can_floor", json.dumps(config)],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdin is not None and process.stdout is not None
    failed: dict = {}

    def ended(reason: str | None) -> dict:
        if process.poll() is None:
            process.kill()
        _, err = process.communicate(timeout=10)
        failed.update(available=False, reason=reason or (err.strip().splitlines()[-1] if err.strip()
                                                         else f"exit {process.returncode}"))
        return failed

    def measure() -> dict:
        assert process.stdin is not None and process.stdout is not None
        if failed:
            return failed
        try:
            process.stdin.write("go\n")
            process.stdin.flush()
        except OSError:  # it has ended: its stderr says why
            return ended(None)
        wait = 60 + 4 * duration
        line = process.stdout.readline() if select.select([process.stdout], [], [], wait)[0] else None
        if line is None:
            return ended(f"no figures from the floor process within {wait:g} s")
        return json.loads(line) if line.strip() else ended(None)

    try:
        if select.select([process.stdout], [], [], FLOOR_START_WAIT)[0] and process.stdout.readline().strip() == READY:
            yield measure
        else:
            yield lambda: {"available": False, "reason": f"the floor process did not start within {FLOOR_START_WAIT:g} s"}
    finally:
        if not failed:
            if process.poll() is None:
                process.kill()
            process.communicate(timeout=10)


def observed_delay(controller: WallController) -> float | None:
    """The loop delay (samples) the run saw: the delay its gate assumed plus the p99 of each cycle's
    start lateness and input age (the supervisor's measure, over the whole run); None before a cycle."""
    record = controller.record
    beyond = record.column("lateness_s") / controller.period + record.column("input_age")
    assumed = max(axis.delay for axis in controller.gate.axes)
    return assumed + float(np.percentile(beyond, 99)) if beyond.size else None


def controller_run(settings: RealtimeSettings, duration: float, bus: dict, process: subprocess.Popen,
                   profile: Profile | AxesProfile, node_id: int | None = NODE_ID, preflight_cycles: int | None = None) -> dict:
    """One ``haptic-bus run`` session of ``profile`` (loaded once per section: loading judges it, seconds for
    three axes; one axis: drive ``node_id``; several: the profile's) against the simulated drive ``process``
    on ``bus``, ramped in if it starts in contact; ``preflight_cycles``: its pre-flight's (None: the product's).
    A drive found in FAULT is reset first, as ``--reset-fault`` does: in one quick run of seven, on a machine loaded
    beyond the hogs (load average 6.7), the drive sat in FAULT (0x8250, RPDO timeout) after a completed pair, and
    every further pair's run was refused for it; the reset comes before pre-flight, outside what a run measures."""
    from haptic_bus.app.runner import RunOptions, run

    with tempfile.TemporaryDirectory() as out:
        with ThreadCpu() as threads:
            result = run(profile, bus, RunOptions(duration, pacing="wall", out_dir=Path(out) / "run", live=False,
                                                  scheduling=settings, start_in_contact="ramp", plots=False,
                                                  preflight_cycles=preflight_cycles, reset_fault=True),
                         node_id=node_id)
        document = read_document(result.folder)
    writer = document.get("writer", {}).get("cpu_s")  # the writer process's own account (issue 26: report it)
    figures = {"exit_reason": result.exit_reason, "error": result.error,
               "thread_cpu_s": threads.by_name() | ({WRITER: writer} if writer is not None else {}), "writer_cpu_s": writer,
               "drive_policy": _POLICIES.get(os.sched_getscheduler(process.pid)), "scheduling": document.get("realtime")}
    if result.controller is not None and isinstance(result.controller.clock, RealClock):
        figures.update(clock_figures(result.controller.clock))
        figures["compute_s"] = result.summary.compute_percentiles if result.summary is not None else {}
        figures["observed_delay"] = observed_delay(result.controller)
        figures["preflight"] = document.get("preflight", {}).get("reason")
    return figures


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 6; returns its section of ``bench.json``."""
    from haptic_bus.bench.host_gaps import host_gaps
    from haptic_bus.bench.processes import canopen_simulator, cpu_hogs

    duration = size.pick(0.15, 1.0, 15.0)  # smoke: 150 cycles at T = 1 ms (75 for three axes at 2 ms), the bare clock
    # half that: each still fills the SEGMENTS stretches (>= 2 cycles each) and the first-cycles window; every second of a
    # run here costs the controller, the drive, the writer, the floor and the hog their share of a core
    profile = load_profile(PROFILE)
    period = one_axis_only(profile, "bench").loop.period
    hogs = size.pick(1, os.cpu_count() or 1, os.cpu_count() or 1)  # smoke: one hog shows the hogged run works
    host: list[dict] | str  # the probes' figures, or why there are none (the runs do not depend on them)
    try:
        host = host_gaps(size.pick(0.2, 1.0, 5.0))  # what no process here avoids, before anything else runs
    except (RuntimeError, OSError, ValueError, subprocess.TimeoutExpired) as exc:
        host = f"{type(exc).__name__}: {exc}"
    tick("real time: the host's gaps")
    runs: dict[str, dict] = {}
    with canopen_simulator(PROFILE, (NODE_ID,), "--operator", HAND) as (bus, process), ExitStack() as floors:
        floor: Callable[[], dict] | None = None  # one floor process for the default runs, started before the first
        for label, names in size.pick(SMOKE_RUNS, RUNS, RUNS).items():
            runs[label] = {}
            for name in names:
                entry: dict = {}
                try:
                    # the default set-up beside python-can alone, the same frames, the same conditions
                    if name == "default" and floor is None:
                        floor = floors.enter_context(can_floor(bus, (NODE_ID,), FLOOR_TPDOS, period, duration))
                    with cpu_hogs(hogs) if label == "CPU hog" else nullcontext():
                        def again(setup: RealtimeSettings = SETUPS[name]) -> dict:
                            return controller_run(setup, duration, bus, process, profile,
                                                  preflight_cycles=preflight_cycles(size))

                        def bare(setup: RealtimeSettings = SETUPS[name]) -> dict:
                            return bare_clock(setup, period, round(duration / 2 / period))

                        entry["controller"], entry["bare_clock"] = again(), bare()
                        if name == "default" and floor is not None:
                            entry["floor"] = floor()
                            entry["pairs"] = paired_runs((entry["controller"], entry["bare_clock"], entry["floor"]),
                                                         functools.partial(measure_pair, again, bare, floor), size.pick(*PAIRS))
                except Exception as exc:
                    entry = {"available": False, "reason": f"{type(exc).__name__}: {exc}"}
                runs[label][name] = entry
                tick(f"real time: {name}, {label}")
    axes = axes_runs(size, duration)
    tick("real time: three axes")
    quiet = runs["quiet"]
    default, untuned = quiet["default"].get("controller", {}), quiet["untuned"].get("controller", {})
    target = {"core_share_target": CORE_TARGET}
    if default.get("core_share") and untuned.get("lateness_p99_s"):
        target.update({
            "default_core_share": default["core_share"]["median"],
            "default_lateness_p99_s": default["lateness_p99_s"]["median"],
            "untuned_lateness_p99_s": untuned["lateness_p99_s"]["median"],
            "core_met": default["core_share"]["median"] <= CORE_TARGET,
            "lateness_no_worse": default["lateness_p99_s"]["median"] <= untuned["lateness_p99_s"]["median"],
            "no_startup_stall": bool(default["no_startup_stall"]),
        })
    return {
        "description": f"T = {period * 1e3:g} ms with the real clock for {duration:g} s: haptic-bus run's session against "
                       f"python -m sim_drive --operator {HAND} on udp_multicast (two processes, the hand taking the "
                       f"handle once it is powered), set-ups of the control thread quiet and beside {hogs} busy processes",
        "period_s": period, "duration_s": duration, "segments": SEGMENTS, "hog_processes": hogs,
        "scheduler": scheduler_info(), "host_gaps": host, "runs": runs, "target": target, "axes": axes,
        "issue_26": issue_26_figures(runs) | {"three axes": axes_figures(axes)},
    }


def preflight_cycles(size: Size) -> int | None:
    """The pre-flight cycles of each run: the product's 500 (None), but 200 in the smoke run (0.2 s at T = 1 ms,
    0.4 s for three axes at 2 ms; the product's 0.5 s and 1 s are three and seven times a smoke run's cycles, each
    cycle costing the controller and the drive, and the hog beside the hogged run): the verdict's p99.5 is still
    a measured cycle, and the run is still refused or started as the product decides."""
    return size.pick(SMOKE_PREFLIGHT_CYCLES, None, None)


def axes_runs(size: Size, duration: float) -> dict:
    """Three axes (:data:`AXES_PROFILE`) in the default set-up against one simulated three-axis device, its hand
    the profile's ``[space.operator]`` (taking the handle once the drives are enabled), quiet (and, beyond the
    smoke size, beside the hogs), each beside python-can's floor for its cycle."""
    from haptic_bus.bench.processes import canopen_simulator, cpu_hogs

    axes, label = axes_profile(size)
    period = axes.period
    loads = ("quiet",) if size.pick(True, False, False) else ("quiet", "CPU hog")
    out: dict = {"profile": label, "node_ids": list(AXES_NODE_IDS), "period_s": period}
    try:
        with (canopen_simulator(AXES_PROFILE, AXES_NODE_IDS) as (bus, process),
              can_floor(bus, AXES_NODE_IDS, FLOOR_TPDOS, period, duration) as floor):
            def again() -> tuple[dict, dict, dict]:
                return measure_pair(lambda: controller_run(SETUPS["default"], duration, bus, process, axes, None,
                                                           preflight_cycles(size)),
                                    lambda: bare_clock(SETUPS["default"], period, round(duration / 2 / period)), floor)

            for load in loads:
                with cpu_hogs(os.cpu_count() or 1) if load == "CPU hog" else nullcontext():
                    first = again()
                    entry = dict(zip(("controller", "bare_clock", "floor"), first))
                    entry["pairs"] = paired_runs(first, again, size.pick(*PAIRS))
                    out[load] = entry
    except Exception as exc:
        out.update(available=False, reason=f"{type(exc).__name__}: {exc}")
    return out


def axes_profile(size: Size) -> tuple[AxesProfile, str]:
    """:data:`AXES_PROFILE`, gated, and what the section calls it.  The smoke run leaves its ball out: the
    coupled gate judges a sphere by a search over directions (a second of a core at each new loop delay, where a
    box and a plane take a millisecond), and a run judges its scene again in the judge worker and in pre-flight, at
    the measured delay, while the drives cycle on waiting for the verdict: the smoke's three-axis run took about
    9 s of CPU with the ball, 3 s without.  Its figures only show that a three-axis run goes through every step,
    which the block and the slope, three axes on one SYNC of the same device, still do."""
    profile = read_profile(AXES_PROFILE)
    if not isinstance(profile, AxesProfile):
        raise TypeError(f"{AXES_PROFILE} has no [[axes]]")
    label = AXES_PROFILE
    if size.pick(True, False, False):
        profile = dataclasses.replace(profile, space=tuple(o for o in profile.space if not isinstance(o, Sphere)))
        label += " without its ball (smoke)"
    admit(profile)
    return profile, label
