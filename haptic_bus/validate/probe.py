"""The probe: a gentle hold about the rest position plus a small periodic multisine, as a scene the controller renders.

**The hold** (:func:`gentle_hold`) is a spring and damper about where the handle is at the first
cycle: ``K = m w_h^2`` and ``B = max(2 m w_h - b, 7 K T)`` (critically damped at
:data:`HOLD_HZ` with the handle's own ``b``, and the bandwidth rule's ``alpha = B/(K T) > 6``),
halved until the run's gate accepts it with its own policy (its safety margin included): inside
the gate's passive set.  Its slowest pole sets how many probe periods are left to the start's
transient (:func:`settle_periods`).

**The probe** (:class:`ProbePlan`): one period of ``N`` samples (the power of two nearest
:data:`PERIOD_SECONDS`), every harmonic of ``1/(N T)`` from :data:`LOW_HZ` to
``HIGH_FRACTION / T`` with equal amplitude and Schroeder's phases (crest factor about 1.7), repeated
after a quiet phase of :data:`QUIET_SECONDS` in which the hold alone acts and the velocity's
noise is measured.  Its peak (:class:`AmplitudeRule`) is what gives every excited frequency a
signal-to-noise ratio of :data:`SNR` -- against the measured velocity noise (at least the counts'
quantisation) after averaging the measured periods, and against the force's own rounding (one per
mille of rated torque; periodic, so not averaged) -- at least :data:`FLOOR_SHARE` and at most :data:`CEILING_SHARE` of the
force limit, and small enough that the predicted excursion stays inside the travel.

:class:`ProbeScene` is a :class:`~haptic_bus.control.scene.CompiledScene` (the hold, a detent
judged by the gate like any wall) whose force also carries the probe: the wall force
``u = K (x - x_0) + B v - p_k`` (N), so the motor pushes ``p_k - K (x - x_0) - B v``.  The probe's
cycle count, rest position and amplitude live in a :class:`Probe` the scene shares with the scenes
an upload would derive from it.  Units: s, m, m/s, N.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.scene import CompiledScene, Detent, compile_scene
from haptic_bus.errors import Refusal
from haptic_bus.identify.excitation import multisine
from haptic_bus.validate.model import Hold, Prediction

PERIOD_SECONDS = 0.5  # s: the probe's period (the power of two samples nearest to it)
LOW_HZ = 2.0  # Hz: lowest excited harmonic
HIGH_FRACTION = 0.4  # of the sampling rate 1/T: highest excited harmonic (0.8 of Nyquist)
QUIET_SECONDS = 0.5  # s: the hold alone, the velocity noise measured over its second half
MEASURED_PERIODS = 8  # probe periods averaged (the uncertainty is their scatter)
MAX_SETTLE_PERIODS = 10  # probe periods at most left to the start's transient
HOLD_HZ = 2.0  # Hz: the hold's corner
SNR = 100.0  # amplitude of every excited frequency's response over its noise, after averaging
FLOOR_SHARE = 0.01  # of the force limit: the smallest probe peak
CEILING_SHARE = 0.1  # of the force limit: the largest probe peak
HOLD_NAME = "hold"
_REACH = 1e6  # m: the hold acts wherever the handle is


def gentle_hold(loop: DeviceLoop, gate: PassivityGate) -> Hold:
    """The hold of the module docstring, accepted by ``gate``; Refusal if no halving of it is."""
    omega = 2.0 * math.pi * HOLD_HZ
    stiffness = loop.m * omega * omega
    for _ in range(20):
        hold = Hold(stiffness, max(2.0 * loop.m * math.sqrt(stiffness / loop.m) - loop.b, 7.0 * stiffness * loop.T))
        if gate.passes(hold_scene(hold)):
            return hold
        stiffness *= 0.5
    raise Refusal(f"no gentle hold passes the gate ({loop.describe()}): the last tried was K = {hold.stiffness:.3g} N/m, "
                  f"B = {hold.damping:.3g} N s/m")


def hold_scene(hold: Hold) -> CompiledScene:
    """The hold as a scene: one detent named :data:`HOLD_NAME` about 0 (the rest position), reaching everywhere."""
    return compile_scene([Detent(HOLD_NAME, 0.0, _REACH, hold.stiffness, hold.damping)])


def settle_periods(loop: DeviceLoop, hold: Hold, samples: int) -> int:
    """Probe periods of ``samples`` cycles for the start's transient to fall below 1e-6: 14 time
    constants of the held handle's slowest pole (continuous ``m s^2 + (b + B) s + K``), at least 1."""
    rate = (loop.b + hold.damping) / (2.0 * loop.m)
    slowest = rate - math.sqrt(max(0.0, rate * rate - hold.stiffness / loop.m))
    return min(MAX_SETTLE_PERIODS, max(1, math.ceil(14.0 / (slowest * samples * loop.T))))


