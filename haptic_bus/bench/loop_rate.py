"""Benchmark 4: closed-loop cycles per second in virtual time, and the hot path's PDO codec.

Every run is the product's controller (:class:`haptic_bus.control.controller.WallController`, the
``cia402-handle`` profile's scene and gate, :class:`haptic_bus.control.clock.VirtualClock`) against the
simulated drive, whose plant advances exactly ``T`` per cycle, so the rate is what the CPU and
the link allow:

* **lock-step bus, 1 process** -- :func:`haptic_bus.app.rig.simulated_canopen` on
  :mod:`drives.lockstep_bus` (each frame served in the sender's thread: one thread in all);
* **python-can virtual bus, 1 process** -- the same on python-can's threaded ``virtual`` bus;
* **udp_multicast, 2 processes** -- ``python -m sim_drive`` as a subprocess on a unique
  loopback multicast port, the master here;
* **Modbus TCP loopback, 2 processes** -- ``haptic_bus.bench.modbus_poll``'s simulator subprocess and
  :class:`drives.modbus.drive.ModbusDrive` (``split``: one read + one write request per
  cycle), plus that module's own ``bench_cycle`` in both cycle modes.

Beside each, :func:`haptic_bus.bench.hot_path.bench_closed_loop` (the bare read/write cycle
with a damper law, no scene, no observer, no record) on the same link.  Every rate is a median
with min-max over at least 5 runs.  Issue 14's yardstick: the lock-step loop against python-can's
own two-thread SYNC/TPDO/RPDO echo on its virtual bus
(:func:`~haptic_bus.bench.hot_path.bench_echo_floor`), timed pairwise (target >= 1.5 x); and
the two in-process buses' trajectories from the same start compared bit for bit.  Finally
:func:`haptic_bus.bench.hot_path.bench_pdo_codecs`: the master's hot path against canopen's
generic PDO path on the same frames.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drives.base import Drive
from haptic_bus.app.profiles import Profile, load_profile, one_axis_only
from haptic_bus.bench.size import Size
from haptic_bus.bench.timing import REPEATS, Spread, paired, repeated, timed_once
from haptic_bus.control.clock import VirtualClock
from haptic_bus.control.controller import WallController
from haptic_bus.control.gate import PassivityGate

PROFILE = "cia402-handle"
NODE_ID = 5
FLOOR_RATIO_TARGET = 1.5
ECHO_CYCLES = 4_000  # cycles a run against the echo floor: the lock-step drive idles through each echo run, and its
# RPDO deadline (2 s of wall clock in virtual time, drives.safety.VIRTUAL_TIME_DEADLINE) must not expire meanwhile
TRAJECTORY = ("time_s", "position_m", "velocity_m_per_s", "force_n", "torque_permille", "energy_j", "scene_id", "scale")


def _controller(profile: Profile, drive: Drive, gate: PassivityGate) -> WallController:
    return WallController(drive, gate, profile.compiled_scene(), force_limit=profile.force_limit,
                          clock=VirtualClock(profile.loop.period))


def _timed_run(controller: WallController, cycles: int) -> float:
    seconds, summary = timed_once(lambda: controller.run(cycles))
    if summary.error:
        raise RuntimeError(f"the controller run ended with an error: {summary.error}")
    return seconds


def _controller_rate(profile: Profile, drive: Drive, gate: PassivityGate, cycles: int) -> dict:
    """Cycles/s of the WallController on an enabled ``drive``, and of the bare read/write loop (spreads)."""
    from haptic_bus.bench.hot_path import bench_closed_loop

    controller = _controller(profile, drive, gate)
    controller.run(min(200, cycles))  # warm-up
    rate = repeated(lambda: _timed_run(controller, cycles)).rate(cycles)
    compute = controller.summary().compute_percentiles.get("p50")
    bare = repeated(lambda: bench_closed_loop(drive, cycles).seconds).rate(cycles)
    return {"cycles": cycles, "controller_cycles_per_s": rate.median, "controller_rate": rate.to_dict(),
            "controller_compute_p50_s": compute, "bare_cycles_per_s": bare.median, "bare_rate": bare.to_dict()}


def in_process(profile: Profile, cycles: int, interface: str) -> tuple[dict, np.ndarray]:
    """In-process simulated slave + master on ``interface``: the rates, and the trajectory of the
    first ``cycles`` cycles from the start (columns :data:`TRAJECTORY`)."""
    from haptic_bus.app.rig import simulated_canopen

    with simulated_canopen(profile, interface=interface) as (_, drive):
        controller = _controller(profile, drive, profile.gate())
        _timed_run(controller, cycles)
        trajectory = np.column_stack([controller.record.column(name) for name in TRAJECTORY])
        return _controller_rate(profile, drive, profile.gate(), cycles), trajectory


def against_echo_floor(profile: Profile, cycles: int) -> dict:
    """The lock-step closed loop against python-can's threaded echo, pairwise (ratio of rates)."""
    from haptic_bus.app.rig import simulated_canopen
    from haptic_bus.bench.hot_path import bench_echo_floor

    cycles = min(cycles, ECHO_CYCLES)
    with simulated_canopen(profile) as (_, drive):
        controller = _controller(profile, drive, profile.gate())
        controller.run(min(200, cycles))
        echo, loop, ratio = paired(lambda: bench_echo_floor(cycles).seconds, lambda: _timed_run(controller, cycles))
    return {"cycles": cycles, "lockstep_rate": loop.rate(cycles).to_dict(), "echo_floor_rate": echo.rate(cycles).to_dict(),
            "ratio": ratio.to_dict(), "ratio_target": FLOOR_RATIO_TARGET, "met": ratio.median >= FLOOR_RATIO_TARGET,
            "note": "ratio = lock-step controller cycles/s over python-can's two-thread SYNC/TPDO/RPDO echo on its "
                    "virtual bus, per pair of runs"}


