"""The simulated drive's hidden truth: Coulomb friction, velocity noise, and how profiles state them."""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest

from drives.cia402 import Command
from haptic_bus.errors import ParameterError
from sim_drive.device import SimulatedDrive
from sim_drive.handle import Handle
from sim_drive.operator import ConstantPush, Sinusoid
from sim_drive.parameters import DeviceParameters, Timing
from sim_drive.profile import read_simulated_device

M, B = 0.5, 2.0  # kg, N s/m: time constant m/b = 0.25 s


def enable(drive: SimulatedDrive) -> SimulatedDrive:
    """CST and OPERATION ENABLED."""
    drive.write_object(0x6060, 10)
    for command in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        drive.write_controlword(command.word)
    return drive


def ledger_residual(drive: SimulatedDrive) -> float:
    """``operator - (kinetic + viscous + Coulomb + motor)`` in J: zero for an exact ledger from rest."""
    kinetic = 0.5 * drive.parameters.mass * drive.velocity**2
    return drive.operator_energy - (kinetic + drive.viscous_energy + drive.friction_energy + drive.wall_energy)


# --------------------------------------------------------------------------- Coulomb friction


@pytest.mark.parametrize("operator", [ConstantPush(1.9), ConstantPush(-1.9), Sinusoid(1.2, 30.0, offset=0.7)])
def test_a_push_below_the_coulomb_force_does_not_move_a_resting_handle(operator) -> None:
    """|w + F| <= Fc throughout (F = 0.05 N from the motor): the handle sticks, exactly, and nothing does work."""
    drive = enable(SimulatedDrive(DeviceParameters(mass=M, friction=B, coulomb_friction=2.0, substeps=4), "ideal", operator))
    drive.sync()
    drive.write_object(0x6071, -5 if operator.force(0.0, 0.0, 0.0) < 0 else 5)
    for _ in range(1000):
        drive.sync()
    assert (drive.velocity, drive.position, drive.velocity_counts, drive.position_counts) == (0.0, 0.0, 0, 0)
    assert drive.operator_energy == drive.wall_energy == drive.friction_energy == drive.viscous_energy == 0.0


@pytest.mark.parametrize("push", [3.0, -3.0])
def test_above_it_the_velocity_is_the_first_order_response_to_the_push_minus_fc(push: float) -> None:
    """From rest, ``v(t) = ((F - Fc sgn F)/b)(1 - exp(-b t/m))`` and the steady velocity is ``(F - Fc)/b``
    (32 time constants: ``exp(-32) = 1.3e-14`` of it is left); exact ZOH, so to 1e-12 relative."""
    coulomb = 1.0
    drive = SimulatedDrive(DeviceParameters(mass=M, friction=B, coulomb_friction=coulomb), operator=ConstantPush(push))
    steady = (push - math.copysign(coulomb, push)) / B
    for k in range(8001):
        drive.sync()
        if k % 250 == 0:
            assert drive.velocity == pytest.approx(steady * -math.expm1(-B * k * 1e-3 / M), rel=1e-12, abs=1e-300)
    assert drive.velocity == pytest.approx(steady, rel=1e-12)
    assert abs(ledger_residual(drive)) <= 1e-12 * drive.operator_energy


@pytest.mark.parametrize("b", [B, 0.0])
@pytest.mark.parametrize("substeps", [1, 3])
def test_a_sliding_handle_stops_when_and_where_the_closed_form_says(b: float, substeps: int) -> None:
    """Coasting at ``v0`` against ``Fc`` alone: it stops at ``t* = (m/b) log(1 + b v0/Fc)`` (``m v0/Fc`` for
    b = 0), at ``x* = (m v0 - Fc t*)/b`` (``m v0^2/(2 Fc)``), and stays: velocity exactly 0 after.
    The Coulomb loss is ``Fc x*`` and the viscous loss the rest of ``m v0^2/2`` (to round-off)."""
    v0, coulomb = 0.3037, 1.0
    handle = Handle(DeviceParameters(mass=M, friction=b, coulomb_friction=coulomb, substeps=substeps))
    handle.velocity = v0
    stop = M / b * math.log1p(b * v0 / coulomb) if b else M * v0 / coulomb
    where = (M * v0 - coulomb * stop) / b if b else M * v0 * v0 / (2 * coulomb)
    assert 0.1 < stop < 0.2 and stop * 1e3 % 1 > 0.01  # the stop falls inside a period
    for _ in range(300):
        handle.advance(0.0, 0.0)
    assert handle.velocity == 0.0
    assert handle.position == pytest.approx(where, rel=1e-12)
    assert handle.friction_energy == pytest.approx(coulomb * where, rel=1e-12)
    assert handle.viscous_energy == pytest.approx(0.5 * M * v0 * v0 - coulomb * where, rel=1e-11, abs=1e-15)


