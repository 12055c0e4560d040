"""The simulated drive's hidden departures from the model (issue 27, item 3): ``--extra-delay`` and
``--transmission``, exact between samples, out of the master's reach, refused with one line when invalid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drives.cia402 import Command
from drives.modbus.register_map import REGISTERS
from haptic_bus.analysis.plant import zoh_coefficients
from haptic_bus.analysis.transmission import Transmission
from sim_drive.canopen.manufacturer import ManufacturerObjects
from sim_drive.canopen.pdo_engine import SlaveCounters
from sim_drive.cli import _parse, build_parser, main
from sim_drive.device import SimulatedDrive
from sim_drive.handle import Handle, Step
from sim_drive.modbus.bank import RegisterBank
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.setups import drive_setup
from sim_drive.transmission import TwoMassHandle
from tests.run_rig import enabled_drive

M, B, T = 1.0, 20.0, 1e-3
ROUND_OFF = 1e-12  # relative: a few dozen exact steps, each a handful of roundings


def _velocities(drive: SimulatedDrive, targets: list[int]) -> list[float]:
    """The true (motor-side) velocity after each SYNC, target ``targets[k]`` written after SYNC k."""
    found = []
    for target in targets:
        drive.sync()
        found.append(drive.velocity)
        drive.write_object(0x6071, target)
    return found


@pytest.mark.parametrize("timing, extra", [(Timing.IDEAL, 1.3), (Timing.RECEPTION, 1.05)])
def test_every_timing_with_its_extra_delay_is_the_same_loop_delay(timing: Timing, extra: float) -> None:
    """cia402 + 0.3, ideal + 1.3 and reception (0.25) + 1.05 all apply each target 1.3 samples after its sample."""
    rng = np.random.default_rng(3)
    targets = [int(t) for t in rng.integers(-900, 900, 40)]
    base = DeviceParameters(mass=M, friction=B, reception_delay=0.25)
    reference = _velocities(enabled_drive(DeviceParameters(mass=M, friction=B, extra_delay=0.3)), targets)
    other = _velocities(enabled_drive(DeviceParameters(mass=M, friction=B, reception_delay=0.25, extra_delay=extra), timing),
                        targets)
    assert other == pytest.approx(reference, rel=ROUND_OFF, abs=ROUND_OFF * max(map(abs, reference)))
    assert _velocities(enabled_drive(base), targets) != pytest.approx(reference, rel=1e-3)  # the delay shows


def test_the_delayed_torque_switches_at_its_instant_within_the_period() -> None:
    """A step written after SYNC 0 is latched at SYNC 1 and acts from 0.3 T after it: at SYNC 2 the
    handle has moved under it for 0.7 T exactly (the exact ZOH over 0.7 T), 0x6077 still says the timing's."""
    drive = enabled_drive(DeviceParameters(mass=M, friction=B, extra_delay=0.3))
    drive.sync()
    drive.write_object(0x6071, 1000)
    drive.sync()
    assert drive.velocity == 0.0 and drive.torque_actual == 1000  # the master sees the torque it asked for
    drive.sync()
    force = 1000 * drive.parameters.rated_torque / 1000 * drive.parameters.force_per_torque
    assert drive.velocity == pytest.approx(force * zoh_coefficients(M, B, 0.7 * T).k1, rel=ROUND_OFF)


def test_a_drive_not_enabled_flushes_the_delayed_targets() -> None:
    drive = enabled_drive(DeviceParameters(mass=M, friction=B, extra_delay=2.5))
    drive.sync()
    drive.write_object(0x6071, 500)
    for _ in range(3):  # latched at the first SYNC, on the 2.5-sample line since: due at the fourth
        drive.sync()
    assert drive.velocity == 0.0  # still on its way when the drive is disabled
    drive.write_controlword(Command.DISABLE_OPERATION.word)
    for _ in range(5):
        drive.sync()
    assert drive.velocity == 0.0 and drive.wall_energy == 0.0


def _free_motor_velocities(transmission: Transmission, cycles: int) -> np.ndarray:
    drive = enabled_drive(DeviceParameters(mass=M, friction=B, transmission=transmission))
    return np.array(_velocities(drive, [1000] + [0] * (cycles - 1)))


