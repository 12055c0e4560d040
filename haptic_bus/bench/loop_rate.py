"""Benchmark 4: closed-loop cycles per second in virtual time, and the hot path's PDO codec.

Every run is the product's controller (:class:`haptic_bus.control.controller.WallController`, the
``cia402-handle`` profile's scene and gate, :class:`haptic_bus.control.clock.VirtualClock`) against the
simulated drive, whose plant advances exactly ``T`` per cycle, so the rate is what the CPU and
the link allow:

* **virtual bus, 1 process** -- :func:`haptic_bus.app.rig.simulated_canopen` (the simulated
  CANopen slave and the master on python-can's ``virtual`` bus, in one process);
* **udp_multicast, 2 processes** -- ``python -m sim_drive`` as a subprocess on a unique
  loopback multicast port, the master here;
* **Modbus TCP loopback, 2 processes** -- ``haptic_bus.bench.modbus_poll``'s simulator subprocess and
  :class:`drives.modbus.drive.ModbusDrive` (``split``: one read + one write request per
  cycle), plus that module's own ``bench_cycle`` in both cycle modes.

Beside each, :func:`haptic_bus.bench.hot_path.bench_closed_loop` (the bare read/write cycle
with a damper law, no scene, no observer, no record) on the same link.  Finally
:func:`haptic_bus.bench.hot_path.bench_pdo_codecs`: the master's hot path against canopen's
generic PDO path on the same frames (ratio).
"""

from __future__ import annotations

import os
import random
import subprocess
import time
from pathlib import Path
from typing import Callable

from haptic_bus.app.profiles import Profile, load_profile
from haptic_bus.app.rig import simulator_command
from haptic_bus.bench.timing import timed_once
from haptic_bus.control.clock import VirtualClock
from haptic_bus.control.controller import WallController

PROFILE = "cia402-handle"
NODE_ID = 5
_START_WAIT = 30.0  # s: the subprocess imports numpy/scipy/canopen before it answers
_REPO = Path(__file__).resolve().parents[2]


def _controller_rate(profile: Profile, drive, gate, cycles: int) -> dict:
    """Cycles/s of the WallController on an enabled ``drive``, and of the bare read/write loop."""
    from haptic_bus.bench.hot_path import bench_closed_loop

    controller = WallController(drive, gate, profile.compiled_scene(), force_limit=profile.force_limit,
                                clock=VirtualClock(profile.loop.period))
    controller.run(min(200, cycles))  # warm-up
    seconds, summary = timed_once(lambda: controller.run(cycles))
    if summary.error:
        raise RuntimeError(f"the controller run ended with an error: {summary.error}")
    bare = bench_closed_loop(drive, cycles)
    return {"cycles": cycles, "controller_cycles_per_s": cycles / seconds,
            "controller_compute_p50_s": summary.compute_percentiles.get("p50"),
            "bare_cycles_per_s": bare.cycles_per_second}


def virtual_bus(profile: Profile, cycles: int) -> dict:
    """In-process: simulated slave + master on python-can's virtual bus."""
    from haptic_bus.app.rig import simulated_canopen

    with simulated_canopen(profile) as (_, drive):
        return _controller_rate(profile, drive, profile.gate(), cycles)


def _wait_heartbeat(bus_kwargs: dict, node_id: int, process: subprocess.Popen, timeout: float) -> None:
    import can

    deadline = time.monotonic() + timeout
    with can.Bus(**bus_kwargs) as bus:
        while time.monotonic() < deadline:
            if process.poll() is not None:
                raise RuntimeError(f"the simulator exited early with status {process.returncode}")
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x700 + node_id:
                return
    raise RuntimeError(f"no heartbeat of node {node_id} within {timeout} s")


def _stop(process: subprocess.Popen) -> int:
    process.terminate()
    try:
        return process.wait(10)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.wait(10)


