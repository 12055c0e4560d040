"""The measured responses at the probe's frequencies, each with its uncertainty from the scatter across periods.

The probe is periodic, so every measured period is one realisation of the same response plus
noise.  Per period ``j`` (``N`` samples from :attr:`~haptic_bus.validate.probe.ProbePlan.measured_from`)
the DFT at each excited bin gives a response ``H_j = Y_j / U_j``; the estimate is their mean and
its standard error ``sqrt(sum |H_j - mean|^2 / (P (P - 1)))`` (``P`` periods): the variance
across periods, no model of the noise needed.  Nothing else leaks into the bins: a whole number
of periods of a periodic signal has its energy exactly on them once the transient is gone.

What repeats every period does not scatter: rounding a periodic signal to its unit (counts, one
per mille of torque) is a periodic error, the same in every period.  So each side's quantum ``q``
adds its rounding's spread ``q sqrt(N/12)`` per bin (uniform rounding, spread over the bins as a
white error; ``N`` samples a period), relative to that side's mean spectrum, in quadrature with
the scatter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptic_bus.validate.probe import ProbePlan


@dataclass(frozen=True)
class Measured:
    """A response at ``theta`` (rad): ``mean`` (complex, the output's unit per the input's) and its
    standard ``error`` (same unit, real)."""

    theta: np.ndarray
    mean: np.ndarray
    error: np.ndarray

    def relative_to(self, predicted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``|mean / predicted - 1|`` and its standard error ``error / |predicted|`` (dimensionless)."""
        return np.abs(self.mean / predicted - 1.0), self.error / np.abs(predicted)


def period_spectra(signal: np.ndarray, plan: ProbePlan) -> np.ndarray:
    """The DFT of ``signal`` (one value a cycle from the run's first) at the excited bins, one row per measured period."""
    start = plan.measured_from
    periods = signal[start:start + plan.periods * plan.samples].reshape(plan.periods, plan.samples)
    return np.fft.rfft(periods, axis=1)[:, plan.bins]


def response(output: np.ndarray, into: np.ndarray, plan: ProbePlan, quanta: tuple[float, float] = (0.0, 0.0)) -> Measured:
    """The response from ``into`` to ``output`` (signals a cycle each) at the excited bins, ``quanta``
    the units ``output`` and ``into`` are rounded to (module docstring)."""
    outputs, inputs = period_spectra(output, plan), period_spectra(into, plan)
    ratios = outputs / inputs
    mean = ratios.mean(axis=0)
    spread = np.sum(np.abs(ratios - mean) ** 2, axis=0) / (plan.periods * (plan.periods - 1))
    rounding = np.sqrt(plan.samples / 12.0)
    relative = sum((q * rounding / np.abs(side.mean(axis=0))) ** 2 for q, side in zip(quanta, (outputs, inputs)))
    return Measured(plan.theta, mean, np.sqrt(spread + np.abs(mean) ** 2 * relative))