def test_stops_inside_pieces_compose_exactly_across_sub_steps() -> None:
    """Held forces with stops, sticks and reversals inside the pieces: 1 or 7 sub-steps per period give
    the same motion to round-off (a stop found approximately would depend on where pieces end)."""
    drives = [enable(SimulatedDrive(DeviceParameters(mass=M, friction=B, coulomb_friction=0.6, substeps=n), "cia402"))
              for n in (1, 7)]
    targets = [90, 90, 40, -20, -75, -75, 0, 55, -58, 10] * 40  # per mille, 10 mN each
    stuck = 0
    for target in targets:
        for drive in drives:
            drive.write_object(0x6071, target)
            drive.sync()
        stuck += drives[0].velocity == 0.0
    one, seven = drives
    assert 0 < stuck < len(targets)  # it sticks sometimes, and slides the rest
    assert seven.velocity == pytest.approx(one.velocity, rel=1e-10, abs=1e-15)
    assert seven.position == pytest.approx(one.position, rel=1e-10)
    for name in ("friction_energy", "viscous_energy", "wall_energy"):
        assert getattr(seven, name) == pytest.approx(getattr(one, name), rel=1e-10), name


@pytest.mark.parametrize("b", [B, 0.0])
@pytest.mark.parametrize("timing", ["cia402", "reception"])
def test_the_energy_ledger_closes_through_stick_slip(b: float, timing: str) -> None:
    """operator work = kinetic + viscous + Coulomb + motor work, through a run that sticks and slides.

    A spring wall (K = 200 N/m, B = 2 N s/m) in the loop, a 1.5 N sinusoid against 0.8 N of
    Coulomb friction, 3 sub-steps and the lowpass model (the piece path).  Every term is summed
    over ~10^4 pieces, each exact to a few ulp: the residual is below 1e-11 of the energy
    turned over (the dissipated energy plus the motor's work).
    """
    parameters = DeviceParameters(mass=M, friction=b, coulomb_friction=0.8, substeps=3, velocity="lowpass:0.002",
                                  velocity_per_count=1e-9, rated_torque=0.001, force_per_torque=100.0,
                                  max_torque_permille=30000)
    drive = enable(SimulatedDrive(parameters, timing, Sinusoid(1.5, 2.0)))
    per_mille = parameters.scaling.newton_per_permille
    x = 0.0
    stuck = 0
    for _ in range(3000):
        drive.sync()
        y = drive.velocity_counts * parameters.velocity_per_count
        x += parameters.period * y
        drive.write_object(0x6071, round(-(200.0 * x + 2.0 * y) / per_mille))
        stuck += drive.velocity == 0.0
    assert 0 < stuck < 3000 and drive.friction_energy > 0
    turned_over = drive.viscous_energy + drive.friction_energy + abs(drive.wall_energy)
    assert abs(ledger_residual(drive)) <= 1e-11 * turned_over


# --------------------------------------------------------------------------- velocity noise


def resting_noise(seed: int | None, samples: int, sigma: float = 40.0) -> np.ndarray:
    """0x606C of a resting handle with ``sigma`` counts rms of noise."""
    drive = SimulatedDrive(DeviceParameters(velocity_noise=sigma, noise_seed=seed))
    counts = []
    for _ in range(samples):
        drive.sync()
        counts.append(drive.velocity_counts)
        assert drive.position_counts == 0  # the encoder is not noisy
    return np.array(counts, dtype=float)


def test_velocity_noise_has_the_stated_rms_and_is_reproducible() -> None:
    """Zero-mean Gaussian noise of sigma = 40 counts, rounded to counts: rms sqrt(sigma^2 + 1/12).

    Over N = 20 000 samples the mean has standard deviation sigma/sqrt(N) = 0.28 counts and the
    rms a relative one of 1/sqrt(2N) = 0.5 %: both are asserted to 5 standard deviations (a
    seeded run is deterministic; the tolerance says why this seed is no lucky one).
    """
    sigma, n = 40.0, 20_000
    counts = resting_noise(7, n, sigma)
    expected_rms = math.sqrt(sigma**2 + 1.0 / 12.0)
    assert abs(counts.mean()) <= 5 * sigma / math.sqrt(n)
    assert abs(math.sqrt(np.mean(counts**2)) / expected_rms - 1.0) <= 5 / math.sqrt(2 * n)
    assert np.array_equal(resting_noise(7, 500, sigma), counts[:500])  # the same seed, the same noise
    assert not np.array_equal(resting_noise(8, 500, sigma), counts[:500])