def udp_multicast(profile: Profile, cycles: int) -> dict:
    """Two processes: ``python -m sim_drive`` on udp_multicast (unique port) and the master here."""
    from drives.canopen.drive import CanopenDrive
    from drives.safety import SafetySettings

    group = f"239.74.{160 + os.getpid() % 64}.{1 + os.getpid() % 250}"
    port = random.randint(45000, 55000)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(_REPO), env.get("PYTHONPATH")]))
    args = simulator_command("--interface", "udp_multicast", "--channel", group,
                             "--bus-option", f"port={port}", "--node-id", str(NODE_ID), "--profile", PROFILE)
    process = subprocess.Popen(args, cwd=_REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_heartbeat({"interface": "udp_multicast", "channel": group, "port": port}, NODE_ID, process, _START_WAIT)
        drive = CanopenDrive(NODE_ID, interface="udp_multicast", channel=group, bus_kwargs={"port": port},
                             period=profile.loop.period, scaling=profile.scaling(),
                             safety=SafetySettings().for_virtual_time(profile.loop.period))
        try:
            drive.connect()
            drive.enable()
            result = _controller_rate(profile, drive, profile.gate(), cycles)
            drive.disable()
        finally:
            drive.close()
    finally:
        status = _stop(process)
    result["simulator_exit_status"] = status
    result["bus"] = f"udp_multicast {group} port {port}"
    return result


def modbus_tcp(profile: Profile, cycles: int) -> dict:
    """Two processes over Modbus TCP loopback: haptic_bus.bench.modbus_poll's simulator and ModbusDrive."""
    import dataclasses

    from drives.modbus.drive import CYCLE_MODES, ModbusDrive
    from drives.modbus.timing import loop_delay
    from haptic_bus.bench.modbus_poll import bench_cycle, start_simulator, stop_simulator
    from haptic_bus.control.gate import PassivityGate

    process, url = start_simulator("ideal")
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
            timing = bench_cycle(url, mode, cycles)
            result["bench_cycle"][mode] = {"cycles_per_s": timing.cycles_per_second,
                                           "requests_per_cycle": timing.requests_per_cycle,
                                           "round_trip_p50_s": timing.p50, "round_trip_p99_s": timing.p99}
    finally:
        status = stop_simulator(process)
    result["simulator_exit_status"] = status
    result["url"] = url
    return result


def run(quick: bool, tick: Callable[[str], None] = lambda _: None) -> dict:
    """Benchmark 4; returns its section of ``bench.json`` (a failing link is reported, not raised)."""
    from haptic_bus.bench.hot_path import bench_pdo_codecs

    cycles = 2_000 if quick else 20_000
    profile = load_profile(PROFILE)
    links: dict[str, dict] = {}
    for key, label, func in (("virtual", "virtual bus, 1 process", virtual_bus),
                             ("udp_multicast", "udp_multicast, 2 processes", udp_multicast),
                             ("modbus_tcp", "Modbus TCP loopback, 2 processes", modbus_tcp)):
        try:
            links[key] = {"label": label, "available": True, **func(profile, cycles)}
        except Exception as exc:  # noqa: BLE001 - a link that cannot run is a row that says why
            links[key] = {"label": label, "available": False, "reason": f"{type(exc).__name__}: {exc}"}
        tick(f"loop: {label}")
    codec = bench_pdo_codecs(frames=5_000 if quick else 20_000, repeat=5)
    tick("loop: PDO codecs")
    base = links["virtual"].get("controller_cycles_per_s")
    for entry in links.values():
        if entry.get("available") and base:
            entry["ratio_to_virtual"] = entry["controller_cycles_per_s"] / base
    return {
        "description": "closed-loop cycles per second in virtual time (controller + simulated drive); "
                       "hot path vs canopen's generic PDO path",
        "profile": PROFILE,
        "links": links,
        "pdo_codec": {"frames": codec.frames, "hot_path_s": codec.hot_path_s, "generic_s": codec.generic_s,
                      "ratio_generic_over_hot": codec.ratio},
    }
