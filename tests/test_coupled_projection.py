"""Is checking each axis' projection enough?  No: the counterexamples and the one exact case
of haptic_bus.analysis.coupled's notes, number by number.

Tolerances: limits are located to ~1e-12 relative (the zoom of an envelope minimum); the
quoted numbers are rounded in the notes, so 1e-4 relative.  Equal limits (the mobility
projection's theorem) are two independent computations of one number: measured <= 5e-16
relative, 1e-9 asserted.  Time-domain mean powers against ``lambda/2``: within the
summation's own round-off bound (``steady_mean_power``'s ``2 q eps sum |w_k|``), which at a
slow tone of 4096 samples a period, whose terms cancel 8.5e5-fold, allows 1.5e-6 relative
(measured 1.4e-9 with numpy 2.4, 1e-15 with numpy 1.26), and near Nyquist 4e-11; plus 1e-12
of ``lambda`` for the eigenvalue's own error.  An unstable loop's energy from rest is asserted below minus its
round-off bound.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic_bus.analysis.coupled import coupled_verdict, hermitian_impedance
from haptic_bus.analysis.coupled_energy import (
    CoupledMachine,
    adversarial_input,
    commensurate,
    simulate_energies,
    steady_mean_power,
)
from haptic_bus.analysis.coupled_limits import passive_along
from haptic_bus.analysis.coupled_loop import CoupledLoop, plane_wall
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.limits import passive_set
from haptic_bus.analysis.loop import WallLoop

T = 1e-3
DIAGONAL = [1.0, 1.0]
HANDLE = WallLoop(1.0, 20.0, T, 0, 0, 1, "average")  # the cia402-handle profile's axis


def _mobility(axes: tuple[WallLoop, ...], normal: list[float], K: float, B: float, timing: WallLoop) -> WallLoop:
    """The 1-D loop along ``normal`` with ``m_n = 1/(n^T M^-1 n)``, ``b_n = 1/(n^T b^-1 n)`` and ``timing``'s D and velocity."""
    n = np.array(normal) / np.linalg.norm(normal)
    m = 1.0 / sum(ni * ni / a.m for ni, a in zip(n, axes))
    b = 1.0 / sum(ni * ni / a.b for ni, a in zip(n, axes))
    return WallLoop(m, b, T, K, B, timing.delay, timing.velocity)


def _active_from_rest(loop: CoupledLoop) -> float:
    """The least operator energy (J) from rest under the adversarial tone, plus its round-off bound."""
    theta, force = adversarial_input(loop, np.geomspace(1e-3, math.pi, 48))
    runs = simulate_energies([CoupledMachine(loop, theta, force)], 3000)
    assert runs.roundoff[0] < 1e-5
    return float(runs.lowest[0] + runs.roundoff[0])


def _assert_time_domain_power_is_half_least(loop: CoupledLoop, theta: float) -> float:
    """The mean power (W) of ``W = Z v`` at the commensurate ``theta``, checked to be ``lambda_min/2`` within its round-off."""
    theta, samples = commensurate(theta)
    part = hermitian_impedance(loop, np.array([theta]))
    values, vectors = np.linalg.eigh(part.matrix[0])
    machine = CoupledMachine(loop, theta, part.full[0] @ vectors[:, 0])
    power = steady_mean_power(machine, samples)
    assert abs(power.mean - values[0] / 2) <= power.roundoff + 1e-12 * abs(values[0])
    return power.mean


def test_each_axis_alone_misses_a_factor_two_on_identical_axes() -> None:
    axes = (HANDLE, HANDLE)
    per_axis = passive_set(HANDLE, "K").largest / 0.5  # K n_i^2 <= the axis' own limit
    coupled = passive_along(axes, DIAGONAL, 0.0, 0.0, "K").largest
    assert per_axis == pytest.approx(26_666.67, rel=1e-4)
    assert coupled == pytest.approx(13_333.34, rel=1e-4)
    alone = exact_verdict(HANDLE.with_wall(10_000.0, 0.0))  # K = 20 000 along the diagonal, seen by one axis
    assert alone.passive and alone.margin == pytest.approx(5.0, rel=1e-4)
    loop = plane_wall(axes, DIAGONAL, 20_000.0, 0.0)
    verdict = coupled_verdict(loop)
    assert verdict.outcome == "unstable" and verdict.spectral_radius == pytest.approx(1.00478, abs=1e-5)
    assert _active_from_rest(loop) < -1e6


