"""Which velocity does the drive report?  0x606C against the models of DESIGN 3.5, from the same run.

For each candidate -- ``point`` ``v(kT)``, ``average`` ``(x(kT) - x(kT - T))/T``, ``window:TW``
``(x(kT) - x(kT - TW))/TW`` and ``lowpass:TAU`` (a first-order filter of ``v``) -- the value
0x606C would have is computed from the encoder, the commanded forces and the fitted plant
(:func:`~haptic_bus.identify.model.sample_velocity`), on the cycles where the fit's equations hold
(no reversal nearby).  ``TW`` and ``TAU`` are fitted (:func:`scipy.optimize.minimize_scalar` on a
log scale).  The distance of a model is the rms of ``0x606C - model`` (0x606C units); what is left
for the right model is the drive's noise and rounding.

The models are ranked by the Bayesian information criterion ``n ln(mean square) + p ln n``
(``p = 1`` for a fitted time): a window or filter must explain enough more than ``point`` or
``average`` to pay for its parameter (and one that lags less than :data:`SAME_LAG` of a period
is ``point``, a window within it of ``T`` is ``average``: they are dropped, not listed twice).
Every model within :data:`EVIDENCE` of the best is *consistent* with the data (a BIC difference
above 10 is "very strong" evidence against a model); a declared model matches when it is one of
them.

A fitted time is an estimate too, and a longer window or filter lags more (the gate's
pessimistic side).  :attr:`ModelDistance.credible` is the model with the longest time the data
still allow: the largest time whose mean square exceeds the best's by at most :data:`CREDIBLE_CHI2`
in ``n ln(ms / ms_best)`` (a likelihood ratio with one parameter: 9 is 3 sigma, as the friction and
the delay the gate judges).  What ``--write-profile`` writes is the best model's credible one.
Units: s, m/s; distances in 0x606C units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from haptic_bus.analysis.velocity import LOWPASS_RANGE, VelocityModel
from haptic_bus.identify.model import Plant, sample_velocity, usable_equations
from haptic_bus.identify.record import Record

EVIDENCE = 10.0  # BIC units
SHORTEST = 1e-3  # of T: the shortest window or filter constant tried
LONGEST_FILTER = 100.0  # x T: the longest filter constant tried
SIGNIFICANT = 3  # digits of a fitted time in the model string
SAME_LAG = 0.01  # of T: a window or filter lagging less than this is point (a window this close to T, average)
CREDIBLE_CHI2 = 9.0  # n ln(ms/ms_best) at the longest credible time: 3 sigma for one parameter


@dataclass(frozen=True)
class ModelDistance:
    """A candidate ``model`` (profile string), its rms distance to 0x606C (0x606C units), its ``bic``,
    and the ``credible`` model: the same with the longest window or filter time the data allow
    (``model`` itself for point and average)."""

    model: str
    rms: float
    bic: float
    credible: str


@dataclass(frozen=True)
class VelocityCheck:
    """The candidates (best first), the ones ``consistent`` with the data, the ``declared`` model
    (None if the profile states none) with its distance, and ``samples`` compared."""

    distances: tuple[ModelDistance, ...]
    consistent: tuple[str, ...]
    declared: ModelDistance | None
    samples: int

    @property
    def best(self) -> str:
        """The model 0x606C matches best."""
        return self.distances[0].model

    @property
    def credible(self) -> str:
        """The best model with the longest time the data allow (what the gate should judge)."""
        return self.distances[0].credible

    @property
    def matches_declared(self) -> bool | None:
        """Whether the declared model is consistent with 0x606C (None when nothing is declared)."""
        if self.declared is None:
            return None
        return self.declared.bic - self.distances[0].bic <= EVIDENCE


def check_velocity(record: Record, plant: Plant, declared: VelocityModel | str | None = None) -> VelocityCheck:
    """Compare 0x606C with every velocity model (see the module docstring)."""
    usable = usable_equations(record)  # usable[i] <-> SYNC i + 1
    measured = record.velocity[1:-1][usable]
    n = int(measured.size)
    per_count = record.scale.velocity
    period = record.period

    def mean_square(model: VelocityModel) -> float:
        return float(np.mean((measured - sample_velocity(record, plant, model)[usable]) ** 2))

    def distance(model: VelocityModel, parameters: int, credible: VelocityModel | None = None) -> ModelDistance:
        square = max(mean_square(model), 1e-300)
        return ModelDistance(str(model), math.sqrt(square) / per_count, n * math.log(square) + parameters * math.log(n),
                             str(credible or model))

    def fitted(kind: str, low: float, high: float) -> ModelDistance:
        def cost(log_time: float) -> float:
            return mean_square(VelocityModel(kind, min(high, math.exp(log_time))))

        best = minimize_scalar(cost, bounds=(math.log(low), math.log(high)), method="bounded")
        time = min(high, float(f"{math.exp(best.x):.{SIGNIFICANT}g}"))
        floor = max(cost(best.x), 1e-300)

        def excess(log_time: float) -> float:  # n ln(ms/ms_best) - CREDIBLE_CHI2: negative while credible
            return n * math.log(max(cost(log_time), 1e-300) / floor) - CREDIBLE_CHI2

        longest = high
        if excess(math.log(high)) > 0.0:
            longest = math.exp(brentq(excess, best.x, math.log(high), xtol=1e-6))
        longest = min(high, max(time, _round_up(longest)))
        return distance(VelocityModel(kind, time), 1, VelocityModel(kind, longest))

    candidates = [distance(VelocityModel("point"), 0), distance(VelocityModel("average"), 0)]
    longest = min(LOWPASS_RANGE[1], LONGEST_FILTER * period)
    for candidate in (fitted("window", SHORTEST * period, period),
                      fitted("lowpass", max(LOWPASS_RANGE[0], SHORTEST * period), longest)):
        model = VelocityModel.parse(candidate.model)
        lag = model.time / 2.0 if model.kind == "window" else model.time  # the measurement's lag, s
        if SAME_LAG * period < lag and not (model.kind == "window" and model.time > (1.0 - SAME_LAG) * period):
            candidates.append(candidate)  # else it is point (or average) under another name
    ranked = tuple(sorted(candidates, key=lambda c: c.bic))
    consistent = tuple(c.model for c in ranked if c.bic - ranked[0].bic <= EVIDENCE)
    stated = None
    if declared is not None:
        model = VelocityModel.parse(declared)
        stated = distance(model, 0)
    return VelocityCheck(ranked, consistent, stated, n)


def _round_up(time: float) -> float:
    """``time`` (s) rounded up to :data:`SIGNIFICANT` digits."""
    exponent = math.floor(math.log10(time)) - SIGNIFICANT + 1
    digits = math.ceil(time / 10.0**exponent * (1.0 - 1e-12))  # a time already on the grid stays there
    return float(f"{digits * 10.0**exponent:.{SIGNIFICANT}g}")