def test_a_transmission_rings_at_its_two_mass_frequency() -> None:
    """20000 N/m to a 0.3 kg motor under the 1 kg handle: the motor's velocity after a torque pulse
    rings at sqrt(k (1/M + 1/m)) = 46.9 Hz (the zero crossings of its oscillation about the drift)."""
    transmission = Transmission(20000.0, 0.0, 0.3)
    assert transmission.resonance(M) == pytest.approx(46.85, abs=0.01)
    v = _free_motor_velocities(transmission, 400)
    drift = np.convolve(v, np.ones(21) / 21, mode="same")  # 21 ms is one period of 46.9 Hz to 1.6 %
    ring = (v - drift)[30:370]
    crossings = np.flatnonzero(np.diff(np.sign(ring)) != 0)
    period = 2 * np.mean(np.diff(crossings)) * T
    assert 1.0 / period == pytest.approx(transmission.resonance(M), rel=0.03)  # 1 ms samples of a 21 ms period


def test_a_stiff_transmission_is_a_rigid_handle_of_both_masses() -> None:
    """k 1e8 N/m, c 2e4 N s/m (over-damped: its modes decay within 0.1 ms): the motor's velocity at every
    sample is that of a rigid m + M (exact ZOH) to within the coupling's lag, about c/k = 0.2 ms of 1 ms."""
    v = _free_motor_velocities(Transmission(1e8, 2e4, 0.3), 30)
    rigid = _velocities(enabled_drive(DeviceParameters(mass=M + 0.3, friction=B)), [1000] + [0] * 29)
    assert v == pytest.approx(rigid, rel=1e-3, abs=1e-3 * max(map(abs, rigid)))


def test_the_transmissions_energy_ledger_balances() -> None:
    """operator work = kinetic and spring energy + b and c losses + the motor's work taken out, to round-off."""
    handle = TwoMassHandle(Transmission(20000.0, 2.0, 0.3))
    handle.configure(DeviceParameters(mass=M, friction=B, substeps=4))
    from sim_drive.operator import Sinusoid

    handle.operator = Sinusoid(2.0, 30.0)
    for k in range(300):
        handle.advance(0.5 * math.sin(k / 7), 0.5 * math.sin(k / 7))
    balance = handle.mechanical_energy() + handle.viscous_energy + handle.wall_energy
    assert handle.operator_energy == pytest.approx(balance, rel=1e-9, abs=1e-12)
    assert handle.viscous_energy > 0 and handle.operator_energy != 0


def test_a_late_sync_moves_the_transmission_exactly_as_two_periods_do() -> None:
    """A real-time drive passes the interval since the last SYNC: 2 T with the force held is, for the
    exact plant, the same as two periods of T (its sub-steps as long as the period's)."""
    parameters = DeviceParameters(mass=M, friction=B, substeps=2)
    stretched, stepped = (TwoMassHandle(Transmission(20000.0, 2.0, 0.3)) for _ in range(2))
    for handle in (stretched, stepped):
        handle.configure(parameters)
        handle.advance(1.5, 1.5)
    stretched.advance_for(2 * T, 0.7, 0.7)
    stepped.advance(0.7, 0.7)
    stepped.advance(0.7, 0.7)
    assert stretched.state == pytest.approx(stepped.state, rel=ROUND_OFF, abs=ROUND_OFF * np.max(np.abs(stepped.state)))
    assert stretched.time == stepped.time == pytest.approx(3 * T)


def test_a_transmission_is_one_axis_only(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--interface", "virtual", "--channel", "departures", "--node-ids", "5,6", "--transmission",
                 "20000:2:0.3"]) == 2
    assert "one axis only" in capsys.readouterr().err


