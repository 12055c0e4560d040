"""The verdict: does the measured closed loop hold to the model's prediction, and if not, how does it differ?

The probe's response in velocity is compared frequency by frequency with the model's (exact,
:mod:`~haptic_bus.validate.model`).  A frequency is **resolved** when three standard errors of the
measurement (:mod:`~haptic_bus.validate.spectra`) are within the tolerance, and there it
**departs** when ``|measured / predicted - 1|`` exceeds the tolerance plus those three standard
errors.  The model **holds** when every probed frequency is resolved and none departs: "holds to
within X % up to f Hz", ``f`` the probe's highest frequency, ``X`` the largest relative
difference.  When a resolved frequency departs, the measured plant is fitted with every
departure :mod:`~haptic_bus.validate.departures` knows, and the best candidate's findings name
how the device differs.  When none departs but a band of frequencies is not resolved, the
measurement **cannot tell** (neither verdict, exit 1): from the lowest frequency already, or
above the resolved band that starts there (noise, the timing's jitter, or a response that does
not settle from period to period: an undamped mode the gate calls unstable left only its
scatter, and "holds up to 55 Hz" of the probe's 398 Hz had said nothing of it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.validate.departures import Fit, departures, explains, nominal
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
    up_to: float
    holds: bool
    fits: tuple[Fit, ...]

    @property
    def verdict(self) -> str:
        """``holds``, ``differs`` or ``cannot tell`` (module docstring)."""
        return "holds" if self.holds else "differs" if self.fits else "cannot tell"

    @property
    def findings(self) -> list[dict[str, Any]]:
        """The best candidate's findings, JSON-ready (none unless the device differs)."""
        return [finding.to_dict() for finding in self.fits[0].findings] if self.verdict == "differs" else []

    def summary(self) -> str:
        """One line: holds to within X % up to f Hz, differs and how, or cannot tell."""
        verdict = self.verdict
        if verdict == "holds":
            return f"the model holds to within {100 * self.within:.2g} % up to {self.up_to:.4g} Hz"
        if verdict == "cannot tell" and self.up_to > 0.0:
            return (f"cannot tell above {self.up_to:.4g} Hz (the probe reaches {self.plan.frequencies[-1]:.4g} Hz): the "
                    f"model holds to within {100 * self.within:.2g} % up to there, above it the measurement's scatter "
                    f"across periods exceeds the tolerance of {100 * self.tolerance:.3g} % (noise, the cycle's timing "
                    "jitter, or a response that does not settle: an undamped mode)")
        if verdict == "cannot tell":
            return (f"cannot tell: at {self.plan.frequencies[0]:.3g} Hz already the measurement's uncertainty exceeds "
                    f"the tolerance of {100 * self.tolerance:.3g} % (noise, or the cycle's timing jitter)")
        best = self.fits[0]
        said = "; ".join(finding.describe() for finding in best.findings)
        differs = (f"the device differs from the model: by up to {100 * self.within:.3g} % up to {self.up_to:.4g} Hz "
                   f"(tolerance {100 * self.tolerance:.3g} %)")
        if not self.explained:
            return (f"{differs}; no departure validate fits explains it within the measurement's uncertainty (the "
                    f"closest, {said}, leaves an rms misfit of {100 * best.misfit:.2g} %)")
        return f"{differs}; best explained by {said} (rms misfit left {100 * best.misfit:.2g} %)"

    @property
    def explained(self) -> bool:
        """Whether the best candidate explains the departure within the measurement's uncertainty
        (:func:`~haptic_bus.validate.departures.explains`; True unless the device differs)."""
        return self.verdict != "differs" or explains(self.fits[0], 2 * self.plan.bins.size)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the verdict, the findings, every candidate's fit, the probe, the model, and the
        responses per frequency (velocity and position per N of probe, the plant in m/s per N)."""
        plan = self.plan
        return {
            "verdict": self.verdict,
            "within_percent": 100 * self.within,
            "up_to_hz": self.up_to,
            "tolerance_percent": 100 * self.tolerance,
            "findings": self.findings,
            "explained": self.explained,
            "candidates": [{"name": fit.name, "chi2": fit.chi2, "parameters": fit.parameters, "misfit": fit.misfit,
                            "findings": [f.to_dict() for f in fit.findings]} for fit in self.fits],
            "probe": {"amplitude_n": self.amplitude, "velocity_noise_m_per_s": self.noise,
                      "hold": {"K": self.hold.stiffness, "B": self.hold.damping},
                      "band_hz": [float(plan.frequencies[0]), float(plan.frequencies[-1])], "tones": int(plan.bins.size),
                      "period_samples": plan.samples, "quiet_cycles": plan.quiet, "settle_periods": plan.settle,
                      "measured_periods": plan.periods, "drive_seconds": plan.cycles * plan.period},
            "model": {"m": self.loop.m, "b": self.loop.b, "T": self.loop.T, "delay": self.loop.delay,
                      "velocity": str(self.loop.velocity)},
            "responses": {"frequencies_hz": plan.frequencies.tolist(),
                          **{name: _response_dict(measured, predicted) for name, measured, predicted in (
                              ("velocity", self.velocity, self.prediction.velocity),
                              ("position", self.position, self.prediction.position),
                              ("plant", self.plant, self.prediction.plant))}},
        }


def _response_dict(measured: Measured, predicted: np.ndarray) -> dict[str, list[float]]:
    """A response per excited frequency, JSON-ready: measured (real, imaginary, standard error) and predicted."""
    return {"measured_re": measured.mean.real.tolist(), "measured_im": measured.mean.imag.tolist(),
            "error": measured.error.tolist(), "predicted_re": predicted.real.tolist(),
            "predicted_im": predicted.imag.tolist()}


def validate(loop: DeviceLoop, hold: Hold, plan: ProbePlan, prediction: Prediction, signals: Signals, amplitude: float,
             noise: float, tolerance: float = DEFAULT_TOLERANCE) -> Validation:
    """The verdict on one run's ``signals`` (module docstring)."""
    per_velocity, per_position, per_force = signals.quanta  # the force's rounding acts on the probe's way in
    velocity = response(signals.velocity, signals.probe, plan, (per_velocity, per_force))
    position = response(signals.position, signals.probe, plan, (per_position, per_force))
    plant = response(signals.velocity, signals.force, plan, (per_velocity, 0.0))  # the force sent is known exactly
    relative, error = velocity.relative_to(prediction.velocity)
    resolved = CONFIDENCE * error <= tolerance
    band = int(np.argmin(resolved)) if not resolved.all() else resolved.size  # the resolved bins from the lowest
    if band == 0:
        return Validation(loop, hold, plan, amplitude, noise, prediction, plant, velocity, position, tolerance,
                          float(np.max(relative)), 0.0, False, ())
    departs = resolved & (relative > tolerance + CONFIDENCE * error)
    if not departs.any():  # holds over the resolved band; over the whole probe, or it cannot tell above it
        within, up_to = float(np.max(relative[:band])), float(plan.frequencies[band - 1])
        complete = band == resolved.size
        return Validation(loop, hold, plan, amplitude, noise, prediction, plant, velocity, position, tolerance, within,
                          up_to, complete, (nominal(plant, loop),) if complete else ())
    within, up_to = float(np.max(relative[resolved])), float(plan.frequencies[resolved][-1])
    return Validation(loop, hold, plan, amplitude, noise, prediction, plant, velocity, position, tolerance, within,
                      up_to, False, tuple(departures(plant, loop)))