def test_noise_rides_on_the_model_and_the_seed_survives_unrelated_changes() -> None:
    """Noise adds to the model's value (here a moving handle's); reconfiguring anything else keeps the sequence going."""
    push = ConstantPush(1.0)
    quiet = SimulatedDrive(DeviceParameters(velocity_per_count=1e-9), operator=push)
    noisy = SimulatedDrive(DeviceParameters(velocity_per_count=1e-9, velocity_noise=3.0, noise_seed=11), operator=push)
    reference = SimulatedDrive(DeviceParameters(velocity_noise=3.0, noise_seed=11))
    differences, expected = [], []
    for k in range(400):
        if k == 200:
            noisy.reconfigure(max_torque_permille=1000)
            reference.reconfigure(max_torque_permille=1000)
        for drive in (quiet, noisy, reference):
            drive.sync()
        differences.append(noisy.velocity_counts - quiet.velocity_counts)
        expected.append(reference.velocity_counts)
    # the same draws: at rest they are round(n), moving round(v/vpc + n) - round(v/vpc), within one count of it
    assert np.max(np.abs(np.array(differences) - np.array(expected))) <= 1
    assert np.std(differences) > 2.0


# --------------------------------------------------------------------------- validation and profiles


@pytest.mark.parametrize(
    ("field", "value"),
    [("coulomb_friction", -0.1), ("coulomb_friction", float("nan")), ("coulomb_friction", 2e6),
     ("velocity_noise", -1.0), ("velocity_noise", float("inf")), ("velocity_noise", "3"),
     ("noise_seed", -1), ("noise_seed", 1.5), ("noise_seed", True), ("noise_seed", "7")],
)
def test_bad_truth_parameters_name_the_field_and_its_range(field: str, value: object) -> None:
    with pytest.raises(ParameterError, match=field) as caught:
        DeviceParameters(**{field: value})  # type: ignore[arg-type]
    assert caught.value.name == field and caught.value.allowed


def write(tmp_path: pathlib.Path, text: str) -> pathlib.Path:
    path = tmp_path / "truth.toml"
    path.write_text(text)
    return path


def test_a_profile_states_the_drives_truth(tmp_path: pathlib.Path) -> None:
    (axis,) = read_simulated_device(write(tmp_path, (
        '[device]\nmass = 0.8\nfriction = 2.0\nvelocity = "window:0.0005"\ncoulomb_friction = 0.4\n'
        'velocity_noise = 2.5\nnoise_seed = 42\n[loop]\nperiod = 0.001\ntiming = "reception"\ndelay = 0.3\n'
    ))).axes
    p = axis.parameters
    assert (p.mass, p.friction, str(p.velocity)) == (0.8, 2.0, "window:0.0005")
    assert (p.coulomb_friction, p.velocity_noise, p.noise_seed) == (0.4, 2.5, 42)
    assert axis.timing is Timing.RECEPTION and p.reception_delay == 0.3
    assert SimulatedDrive(p, axis.timing).loop_delay == 0.3
    (plain,) = read_simulated_device(write(tmp_path, '[loop]\ntiming = "cia402"\ndelay = 1\n')).axes
    assert plain.timing is Timing.CIA402 and plain.parameters == DeviceParameters()


@pytest.mark.parametrize(
    ("text", "field"),
    [('[loop]\ntiming = "reception"\ndelay = 1.0\n', "loop.delay"),
     ('[loop]\ntiming = "cia402"\ndelay = 0.5\n', "loop.delay"),
     ('[loop]\ndelay = 0.5\n', "loop.delay"),
     ('[loop]\ntiming = "late"\n', "loop.timing"),
     ('[device]\ncoulomb_friction = -1.0\n', "device.coulomb_friction"),
     ('[device]\nvelocity = "median"\n', "device.velocity"),
     ('[device]\nvelocity = "window:0.002"\n', "device.velocity"),
     ('[device]\nnoise_seed = "x"\n', "device.noise_seed")],
)
def test_profile_errors_name_the_profile_key(tmp_path: pathlib.Path, text: str, field: str) -> None:
    with pytest.raises(ParameterError, match=r"truth\.toml") as caught:
        read_simulated_device(write(tmp_path, text))
    assert caught.value.name == field


def test_the_viscous_series_with_its_constants_kept_sums_as_its_loop_did() -> None:
    """``exp[0, 0, -c, -2c]``'s series takes its term constants from a table made once: the same floats
    in the same operations as the loop that computed them every call, so the same sum, to the bit."""
    from sim_drive.handle import _SERIES_BELOW, _SERIES_TERMS, _exp_0_0_c_2c

    def loop(c: float) -> float:
        total, power, factorial = 0.0, 1.0, 6.0
        for n in range(_SERIES_TERMS):
            total += power * (2.0 ** (n + 1) - 1.0) / factorial
            power *= -c
            factorial *= n + 4
        return total

    rng = np.random.default_rng(11)
    cs = [0.0, *rng.uniform(0.0, _SERIES_BELOW, 4000), *rng.uniform(0.0, 1e-4, 1000), *(k * 1e-5 for k in range(3000))]
    assert [_exp_0_0_c_2c(float(c)) for c in cs] == [loop(float(c)) for c in cs]
    assert _exp_0_0_c_2c(0.0) == pytest.approx(1.0 / 6.0, rel=1e-15)  # the limit, to round-off
