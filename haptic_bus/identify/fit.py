"""The fit of the exact model: bias-compensated least squares on encoder increments, with standard errors.

For every whole delay ``d`` in ``0 .. max_delay`` a linear least-squares fit (:func:`numpy.linalg.lstsq`)
of the model at ``delta = 0`` -- linear in ``[a, T^2 g/(m r), ..., -Fc ...]`` -- gives start values
and ranks the ``d``.  The two best are refined by :func:`scipy.optimize.least_squares` over
``(m, b, Fc, delta)`` with ``0 <= delta <= 1`` (the delay ``D = d + delta`` is continuous across
whole samples: ``delta = 1`` is ``d + 1``); the smaller cost wins.

**Quantisation.**  The encoder's rounding adds :func:`~haptic_bus.identify.model.quantization_variance`
``(a)`` to every ``e_j`` in expectation, and that term depends on ``a``: plain least squares
minimises it too, pulling ``a`` down and ``b`` up (+9 % on ``b`` with 10 um increments on a
0.37 kg, 2.9 N s/m handle; 0.1 % with 0.1 um).  The fit minimises ``sum e_j^2 - n var(a)``
instead, the cost with its known noise part taken out, whose minimiser is consistent;
``least_squares`` does it with one extra residual ``sqrt(n (1 - var(a)))``, whose square adds
``-n var(a)`` plus a constant.  (Bias-compensated least squares, written as a sum of squares.)

**Standard errors.**  A rounding error enters three consecutive equations, so the residuals are
correlated (lag 1 about -0.67) and the textbook ``(J'J)^-1 s^2`` is wrong (3-4 times too large
here).  The covariance is the sandwich ``(J'J)^-1 S (J'J)^-1`` with ``S`` the Newey-West estimate
of the long-run covariance of the scores ``J_j e_j`` (Bartlett weights, ``L = floor(4 (n/100)^(2/9))``
lags).  Written here in a few lines rather than adding statsmodels for it.  Against the spread of
repeated runs on the simulated drive it is 1-2 times conservative for ``m`` and ``b`` and right
for ``D``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from haptic_bus.analysis.loop import FRICTION_RANGE, MASS_RANGE
from haptic_bus.errors import Refusal
from haptic_bus.identify.bounds import MAX_DELAY
from haptic_bus.identify.model import IncrementEquations, Plant, quantization_variance, usable_equations
from haptic_bus.identify.record import Record

MIN_EQUATIONS = 200
REFINED = 2  # whole delays refined by the nonlinear fit
DELTA_STARTS = (0.25, 0.75)
CORRELATION_LAGS = range(3, 21)  # beyond the rounding's own reach (lags 1, 2)
DELAY_RESOLUTION = 0.05  # samples: the fraction is resolved when its standard error is below this
WHOLE_TOLERANCE = 0.01  # samples: a delay this close to a whole number (or within 3 sigma) is whole
_TOLERANCE = 1e-12


@dataclass(frozen=True)
class Estimate:
    """A fitted ``value`` and its standard error (same unit)."""

    value: float
    stderr: float

    def interval(self, z: float = 1.96) -> tuple[float, float]:
        """``value -+ z stderr`` (95 % for the default ``z``, normal approximation)."""
        return self.value - z * self.stderr, self.value + z * self.stderr

    @property
    def relative(self) -> float:
        """``stderr / |value|`` (inf for a zero value)."""
        return self.stderr / abs(self.value) if self.value else math.inf


@dataclass(frozen=True)
class PlantFit:
    """The fitted plant with standard errors and the residual check.

    ``mass`` kg, ``friction`` N s/m, ``coulomb`` N, ``delay`` samples; ``equations`` fitted;
    ``residual_rms`` and ``quantization_rms`` (what rounding alone leaves) in increments;
    ``residual_correlation``: the largest ``|autocorrelation|`` of the residuals at lags 3-20,
    against ``correlation_bound`` (``4/sqrt(n)``); ``compensation``: how much the quantisation
    compensation moved ``b`` (N s/m, compensated minus plain least squares); ``delays``: residual
    rms (increments) of the linear fit per whole delay; ``directions``: usable equations moving
    towards +x and towards -x.
    """

    mass: Estimate
    friction: Estimate
    coulomb: Estimate
    delay: Estimate
    equations: int
    residual_rms: float
    quantization_rms: float
    residual_correlation: float
    correlation_bound: float
    compensation: float
    delays: tuple[float, ...]
    directions: tuple[int, int]

    @property
    def plant(self) -> Plant:
        """The estimate as a :class:`Plant`."""
        return Plant(self.mass.value, self.friction.value, self.coulomb.value, self.delay.value)

    @property
    def fraction_resolved(self) -> bool:
        """The data pin the delay to within :data:`DELAY_RESOLUTION` samples (one sigma)."""
        return self.delay.stderr <= DELAY_RESOLUTION

    @property
    def whole_delay(self) -> int | None:
        """The whole number of samples the delay is consistent with, if any (and resolved)."""
        nearest = round(self.delay.value)
        close = abs(self.delay.value - nearest) <= max(3.0 * self.delay.stderr, WHOLE_TOLERANCE)
        return nearest if close and self.fraction_resolved else None

    @property
    def friction_low(self) -> float:
        """The lowest credible ``b``: ``max(0, b - 3 sigma)``, N s/m (what the gate judges with)."""
        return max(0.0, self.friction.value - 3.0 * self.friction.stderr)

    @property
    def delay_high(self) -> float:
        """The largest credible delay, samples: ``D + 3 sigma``, rounded up to whole samples when the
        fraction is not resolved."""
        high = self.delay.value + 3.0 * self.delay.stderr
        return high if self.fraction_resolved else float(math.ceil(high - 1e-9))


def fit_plant(record: Record, max_delay: int = MAX_DELAY) -> PlantFit:
    """Fit ``m``, ``b``, ``Fc`` and ``D`` to ``record`` (see the module docstring); Refusal
    when fewer than :data:`MIN_EQUATIONS` equations are usable."""
    usable = usable_equations(record)
    if usable.sum() < MIN_EQUATIONS:
        raise Refusal(f"only {int(usable.sum())} of {usable.size} cycles moved clearly in one direction "
                      f"(at least {MIN_EQUATIONS} are needed): the handle moved too few encoder increments "
                      f"({record.scale.position:g} m each) per cycle, or kept sticking")
    systems = [IncrementEquations(record, d, usable) for d in range(max_delay + 1)]
    linear = [_linear_start(system) for system in systems]
    ranked = sorted(range(len(systems)), key=lambda d: linear[d][1])[:REFINED]
    best: tuple[OptimizeResult, IncrementEquations] | None = None
    for d in ranked:
        start = linear[d][0]
        for delta in DELTA_STARTS:
            result = _refine(systems[d], start, delta)
            if best is None or result.cost < best[0].cost:
                best = result, systems[d]
    assert best is not None
    result, system = best
    return _summarise(result, system, tuple(rms for _, rms in linear))


def _linear_start(system: IncrementEquations) -> tuple[Plant, float]:
    """The least-squares fit of the model at ``delta = 0``: a start and its residual rms (increments)."""
    step0, step1 = system.steps
    now0, now1 = system.now
    columns = np.column_stack([step0, now1, now0, system.sign])
    coefficients, *_ = np.linalg.lstsq(columns, step1, rcond=None)
    rms = float(np.sqrt(np.mean((step1 - columns @ coefficients) ** 2)))
    a = float(np.clip(coefficients[0], 1e-6, 1.0 - 1e-12))
    forcing = coefficients[1] + coefficients[2]  # the DC gain from force to increments over two cycles
    c = -math.log(a)  # b T / m
    period, resolution = system.period, system.resolution
    _, phi, g_now, _ = system.coefficients(1.0, c / period, 0.0)
    if forcing <= 0:
        return Plant(1.0, 0.0, 0.0, float(system.whole_delay)), math.inf
    mass = period * period * (g_now[1] * (1.0 - a) + phi * g_now[0]) / (resolution * forcing)
    mass = float(np.clip(mass, MASS_RANGE[0], MASS_RANGE[1]))
    coulomb = max(0.0, -float(coefficients[3]) / forcing)
    return Plant(mass, c * mass / period, coulomb, float(system.whole_delay)), rms


def _refine(system: IncrementEquations, start: Plant, delta: float, compensate: bool = True) -> OptimizeResult:
    """``least_squares`` over ``(m, b, Fc, delta)`` from ``start`` (with the quantisation compensation)."""
    count, period = system.count, system.period

    def residuals(theta: np.ndarray) -> np.ndarray:
        mass, friction, coulomb, fraction = theta
        e = system.residuals(mass, friction, coulomb, fraction)
        if not compensate:
            return e
        a = math.exp(-friction * period / mass)
        return np.append(e, math.sqrt(count * (1.0 - quantization_variance(a))))

    low = [MASS_RANGE[0], FRICTION_RANGE[0], 0.0, 0.0]
    high = [MASS_RANGE[1], FRICTION_RANGE[1], np.inf, 1.0]
    theta0 = np.clip([start.mass, start.friction, start.coulomb, delta], low, np.minimum(high, 1e11))
    return least_squares(residuals, theta0, bounds=(low, high), x_scale="jac",
                         ftol=_TOLERANCE, xtol=_TOLERANCE, gtol=_TOLERANCE, max_nfev=400)


def newey_west(jacobian: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """The sandwich covariance ``(J'J)^-1 S (J'J)^-1`` with Newey-West's ``S`` of the scores ``J_j e_j``."""
    scores = jacobian * residuals[:, None]
    scores -= scores.mean(axis=0)
    n = scores.shape[0]
    lags = int(4 * (n / 100.0) ** (2.0 / 9.0))
    long_run = scores.T @ scores
    for lag in range(1, lags + 1):
        weighted = (1.0 - lag / (lags + 1.0)) * (scores[lag:].T @ scores[:-lag])
        long_run += weighted + weighted.T
    bread = np.linalg.pinv(jacobian.T @ jacobian)
    return bread @ long_run @ bread


