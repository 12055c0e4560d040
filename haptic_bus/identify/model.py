"""The exact sampled model of the free handle that the identification fits (DESIGN 3, 3.5).

The handle ``m dv/dt + b v + Fc sgn(v) = F(t)``: ``F`` the motor force at the handle (N, positive
towards +x), the force ``F_k`` commanded in cycle ``k`` acting from ``(k + D) T``, ``D = d + delta``.
Over the interval ``j`` (``[jT, (j+1)T)``) the force is ``F_{j-d-1}`` for the first ``delta T`` and
``F_{j-d}`` after.  While the handle does not reverse in the interval, Coulomb friction is the
constant force ``-Fc s_j`` (``s_j`` the direction of motion), and the exact period map of
:func:`haptic_bus.analysis.sampled_loop.period_map` -- the plant with the ``average`` measurement,
whose second state is the displacement over the period -- gives, in scaled units (``f T/m``),

    v_{j+1} = a v_j + r0_j,     y_j = (x_{j+1} - x_j)/T = phi v_j + r1_j,
    r_j = (T/m) (gamma_now (F_{j-d} - Fc s_j) + gamma_before (F_{j-d-1} - Fc s_j)).

The velocity is never measured here: eliminating it between two intervals,

    e_j = y_{j+1} - a y_j - r1_{j+1} - phi r0_j + a r1_j = 0,

exactly, in the encoder positions and the commanded forces alone.  0x606C stays out of the fit:
its noise, in a regressor, would bias the coefficient it multiplies towards zero (errors in
variables), and nothing would tell by how much.  The encoder's rounding is the only noise left;
:func:`quantization_variance` is what it adds to ``e_j``, which the fit takes out.

Equations are kept only where the motion has one direction over the two intervals and their
neighbours, and the displacement of each is larger than its change from one interval to the next
plus :data:`MARGIN_COUNTS` (so the velocity cannot pass through zero inside: no reversal, no
sticking, the Coulomb term is the constant above).  Residuals are in encoder increments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.sampled_loop import PeriodMap, period_map
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.identify.record import Record

MARGIN_COUNTS = 2.0  # increments: a displacement this much above its change cannot hide a reversal


@dataclass(frozen=True)
class Plant:
    """A candidate handle: ``mass`` kg, viscous ``friction`` N s/m, ``coulomb`` friction N, loop ``delay`` samples."""

    mass: float
    friction: float
    coulomb: float
    delay: float

    @property
    def whole_delay(self) -> int:
        """``d``: the whole samples of the delay."""
        return int(np.floor(self.delay))

    def exact_map(self, period: float, velocity: VelocityModel | str = "average") -> PeriodMap:
        """The exact period map of this plant with the measurement ``velocity`` (scaled units)."""
        fraction = self.delay - self.whole_delay
        return period_map(WallLoop(self.mass, self.friction, period, 0.0, 0.0, fraction, VelocityModel.parse(velocity)))


def usable_equations(record: Record) -> np.ndarray:
    """Which equations ``e_j`` (``j = 0 .. N-3``) hold exactly (bool array): see the module docstring;
    an equation on a stale cycle's position (it uses ``x_j .. x_{j+2}``) is left out too."""
    steps = np.diff(record.position_counts.astype(float))
    usable = np.zeros(max(0, steps.size - 1), dtype=bool)
    if steps.size < 4:
        return usable
    window = sliding_window_view(steps, 4)  # intervals j-1 .. j+2 for j = 1 .. n-3
    change = sliding_window_view(np.abs(np.diff(steps)), 3).max(axis=1)
    one_way = np.all(window > 0, axis=1) | np.all(window < 0, axis=1)
    clear = np.abs(window).min(axis=1) > change + MARGIN_COUNTS
    usable[1 : 1 + window.shape[0]] = one_way & clear
    return usable & ~sliding_window_view(~record.fresh, 3).any(axis=1)


def quantization_variance(a: float) -> float:
    """Variance (increments^2) rounding the encoder to increments adds to ``e_j``: ``(1 + (1+a)^2 + a^2)/12``.

    ``e_j`` is ``q_{j+2} - (1 + a) q_{j+1} + a q_j`` in the rounding errors ``q``, uniform on
    ``[-1/2, 1/2]`` and independent while the handle moves many increments per cycle.
    """
    return (1.0 + (1.0 + a) ** 2 + a * a) / 12.0