def test_the_hidden_departures_are_out_of_the_masters_reach() -> None:
    """Every SDO object and Modbus register reads the same with and without them (before motion)."""
    plain = SimulatedDrive(DeviceParameters(mass=M, friction=B))
    hidden = SimulatedDrive(DeviceParameters(mass=M, friction=B, extra_delay=0.3, transmission="20000:2:0.3"))
    for index in plain.readable_objects():
        assert plain.read_object(index) == hidden.read_object(index)
    objects = [ManufacturerObjects(drive, SlaveCounters()) for drive in (plain, hidden)]
    for index in (0x2000, 0x2001, 0x2002, 0x2003, 0x2010):
        for sub in range(1, 8):
            assert objects[0].read(index, sub) == objects[1].read(index, sub)
    banks = [RegisterBank(drive) for drive in (plain, hidden)]
    for spec in REGISTERS:
        assert banks[0].read(spec.address, spec.end - spec.address) == banks[1].read(spec.address, spec.end - spec.address)


def test_the_flags_reach_the_truth() -> None:
    parameters, _, _ = drive_setup(_parse(build_parser(), ["--interface", "virtual", "--channel", "x", "--node-id", "5",
                                                            "--transmission", "20000:2:0.3", "--extra-delay", "0.3"]))
    assert parameters.coupling == Transmission(20000.0, 2.0, 0.3) and parameters.extra_delay == 0.3


@pytest.mark.parametrize("flags, allowed", [
    (["--transmission", "20000:2"], "STIFFNESS:DAMPING:MOTOR_MASS (N/m, N s/m, kg), stiffness in (0, 1e+12] N/m"),
    (["--transmission", "0:2:0.3"], "stiffness in (0, 1e+12] N/m"),
    (["--transmission", "20000:2:0.3", "--coulomb", "0.1"], "no transmission with Coulomb friction"),
    (["--extra-delay", "-0.1"], "a finite real in [0, 100] samples"),
    (["--extra-delay", "soon"], "a finite real in [0, 100] samples"),
])
def test_invalid_departures_exit_2_with_one_line(flags: list[str], allowed: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--interface", "virtual", "--channel", "departures", "--node-id", "5", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and allowed in err[0] and err[0].startswith("haptic-bus sim: error: --")


@pytest.mark.parametrize("velocity", ["average", "window:0.0003", "lowpass:0.002"])
def test_late_and_early_syncs_reuse_kept_steps_and_move_the_handle_bit_for_bit_as_steps_made_afresh(velocity: str) -> None:
    """A wall clock's SYNC closes an interval other than T: its pieces are kept per length, and a piece
    as long as one already met (the window piece of every interval longer than T with ``average``) is not
    computed again.  The same numbers as every step computed afresh, to the bit."""
    from haptic_bus.analysis.velocity import VelocityModel

    parameters = DeviceParameters(mass=2.0, friction=30.0, period=2e-3, velocity=VelocityModel.parse(velocity),
                                  velocity_per_count=1e-9)
    kept, fresh = enabled_drive(parameters), enabled_drive(parameters)
    handle, fresh_handle = kept.handle, fresh.handle
    assert isinstance(handle, Handle) and isinstance(fresh_handle, Handle)
    fresh_handle._kept_step = fresh_handle._step  # type: ignore[method-assign]  # every piece's step made anew
    made: list[float] = []
    step = handle._step

    def counted(h: float) -> Step:
        made.append(h)
        return step(h)

    handle._step = counted  # type: ignore[method-assign]
    intervals = [2e-3 + k * 1e-6 for k in (0, 137, -211, 137, 498, -4, 0, 1, -211, 12, 498, 300)]
    for k, interval in enumerate(intervals):
        for drive in (kept, fresh):
            drive.sync(interval)
            drive.write_object(0x6071, (-1) ** k * 100 * (k + 1))
        assert (kept.velocity, kept.position, kept.velocity_counts) == (fresh.velocity, fresh.position, fresh.velocity_counts)
        assert (kept.operator_energy, kept.wall_energy, kept.viscous_energy) == \
            (fresh.operator_energy, fresh.wall_energy, fresh.viscous_energy)
    assert kept.velocity != 0.0 and kept.viscous_energy > 0.0  # it moved: the comparison compared something
    if velocity == "average":  # one step per new interval: a longer one's window piece is T long, made at configure
        assert len(made) == len(set(intervals) - {2e-3}) and 2e-3 not in made
    assert len(made) == len(set(made))  # no length made twice