@dataclass(frozen=True)
class ProbePlan:
    """The probe's timing: ``period`` ``T`` s, ``samples`` ``N`` per probe period, harmonics
    ``low..high``, ``quiet`` cycles first, then ``settle`` periods left to the transient and
    ``periods`` measured."""

    period: float
    samples: int
    low: int
    high: int
    quiet: int
    settle: int
    periods: int = MEASURED_PERIODS

    @classmethod
    def for_loop(cls, loop: DeviceLoop, hold: Hold) -> ProbePlan:
        """The plan for ``loop`` held by ``hold`` (module docstring)."""
        samples = 1 << max(6, round(math.log2(PERIOD_SECONDS / loop.T)))
        resolution = 1.0 / (samples * loop.T)
        high = min(samples // 2 - 1, math.floor(HIGH_FRACTION / loop.T / resolution))
        low = min(high, max(1, math.ceil(LOW_HZ / resolution)))
        return cls(loop.T, samples, low, high, round(QUIET_SECONDS / loop.T), settle_periods(loop, hold, samples))

    def wave(self) -> np.ndarray:
        """One period of the probe, peak 1 (dimensionless)."""
        return multisine(self.samples, self.low, self.high, tilt=0.0)

    def steady(self, response: np.ndarray) -> np.ndarray:
        """One period of the steady response (the output's unit per N of peak) to the probe of peak 1 N,
        ``response`` given at the excited frequencies (the output's unit per N)."""
        spectrum = np.zeros(self.samples // 2 + 1, dtype=complex)
        spectrum[self.bins] = np.fft.rfft(self.wave())[self.bins] * response
        return np.fft.irfft(spectrum, self.samples)

    @property
    def bins(self) -> np.ndarray:
        """The excited harmonics (DFT bins of one period)."""
        return np.arange(self.low, self.high + 1)

    @property
    def theta(self) -> np.ndarray:
        """The excited frequencies as ``omega T`` (rad)."""
        return 2.0 * np.pi * self.bins / self.samples

    @property
    def frequencies(self) -> np.ndarray:
        """The excited frequencies, Hz."""
        return self.bins / (self.samples * self.period)

    @property
    def measured_from(self) -> int:
        """The first cycle of the measured periods."""
        return self.quiet + self.settle * self.samples

    @property
    def cycles(self) -> int:
        """Every cycle of the run."""
        return self.measured_from + self.periods * self.samples


@dataclass(frozen=True)
class AmplitudeRule:
    """The probe's peak (N) for a measured velocity noise (module docstring): ``per_noise`` N of
    peak per m/s rms of noise, ``quantum`` (m/s) the least noise the counts' rounding leaves,
    ``force_floor`` N the peak the force's own quantisation needs, and ``floor``/``ceiling`` N."""

    per_noise: float
    quantum: float
    force_floor: float
    floor: float
    ceiling: float

    @classmethod
    def design(cls, plan: ProbePlan, prediction: Prediction, velocity_per_count: float, newton_per_permille: float,
               force_limit: float, travel: float) -> AmplitudeRule:
        """The rule for ``plan`` whose responses ``prediction`` predicts, the drive's units (m/s per
        count, N per per mille), the force limit (N) and the travel (m either side)."""
        spectrum = np.abs(np.fft.rfft(plan.wave())[plan.bins])  # per unit peak
        spread = math.sqrt(plan.samples / plan.periods)  # a white noise's rms per bin after averaging, per unit rms
        per_noise = SNR * spread / float(np.min(spectrum * np.abs(prediction.velocity)))
        # the force's rounding repeats every period: it does not average out
        force_floor = SNR * math.sqrt(plan.samples / 12.0) * newton_per_permille / float(np.min(spectrum))
        per_newton = float(np.max(np.abs(plan.steady(prediction.position))))  # m of excursion per N of peak
        ceiling = min(CEILING_SHARE * force_limit, 0.5 * travel / per_newton)
        return cls(per_noise, velocity_per_count / math.sqrt(12.0), force_floor, min(FLOOR_SHARE * force_limit, ceiling),
                   ceiling)

    def amplitude(self, noise: float) -> float:
        """The peak (N) for a velocity noise of ``noise`` m/s rms."""
        needed = max(self.per_noise * max(noise, self.quantum), self.force_floor, self.floor)
        return min(self.ceiling, needed)


class Probe:
    """The probe's state across cycles: the cycle count, the rest position ``centre`` (m, the first
    cycle's), the velocity noise measured in the quiet phase (m/s rms) and the peak chosen (N).

    ``travel`` (m either side of the rest position) is the free room the user gave: the first cycle
    that finds the handle further out ends the probe for good (the hold alone then acts until the run
    stops), is kept as ``left`` (the cycle and the offset, m) and calls ``on_leave()`` once.  A handle
    that goes that far under a probe designed to move it half as far is pushed by something else
    (a hand, gravity, a spring): the response then measures that too."""

    def __init__(self, plan: ProbePlan, rule: AmplitudeRule, travel: float, on_leave: Callable[[], object]) -> None:
        self.plan = plan
        self.rule = rule
        self.travel = travel
        self.on_leave = on_leave
        self.wave: list[float] = plan.wave().tolist()
        self.cycle = 0
        self.centre: float | None = None
        self.left: tuple[int, float] | None = None
        self.noise = 0.0
        self.amplitude = 0.0
        self._moments = [0, 0.0, 0.0]  # count, sum (m/s), sum of squares (m^2/s^2)

    def step(self, x: float, v: float) -> tuple[float, float]:
        """This cycle's rest position (m) and probe force (N), the handle at ``x`` m moving at ``v`` m/s."""
        k = self.cycle
        self.cycle = k + 1
        if self.centre is None:
            self.centre = x
        if self.left is None and abs(x - self.centre) > self.travel:
            self.left = (k, x - self.centre)
            self.on_leave()
        if self.left is not None:
            return self.centre, 0.0
        quiet = self.plan.quiet
        if k < quiet:
            if 2 * k >= quiet:
                moments = self._moments
                moments[0] += 1
                moments[1] += v
                moments[2] += v * v
            return self.centre, 0.0
        if k == quiet:
            count, total, squares = self._moments
            self.noise = math.sqrt(max(0.0, squares / count - (total / count) ** 2)) if count else 0.0
            self.amplitude = self.rule.amplitude(self.noise)
        return self.centre, self.amplitude * self.wave[(k - quiet) % self.plan.samples]

    def forces(self, cycles: int) -> np.ndarray:
        """The probe force (N) of cycles ``0 .. cycles - 1``, as :meth:`step` gave them."""
        k = np.arange(cycles)
        wave = np.asarray(self.wave)
        pushing = (k >= self.plan.quiet) & (k < (self.left[0] if self.left is not None else cycles))
        return np.where(pushing, self.amplitude * wave[(k - self.plan.quiet) % self.plan.samples], 0.0)


@dataclass(frozen=True)
class ProbeScene(CompiledScene):
    """The hold (a compiled scene, what the gate judges) with the :class:`Probe` added to its force."""

    probe: Probe

    @classmethod
    def holding(cls, hold: Hold, probe: Probe) -> ProbeScene:
        """The scene of ``hold`` carrying ``probe``."""
        return cls.around(hold_scene(hold), probe)

    @classmethod
    def around(cls, scene: CompiledScene, probe: Probe) -> ProbeScene:
        """``scene`` (the hold) carrying ``probe``."""
        fields = {f.name: getattr(scene, f.name) for f in dataclasses.fields(CompiledScene)}
        return cls(**fields, probe=probe)

    def force(self, x: float, v: float) -> float:
        """The wall force ``u`` (N): the hold about the rest position minus the probe (module docstring)."""
        centre, push = self.probe.step(x, v)
        return CompiledScene.force(self, x - centre, v) - push

    def stored_energy(self, x: float) -> float:
        """The hold's spring energy at ``x`` m (J): 0 before the rest position is known."""
        centre = self.probe.centre
        return 0.0 if centre is None else CompiledScene.stored_energy(self, x - centre)

    def with_walls(self, changes: Mapping[str, tuple[float, float]]) -> ProbeScene:
        """The hold with its ``(K, B)`` changed, still carrying this probe."""
        return ProbeScene.around(CompiledScene.with_walls(self, changes), self.probe)

    def scaled(self, factor: float) -> ProbeScene:
        """The hold scaled by ``factor``, still carrying this probe."""
        return ProbeScene.around(CompiledScene.scaled(self, factor), self.probe)