class IncrementEquations:
    """The equations ``e_j`` of one record for the whole delay ``whole_delay`` on the ``usable`` rows.

    The record's columns are laid out once; :meth:`residuals` then costs a few vector operations.
    """

    def __init__(self, record: Record, whole_delay: int, usable: np.ndarray) -> None:
        steps = np.diff(record.position_counts.astype(float))
        force = record.force
        padded = np.concatenate([np.zeros(whole_delay + 1), force])
        j = np.arange(steps.size)
        now, before = padded[j + 1], padded[j]  # F_{j-d}, F_{j-d-1} of interval j
        sign = np.sign(steps)
        rows = np.flatnonzero(usable)
        self.period = record.period
        self.resolution = record.scale.position
        self.whole_delay = whole_delay
        self.steps = steps[rows], steps[rows + 1]
        self.now = now[rows], now[rows + 1]
        self.before = before[rows], before[rows + 1]
        self.sign = sign[rows]

    @property
    def count(self) -> int:
        """How many equations."""
        return int(self.sign.size)

    def coefficients(self, mass: float, friction: float, delta: float) -> tuple[float, float, np.ndarray, np.ndarray]:
        """``a``, ``phi``, ``gamma_now``, ``gamma_before`` of the plant (scaled), ``0 <= delta <= 1``."""
        pmap = Plant(mass, friction, 0.0, delta).exact_map(self.period)
        return 1.0 + pmap.phi_minus_identity[0, 0], pmap.phi_minus_identity[1, 0], pmap.gamma_now, pmap.gamma_before

    def residuals(self, mass: float, friction: float, coulomb: float, delta: float) -> np.ndarray:
        """``e_j`` in increments for the plant (``delta`` in [0, 1] on top of :attr:`whole_delay`)."""
        a, phi, g_now, g_before = self.coefficients(mass, friction, delta)
        scale = self.period * self.period / (mass * self.resolution)  # increments per N: T/m scales F, T/resolution y
        now0, now1 = self.now
        before0, before1 = self.before
        step0, step1 = self.steps
        c_now = phi * g_now[0] - a * g_now[1]
        c_before = phi * g_before[0] - a * g_before[1]
        total1, total0 = g_now[1] + g_before[1], c_now + c_before
        forcing = g_now[1] * now1 + g_before[1] * before1 + c_now * now0 + c_before * before0
        return step1 - a * step0 - scale * (forcing - coulomb * (total1 + total0) * self.sign)


def first_order_filter(drive: np.ndarray, pole: float) -> np.ndarray:
    """``y_j = pole * y_{j-1} + drive_j`` from rest (``y_{-1} = 0``), ``0 <= pole < 1``: what
    ``scipy.signal.lfilter([1], [1, -pole], drive)`` computes, to within a few roundings (a sum
    grouped otherwise), without importing scipy.signal (and scipy.stats with it: 1 s of CPU in
    every process that identifies).  Doubling: after the pass with shift ``s``, ``y_j`` sums
    ``pole^k drive_{j-k}`` over ``k < 2 s``; log2(N) vector passes, stopped once ``pole^s`` is 0."""
    filtered = np.array(drive, dtype=float)
    weight, shift = pole, 1
    while shift < filtered.size and weight != 0.0:
        filtered[shift:] += weight * filtered[:-shift]  # the product is a new array: no overlap with the sum
        weight, shift = weight * weight, 2 * shift
    return filtered


def sample_velocity(record: Record, plant: Plant, model: VelocityModel | str) -> np.ndarray:
    """What 0x606C would be (m/s) at each SYNC ``j = 1 .. N-2`` for a drive reporting ``model``, given
    the encoder, the commanded forces and ``plant``.

    The velocity at SYNC ``j - 1`` comes from the encoder step after it, ``v = (y - r1)/phi``; the
    measurement's exact period map then carries it, and any state of the measurement (a filter),
    over the interval to SYNC ``j`` under the forces of that interval.  Every model starts from the
    same step, so they share its rounding and differ only by what they measure (a window of
    vanishing width *is* ``point``, to the last digit of the data).
    """
    model = VelocityModel.parse(model)
    period = record.period
    steps = np.diff(record.position_counts.astype(float))
    padded = np.concatenate([np.zeros(plant.whole_delay + 1), record.force])
    j = np.arange(steps.size)
    sign = np.sign(steps)
    now, before = padded[j + 1] - plant.coulomb * sign, padded[j] - plant.coulomb * sign
    per_mass = period / plant.mass
    plain = plant.exact_map(period)
    known = per_mass * (plain.gamma_now[1] * now + plain.gamma_before[1] * before)
    velocity = (steps * record.scale.position / period - known) / plain.phi_minus_identity[1, 0]  # SYNC 0 .. N-2
    pmap = plant.exact_map(period, model)
    first = pmap.phi_minus_identity[:, 0] + np.eye(pmap.c.size)[:, 0]  # Phi's column of v
    drive = first[:, None] * velocity + per_mass * (pmap.gamma_now[:, None] * now + pmap.gamma_before[:, None] * before)
    if model.kind == "lowpass":  # the filter's state: nu_{j+1} = e^{-T/TAU} nu_j + drive_j, from rest
        drive[1] = first_order_filter(drive[1], 1.0 + pmap.phi_minus_identity[1, 1])
    return (pmap.c @ drive)[:-1]  # SYNC 1 .. N-1, the last dropped