def udp_multicast(profile: Profile, cycles: int) -> dict:
    """Two processes: ``python -m sim_drive`` on udp_multicast (unique port) and the master here."""
    from drives.canopen.drive import CanopenDrive
    from drives.safety import SafetySettings
    from haptic_bus.bench.processes import canopen_simulator

    with canopen_simulator(PROFILE, (NODE_ID,)) as (bus, _):
        drive = CanopenDrive(NODE_ID, interface=bus["interface"], channel=bus["channel"], bus_kwargs={"port": bus["port"]},
                             period=profile.loop.period, scaling=profile.scaling(),
                             safety=SafetySettings().for_virtual_time(profile.loop.period))
        try:
            drive.connect()
            drive.enable()
            result = _controller_rate(profile, drive, profile.gate(), cycles)
            drive.disable()
        finally:
            drive.close()
    result["bus"] = f"udp_multicast {bus['channel']} port {bus['port']}"
    return result


def modbus_tcp(profile: Profile, cycles: int) -> dict:
    """Two processes over Modbus TCP loopback: haptic_bus.bench.modbus_poll's simulator and ModbusDrive."""
    import dataclasses

    from drives.modbus.drive import CYCLE_MODES, ModbusDrive
    from drives.modbus.timing import loop_delay
    from haptic_bus.bench.modbus_poll import bench_cycle, start_simulator, stop_simulator

    process, url = start_simulator("ideal", profile=PROFILE)  # its scaling objects match the profile's
    try:
        drive = ModbusDrive.from_url(url, scaling=profile.scaling())
        try:
            drive.connect()
            delay = loop_delay(drive, profile.loop.period)
            gate = PassivityGate(dataclasses.replace(profile.device_loop(), delay=delay), profile.gate_policy)
            drive.enable()
            result = _controller_rate(profile, drive, gate, cycles)
            drive.disable()
        finally:
            drive.close()
        result["bench_cycle"] = {}
        for mode in CYCLE_MODES:
            timings = [bench_cycle(url, mode, cycles) for _ in range(REPEATS)]
            rate = Spread.of([t.cycles_per_second for t in timings])
            result["bench_cycle"][mode] = {"cycles_per_s": rate.median, "rate": rate.to_dict(),
                                           "requests_per_cycle": timings[0].requests_per_cycle,
                                           "round_trip_p50_s": float(np.median([t.p50 for t in timings])),
                                           "round_trip_p99_s": float(np.median([t.p99 for t in timings]))}
    finally:
        status = stop_simulator(process)
    result["simulator_exit_status"] = status
    result["url"] = url
    return result


def run(size: Size, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 4; returns its section of ``bench.json`` (a failing link is reported, not raised)."""
    from haptic_bus.bench.hot_path import bench_pdo_codecs

    cycles = size.pick(100, 500, 20_000)  # smoke: 100 cycles (0.1 s of virtual time) still run every link, time five
    # repeats and compare the two in-process trajectories frame for frame
    profile = one_axis_only(load_profile(PROFILE), "bench")
    links: dict[str, dict] = {}
    trajectories: dict[str, np.ndarray] = {}

    def one_process(interface: str) -> Callable[[Profile, int], dict]:
        def measure(profile: Profile, cycles: int) -> dict:
            rates, trajectories[interface] = in_process(profile, cycles, interface)
            return rates
        return measure

    for key, label, func in (("lockstep", "lock-step bus, 1 process", one_process("lockstep")),
                             ("virtual", "python-can virtual bus, 1 process", one_process("virtual")),
                             ("udp_multicast", "udp_multicast, 2 processes", udp_multicast),
                             ("modbus_tcp", "Modbus TCP loopback, 2 processes", modbus_tcp)):
        try:
            links[key] = {"label": label, "available": True, **func(profile, cycles)}
        except Exception as exc:
            links[key] = {"label": label, "available": False, "reason": f"{type(exc).__name__}: {exc}"}
        tick(f"loop: {label}")
    floor = against_echo_floor(profile, cycles)
    tick("loop: lock-step against the echo floor")
    codec = bench_pdo_codecs(frames=size.pick(500, 5_000, 20_000), repeat=REPEATS)
    tick("loop: PDO codecs")
    base = links["lockstep"].get("controller_cycles_per_s")
    for entry in links.values():
        if entry.get("available") and base:
            entry["ratio_to_lockstep"] = entry["controller_cycles_per_s"] / base
    same = ("lockstep" in trajectories and "virtual" in trajectories
            and trajectories["lockstep"].shape == trajectories["virtual"].shape
            and bool(np.all(trajectories["lockstep"] == trajectories["virtual"])))
    return {
        "description": "closed-loop cycles per second in virtual time (controller + simulated drive); the lock-step "
                       "loop against python-can's threaded echo; hot path vs canopen's generic PDO path",
        "profile": PROFILE,
        "links": links,
        "echo_floor": floor,
        "trajectories_identical": {"cycles": cycles, "lockstep_equals_virtual": same},
        "pdo_codec": {"frames": codec.frames, "hot_path_s": codec.hot_path.median, "generic_s": codec.generic.median,
                      "hot_path": codec.hot_path.to_dict(), "generic": codec.generic.to_dict(),
                      "ratio_generic_over_hot": codec.ratio},
    }
