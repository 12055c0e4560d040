"""The verdict: does the measured closed loop hold to the model's prediction, and if not, how does it differ?

The probe's response in velocity is compared frequency by frequency with the model's (exact,
:mod:`~haptic_bus.validate.model`): the model **holds** when at every excited frequency
``|measured / predicted - 1|`` is at most the tolerance plus three standard errors of the
measurement (:mod:`~haptic_bus.validate.spectra`); the run then "holds to within X % up to f Hz",
``X`` the largest relative difference, ``f`` the highest excited frequency.  Otherwise the
measured plant is fitted with every departure :mod:`~haptic_bus.validate.departures` knows, and
the best candidate's findings name how the device differs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.validate.departures import Fit, departures, nominal
from haptic_bus.validate.model import Hold, Prediction
from haptic_bus.validate.probe import ProbePlan
from haptic_bus.validate.spectra import Measured, response

DEFAULT_TOLERANCE = 0.05  # relative difference the model may leave at any frequency (5 %)
CONFIDENCE = 3.0  # standard errors of the measurement allowed on top of the tolerance


@dataclass(frozen=True)
class Signals:
    """One value a cycle from the run's first: reported ``velocity`` m/s, the controller's
    ``position`` m, the ``force`` sent N and the ``probe`` N; and the units they are rounded to
    (``quanta``: m/s, m and N: a count of 0x606C, of 0x6064 and one per mille of torque)."""

    velocity: np.ndarray
    position: np.ndarray
    force: np.ndarray
    probe: np.ndarray
    quanta: tuple[float, float, float]


@dataclass(frozen=True)
class Validation:
    """What ``validate`` measured and concluded (SI units; ``tolerance`` and ``within`` as fractions)."""

    loop: DeviceLoop
    hold: Hold
    plan: ProbePlan
    amplitude: float
    noise: float
    prediction: Prediction
    plant: Measured
    velocity: Measured
    position: Measured
    tolerance: float
    within: float
    holds: bool
    fits: tuple[Fit, ...]

    @property
    def up_to(self) -> float:
        """The highest excited frequency, Hz."""
        return float(self.plan.frequencies[-1])

    @property
    def findings(self) -> list[dict[str, Any]]:
        """The best candidate's findings, JSON-ready (none when the model holds)."""
        return [] if self.holds or not self.fits else [finding.to_dict() for finding in self.fits[0].findings]

    def summary(self) -> str:
        """One line: holds to within X % up to f Hz, or differs and how."""
        if self.holds:
            return f"the model holds to within {100 * self.within:.2g} % up to {self.up_to:.4g} Hz"
        best = self.fits[0]
        said = "; ".join(finding.describe() for finding in best.findings)
        return (f"the device differs from the model: up to {100 * self.within:.3g} % below {self.up_to:.4g} Hz "
                f"(tolerance {100 * self.tolerance:.3g} %); best explained by {said} (rms misfit left "
                f"{100 * best.misfit:.2g} %)")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the verdict, the findings, every candidate's fit, the probe and the model."""
        plan = self.plan
        return {
            "verdict": "holds" if self.holds else "differs",
            "within_percent": 100 * self.within,
            "up_to_hz": self.up_to,
            "tolerance_percent": 100 * self.tolerance,
            "findings": self.findings,
            "candidates": [{"name": fit.name, "chi2": fit.chi2, "misfit": fit.misfit,
                            "findings": [f.to_dict() for f in fit.findings]} for fit in self.fits],
            "probe": {"amplitude_n": self.amplitude, "velocity_noise_m_per_s": self.noise,
                      "hold": {"K": self.hold.stiffness, "B": self.hold.damping},
                      "band_hz": [float(plan.frequencies[0]), self.up_to], "tones": int(plan.bins.size),
                      "period_samples": plan.samples, "quiet_cycles": plan.quiet, "settle_periods": plan.settle,
                      "measured_periods": plan.periods, "drive_seconds": plan.cycles * plan.period},
            "model": {"m": self.loop.m, "b": self.loop.b, "T": self.loop.T, "delay": self.loop.delay,
                      "velocity": str(self.loop.velocity)},
        }


def validate(loop: DeviceLoop, hold: Hold, plan: ProbePlan, prediction: Prediction, signals: Signals, amplitude: float,
             noise: float, tolerance: float = DEFAULT_TOLERANCE) -> Validation:
    """The verdict on one run's ``signals`` (module docstring)."""
    per_velocity, per_position, per_force = signals.quanta  # the force's rounding acts on the probe's way in
    velocity = response(signals.velocity, signals.probe, plan, (per_velocity, per_force))
    position = response(signals.position, signals.probe, plan, (per_position, per_force))
    plant = response(signals.velocity, signals.force, plan, (per_velocity, per_force))
    relative, error = velocity.relative_to(prediction.velocity)
    holds = bool(np.all(relative <= tolerance + CONFIDENCE * error))
    fits = (nominal(plant, loop),) if holds else tuple(departures(plant, loop))
    return Validation(loop, hold, plan, amplitude, noise, prediction, plant, velocity, position, tolerance,
                      float(np.max(relative)), holds, fits)
