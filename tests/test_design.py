"""The seed's design tools: eq. 25, Fig. 6 step response, Fig. 5 Nyquist data, Fig. 4 curves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic_bus.analysis.closed_form import velocity_sampling_slack
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.design import (
    BANDWIDTH_ALPHA,
    SEED_PERIODS,
    bandwidth_rule,
    exact_region_boundary,
    exact_region_floor,
    force_step_response,
    nyquist_data,
    passive_region_curves,
)
from haptic_bus.analysis.energy import Constant, simulate
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import phi1

M, B_FRICTION, T = 0.5, 0.1, 1e-3
SEED = WallLoop(M, B_FRICTION, T, 200.0, 100.0, 0)
SEED_D1 = WallLoop(M, B_FRICTION, T, 200.0, 100.0, 1)
ALPHA = np.geomspace(1e-3, 1e4, 701)


# --------------------------------------------------------------------------- eq. 25


def test_bandwidth_rule_seed_design():
    alpha, ok = bandwidth_rule(SEED)
    assert alpha == pytest.approx(500.0, rel=1e-15)  # 100 / (200 * 1e-3)
    assert ok


def test_bandwidth_rule_is_strict_and_handles_no_spring():
    at_six = SEED.with_wall(100.0 / (BANDWIDTH_ALPHA * T), 100.0)
    assert bandwidth_rule(at_six)[0] == pytest.approx(6.0, rel=1e-14)
    assert bandwidth_rule(SEED.with_wall(200.0, 0.5))[1] is False  # alpha = 2.5
    assert bandwidth_rule(SEED.with_wall(0.0, 100.0)) == (math.inf, True)


# --------------------------------------------------------------------------- Fig. 6


def test_seed_step_response_poles_final_value_and_settling():
    step = force_step_response(SEED)
    rep = step.report
    np.testing.assert_allclose(np.sort(rep.poles.real), [0.8014, 0.998], atol=5e-5)  # the seed's numbers
    assert not rep.oscillatory  # both poles real and positive: no ringing
    assert rep.final_value == 1.0  # k1 K T / P(1), P(1) = k1 K T: the wall holds the push
    # the run ends when the slowest mode is down to 1e-6 of its start: the tail is there
    assert abs(step.force[-1] - 1.0) < 1e-7
    assert rep.settling_time == pytest.approx(0.017, abs=0.5e-3)  # 17 samples
    assert step.force[0] == 0.0
    # u_1 = k1 (KT + B): one period of the push through the plant, then K x + B v
    k1 = -math.expm1(-SEED.c) / SEED.b
    assert step.force[1] == pytest.approx(k1 * (200.0 * T + 100.0), rel=1e-13)


def test_seed_step_response_creeps_just_over_the_final_value():
    """The seed says "without overshoot"; exactly, the wall force peaks 0.84 % over 1 N.

    Not ringing (poles real): after the fast mode (0.8014, ~5 ms) the handle creeps into the
    damper with time constant B/K = 0.5 s (pole 0.998), and with ``u = W - m dv/dt - b v``,
    ``v = (W/B) e^{-tK/B}``, the wall force exceeds W by ``(mK/B - b)/B e^{-tK/B}`` (0.9 % at
    t = 0, 0.83 % at the peak time).  The pole 0.997986 sits 1.8e-5 below the wall's zero
    B/(KT + B) = 0.998004, so the slow mode's residue is small and positive.
    """
    rep = force_step_response(SEED).report
    assert 0.0 < rep.overshoot < 1.0
    assert rep.overshoot == pytest.approx(0.8390, abs=1e-4)
    creep = (M * 200.0 / 100.0 - B_FRICTION) / 100.0 * math.exp(-rep.peak_time * 200.0 / 100.0) * 100.0
    assert rep.overshoot == pytest.approx(creep, rel=0.03)  # continuous-time estimate, O(m/B / (B/K)) = 1 %
    zero = 100.0 / (200.0 * T + 100.0)
    slow = float(np.max(rep.poles.real))
    assert 0.0 < zero - slow < 2e-5


def _seed_transfer_function(loop: WallLoop) -> tuple[np.ndarray, np.ndarray]:
    """The seed's loop (point velocity, whole delay d) as ``U/W`` in powers of ``z^-1``, written out:
    ``v_{k+1} = a v_k - k1 u_{k-d} + k1 w``, ``u = (KTz/(z - 1) + B) v``, so
    ``U/W = k1 (K T z + B (z - 1)) z^d / P(z)``, ``P = (z - a)(z - 1) z^d + k1 (K T z + B (z - 1))``."""
    d, a = int(loop.delay), math.exp(-loop.c)
    k1 = loop.T / loop.m * phi1(loop.c)
    den = np.polyadd(np.polymul([1.0, -(1.0 + a), a], np.eye(d + 1)[0]), k1 * np.array([loop.K * loop.T + loop.B, -loop.B]))
    return k1 * np.array([0.0, loop.K * loop.T + loop.B, -loop.B]), den


def test_step_response_equals_the_seed_recursion_and_the_sampled_data_simulation():
    from scipy.signal import lfilter  # here, not at collection: scipy.signal brings scipy.stats, 0.7 s a worker

    for loop in (SEED, SEED_D1, SEED.with_wall(0.0, 100.0), WallLoop(0.04, 0.8, 1e-3, 1000.0, 2.0, 2)):
        step = force_step_response(loop, 400)
        # independent: the seed's closed-loop recursion (valid for point velocity, whole delays)
        num, den = _seed_transfer_function(loop)
        np.testing.assert_allclose(step.force, lfilter(num, den, np.ones(400)), atol=1e-9)
        # and the exact energy simulation under a constant 1 N push, wall force as applied
        record = simulate(loop, Constant(1.0), 400, 4)
        np.testing.assert_allclose(record.wall_force, step.applied, rtol=0, atol=1e-12)


def test_steady_wall_force_equals_the_push_with_any_delay_and_without_spring():
    for d in (0, 1, 2, 3):
        loop = WallLoop(M, B_FRICTION, T, 200.0, 100.0, d)
        step = force_step_response(loop)
        assert step.report.final_value == 1.0
        assert abs(step.force[-1] - 1.0) < 1e-6
    # no spring: the handle keeps moving at W/(b + B) and the wall force is B of that
    damper = force_step_response(SEED.with_wall(0.0, 100.0))
    assert damper.report.final_value == pytest.approx(100.0 / 100.1, rel=1e-5)  # exact: k1B/(1 - a + k1B)
    assert damper.force[-1] == pytest.approx(damper.report.final_value, rel=1e-5)  # mode down to 1e-6, residue ~1


# --------------------------------------------------------------------------- Fig. 5


def test_seed_nyquist_lies_in_the_right_half_plane():
    data = nyquist_data(SEED, 3000)
    assert data.theta[0] > 0 and data.theta[-1] == math.pi
    assert np.all(data.t_zw.real > 0)  # Fig. 5: passive by the seed's test
    assert np.all(data.t_fund.real > 0)  # and by the exact one
    # both leave the origin (the wall's integrator) and reach 1/b at the plant corner
    assert abs(data.t_zw[0]) < 1e-3 and float(np.max(data.t_zw.real)) == pytest.approx(1 / 100.1, rel=1e-3)


def test_nyquist_with_one_sample_delay_crosses_into_the_left_half_plane():
    data = nyquist_data(SEED_D1, 3000)
    assert np.min(data.t_zw.real) < 0 and np.min(data.t_fund.real) < 0


def test_seed_t_zw_gap_to_t_fund_at_nyquist_is_two_percent():
    """DESIGN 3.2's "about 2 % near pi": it is 1.93 % at theta = pi itself (but see test_energy)."""
    from haptic_bus.analysis.frequency import seed_t_zw, t_fund

    gap = seed_t_zw(SEED, math.pi)[0].real / t_fund(SEED, math.pi)[0].real - 1
    assert gap == pytest.approx(0.0193, abs=5e-4)


