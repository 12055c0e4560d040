"""The controller end to end through the bus: simulated drive (real CANopen slave) + master +
controller, in one process on python-can's virtual bus, virtual time."""

from __future__ import annotations

import dataclasses
import math
import random
import threading
import time
import uuid

import numpy as np
import pytest

from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.design import force_step_response
from haptic_bus.analysis.energy import commensurate_theta
from haptic_bus.analysis.frequency import t_fund
from haptic_bus.analysis.loop import DeviceLoop, WallLoop
from haptic_bus.app.cli import main
from haptic_bus.app.profiles import load_profile
from haptic_bus.app.rig import simulated_canopen
from haptic_bus.control.controller import WallController
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.joints import encoder_origin
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.scene import Wall, compile_scene
from haptic_bus.errors import Refusal
from haptic_bus.node.controller_node import ABORT_INVALID_VALUE, ControllerNode
from haptic_bus.node.upload import upload_walls
from sim_drive.operator import ConstantPush, Sinusoid, StepPush


def seed_at_the_wall():
    """The seed-ideal profile with its wall's surface where the handle starts (x = 0): in contact
    from the first push, the linear case the analysis describes."""
    profile = load_profile("seed-ideal")
    wall = Wall("wall", 0.0, -1, 200.0, 100.0)
    return dataclasses.replace(profile, scene=(wall,))


def controller_for(profile, drive, **kwargs) -> WallController:
    return WallController(drive, profile.gate(), profile.compiled_scene(), force_limit=profile.force_limit,
                          origin=encoder_origin(drive), **kwargs)


def test_constant_push_settles_at_f_over_k() -> None:
    profile = load_profile("cia402-handle")
    push = 3.0
    with simulated_canopen(profile, operator=ConstantPush(push)) as (sim, drive):
        controller = controller_for(profile, drive)
        energy_before = sim.drive.operator_energy
        summary = controller.run(1500)
        true_position = sim.drive.position
        operator_energy = sim.drive.operator_energy - energy_before
    assert summary.error is None and summary.cycles == 1500
    wall = profile.scene[0]
    x = controller.record.column("position_m")[-1]
    # The torque target is whole per-mille counts: the wall force can sit up to half a count
    # (newton_per_permille / 2) from the push, so the penetration up to that over K.
    resolution = drive.scaling.newton_per_permille / wall.stiffness
    assert x - wall.position == pytest.approx(push / wall.stiffness, abs=resolution)
    # x_k = x_0 + T sum(v_k) is a Riemann sum of the exact integral the drive's plant does: the two
    # differ by at most one sample of travel (T max|v|), never by drift
    v = controller.record.column("velocity_m_per_s")
    assert x == pytest.approx(true_position, abs=1e-3 * np.max(np.abs(v)))
    # the port's energy from positions (b dx^2/T - F dx a period) is what the operator put in, which
    # the drive integrates exactly, less the kinetic energy (nil at rest): within a per cent
    assert not summary.observer_flagged and summary.observer_active_cycles == 0
    assert summary.energy == pytest.approx(operator_energy, rel=0.01)
    assert summary.layer == "guard" and summary.layer_interventions == 0


def test_seed_design_with_ideal_timing_reproduces_the_analysis_step_response() -> None:
    profile = seed_at_the_wall()
    level = 2.0
    # the drive's clock runs from its first SYNC (enable walks take a few): step well after that
    with simulated_canopen(profile, operator=StepPush(level, 0.3)) as (sim, drive):
        controller = controller_for(profile, drive, passivity=LayerPolicy("off"))  # the linear analysis: nothing else acts
        controller.run(1800)
        assert sim.drive.time - controller.cycles * 1e-3 < 0.25
    force = controller.record.column("force_n")
    onset = int(np.flatnonzero(np.abs(force) > 0)[0])  # analytic u_0 = 0, u_1 is the first push
    loop = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0)
    analytic = level * force_step_response(loop, 1400).force
    measured = force[onset - 1: onset - 1 + analytic.size]
    # quantisation: torque in 10 mN counts (the applied force differs by <= 5 mN each cycle,
    # a disturbance the loop passes with unit DC gain) and velocity in 1e-6 m/s counts (B * 1e-6)
    assert np.max(np.abs(measured - analytic)) < 0.01
    # the seed's Fig. 6 shows no overshoot; exactly, the zero at z = B/(KT + B) = 0.998004 just
    # outside the slow pole 0.997986 gives 0.84 % at 43 ms, and the bus reproduces that too
    report = force_step_response(loop).report
    assert report.overshoot == pytest.approx(0.839, abs=0.01) and not report.oscillatory
    assert measured.max() == pytest.approx(level * report.peak, abs=0.01)