def _summarise(result: OptimizeResult, system: IncrementEquations, delays: tuple[float, ...]) -> PlantFit:
    jacobian, e = result.jac[:-1], result.fun[:-1]
    stderr = np.sqrt(np.maximum(np.diag(newey_west(jacobian, e)), 0.0))
    mass, friction, coulomb, delta = (float(v) for v in result.x)
    plain = _refine(system, Plant(mass, friction, coulomb, 0.0), delta, compensate=False)
    a = math.exp(-friction * system.period / mass)
    centred = e - e.mean()
    power = float(centred @ centred)
    correlation = max((abs(float(centred[lag:] @ centred[:-lag])) / power for lag in CORRELATION_LAGS), default=0.0)
    forward = int(np.count_nonzero(system.sign > 0))
    return PlantFit(
        mass=Estimate(mass, float(stderr[0])),
        friction=Estimate(friction, float(stderr[1])),
        coulomb=Estimate(coulomb, float(stderr[2])),
        delay=Estimate(system.whole_delay + delta, float(stderr[3])),
        equations=system.count,
        residual_rms=float(np.sqrt(np.mean(e * e))),
        quantization_rms=math.sqrt(quantization_variance(a)),
        residual_correlation=correlation if power > 0 else 0.0,
        correlation_bound=4.0 / math.sqrt(system.count),
        compensation=friction - float(plain.x[1]),
        delays=delays,
        directions=(forward, system.count - forward),
    )