# --------------------------------------------------------------------------- Fig. 4


def test_fig4_region_order_at_the_same_period():
    curves = passive_region_curves(ALPHA, M, B_FRICTION, (T,))
    velocity = curves.velocity[0]
    # region above the curve: velocity's contains Liu 2011's, which contains Colgate's
    assert np.all(velocity < curves.liu2011)
    assert np.all(curves.liu2011 < curves.colgate)
    np.testing.assert_allclose(curves.colgate - curves.liu2011, 0.5, rtol=1e-12)


def test_fig4_smaller_period_wider_region_and_default_periods():
    curves = passive_region_curves(ALPHA)
    np.testing.assert_array_equal(curves.periods, SEED_PERIODS)
    assert np.all(np.diff(curves.velocity, axis=0) > 0)  # T = 1 < 5 < 10 ms: curve rises with T
    # eq. 24 is eq. 3 scaled by tanh(bT/2m)
    for row, period in zip(curves.velocity, SEED_PERIODS):
        np.testing.assert_allclose(row / curves.colgate, math.tanh(B_FRICTION * period / (2 * M)), rtol=1e-14)


def test_fig4_convention_points_above_the_curve_are_walls_passing_eq23():
    """Device fixed: the point (alpha, beta) is the wall B = b/beta, K = B/(alpha T)."""
    curves = passive_region_curves(ALPHA[::50], M, B_FRICTION, (T,))
    for alpha, boundary in zip(curves.alpha, curves.velocity[0]):
        for factor, expected in ((1.01, True), (0.99, False)):
            beta = boundary * factor
            damping = B_FRICTION / beta
            loop = WallLoop(M, B_FRICTION, T, damping / (alpha * T), damping)
            assert (velocity_sampling_slack(loop) >= 0) is expected


def test_exact_boundary_is_eq24_for_the_seed_device_without_delay():
    c = B_FRICTION * T / M
    floor = exact_region_floor(M, B_FRICTION, T, 0)
    assert floor == pytest.approx(math.tanh(c / 2), rel=1e-9)
    beta = floor * np.geomspace(1.001, 1e5, 25)
    alpha = exact_region_boundary(M, B_FRICTION, T, 0, beta)
    expected = 1.0 / (2.0 * (beta / math.tanh(c / 2) - 1.0))  # eq. 24 solved for alpha
    np.testing.assert_allclose(alpha, expected, rtol=1e-6)
    assert np.all(np.isnan(exact_region_boundary(M, B_FRICTION, T, 0, floor * np.array([0.5, 0.99]))))


def test_exact_boundary_with_delay_agrees_with_the_verdict_and_excludes_the_seed_design():
    floor = exact_region_floor(M, B_FRICTION, T, 1)
    assert 0.8 < floor < 0.87  # one sample of delay: beta >= ~0.83, i.e. B <= 1.2 b
    assert SEED_D1.beta < floor and not exact_verdict(SEED_D1).passive
    beta = floor * np.array([1.01, 1.5, 4.0, 30.0])
    alpha = exact_region_boundary(M, B_FRICTION, T, 1, beta)
    for a, bt in zip(alpha, beta):
        damping = B_FRICTION / bt
        for factor, expected in ((1.02, True), (0.98, False)):
            loop = WallLoop(M, B_FRICTION, T, damping / (a * factor * T), damping, 1)
            assert exact_verdict(loop).passive is expected
