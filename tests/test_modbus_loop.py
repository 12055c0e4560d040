"""The controller (haptic_bus.control.controller.WallController) closed through Modbus TCP on loopback:
ModbusDrive -> pymodbus -> the simulated drive's server (in a thread of this process), virtual time.

Numbers come from the exact discrete loop of the seed's device (m = 0.5 kg, b = 0.1 N s/m,
T = 1 ms) and wall (K = 200 N/m, B = 100 N s/m): with ``a = exp(-bT/m)``, ``k1 = (1 - a)/b``,
``v_{k+1} = a v_k + k1 (w_k - u_k)``, ``u_k = K x_k + B v_k``, ``x_k = x_{k-1} + T v_k``, the
force response to the operator is ``U/W = k1 ((KT + B) z - B) / D(z)`` with
``D(z) = (z - a)(z - 1) + k1 ((KT + B) z - B)``, poles 0.998 and 0.8014.

Quantisation bounds the difference, as in the CANopen loop tests: each cycle the applied force
differs from the computed one by a torque rounding ``|r| <= F_q / 2`` (``F_q`` = 10 mN, one per
mille) and the velocity by a count rounding ``|n| <= q_v / 2`` (``q_v`` = 1e-6 m/s); the loop is
linear, so the recorded force is within ``||h_r||_1 F_q / 2 + ||h_n||_1 q_v / 2`` of the exact
response, ``h_r``, ``h_n`` the impulse responses from those inputs to ``u``, computed here.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drives.cia402 import POSITION_ACTUAL
from drives.modbus.drive import ModbusDrive
from drives.modbus.timing import SAFETY_FACTOR, loop_delay, measure_poll
from drives.safety import SafetySettings
from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.control.controller import WallController
from haptic_bus.control.cycle_loop import RunSummary
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.scene import Wall, compile_scene
from sim_drive.modbus import ModbusSimServer
from sim_drive.operator import ConstantPush
from sim_drive.parameters import DeviceParameters

M, B_FRICTION, T = 0.5, 0.1, 1e-3
K_WALL, B_WALL = 200.0, 100.0
# the loop runs in virtual time: the drive's watchdog guards a dead master, not a busy machine
VIRTUAL_TIME_SAFETY = SafetySettings().for_virtual_time(T)
A = np.exp(-B_FRICTION * T / M)
K1 = -np.expm1(-B_FRICTION * T / M) / B_FRICTION
DEN = np.array([1.0, -(1.0 + A) + K1 * (K_WALL * T + B_WALL), A - K1 * B_WALL])  # D(z)
NUM_W = K1 * np.array([0.0, K_WALL * T + B_WALL, -B_WALL])  # U/W
NUM_N = np.polymul([1.0, -A], [K_WALL * T + B_WALL, -B_WALL])  # U/N: velocity rounding -> force


def l1(num: np.ndarray, n: int = 20_000) -> float:
    from scipy.signal import lfilter  # here, not at collection: scipy.signal brings scipy.stats, 0.7 s a worker

    impulse = np.zeros(n)
    impulse[0] = 1.0
    return float(np.sum(np.abs(lfilter(num, DEN, impulse))))


def quantisation_bound(newton_per_permille: float, velocity_per_count: float) -> float:
    """N: the largest force difference torque and velocity rounding can make (module docstring)."""
    return l1(NUM_W) * newton_per_permille / 2 + l1(NUM_N) * velocity_per_count / 2


PUSH, CYCLES = 2.0, 4000  # N from t = 0 (a step at cycle 0), cycles: the settling bound below needs 4000


@dataclasses.dataclass(frozen=True)
class PushedRun:
    """What one run of the seed's loop under the push left: the controller's and the drive's view."""

    cycle: str  # the Modbus cycle: "split" or "fc23"
    delay: float  # samples, as the drive announced it before enabling
    timing: str  # the simulated drive's timing, as it announced it
    summary: RunSummary
    force: np.ndarray  # N, the controller's force of every cycle
    position: float  # m, the controller's last position
    plant_time: float  # s, the simulated drive's clock at the end
    plant_position: float  # m, the simulated handle's at the end
    newton_per_permille: float
    velocity_per_count: float  # m/s
    requests_per_cycle: float


@pytest.fixture(scope="module", params=["split", "fc23"])
def pushed(request: pytest.FixtureRequest) -> PushedRun:
    """The seed's device in ideal timing, wall surface at x = 0, pushed by PUSH N from rest for CYCLES
    cycles: one run per Modbus cycle, read by the step-response and the settling tests (the step is
    the run's first cycles, the settled wall its last)."""
    parameters = DeviceParameters(mass=M, friction=B_FRICTION, period=T)
    with ModbusSimServer(timing="ideal", operator=ConstantPush(PUSH), parameters=parameters) as server, \
            ModbusDrive("127.0.0.1", server.port, cycle=request.param, timeout=2.0, with_position=True,
                        safety=VIRTUAL_TIME_SAFETY) as drive:
        drive.connect()
        delay = loop_delay(drive, T)
        gate = PassivityGate(DeviceLoop(M, B_FRICTION, T, delay))
        drive.enable()
        origin = drive.read_object(POSITION_ACTUAL) * drive.scaling.position_per_count
        scene = compile_scene([Wall("wall", 0.0, -1, K_WALL, B_WALL)])
        # the seed's b = 0.1 N s/m leaves the passivity layer's budget almost nothing: off, so that
        # the loop is the linear one the analysis describes (the layer: test_passivity_timing.py)
        controller = WallController(drive, gate, scene, force_limit=30.0, origin=origin, passivity=LayerPolicy("off"))
        summary = controller.run(CYCLES)
        return PushedRun(request.param, delay, drive.connected().simulated_timing, summary,
                         controller.record.column("force_n"), float(controller.record.column("position_m")[-1]),
                         server.drive.time, server.drive.position, drive.scaling.newton_per_permille,
                         drive.scaling.velocity_per_count, drive.stats.cyclic_requests / drive.stats.cycles)


