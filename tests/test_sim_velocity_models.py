"""The simulated drive closes the loop the analysis models: velocity models, reception timing, delay.

The central check drives the simulated drive's ``sync()`` loop with the controller's wall law in
Python and an operator tone, and compares it with :func:`haptic_bus.analysis.energy.simulate`
(the exact reference of the sampled loop) for the same :class:`WallLoop`.  The two differ only
by what the drive quantises and by how the drive holds the operator's force, so the tolerance is
a bound on those (see :func:`error_bound`), not a guess.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from drives.cia402 import Command
from haptic_bus.analysis.energy import Tones, simulate, wall_forces
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import spectral_radius
from haptic_bus.analysis.sampled_loop import ClosedLoopLayout, period_map, shifted_closed_loop
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.errors import ParameterError
from sim_drive.canopen.manufacturer import TIMING, ManufacturerObjects
from sim_drive.canopen.pdo_engine import SlaveCounters
from sim_drive.cli import build_parser
from sim_drive.device import SimulatedDrive
from sim_drive.operator import OperatorModel, Sinusoid
from sim_drive.parameters import DeviceParameters, Timing

# A handle that stays stable with every model and delay below (closed-loop radius about 0.995).
M, B_VISCOUS, T = 0.5, 2.0, 1e-3
K, B_WALL = 300.0, 3.0
N_SAMPLES, SUBSTEPS = 1500, 16
AMPLITUDE, OMEGA, PHASE = 1.0, 0.05 / T, 0.3  # the operator's tone: 1 N at theta = omega T = 0.05 (8 Hz)
VELOCITY_PER_COUNT = 1e-10  # m/s: peak speeds near 0.08 m/s stay far inside INTEGER32 (8e8 counts)
RATED_TORQUE = 1e-3  # N m: the smallest 0x6076 (1 mN m), so force_per_torque sets the force per per mille
FULL_SCALE = 32767  # per mille: 0x6071's whole INTEGER16 range is used for the wall force


@dataclass(frozen=True)
class MidpointTone(OperatorModel):
    """``amplitude sin(omega t + phase)`` N evaluated at the middle of the sub-step of ``2 half`` s it is held over.

    The drive holds the operator's force over each sub-step; the midpoint value makes that hold
    second order: per sub-step the held force differs from the tone's mean by at most
    ``amplitude (omega h)^2 / 24`` N.
    """

    amplitude: float
    omega: float
    phase: float
    half: float

    def force(self, t: float, position: float, velocity: float) -> float:
        """The tone at ``t + half`` (N)."""
        return self.amplitude * math.sin(self.omega * (t + self.half) + self.phase)


def enable(drive: SimulatedDrive) -> SimulatedDrive:
    """CST and OPERATION ENABLED."""
    drive.write_object(0x6060, 10)
    for command in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        drive.write_controlword(command.word)
    return drive


def run_wall(drive: SimulatedDrive, stiffness: float, damping: float, samples: int) -> tuple[np.ndarray, ...]:
    """The controller's loop over ``samples + 1`` SYNCs: ``x_k = x_{k-1} + T y_k``, ``u_k = K x_k + B y_k``,
    target torque ``-u_k``; returns the true velocity (m/s), the operator energy (J) and ``u_k`` (N) per SYNC."""
    p = drive.parameters
    per_mille = p.rated_torque_mnm / 1e6 * p.force_per_torque
    x = 0.0
    velocity, energy, wall = [], [], []
    for _ in range(samples + 1):
        drive.sync()
        y = drive.velocity_counts * p.velocity_per_count
        x += p.period * y
        u = stiffness * x + damping * y
        drive.write_object(0x6071, round(-u / per_mille))
        velocity.append(drive.velocity)
        energy.append(drive.operator_energy)
        wall.append(u)
    return np.array(velocity), np.array(energy), np.array(wall)


def error_gains(loop: WallLoop, samples: int) -> tuple[float, float]:
    """l1 gains from an error (N) in one applied wall force to the sampled velocity (m/s per N) and to ``u_k`` (N/N).

    The loop is linear: an error ``e`` in the force the drive applies for ``u_k`` enters the
    closed-loop state ``xi`` of :mod:`haptic_bus.analysis.sampled_loop` as ``-gamma_now e`` on the
    plant (when it acts in the same period, ``d = 0``) and ``+e`` in the first held-force slot
    (when it acts later); then ``xi`` evolves by ``M``.  Summing the magnitudes of the responses
    bounds the effect of any error sequence bounded by 1 N.
    """
    pmap = period_map(loop)
    integrator = loop.K > 0
    layout = ClosedLoopLayout(pmap, loop.kappa, loop.q, loop.delay, integrator)
    matrix = shifted_closed_loop(pmap, loop.kappa, loop.q, loop.delay, integrator) + np.eye(layout.size)
    state = np.zeros(layout.size)
    if layout.d == 0:
        state[: layout.n] -= pmap.gamma_now
    if layout.slots:
        state[layout.first_slot] += 1.0
    state *= loop.T / loop.m  # scaled force per N
    velocity_gain = wall_gain = 0.0
    for _ in range(samples):
        velocity_gain += abs(state[0])
        wall_gain += abs(layout.u_row @ state) * loop.m / loop.T
        state = matrix @ state
    return velocity_gain, wall_gain


def error_bound(loop: WallLoop, newton_per_permille: float, samples: int) -> float:
    """A bound (N) on the error of every force the drive applies, against the exact loop's.

    Three sources: the target's rounding to whole per mille (``npp/2``); the velocity's rounding
    to counts, which reaches the force through ``B y`` and the integrated ``K x`` (at most
    ``(K T samples + B) vpc/2``); and the midpoint hold of the operator's force (at most
    ``A (omega h)^2/24``, an error on the handle like the wall's).
    """
    h = loop.T / SUBSTEPS
    return (0.5 * newton_per_permille + (loop.K * loop.T * samples + loop.B) * 0.5 * VELOCITY_PER_COUNT
            + AMPLITUDE * (OMEGA * h) ** 2 / 24.0)


MODELS = ["point", "average", "window:0.0004", "lowpass:0.002"]
TIMINGS = [("ideal", 0.0), ("cia402", 0.0), ("reception", 0.1), ("reception", 0.5), ("reception", 0.9)]


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize(("timing", "delta"), TIMINGS)
def test_the_drive_closes_the_loop_the_analysis_models(model: str, timing: str, delta: float) -> None:
    """Trajectory, wall force and operator energy of the simulated loop match energy.simulate.

    Tolerance: the drive's loop differs from the exact one by force errors bounded by
    ``eps`` (:func:`error_bound`: dominated by the torque's INTEGER16 rounding, about 1.3e-5 N
    against a 0.7 N wall force); their effect is bounded by ``eps`` times the l1 gains of the
    closed loop (:func:`error_gains`), doubled to cover the O(h^2) remainder of the hold.  The
    energy difference ``int w (v_sim - v_ref) dt`` is at most ``A t`` times the velocity bound,
    doubled again for the excursion between samples.  A wrong delta (0.25 instead of 0.5) or
    velocity model changes the velocity by 1e-2 of its peak, a thousand times the bound.
    """
    loop = WallLoop(M, B_VISCOUS, T, K, B_WALL, Timing(timing).loop_delay(delta), model)
    assert spectral_radius(loop) < 0.996  # stable: the comparison is over a bounded response
    tones = Tones((OMEGA,), (AMPLITUDE,), (PHASE,))
    reference = simulate(loop, tones, N_SAMPLES, SUBSTEPS)
    u_reference, _ = wall_forces(loop, tones, N_SAMPLES + 1)
    newton_per_permille = float(np.abs(u_reference).max()) / (0.8 * FULL_SCALE)  # 20 % headroom: no saturation
    parameters = DeviceParameters(
        mass=M, friction=B_VISCOUS, period=T, velocity_per_count=VELOCITY_PER_COUNT, position_per_count=1e-12,
        rated_torque=RATED_TORQUE, force_per_torque=newton_per_permille / (RATED_TORQUE / 1000.0),
        max_torque_permille=FULL_SCALE, substeps=SUBSTEPS, velocity=model, reception_delay=delta,
    )
    drive = enable(SimulatedDrive(parameters, timing, MidpointTone(AMPLITUDE, OMEGA, PHASE, 0.5 * T / SUBSTEPS)))
    assert drive.loop_delay == loop.delay
    velocity, energy, wall = run_wall(drive, K, B_WALL, N_SAMPLES)

    eps = error_bound(loop, newton_per_permille, N_SAMPLES)
    velocity_gain, wall_gain = error_gains(loop, N_SAMPLES)
    velocity_bound = 2.0 * velocity_gain * eps
    times = np.arange(N_SAMPLES + 1) * T
    assert np.all(np.abs(velocity - reference.velocity[::SUBSTEPS]) <= velocity_bound)
    assert np.all(np.abs(wall - u_reference) <= 2.0 * (wall_gain + 1.0) * eps)
    assert np.all(np.abs(energy - reference.energy[::SUBSTEPS]) <= 2.0 * AMPLITUDE * times * velocity_bound + 1e-15)
    # the bounds are tight enough to mean something: a hundredth of the signals at most
    assert velocity_bound < 1e-3 * np.abs(reference.velocity).max()
    assert 2.0 * AMPLITUDE * times[-1] * velocity_bound < 1e-2 * np.abs(reference.energy).max()


def step_from_rest(timing: Timing, model: str, delta: float = 0.25) -> tuple[SimulatedDrive, float]:
    """A drive (counts of 1e-10 m/s) that gets a 0.15 N target in answer to SYNC 0; returns it and the force (N)."""
    drive = enable(SimulatedDrive(DeviceParameters(velocity=model, reception_delay=delta, velocity_per_count=1e-10), timing))
    drive.sync()
    drive.write_object(0x6071, 15)
    return drive, 15 * drive.parameters.scaling.newton_per_permille


@pytest.mark.parametrize("delta", [0.0, 0.1, 0.5, 0.9])
def test_reception_applies_the_target_delta_after_the_sync(delta: float) -> None:
    """v(kT) = (F/b)(1 - exp(-b (k - delta) T / m)): the step starts delta T after SYNC 0, exactly."""
    drive, force = step_from_rest(Timing.RECEPTION, "point", delta)
    p = drive.parameters
    for k in range(1, 300):
        drive.sync()
        exact = force / p.friction * -math.expm1(-p.friction * (k - delta) * p.period / p.mass)
        assert drive.velocity == pytest.approx(exact, rel=1e-12)
    assert drive.loop_delay == delta and drive.torque_actual == 15


def exact_step_velocity(model: VelocityModel, force: float, p: DeviceParameters, t: float) -> float:
    """The velocity ``model`` reports at ``t`` s after a force step ``force`` N on the handle at rest (closed forms)."""
    rate = p.friction / p.mass
    terminal = force / p.friction
    if t <= 0.0:
        return 0.0
    if model.kind == "point":
        return terminal * -math.expm1(-rate * t)
    if model.kind == "lowpass":  # tau nu' = v - nu: nu = V (1 - (l e^{-r t} - r e^{-l t}) / (l - r))
        lam = 1.0 / model.time
        return terminal * (1.0 - (lam * math.exp(-rate * t) - rate * math.exp(-lam * t)) / (lam - rate))
    window = model.window(p.period)
    assert window is not None

    def x(s: float) -> float:  # position, m
        return terminal * (s + math.expm1(-rate * s) / rate) if s > 0.0 else 0.0

    return (x(t) - x(t - window)) / window


@pytest.mark.parametrize("model", ["point", "average", "window:0.0003", "lowpass:0.004"])
@pytest.mark.parametrize("timing", list(Timing))
def test_each_model_reports_what_the_analysis_defines(model: str, timing: Timing) -> None:
    """0x606C after a force step from rest against closed forms: v(kT); (x(kT) - x(kT - TW))/TW; the filtered nu(kT).

    0x606C is the exact value rounded to counts: within half a count, plus 1e-3 count for the
    closed forms' own round-off (``x(t) - x(t - TW)`` cancels; at most ~1e-14 m/s here).
    """
    drive, force = step_from_rest(timing, model)
    p = drive.parameters
    onset = drive.loop_delay * p.period  # the step acts from t = D T
    for k in range(1, 200):
        drive.sync()
        exact = exact_step_velocity(p.velocity, force, p, k * p.period - onset)
        assert abs(drive.velocity_counts - exact / p.velocity_per_count) <= 0.5 + 1e-3


def test_the_inlined_sub_steps_and_the_piece_path_agree() -> None:
    """The plant under the same forces does not depend on which path advances it (point: inlined;
    lowpass: piece by piece): velocity, position and every energy agree to round-off."""
    drives = [enable(SimulatedDrive(DeviceParameters(substeps=5, velocity=model), Timing.CIA402, Sinusoid(2.0, 40.0)))
              for model in ("point", "lowpass:0.001")]
    assert drives[0].handle.advance.__name__ != drives[1].handle.advance.__name__
    for k in range(400):
        for drive in drives:
            drive.write_object(0x6071, (k * 37) % 200 - 100)
            drive.sync()
    fast, pieces = drives
    for name in ("velocity", "position", "operator_energy", "wall_energy", "viscous_energy"):
        assert getattr(pieces, name) == pytest.approx(getattr(fast, name), rel=1e-12, abs=1e-18), name


def test_timing_delays_and_changes() -> None:
    assert (Timing.CIA402.delay, Timing.IDEAL.delay, Timing.RECEPTION.delay) == (1.0, 0.0, 0.25)
    assert Timing.RECEPTION.loop_delay(0.7) == 0.7 and Timing.CIA402.loop_delay(0.7) == 1.0
    drive = enable(SimulatedDrive(DeviceParameters(reception_delay=0.4), "cia402"))
    drive.write_object(0x6071, 100)
    drive.sync()
    assert drive.torque_actual == 100 and drive.loop_delay == 1.0
    drive.timing = "reception"  # the latched torque keeps acting until the new target's reception
    assert drive.timing is Timing.RECEPTION and drive.loop_delay == 0.4
    drive.write_object(0x6071, -50)
    before = drive.velocity
    drive.sync()
    p = drive.parameters
    per_mille = p.scaling.newton_per_permille
    expected = before
    for force, fraction in ((100 * per_mille, 0.4), (-50 * per_mille, 0.6)):
        h = fraction * p.period
        expected = expected * math.exp(-p.friction * h / p.mass) + force / p.friction * -math.expm1(-p.friction * h / p.mass)
    assert drive.velocity == pytest.approx(expected, rel=1e-12)
    assert drive.torque_actual == -50
    drive.reconfigure(reception_delay=0.0)
    assert drive.loop_delay == 0.0


@pytest.mark.parametrize(("field", "value"), [("reception_delay", 1.0), ("reception_delay", -0.1), ("velocity", "median"),
                                              ("velocity", "window:0.002"), ("velocity", 3)])
def test_bad_timing_and_model_parameters_name_the_field(field: str, value: object) -> None:
    with pytest.raises(ParameterError, match=field) as caught:
        DeviceParameters(**{field: value})  # type: ignore[arg-type]
    assert caught.value.name == field and "simulated drive" in str(caught.value)


def test_reception_over_sdo_and_the_command_line() -> None:
    drive = SimulatedDrive()
    objects = ManufacturerObjects(drive, SlaveCounters())
    objects.write(TIMING, 6, 0.6)
    objects.write(TIMING, 1, 2)
    assert drive.timing is Timing.RECEPTION and objects.read(TIMING, 1) == 2 and objects.read(TIMING, 6) == 0.6
    assert drive.loop_delay == 0.6
    assert build_parser().parse_args(["--timing", "reception"]).timing == "reception"
