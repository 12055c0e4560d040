"""How the device departs from the model: fits of the measured plant, each departure with its uncertainty.

The measured plant is the response from the force sent (N, the torque target each cycle: known
exactly) to the reported velocity (m/s) at the probe's frequencies (:mod:`~haptic_bus.validate.spectra`).
Each candidate is an exact sampled plant with a few free parameters, fitted by weighted least
squares (the residual at each frequency over its standard error, real and imaginary parts):

- ``delay``: the profile's plant with the loop delay ``D + e`` (:func:`~haptic_bus.validate.model.plant_response`);
  ``value`` is the extra delay ``e`` in samples;
- ``resonance``: a transmission between motor and handle (:mod:`~haptic_bus.validate.two_mass`, the
  handle keeping the profile's ``m`` and ``b``): the free mode's natural ``frequency`` (Hz) and
  ``damping`` ratio, and the transmission fitted (``stiffness`` N/m, ``coupling_damping`` N s/m,
  ``motor_mass`` kg: what a profile's ``[device.transmission]`` states);
- ``filter``: a first-order lag ``1/(1 + j omega tau)`` on the force (``tau`` s; continuous, so
  exact only for ``tau`` well above ``T``);
- ``mass`` and ``friction``: the rigid plant with other ``m`` (kg) and ``b`` (N s/m).

The candidate with the least ``chi2 + 2 k`` (Akaike's criterion, ``k`` its free parameters) names the
departure.  Least ``chi2`` alone would name the candidate with more parameters whenever it can mimic a
simpler one: a transmission with ``c = b`` and ``k = b^2/m`` behind a motor mass ``M`` is exactly a
rigid handle of mass ``M`` and friction ``b``, so a handle 20 % heavier than the profile's was named a
3.2 Hz "resonance" of damping ratio 1 (its ``chi2`` lower by 0.1 of 406 numbers).  Akaike's penalty alone
still let it win by chance (:func:`unseen_resonance`): a resonance the probe cannot have seen as one is
ranked after every other candidate.  Uncertainties are
one standard deviation from the fit's covariance ``(J^T J)^-1``, scaled up by the reduced
chi-square when the model leaves more residual than the noise explains (so an approximate model
does not claim its noise-level precision); a derived quantity (frequency, damping) carries the
covariance through its numerical gradient.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.validate import two_mass
from haptic_bus.validate.model import plant_response, with_delay
from haptic_bus.validate.spectra import Measured

Model = Callable[[np.ndarray], np.ndarray]  # parameters -> the plant at the measured frequencies
UNITS = {("delay", "value"): " samples (extra)", ("resonance", "frequency"): " Hz", ("resonance", "damping"): "",
         ("resonance", "stiffness"): " N/m", ("resonance", "coupling_damping"): " N s/m", ("resonance", "motor_mass"): " kg",
         ("filter", "tau"): " s", ("mass", "value"): " kg", ("friction", "value"): " N s/m"}
_ERROR_FLOOR = 1e-9  # of |H|: a frequency measured without any scatter (a noiseless simulation) still gets a weight
EXPLAINED_QUANTILE = 0.999  # a fit's chi2 beyond this quantile of its chi-square distribution explains nothing
_UNSEEN_WEIGHT = 1e-8  # a parameter's share of an unseen direction (unit vector) above round-off: undetermined


@dataclass(frozen=True)
class Finding:
    """One departure: ``kind``, its ``values`` (SI units, samples for a delay) and their ``uncertainty``
    (None for a value the data do not determine: the fit left it at a bound of its range, the
    measured response does not depend on it, or it is a mode's damping ratio of an over-damped pair)."""

    kind: str
    values: dict[str, float]
    uncertainty: dict[str, float | None]

    def to_dict(self) -> dict[str, Any]:
        """``{"kind": ..., <values>, "uncertainty": u}`` (``u`` a number for one value, else one per value)."""
        uncertainty: Any = next(iter(self.uncertainty.values())) if len(self.uncertainty) == 1 else self.uncertainty
        return {"kind": self.kind, **self.values, "uncertainty": uncertainty}

    def describe(self) -> str:
        """One line: the kind and each value with its uncertainty and unit."""
        return f"{self.kind}: " + ", ".join(
            f"{'' if name == 'value' else name + ' '}{value:.4g}{_spread(self.uncertainty[name], UNITS[self.kind, name])}"
            for name, value in self.values.items())


def _spread(sigma: float | None, unit: str) -> str:
    """`` +- sigma unit``, or the unit and that the data do not determine the value."""
    return f"{unit} (undetermined)" if sigma is None else f" +- {sigma:.2g}{unit}"


@dataclass(frozen=True)
class Fit:
    """A candidate fitted: its ``name``, ``findings``, weighted squared residual ``chi2``, the rms
    relative residual ``misfit`` it leaves (dimensionless) and how many ``parameters`` it fitted."""

    name: str
    findings: tuple[Finding, ...]
    chi2: float
    misfit: float
    parameters: int

    @property
    def criterion(self) -> float:
        """Akaike's ``chi2 + 2 k`` (dimensionless): what ranks the candidates, ``k`` the free parameters."""
        return self.chi2 + 2.0 * self.parameters


def explains(fit: Fit, numbers: int) -> bool:
    """Whether ``fit``, over ``numbers`` real numbers (twice the frequencies), leaves only what the
    measurement's uncertainty explains: its ``chi2`` within the 99.9th percentile of the chi-square
    distribution with ``numbers - parameters`` degrees of freedom.  A device no candidate explains
    (Coulomb friction, a velocity estimate the candidates lack) is told so, not named after the
    candidate that came closest.  The quantile is ``2 P^-1(k/2, q)``, ``P`` the regularised lower
    incomplete gamma function (what ``scipy.stats.chi2.ppf`` computes, without loading scipy.stats: 0.5 s)."""
    from scipy.special import gammaincinv

    freedom = max(numbers - fit.parameters, 1)
    return fit.chi2 <= 2.0 * float(gammaincinv(freedom / 2.0, EXPLAINED_QUANTILE))


@dataclass(frozen=True)
class _Solution:
    x: np.ndarray
    covariance: np.ndarray
    chi2: float
    misfit: float
    undetermined: np.ndarray  # bool per parameter: at a bound of its range, or the data do not depend on it


def _weights(measured: Measured) -> np.ndarray:
    return 1.0 / np.maximum(measured.error, _ERROR_FLOOR * np.abs(measured.mean))


def _solve(measured: Measured, model: Model, start: Sequence[float], low: Sequence[float], high: Sequence[float],
           scale: Sequence[float]) -> _Solution:
    """Weighted least squares of ``model`` against ``measured`` from ``start`` within the bounds."""
    from scipy.optimize import least_squares  # lazily: the fit loads scipy.optimize

    weights = _weights(measured)
    scale_ = np.asarray(scale, dtype=float)

    def residual(u: np.ndarray) -> np.ndarray:
        r = (model(u * scale_) - measured.mean) * weights
        return np.concatenate([r.real, r.imag])

    u0 = np.clip(np.asarray(start, dtype=float), low, high) / scale_
    found = least_squares(residual, u0, bounds=(np.asarray(low) / scale_, np.asarray(high) / scale_), x_scale="jac",
                          method="trf")
    chi2 = float(2.0 * found.cost)
    dof = max(1, 2 * measured.mean.size - u0.size)
    covariance, unseen = _covariance(found.jac)
    covariance = covariance * max(1.0, chi2 / dof) * np.outer(scale_, scale_)
    misfit = float(np.sqrt(np.mean(np.abs(model(found.x * scale_) / measured.mean - 1.0) ** 2)))
    return _Solution(found.x * scale_, covariance, chi2, misfit, (found.active_mask != 0) | unseen)


def _covariance(jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(J^T J)^+`` over the directions the data see, and which parameters lie along one they do not:
    a singular value at or below ``max(rows, columns) eps`` times the largest (the pseudo-inverse's own
    cut) is a direction the residual does not change along, whose variance is unbounded, not zero."""
    _, singular, directions = np.linalg.svd(jacobian, full_matrices=False)
    seen = singular > max(jacobian.shape) * np.finfo(float).eps * singular[0]
    kept = directions[seen]
    unseen = np.any(np.abs(directions[~seen]) > _UNSEEN_WEIGHT, axis=0)
    return (kept.T / singular[seen] ** 2) @ kept, unseen


def _sigma(solution: _Solution, i: int) -> float | None:
    """Parameter ``i``'s standard error; None where the data do not determine it."""
    return None if solution.undetermined[i] else float(math.sqrt(max(0.0, solution.covariance[i, i])))


def nominal(measured: Measured, loop: DeviceLoop) -> Fit:
    """The profile's plant itself, nothing fitted."""
    plant = plant_response(loop, measured.theta)
    r = (plant - measured.mean) * _weights(measured)
    misfit = float(np.sqrt(np.mean(np.abs(plant / measured.mean - 1.0) ** 2)))
    return Fit("model", (), float(np.sum(np.abs(r) ** 2)), misfit, 0)


def fit_delay(measured: Measured, loop: DeviceLoop) -> Fit:
    """The extra loop delay (samples) that fits best."""
    solution = _solve(measured, lambda p: plant_response(with_delay(loop, loop.delay + p[0]), measured.theta),
                      [0.0], [-float(loop.delay)], [float(loop.delay) + 10.0], [1.0])
    finding = Finding("delay", {"value": float(solution.x[0])}, {"value": _sigma(solution, 0)})
    return Fit("delay", (finding,), solution.chi2, solution.misfit, 1)


def fit_mass_friction(measured: Measured, loop: DeviceLoop) -> Fit:
    """The rigid handle's mass (kg) and friction (N s/m) that fit best."""
    def model(p: np.ndarray) -> np.ndarray:
        return plant_response(dataclasses.replace(loop, m=p[0], b=p[1]), measured.theta)

    solution = _solve(measured, model, [loop.m, loop.b], [1e-3 * loop.m, 0.0], [1e3 * loop.m, 1e3 * max(loop.b, loop.m)],
                      [loop.m, max(loop.b, 1e-3)])
    findings = [Finding("mass", {"value": float(solution.x[0])}, {"value": _sigma(solution, 0)}),
                Finding("friction", {"value": float(solution.x[1])}, {"value": _sigma(solution, 1)})]

    def departure(finding: Finding, model_value: float) -> float:  # standard errors from the model's value
        sigma = finding.uncertainty["value"]
        change = abs(finding.values["value"] - model_value)
        return change / sigma if sigma else math.inf if change else 0.0

    # the one that departs leads: a hidden friction of 30 was told "mass: 1 +- 1.7e-06 kg; friction: 30 ..."
    order = sorted(zip(findings, (loop.m, loop.b)), key=lambda pair: -departure(*pair))
    return Fit("mass and friction", tuple(finding for finding, _ in order), solution.chi2, solution.misfit, 2)


def fit_filter(measured: Measured, loop: DeviceLoop) -> Fit:
    """The first-order lag on the force (``tau`` s) that fits best."""
    plant = plant_response(loop, measured.theta)
    solution = _solve(measured, lambda p: plant / (1.0 + 1j * measured.theta * p[0] / loop.T),
                      [loop.T], [0.0], [1e3 * loop.T], [loop.T])
    finding = Finding("filter", {"tau": float(solution.x[0])}, {"tau": _sigma(solution, 0)})
    return Fit("filter", (finding,), solution.chi2, solution.misfit, 1)


def fit_resonance(measured: Measured, loop: DeviceLoop) -> Fit:
    """The transmission (stiffness, damping, motor mass) that fits best, as its mode's frequency (Hz)
    and damping ratio."""
    start = _resonance_start(measured, loop)

    def coupling(p: np.ndarray) -> Transmission:
        return Transmission(p[0], p[1], p[2])

    solution = _solve(measured, lambda p: two_mass.response(loop, coupling(p), measured.theta), start,
                      [start[0] * 1e-2, 0.0, start[2] * 1e-2], [start[0] * 1e2, 1e3 * max(loop.b, 1.0), start[2] * 1e2],
                      [start[0], max(loop.b, 1.0) * 0.1, start[2]])
    mode = np.array(two_mass.mode(loop, coupling(solution.x)))
    gradient = np.empty((2, 3))
    for i in range(3):
        step = np.zeros(3)
        step[i] = 1e-6 * max(abs(solution.x[i]), 1e-9)
        gradient[:, i] = (np.array(two_mass.mode(loop, coupling(solution.x + step))) - mode) / step[i]
    sigma = np.sqrt(np.maximum(0.0, np.diag(gradient @ solution.covariance @ gradient.T)))
    derived: list[float | None] = [None if solution.undetermined.any() or not gradient[j].any() else float(sigma[j])
                                   for j in range(2)]  # a zero gradient: the over-damped pair's damping ratio 1
    names = ("stiffness", "coupling_damping", "motor_mass")  # what a profile's [device.transmission] states
    finding = Finding("resonance", {"frequency": float(mode[0]), "damping": float(mode[1]),
                                    **{name: float(value) for name, value in zip(names, solution.x)}},
                      {"frequency": derived[0], "damping": derived[1],
                       **{name: _sigma(solution, i) for i, name in enumerate(names)}})
    return Fit("resonance", (finding,), solution.chi2, solution.misfit, 3)


def _resonance_start(measured: Measured, loop: DeviceLoop) -> list[float]:
    """Stiffness (N/m), damping (N s/m) and motor mass (kg) from the measured plant's peak and dip
    against the model: the dip is the handle's antiresonance ``sqrt(k/m)``, the peak the resonance
    ``sqrt(k (1/M + 1/m))``."""
    ratio = np.abs(measured.mean / plant_response(loop, measured.theta))
    omega = measured.theta / loop.T
    peak = int(np.argmax(ratio))
    dip = int(np.argmin(ratio[:peak])) if peak > 0 else 0
    anti = omega[dip] if dip < peak else omega[peak] / 2.0
    stiffness = loop.m * anti * anti
    motor = 1.0 / max(omega[peak] ** 2 / stiffness - 1.0 / loop.m, 1e-3 / loop.m)
    return [stiffness, 0.1 * max(loop.b, 1.0), motor]


def departures(measured: Measured, loop: DeviceLoop) -> list[Fit]:
    """Every candidate fitted, the best (least :attr:`Fit.criterion`) first; a resonance the probe
    did not see (:func:`unseen_resonance`) after every other."""
    fits = [fit_delay(measured, loop), fit_mass_friction(measured, loop), fit_filter(measured, loop),
            fit_resonance(measured, loop)]
    lowest = float(measured.theta[0]) / (2.0 * math.pi * loop.T)  # Hz: the lowest probed frequency
    return sorted(fits, key=lambda fit: (unseen_resonance(fit, lowest), fit.criterion))


def unseen_resonance(fit: Fit, lowest: float) -> bool:
    """Whether ``fit`` is a resonance the probe cannot have seen as one: its mode below the ``lowest``
    probed frequency (Hz), or a damping the data leave undetermined (an over-damped pair, or a
    parameter at a bound).  A rigid handle of other ``m`` is exactly such a transmission (module
    docstring); with one parameter more it fits the noise a little closer, and Akaike's penalty of 2
    per parameter lets a model that nests another win by chance whenever its ``chi2`` is lower by more
    than 2: P(chi-square(1) > 2) = 0.16 (a handle 30 % heavier was named a 3.2 Hz resonance of
    damping 1, its ``chi2`` lower by 3.3)."""
    if fit.name != "resonance":
        return False
    (finding,) = fit.findings
    return finding.values["frequency"] < lowest or finding.uncertainty["damping"] is None