def test_a_wall_that_only_a_wrong_friction_made_passive_gives_energy_as_the_analysis_says() -> None:
    """Datasheets rarely give b.  The gate is told b = 20 N s/m (cia402 timing, d = 1) and
    passes K = 200, B = 10 with margin +11.6 N s/m; the real handle has the seed's b = 0.1,
    where the same wall is active (margin -8.3 N s/m at theta = 2.006).  At run time the
    operator's exact power matches the d = 1 analysis of the real loop (the passivity layer off, so
    that nothing but the wall acts) -- but the port observer, which credits the claimed b with its
    dissipation, never goes below zero: a wrong effective b is invisible to any observer that does
    not measure the operator's force."""
    claimed = DeviceLoop(0.5, 20.0, 1e-3, 1)
    real = WallLoop(0.5, 0.1, 1e-3, 200.0, 10.0, delay=1)
    assert PassivityGate(claimed).judge(compile_scene([Wall("wall", 0.0, -1, 200.0, 10.0)])).accepted
    # the critical theta rounded to 2 pi p/q, so that q samples hold whole periods
    p, q = commensurate_theta(exact_verdict(real).critical_theta, max_samples=64)
    theta = 2 * math.pi * p / q
    # N: the preload keeps the handle 2.5 mm inside the (unilateral) wall, while the 10 N
    # sinusoid moves it by about 5 um; with a 1 mN torque LSB (0x6076 = 20 mN m, 0x6072 =
    # 30000) the wall's B v ~ 0.1 N spans ~100 counts (a 3-sample period quantises
    # deterministically, biasing the power by about LSB / amplitude)
    amplitude, preload = 10.0, 0.5
    profile = load_profile("seed-ideal")
    profile = dataclasses.replace(
        profile,
        device=dataclasses.replace(profile.device, rated_torque=0.02, max_torque_permille=30000),
        loop=dataclasses.replace(profile.loop, timing="cia402"),
        scene=(Wall("wall", 0.0, -1, 200.0, 10.0),),
    )
    operator = Sinusoid(amplitude, theta / (2 * math.pi * 1e-3), 0.0, preload)
    with simulated_canopen(profile, operator=operator, substeps=64) as (sim, drive):
        controller = WallController(drive, PassivityGate(claimed), profile.compiled_scene(),
                                    force_limit=profile.force_limit, origin=encoder_origin(drive),
                                    passivity=LayerPolicy("off"))
        controller.run(3000)
        e0, t0, x0 = sim.drive.operator_energy, sim.drive.time, sim.drive.position
        controller.run(q * (3000 // q))
        e1, t1, x1 = sim.drive.operator_energy, sim.drive.time, sim.drive.position
    # the preload's work is exactly preload * displacement (it removes the slow creep); the
    # rest is the sinusoid's
    power = (e1 - e0 - preload * (x1 - x0)) / (t1 - t0)
    predicted = amplitude**2 * t_fund(real, theta)[0].real / 2
    assert predicted < 0
    assert power == pytest.approx(predicted, rel=0.03)
    assert sim.drive.wall_energy < 0  # the motor gave energy out
    assert not controller.ports[0].observer.flagged  # it trusts b = 20 N s/m


def test_refused_upload_on_the_api_keeps_the_running_wall() -> None:
    profile = seed_at_the_wall()
    with simulated_canopen(profile) as (_sim, drive):
        controller = controller_for(profile, drive)
        controller.run(10)
        before = controller.scene
        with pytest.raises(Refusal, match=r"passive K at this B: \[0, 1.8e\+06\) N/m"):
            controller.set_wall("wall", 2.0e6, 100.0)
        controller.run(10)
        assert controller.scene is before and controller.applied_scenes == 0
        controller.set_wall("wall", 300.0, 150.0)
        controller.run(1)
        assert controller.scene.by_name()["wall"].stiffness == 300.0 and controller.applied_scenes == 1


def test_refused_upload_over_the_bus_is_an_sdo_abort_and_changes_nothing() -> None:
    profile = seed_at_the_wall()
    channel = f"upload-{uuid.uuid4().hex[:10]}"
    bus = {"interface": "virtual", "channel": channel}  # the node on the drive's network; the client a bus handle of its own
    with simulated_canopen(profile, channel=channel, interface="virtual") as (_sim, drive):
        controller = controller_for(profile, drive)
        with ControllerNode(controller, 42).attached(drive.link.network):
            # between runs canopen's notifier reads the drive's bus (in a run the control thread does)
            drive.link.read_by_notifier()
            with pytest.raises(Refusal) as info:
                upload_walls(bus, 42, {0: (2.0e6, 100.0)})
            assert f"(abort 0x{ABORT_INVALID_VALUE:08X})" in str(info.value)
            (reason,) = info.value.reasons  # the node's 0x2002 text
            assert reason.startswith("refused: passivity gate refused") and "K = 2e+06" in reason
            controller.run(5)
            assert controller.scene.by_name()["wall"].stiffness == 200.0
            drive.link.read_by_notifier()
            assert upload_walls(bus, 42, {0: (250.0, 120.0)}).startswith("accepted")
            controller.run(1)
            assert controller.scene.by_name()["wall"].damping == 120.0
            drive.link.read_by_notifier()
            # the CLI path, same bus: exit 1 for a refusal, one line on stderr
            args = ["upload", "--interface", "virtual", "--channel", channel, "--node-id", "42", "--object", "0"]
            assert main([*args, "--stiffness", "5e6", "--damping", "1"]) == 1
            assert main([*args, "--stiffness", "nan", "--damping", "1"]) == 2
            assert main([*args, "--stiffness", "210", "--damping", "110"]) == 0
            controller.run(1)
            assert controller.scene.by_name()["wall"].stiffness == 210.0


def test_a_verdict_judged_against_a_scene_no_longer_the_latest_is_refused() -> None:
    """The controller node's worker judged against the latest scene; another upload accepted in
    between makes that verdict stale: refused, the other upload kept."""
    from haptic_bus.node.verdicts import judge_walls

    profile = seed_at_the_wall()
    with simulated_canopen(profile) as (_sim, drive):
        controller = controller_for(profile, drive)
        scenes = controller.scenes
        judged = (scenes.gate, scenes.latest)
        verdict = judge_walls(scenes.gate, scenes.latest.scene, {"wall": (300.0, 150.0)})
        assert not isinstance(verdict, str) and verdict[1].accepted
        controller.set_wall("wall", 250.0, 120.0)
        with pytest.raises(Refusal, match=r"the scene \(now scene 1\) changed while the upload was judged"):
            scenes.stage(*verdict, judged)
        assert controller.latest_scene.by_name()["wall"].stiffness == 250.0
        assert judge_walls(scenes.gate, scenes.latest.scene, {"wall": (float("nan"), 1.0)}) == (
            "wall 'wall': stiffness = nan is invalid; allowed: a finite real in [0, 1e+15] N/m")  # plain data back


def test_a_storm_of_concurrent_uploads_never_tears_k_from_b() -> None:
    profile = seed_at_the_wall()
    passive = [(200.0, 100.0), (300.0, 150.0), (1000.0, 400.0)]
    active = [(2.0e6, 100.0), (200.0, 2000.0)]
    seen: set[tuple[float, float]] = set()
    refusals = []
    accepted = []
    stop = threading.Event()

    def uploader(seed: int) -> None:
        rng = random.Random(seed)
        for _ in range(60):
            if stop.is_set():
                return
            K, B = rng.choice(passive + active)
            try:
                controller.set_wall("wall", K, B)
                accepted.append((K, B))
            except Refusal:
                refusals.append((K, B))

    def watch(c: WallController) -> None:
        wall = c.scene.by_name()["wall"]
        seen.add((wall.stiffness, wall.damping))
        assert c.scene.stiffness[-1] == wall.stiffness and c.scene.damping[-1] == wall.damping

    with simulated_canopen(profile) as (_sim, drive):
        controller = controller_for(profile, drive)
        threads = [threading.Thread(target=uploader, args=(seed,)) for seed in range(4)]
        for t in threads:
            t.start()
        deadline = time.monotonic() + 30
        while any(t.is_alive() for t in threads) and time.monotonic() < deadline:
            summary = controller.run(50, on_cycle=watch)
            assert summary.error is None
        stop.set()
        for t in threads:
            t.join(timeout=10)
        controller.run(1)
        # the last accepted upload runs: none was dropped between staging and the swap
        assert controller.scene is controller.latest_scene
    assert refusals and accepted
    assert seen <= set(passive), f"a torn or refused wall ran: {seen - set(passive)}"


@pytest.mark.parametrize("fault", ["silent", "fault", "emcy"])
def test_a_drive_fault_ends_the_run_safely_and_keeps_the_record(fault: str, tmp_path) -> None:
    profile = seed_at_the_wall()
    with simulated_canopen(profile, operator=ConstantPush(1.0)) as (sim, drive):
        # the lock-step bus serves each frame in its sender's thread: a TPDO that comes is in before the SYNC's send
        # returns, so only a missed one waits, 50 ms, not the rig's 0.5 s (three of them for the silent drive)
        drive.cycle.timeout = 0.05
        controller = controller_for(profile, drive)

        def inject(c: WallController) -> None:
            if c.cycles == 100:
                {"silent": sim.go_silent, "fault": lambda: sim.enter_fault(0x2310),
                 "emcy": lambda: sim.send_emcy(0x4310)}[fault]()

        summary = controller.run(1000, on_cycle=inject)
        last_torque = sim.drive.target_torque if fault != "silent" else None
        if fault == "silent":
            sim.resume()  # the drive answers the master's goodbye (silent, it held each of its SDOs)
    assert summary.error is not None and "node 1" in summary.error
    assert 100 <= summary.cycles <= 110  # detected within a few cycles (max_missed_tpdos = 3)
    assert controller.record.total == summary.cycles
    path = controller.record.write_csv(tmp_path / "fault.csv")
    assert len(path.read_text().splitlines()) == summary.cycles + 1
    if last_torque is not None:
        assert last_torque == 0  # the master's safe stop: zero torque, DISABLE VOLTAGE


def test_force_is_saturated_at_the_profile_limit_and_counted() -> None:
    profile = dataclasses.replace(seed_at_the_wall(), force_limit=0.5)
    with simulated_canopen(profile, operator=ConstantPush(2.0)) as (_sim, drive):
        controller = controller_for(profile, drive)
        summary = controller.run(400)
    assert summary.saturated_cycles > 0
    assert summary.peak_force == 0.5
    assert np.max(np.abs(controller.record.column("force_n"))) == 0.5


def test_a_target_beyond_the_drives_limit_is_clamped_once_and_counted_once() -> None:
    # The handle starts 1 m inside a 200 N/m wall: 200 N asked, the drive allows 0x6072 = 3000 per
    # mille = 30 N, the profile's force limit (100 N) is above that: the drive's clamp (the one
    # place a target is saturated) holds it at -3000 and counts it; nothing else clamps or counts.
    profile = load_profile("seed-ideal")
    profile = dataclasses.replace(profile, scene=(Wall("wall", -1.0, -1, 200.0, 100.0),), force_limit=100.0)
    with simulated_canopen(profile) as (sim, drive):
        limit = drive.scaling.max_torque_permille
        assert limit == 3000 and drive.scaling.max_force < profile.force_limit
        controller = controller_for(profile, drive)
        summary = controller.run(1)
        drive.read_inputs()  # the SYNC at which the drive applies the cycle's RPDO
        applied = sim.drive.target_torque
    assert summary.exit_reason == "completed" and summary.cycles == 1
    assert summary.saturated_cycles == 1 and drive.stats.saturated_outputs == 1
    assert int(controller.record.column("torque_permille")[0]) == -limit == applied
    assert controller.record.column("force_n")[0] == pytest.approx(limit * drive.scaling.newton_per_permille, rel=1e-12)


def test_a_frame_with_the_wrong_length_is_dropped_counted_and_the_run_goes_on() -> None:
    profile = seed_at_the_wall()
    with simulated_canopen(profile, operator=ConstantPush(1.0)) as (sim, drive):
        controller = controller_for(profile, drive)
        summary = controller.run(300, on_cycle=lambda c: sim.short_next_tpdo() if c.cycles == 100 else None)
        dropped, missed = drive.stats.dropped_frames, drive.stats.missed_tpdos
    assert summary.error is None and summary.cycles == 300
    assert dropped == 1 and missed == 1  # never decoded; that cycle held the last velocity


def test_real_clock_paces_the_loop_and_reports_every_late_start() -> None:
    """The deadline scheduler at T = 1 ms for 100 cycles: every start's lateness is kept and
    summarised, overruns counted (no threshold asserted: this machine is shared)."""
    from haptic_bus.control.clock import RealClock

    profile = seed_at_the_wall()
    with simulated_canopen(profile) as (_sim, drive):
        controller = controller_for(profile, drive, clock=RealClock(1e-3))
        started = time.perf_counter()
        summary = controller.run(100)
        elapsed = time.perf_counter() - started
    assert summary.error is None and summary.cycles == 100
    assert elapsed >= 0.099  # paced: the 100th start is due 99 ms after the first
    late = controller.clock.lateness()
    assert late.size == 100 and np.all(late >= 0)
    assert set(summary.lateness_percentiles) == {"p50", "p99", "p99.9", "max"}
    assert summary.overruns == int(np.sum(late > 1e-3)) and summary.clock.startswith("real")
