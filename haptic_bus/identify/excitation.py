"""The excitation: a Schroeder-phased multisine, a slow position-holding PD, and an amplitude servo.

**Multisine** (:func:`multisine`): one period of ``N`` samples (``N`` the power of two nearest
:data:`MULTISINE_SECONDS`), every harmonic of ``1/(N T)`` from :data:`LOW_HZ` to
``HIGH_FRACTION / T`` with equal power per octave (amplitude ``1/sqrt(k)``) and Schroeder's
phases for that power spectrum, ``phi_k = -2 pi sum_{l<k} (k - l) p_l`` (``p_l`` the relative
power of harmonic ``l``): a crest factor of about 1.85 instead of ~3.7 for random phases and
~9 for equal ones.  The high harmonics resolve the mass and the fraction of a sample of the loop
delay; the low ones move the handle far (viscous friction, Coulomb reversals).  The band starts
at :data:`LOW_HZ` = 3 Hz: the excursion a force buys falls as ``1/f^2`` and the speed only as
``1/f``, so within a travel envelope 3 Hz moves the handle faster than 1 Hz and keeps it sliding.
Measured over 20 s within +-10 mm (standard errors): a 0.37 kg, 2.9 N s/m handle with 0.2 N of
Coulomb friction -- usable cycles 57 % at 1 Hz, 67 % at 3 Hz; b +-0.16 % and +-0.07 %; D +-0.002
and +-0.0003 samples; a 0.05 kg, 0.3 N s/m desktop handle -- 35 % and 59 %; b +-0.35 % and
+-0.11 %.

**Holding loop** (:class:`HoldingLoop`): ``F = -K (x - x0) - Kd (x_k - x_{k-1})/T`` on the
encoder (0x6064, noise-free), with ``K = m w^2``, ``Kd = 2 m w`` (critically damped at
:data:`HOLD_HZ` for the profile's mass ``m``).  At 0.5 Hz it is orders of magnitude below any
stability limit of a sampled loop with a few samples of delay, whatever the real mass.  It only
keeps the handle centred; the fit uses the force actually commanded, so closing the loop
biases nothing (the regressors are noise-free).

**Amplitude** (:func:`excursion_per_newton`, :class:`AmplitudeServo`): the first amplitude puts
the steady excursion of a frictionless handle of the probe's mass at :data:`TARGET_SHARE` of the
travel; it fades in and out over :data:`FADE_SECONDS` (:func:`fade`: a sudden start gives the
handle a mean velocity ``A/(m w)`` that the slow holding loop would take seconds to catch); at
the end of every multisine period the servo rescales it towards the same target; beyond
:data:`GUARD_SHARE` of the travel it is halved at once, and beyond the travel the excitation ends
(the handle never reaches an end stop outside it).  Units: s, m, N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

MULTISINE_SECONDS = 2.0  # s: period of the multisine (power of two samples nearest to it)
LOW_HZ = 3.0  # Hz: lowest harmonic (above the holding loop's 0.5 Hz; see the module docstring)
HIGH_FRACTION = 0.3  # of the sampling rate 1/T: highest harmonic (0.6 of Nyquist)
HOLD_HZ = 0.5  # Hz: the holding loop's natural frequency
FADE_SECONDS = 1.0  # s: raised-cosine fade in and out (a sudden start would set the handle drifting)
GUARD_SECONDS = 0.25  # s: the guard halves the amplitude at most this often
TARGET_SHARE = 0.5  # of the travel: the excursion the amplitude aims at
GUARD_SHARE = 0.8  # of the travel: halve the amplitude at once


def multisine(samples: int, low: int, high: int, tilt: float = 0.5) -> np.ndarray:
    """One period (``samples`` values, peak 1) of harmonics ``low..high`` of ``1/samples``, amplitude
    ``k^-tilt`` (0.5: equal power per octave; 0: a flat spectrum), Schroeder phases; ValueError for
    an empty band."""
    if not 0 < low <= high < samples // 2:
        raise ValueError(f"harmonics {low}..{high} are no band of a {samples}-sample period")
    k = np.arange(samples // 2 + 1)
    amplitude = np.where((k >= low) & (k <= high), np.maximum(k, 1) ** -float(tilt), 0.0)
    power = amplitude**2 / np.sum(amplitude**2)
    before = np.cumsum(power) - power  # sum_{l<k} p_l
    moment = np.cumsum(k * power) - k * power  # sum_{l<k} l p_l
    phase = -2.0 * np.pi * (k * before - moment)
    wave = np.fft.irfft(amplitude * np.exp(1j * phase), samples)
    return wave / np.max(np.abs(wave))


def multisine_for(period: float) -> np.ndarray:
    """The multisine of this module's band for a loop of period ``period`` s (peak 1)."""
    samples = 1 << max(6, round(math.log2(MULTISINE_SECONDS / period)))
    resolution = 1.0 / (samples * period)  # Hz per harmonic
    high = min(samples // 2 - 1, math.floor(HIGH_FRACTION / period / resolution))
    low = min(high, max(1, math.ceil(LOW_HZ / resolution)))
    return multisine(samples, low, high)


class HoldingLoop:
    """The slow PD on the encoder that keeps the handle near ``origin`` (m); gains from ``mass`` kg."""

    def __init__(self, mass: float, period: float, origin: float) -> None:
        omega = 2.0 * math.pi * HOLD_HZ
        self.stiffness = mass * omega * omega  # N/m
        self.damping = 2.0 * mass * omega  # N s/m
        self.origin = origin
        self._period = period
        self._previous: float | None = None

    def force(self, position: float) -> float:
        """The holding force in N for the position ``position`` m sampled now."""
        previous = position if self._previous is None else self._previous
        self._previous = position
        return -self.stiffness * (position - self.origin) - self.damping * (position - previous) / self._period


def fade(k: int, cycles: int, period: float) -> float:
    """The fade (0..1) at cycle ``k`` of an excitation of ``cycles`` cycles: a raised cosine over
    :data:`FADE_SECONDS` at both ends (at most a third of the run each)."""
    width = min(FADE_SECONDS / period, cycles / 3.0)
    edge = min(k + 0.5, cycles - k - 0.5)
    return 1.0 if edge >= width else 0.5 - 0.5 * math.cos(math.pi * max(0.0, edge) / width)


def excursion_per_newton(wave: np.ndarray, period: float, mass: float, hold: HoldingLoop) -> float:
    """The largest excursion (m) one period of ``wave`` (N per unit amplitude) drives a frictionless
    handle of ``mass`` kg held by ``hold`` to, in steady state (frequency response, delay ignored)."""
    spectrum = np.fft.rfft(wave)
    omega = 2.0 * np.pi * np.fft.rfftfreq(wave.size, period)
    response = 1.0 / (hold.stiffness - mass * omega**2 + 1j * omega * hold.damping)
    return float(np.max(np.abs(np.fft.irfft(spectrum * response, wave.size))))


@dataclass
class AmplitudeServo:
    """The multisine's amplitude (N), kept so that the excursion stays inside ``travel`` m.

    Starts at ``amplitude`` N (at most ``ceiling`` N).  At the end of every multisine period of
    ``length`` cycles the amplitude is scaled by ``TARGET_SHARE travel / peak`` (between 1/2 and 2,
    the response being nearly proportional to it), unless the guard acted in that period; beyond
    ``GUARD_SHARE travel`` it is halved at once (at most once per ``guard_window`` cycles).
    :attr:`left_envelope` is set once the handle is outside the travel.
    """

    amplitude: float
    ceiling: float
    travel: float
    length: int
    guard_window: int
    left_envelope: bool = field(default=False, init=False)
    _peak: float = field(default=0.0, init=False)  # m, the largest excursion in this period
    _steady: bool = field(default=True, init=False)  # no fade in this period
    _count: int = field(default=0, init=False)  # cycles so far
    _guarded_at: int | None = field(default=None, init=False)  # the cycle the guard last halved at

    def __post_init__(self) -> None:
        self.amplitude = min(self.amplitude, self.ceiling)

    def update(self, excursion: float, steady: bool = True) -> float:
        """Take this cycle's excursion ``|x - x0|`` (m); return the amplitude (N) for this cycle.

        ``steady``: the amplitude is not being faded (a period that saw a fade is not adapted on)."""
        self._peak = max(self._peak, excursion)
        self._steady = self._steady and steady
        if excursion > self.travel:
            self.left_envelope = True
        if excursion > GUARD_SHARE * self.travel and (
                self._guarded_at is None or self._count - self._guarded_at >= self.guard_window):
            self.amplitude *= 0.5
            self._guarded_at = self._count
        self._count += 1
        if self._count % self.length == 0:
            guarded = self._guarded_at is not None and self._count - self._guarded_at <= self.length
            if not guarded and self._steady and self._peak > 0:
                ratio = min(2.0, max(0.5, TARGET_SHARE * self.travel / self._peak))
                self.amplitude = min(self.ceiling, self.amplitude * ratio)
            self._peak, self._steady = 0.0, True
        return self.amplitude
