"""The CANopen master against the simulated drive: the same closed-loop scenario on every bus.

The scenario uses nothing but the master's public API and SDO (the simulator's manufacturer
objects 0x2000.. carry its plant and operator model), so it runs unchanged on python-can's
``virtual`` bus in one process, on ``udp_multicast`` with the simulator in a second process
(``python -m sim_drive``, stopped with SIGTERM), and on SocketCAN ``vcan0`` where it exists.

Numbers are checked against the exact discrete responses (:mod:`haptic_bus.analysis.plant`), with
tolerances that follow from the quantisation of the drive's units:

* velocity: 0x606C rounds to whole counts, so ``|v_measured - v_exact| <= q_v / 2`` (plus
  round-off far below a count);
* force in closed loop: each cycle adds a torque rounding error ``|r| <= F_q / 2`` (F_q the
  force of one per mille) and a velocity rounding error ``|n| <= q_v / 2``; the loop is linear,
  so the recorded force differs from the unquantised analytic response by at most
  ``||h_r||_1 F_q / 2 + ||h_n||_1 q_v / 2`` where ``h_r``, ``h_n`` are the loop's impulse
  responses from those error inputs, computed here.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from drives.canopen.drive import DEFAULT_TPDO_WITH_POSITION
from drives.cia402 import State, decode_statusword
from haptic_bus.analysis.plant import ExactPlant, zoh_coefficients

INTERFACE_PARAMS = [
    pytest.param("virtual", id="virtual-1-process"),
    pytest.param("udp_multicast", id="udp_multicast-2-processes"),
    pytest.param("socketcan", id="vcan0-2-processes", marks=pytest.mark.vcan0),
]

# The seed's device and wall.
M, B_FRICTION, T = 0.5, 0.1, 1e-3
K_WALL, B_WALL = 200.0, 100.0

OPERATOR, OPERATOR_CODE, OPERATOR_P1 = 0x2010, 1, 2  # 0x2010:01 model code, :02 p1
CONSTANT_PUSH = 1  # sim_drive.operator.OPERATOR_CODES
TIMING_OBJECT = (0x2002, 1)  # 0 cia402, 1 ideal
PLANT_OBJECT = 0x2000  # :01 m, :02 b


def read_real(drive, index: int, subindex: int) -> float:
    """A REAL64 manufacturer object over SDO."""
    return struct.unpack("<d", drive.sdo_read(index, subindex))[0]


def set_operator_push(drive, force: float) -> None:
    """The simulated operator pushes with a constant ``force`` N from the next SYNC on."""
    drive.sdo_write(OPERATOR, OPERATOR_P1, struct.pack("<d", force))
    drive.sdo_write(OPERATOR, OPERATOR_CODE, bytes([CONSTANT_PUSH]))


def check_simulator_is_the_seed_device(drive, timing: str) -> None:
    assert read_real(drive, PLANT_OBJECT, 1) == M
    assert read_real(drive, PLANT_OBJECT, 2) == B_FRICTION
    assert drive.sdo_read(*TIMING_OBJECT)[0] == {"cia402": 0, "ideal": 1}[timing]


def wall_force_response(w: float, steps: int) -> np.ndarray:
    """u_k (N) of the ideal (delay 0) wall loop for an operator force step ``w`` at k = 0.

    From the characteristic polynomial: U/W = k1 (K T z + B (z - 1)) / ((z - a)(z - 1) + k1 (K T z + B (z - 1))).
    """
    from scipy.signal import lfilter  # here, not at collection: scipy.signal brings scipy.stats, 0.7 s a worker

    co = zoh_coefficients(M, B_FRICTION, T)
    a, k1 = co.a, co.k1
    num = [0.0, k1 * (K_WALL * T + B_WALL), -k1 * B_WALL]  # in powers of z^-1
    den = [1.0, -(a + 1.0) + k1 * (K_WALL * T + B_WALL), a - k1 * B_WALL]
    return lfilter(num, den, np.full(steps, w))


def wall_error_gains(steps: int) -> tuple[float, float]:
    """l1 norms of the loop's impulse responses from a force error and from a velocity error to u_rec."""
    co = zoh_coefficients(M, B_FRICTION, T)

    def response(force_impulse: bool) -> np.ndarray:
        v = x = 0.0
        out = np.empty(steps)
        for k in range(steps):
            y = v + (0.0 if force_impulse or k else 1.0)  # measured velocity
            x += T * y
            u = K_WALL * x + B_WALL * y
            r = 1.0 if force_impulse and k == 0 else 0.0
            f = -u + r  # force the drive applies
            out[k] = -f  # recorded wall force
            v = co.a * v + co.k1 * f
        return out

    return float(np.abs(response(True)).sum()), float(np.abs(response(False)).sum())


def test_seed_wall_closed_loop_poles():
    """The analytic model's poles are the seed's 0.998 and 0.8014 (the reference the loop is judged by)."""
    co = zoh_coefficients(M, B_FRICTION, T)
    den = [1.0, -(co.a + 1.0) + co.k1 * (K_WALL * T + B_WALL), co.a - co.k1 * B_WALL]
    poles = sorted(np.roots(den).real)
    assert poles == pytest.approx([0.8014, 0.998], abs=5e-5)