def test_the_arithmetic_projection_is_optimistic_when_the_axes_differ() -> None:
    axes = (HANDLE, WallLoop(0.25, 5.0, T, 0, 0, 1, "average"))
    arithmetic = WallLoop(0.625, 12.5, T, 0, 0, 1, "average")  # n^T M n, n^T b n
    assert passive_set(arithmetic, "K").largest == pytest.approx(8_333.34, rel=1e-4)
    assert passive_along(axes, DIAGONAL, 0.0, 0.0, "K").largest == pytest.approx(5_333.33, rel=1e-4)
    projected = exact_verdict(arithmetic.with_wall(7_000.0, 0.0))
    assert projected.passive and projected.margin == pytest.approx(2.0, rel=1e-4)
    loop = plane_wall(axes, DIAGONAL, 7_000.0, 0.0)
    assert coupled_verdict(loop).outcome == "unstable"
    assert _active_from_rest(loop) < 0.0


@pytest.mark.parametrize(("velocity", "delay", "B"), [("average", 1, 0.0), ("point", 0.5, 2.0), ("lowpass:0.002", 1, 0.0),
                                                       ("window:0.0005", 1.5, 1.0)])
def test_the_mobility_projection_is_exact_for_one_timing_and_one_b_over_m(velocity: str, delay: float, B: float) -> None:
    rng = np.random.default_rng(22)
    masses = rng.uniform(0.2, 2.0, 3)
    axes = tuple(WallLoop(m, 15.0 * m, T, 0, 0, delay, velocity) for m in masses)  # b/m = 15 1/s on every axis
    normal = list(rng.uniform(0.3, 1.0, 3) * [1, -1, 1])
    projected = passive_set(_mobility(axes, normal, 0.0, B, axes[0]), "K")
    coupled = passive_along(axes, normal, 0.0, B, "K")
    assert len(coupled.intervals) == len(projected.intervals)
    for (lo, hi), (plo, phi) in zip(coupled.intervals, projected.intervals):
        assert lo == pytest.approx(plo, rel=1e-9, abs=1e-9) and hi == pytest.approx(phi, rel=1e-9)
    for K in (0.9 * projected.largest, 1.1 * projected.largest):
        assert coupled_verdict(plane_wall(axes, normal, K, B)).passive == exact_verdict(
            _mobility(axes, normal, K, B, axes[0])).passive


def test_the_mobility_projection_fails_when_b_over_m_differs() -> None:
    axes = (WallLoop(1.0, 20.0, T, 0, 0, 0, "point"), WallLoop(1.0, 2.0, T, 0, 0, 0, "point"))
    assert passive_set(_mobility(axes, DIAGONAL, 0.0, 0.0, axes[0]), "K").largest == pytest.approx(4.000e6, rel=1e-4)
    assert passive_along(axes, DIAGONAL, 0.0, 0.0, "K").largest == pytest.approx(3.0779e6, rel=1e-4)
    projected = exact_verdict(_mobility(axes, DIAGONAL, 3.5e6, 0.0, axes[0]))
    assert projected.passive and projected.margin == pytest.approx(1.648, rel=1e-3)
    loop = plane_wall(axes, DIAGONAL, 3.5e6, 0.0)
    verdict = coupled_verdict(loop)
    assert verdict.outcome == "not passive" and verdict.margin == pytest.approx(-1.4954, rel=1e-4)
    assert verdict.critical_theta == pytest.approx(math.pi)
    power = _assert_time_domain_power_is_half_least(loop, 2 * math.pi * 255 / 512)  # just below Nyquist
    assert power == pytest.approx(-0.7094, rel=1e-4)


def test_with_different_timing_no_one_projection_is_right() -> None:
    axes = (WallLoop(1.0, 20.0, T, 0, 0, 1, "point"), WallLoop(0.5, 10.0, T, 0, 0, 0.5, "average"))
    coupled = passive_along(axes, DIAGONAL, 0.0, 0.0, "K").largest
    second, first = (passive_set(_mobility(axes, DIAGONAL, 0.0, 0.0, timing), "K").largest for timing in reversed(axes))
    assert (first, coupled, second) == pytest.approx((13_289.1, 13_318.5, 13_333.3), rel=1e-5)
    projected = exact_verdict(_mobility(axes, DIAGONAL, 13_325.0, 0.0, axes[1]))
    assert projected.passive and projected.margin == pytest.approx(0.00833, rel=1e-3)
    loop = plane_wall(axes, DIAGONAL, 13_325.0, 0.0)
    verdict = coupled_verdict(loop)
    assert verdict.outcome == "not passive" and verdict.margin == pytest.approx(-0.005838, rel=1e-3)
    assert _assert_time_domain_power_is_half_least(loop, 0.0015339807878856412) < 0  # 4096 samples a period