def test_the_analytic_loop_has_the_seed_poles() -> None:
    assert sorted(np.roots(DEN).real) == pytest.approx([0.8014, 0.998], abs=5e-5)
    assert np.all(np.abs(np.roots(DEN).imag) == 0)


def test_constant_push_settles_at_f_over_k(pushed: PushedRun) -> None:
    assert pushed.delay == 0 and pushed.timing == "ideal"
    summary = pushed.summary
    assert summary.error is None and summary.cycles == CYCLES
    assert pushed.plant_time == pytest.approx(CYCLES * T)  # one plant period per Modbus cycle
    # steady state: the wall force is the push up to half a torque count plus the velocity
    # rounding's share (the quantisation bound), and the slow pole 0.998 has decayed to
    # 0.998**4000 = 3e-4 of F/K
    tolerance = (quantisation_bound(pushed.newton_per_permille, pushed.velocity_per_count)
                 + 0.998**CYCLES * PUSH) / K_WALL
    assert tolerance < 5e-5
    assert pushed.position == pytest.approx(PUSH / K_WALL, abs=tolerance)
    assert pushed.plant_position == pytest.approx(PUSH / K_WALL, abs=tolerance + T * 1e-3)
    assert not summary.observer_flagged


def test_force_step_response_is_the_analytic_discrete_loop(pushed: PushedRun) -> None:
    # the push from rest is a step of PUSH N at cycle 0: the force is the step response, over all CYCLES
    force = pushed.force
    # cycle k of the controller reads the sample taken at t = kT (no time passes while enabling)
    from scipy.signal import lfilter

    analytic = lfilter(NUM_W, DEN, np.full(CYCLES, PUSH))
    bound = quantisation_bound(pushed.newton_per_permille, pushed.velocity_per_count)
    assert bound < 0.006
    assert force[0] == 0.0 and analytic[0] == 0.0
    assert np.max(np.abs(force - analytic)) <= bound
    # real poles, no oscillation; the zero at B/(KT + B) = 0.998004, just above the slow pole,
    # gives the exact loop a 0.84 % peak at k = 43 (haptic_bus.analysis.design.force_step_response agrees)
    assert int(np.argmax(analytic)) == 43 and analytic.max() == pytest.approx(PUSH * 1.0083897, rel=1e-6)
    assert force.max() == pytest.approx(analytic.max(), abs=bound)
    assert pushed.requests_per_cycle == pytest.approx(2.0 if pushed.cycle == "split" else 1.0, abs=2 / CYCLES)


@pytest.mark.parametrize("timing, first_moving_sample", [("ideal", 1), ("cia402", 2)])
@pytest.mark.parametrize("cycle", ["split", "fc23"])
def test_torque_acts_when_the_canopen_simulator_would(timing: str, first_moving_sample: int, cycle: str) -> None:
    """A 1000 per mille (10 N) pulse written in cycle 0: ``ideal`` shows it in sample 1, ``cia402``
    (latched at the next SYNC, like a synchronous drive) in sample 2, as on CANopen."""
    with ModbusSimServer(timing=timing, parameters=DeviceParameters(mass=M, friction=B_FRICTION, period=T)) as server:
        with ModbusDrive("127.0.0.1", server.port, cycle=cycle, timeout=2.0, safety=VIRTUAL_TIME_SAFETY) as drive:
            drive.connect()
            assert loop_delay(drive, T) == {"ideal": 0, "cia402": 1}[timing]
            drive.enable()
            velocities = []
            for k in range(4):
                velocities.append(drive.read_inputs().velocity)
                drive.write_outputs(1000 if k == 0 else 0)
    expected_first = round(K1 * 10.0 / 1e-6)  # counts of 1e-6 m/s
    assert velocities[:first_moving_sample] == [0] * first_moving_sample
    assert velocities[first_moving_sample] == expected_first
    assert velocities[first_moving_sample + 1] == round(A * K1 * 10.0 / 1e-6)


def test_poll_timing_on_loopback_gives_the_fractional_delay_of_its_round_trip() -> None:
    with ModbusSimServer(timing="ideal") as server:
        with ModbusDrive("127.0.0.1", server.port, cycle="split", timeout=2.0) as drive:
            drive.connect()
            poll = measure_poll(drive, 300)
    assert poll.cycles == 300 and poll.requests_per_cycle == 2.0
    assert 0 < poll.p50 <= poll.p99 <= poll.max
    # the force lands at most one round trip after the sample: D = 1.5 p99 / T samples, real
    assert poll.assumed_delay(T) == pytest.approx(SAFETY_FACTOR * poll.p99 / T, rel=1e-15)
    assert server.drive.state.value == "SWITCH ON DISABLED"  # measuring wrote the safe outputs only


def test_a_simulated_drive_with_reception_timing_announces_its_fractional_delay() -> None:
    """Registers 0x0050 (timing 2) and 0x0060 (delta): the gate judges with D = 0.3 samples."""
    parameters = DeviceParameters(mass=M, friction=B_FRICTION, period=T, reception_delay=0.3)
    with ModbusSimServer(timing="reception", parameters=parameters) as server, \
            ModbusDrive("127.0.0.1", server.port, timeout=2.0, safety=VIRTUAL_TIME_SAFETY) as drive:
        drive.connect()
        assert drive.connected().simulated_timing == "reception" and loop_delay(drive, T) == 0.3