@pytest.mark.parametrize("interface", INTERFACE_PARAMS)
@pytest.mark.parametrize(("timing", "delay"), [("ideal", 0), ("cia402", 1)])
def test_constant_torque_gives_the_exact_first_order_velocity(interface, timing, delay, canopen_rig):
    torque, cycles = 500, 300
    with canopen_rig(interface, timing) as r:
        drive = r.drive
        check_simulator_is_the_seed_device(drive, timing)
        drive.enable()
        assert decode_statusword(drive.last_inputs.statusword) is State.OPERATION_ENABLED
        scaling = drive.scaling
        velocities = []
        for _ in range(cycles):
            velocities.append(drive.read_inputs().velocity)
            drive.write_outputs(torque)
        drive.disable()
        assert drive.stats.missed_tpdos == 0 and drive.stats.dropped_frames == 0
    plant = ExactPlant(M, B_FRICTION, T)
    force = torque * scaling.newton_per_permille
    expected = [0.0] * (delay + 1)  # sample 0 precedes any torque; cia402 adds one sample
    while len(expected) < cycles:
        expected.append(plant.advance(force) and plant.velocity)
    measured = np.array(velocities) * scaling.velocity_per_count
    tolerance = scaling.velocity_per_count / 2 * (1 + 1e-6)
    assert np.max(np.abs(measured - np.array(expected))) <= tolerance
    assert measured[-1] > 0.5  # m/s: the response really moved


@pytest.mark.parametrize("interface", INTERFACE_PARAMS)
def test_seed_wall_step_response_matches_the_analytic_closed_loop(interface, canopen_rig):
    """u_k = K x_k + B v_k, x_k = x_{k-1} + T v_k; operator step 10 N; ideal timing (delay 0)."""
    w, cycles = 10.0, 400
    with canopen_rig(interface, "ideal") as r:
        drive = r.drive
        check_simulator_is_the_seed_device(drive, "ideal")
        drive.enable()
        set_operator_push(drive, w)
        q_v = drive.scaling.velocity_per_count
        f_q = drive.scaling.newton_per_permille
        x = 0.0
        recorded = []
        for _ in range(cycles):
            v = drive.read_inputs().velocity * q_v
            x += T * v
            u = K_WALL * x + B_WALL * v
            permille = drive.scaling.torque_permille(-u)  # the drive pushes against the operator
            drive.write_outputs(permille)
            recorded.append(-permille * f_q)
        set_operator_push(drive, 0.0)
        drive.disable()
        assert drive.stats.saturated_outputs == 0
    # The push acts from the interval that the first sample closes: sample 0 is the analytic k = 1.
    expected = wall_force_response(w, cycles + 1)[1:]
    gain_r, gain_n = wall_error_gains(cycles)
    tolerance = gain_r * f_q / 2 + gain_n * q_v / 2 + 1e-9
    error = np.max(np.abs(np.array(recorded) - expected))
    assert error <= tolerance
    assert tolerance < 0.05 * w  # the bound is tight enough to mean something
    assert abs(expected[-1] - w) < 0.01 * w  # the wall force has settled on the operator's push


def test_position_in_a_second_tpdo_matches_the_exact_plant(canopen_rig):
    """Mapping 0x6041 + 0x606C + 0x6064 needs 10 bytes: TPDO1 and TPDO2, both of each SYNC."""
    torque, cycles = 300, 200
    with canopen_rig("virtual", "ideal", tpdo_objects=DEFAULT_TPDO_WITH_POSITION) as r:
        drive = r.drive
        assert [c.size for c in drive.tpdo_codecs] == [6, 4]
        assert drive.sdo_read(0x1A01, 1) == struct.pack("<I", 0x60640020)
        drive.enable()
        positions = []
        for _ in range(cycles):
            inputs = drive.read_inputs()
            positions.append(inputs.position)
            drive.write_outputs(torque)
        scaling = drive.scaling
        assert drive.stats.missed_tpdos == 0
    plant = ExactPlant(M, B_FRICTION, T)
    expected = [0.0]
    while len(expected) < cycles:
        plant.advance(torque * scaling.newton_per_permille)
        expected.append(plant.position)
    measured = np.array(positions) * scaling.position_per_count
    assert np.max(np.abs(measured - expected)) <= scaling.position_per_count / 2 * (1 + 1e-6)
    assert math.isclose(measured[-1], expected[-1], rel_tol=1e-4)


def test_the_cycle_reads_the_exact_plant_and_counts_every_sync_the_drive_heard(canopen_rig):
    """The velocity of each cycle is the exact plant's, rounded to whole 0x606C counts; every SYNC the
    master counts (commissioning's, the enable walk's, the 50 cycles') is one the drive heard."""
    with canopen_rig("virtual", "ideal") as r:
        drive = r.drive
        drive.enable()
        velocities = []
        for _ in range(50):
            velocities.append(drive.read_inputs().velocity)
            drive.write_outputs(1000)
        assert drive.stats.cycles >= 50 and drive.stats.stale_tpdos == 0
        assert drive.stats.syncs_sent == r.sim.drive.sync_count >= 50
    plant = ExactPlant(M, B_FRICTION, T)
    expected = [0]
    for _ in range(49):
        plant.advance(1000 * drive.scaling.newton_per_permille)
        expected.append(round(plant.velocity / drive.scaling.velocity_per_count))
    assert velocities == expected
