"""The time-domain energy check (DESIGN 3.4) and its agreement with the frequency criteria.

Tolerances:

* round-off: :meth:`EnergyRecord.roundoff_bound`, ``(n + 64/(1 - rho)) 2^-53 sum|w dx|`` (recursive
  summation of n terms errs by at most ``(n - 1) u sum|x_i|``; the velocity recursion
  amplifies its own round-off by at most ``1/(1 - rho)``).
* the operator force is held over sub-steps of ``T/S`` at midpoint values; its difference from
  the true sinusoid changes the mean power by ``O((theta/S)^2)`` (measured: 6e-5 relative at
  theta = 3, S = 16; four times less per doubling of S), so 1e-3 is a safe bound for S = 16.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest

from haptic_bus.analysis.closed_form import velocity_sampling_slack
from haptic_bus.analysis.criterion import exact_verdict, seed_verdict
from haptic_bus.analysis.energy import (
    Chirp,
    RandomSinusoids,
    Sinusoid,
    commensurate_theta,
    mean_power,
    simulate,
    simulate_reference,
)
from drives.errors import ParameterError
from haptic_bus.analysis.frequency import t_fund
from haptic_bus.analysis.loop import WallLoop

SEED = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 0)
SEED_D1 = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 1)
BIG_C = WallLoop(0.02442, 512.26, 0.0042836, 185830.0, 0.0, 0)  # bT/m = 89.9: settles within a sample
N = 20_000


# --------------------------------------------------------------------------- the simulation itself


@pytest.mark.parametrize(
    "loop",
    [SEED, SEED_D1, SEED.with_wall(0.0, 100.0), WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 3), BIG_C,
     WallLoop(0.04, 0.0, 1e-3, 1000.0, 2.0, 1)],
    ids=["seed", "seed-d1", "damper-only", "seed-d3", "big-c", "b=0-d1"],
)
def test_vectorised_simulation_equals_the_plain_loop(loop):
    force = RandomSinusoids(loop.T, seed=11)
    fast = simulate(loop, force, 300, 8)
    slow = simulate_reference(loop, force, 300, 8)
    np.testing.assert_allclose(fast.energy, slow.energy, rtol=0, atol=1e-12 * slow.work_scale)
    np.testing.assert_allclose(fast.velocity, slow.velocity, rtol=0, atol=1e-12 * np.max(np.abs(slow.velocity)))
    np.testing.assert_allclose(fast.wall_force, slow.wall_force, rtol=0, atol=1e-12 * max(np.max(np.abs(slow.wall_force)), 1e-300))


def _bare_position(force: float, t: np.ndarray, m: float = 0.5, b: float = 0.1) -> np.ndarray:
    """``x(t) = (W/b)(t - (m/b)(1 - e^{-bt/m}))`` at 40 digits (the float formula cancels)."""
    mpmath.mp.dps = 40
    f, m_, b_ = mpmath.mpf(force), mpmath.mpf(m), mpmath.mpf(b)
    return np.array([float(f / b_ * (mpmath.mpf(s) - m_ / b_ * (1 - mpmath.exp(-b_ * mpmath.mpf(s) / m_)))) for s in t])


def test_energy_is_exact_for_a_constant_push_on_the_bare_handle():
    """No wall: E(t) = W x(t), x = (W/b)(t - (m/b)(1 - e^{-bt/m})); the record has no integration error."""
    loop = WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0)
    record = simulate(loop, lambda t: np.full_like(t, 2.0), 500, 16)
    np.testing.assert_allclose(record.energy, 2.0 * _bare_position(2.0, record.t), rtol=1e-12, atol=1e-300)


def test_energy_at_arbitrary_times_is_exact_between_sub_steps():
    record = simulate(SEED, Sinusoid(1.0, SEED.T), 200, 4)
    np.testing.assert_allclose(record.energy_at(record.t[:-1]), record.energy[:-1], rtol=0, atol=1e-18)
    # bare handle, constant 1 N, one sub-step per period: E(t) = x(t) at times inside sub-steps
    bare = simulate(WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0), lambda t: np.ones_like(t), 2, 1)
    when = np.array([0.25e-3, 0.5e-3, 1.5e-3])
    np.testing.assert_allclose(bare.energy_at(when), _bare_position(1.0, when), rtol=1e-12)


def test_inputs_refuse_frequencies_at_or_above_nyquist():
    for bad in (0.0, math.pi, 4.0, -1.0, float("nan")):
        with pytest.raises(ParameterError):
            Sinusoid(bad, 1e-3)
    with pytest.raises(ParameterError):
        Chirp(0.1, math.pi, 1e-3, 1.0)
    with pytest.raises(ParameterError):
        RandomSinusoids(1e-3, seed=0, theta_max=3.2)
    assert np.max(RandomSinusoids(1e-3, seed=4, theta_max=3.0).thetas) < 3.0


def test_commensurate_theta():
    p, q = commensurate_theta(1.0)
    assert q <= 4096 and abs(2 * math.pi * p / q - 1.0) < 1e-6


# --------------------------------------------------------------------------- passive: E >= 0


def _inputs(T: float, duration: float):
    yield from (Sinusoid(theta, T) for theta in (0.01, 0.3, 1.0, 2.0, 3.0, 3.1, math.pi - 1e-3))
    yield Sinusoid(2.5, T, phase=1.0)
    yield Chirp(1e-3, 0.99 * math.pi, T, duration)
    yield Chirp(0.99 * math.pi, 1e-3, T, duration)
    yield from (RandomSinusoids(T, seed=s, count=8, theta_max=0.999 * math.pi) for s in range(5))


def test_seed_design_without_delay_never_gives_energy_back():
    assert exact_verdict(SEED).passive
    for force in _inputs(SEED.T, N * SEED.T):
        record = simulate(SEED, force, N)
        bound = record.roundoff_bound()
        assert bound < 1e-11  # J; the energies are 1e-6 .. 1e-1 J
        assert np.min(record.energy) >= -bound, force


# --------------------------------------------------------------------------- active: E < 0


def test_one_sample_delay_at_the_critical_frequency_drives_energy_negative():
    verdict = exact_verdict(SEED_D1)
    assert not verdict.passive and verdict.stable
    assert verdict.critical_theta == pytest.approx(1.974, abs=1e-3)
    record = simulate(SEED_D1, Sinusoid(verdict.critical_theta, SEED_D1.T), N)
    assert record.energy[-1] < -5e-4  # J: about -4.39e-5 W for 20 s
    # steadily decreasing: E at the end of each of the last 200 input periods (636 samples)
    period = 2 * math.pi * SEED_D1.T / verdict.critical_theta
    ends = record.t[-1] - period * np.arange(200, -1, -1)
    e = record.energy_at(ends)
    assert np.all(np.diff(e) < 0)
    # the slope is the mean power, up to the aliases' beat, which whole input periods do not
    # cancel (the period is not a whole number of samples): O(1/periods)
    slope = (e[-1] - e[0]) / (ends[-1] - ends[0])
    predicted = 0.5 * t_fund(SEED_D1, verdict.critical_theta)[0].real
    assert slope == pytest.approx(predicted, rel=2e-3)


# --------------------------------------------------------------------------- mean power = |W|^2 Re T_fund / 2


@pytest.mark.parametrize("loop", [SEED, SEED_D1], ids=["d0", "d1"])
@pytest.mark.parametrize("theta", [0.3, 1.0, 2.0, 3.0])
def test_mean_power_matches_t_fund(loop, theta):
    result = mean_power(loop, theta, amplitude=2.0)
    assert abs(result.theta - theta) < 1e-5
    assert result.predicted == pytest.approx(2.0 * t_fund(loop, result.theta)[0].real, rel=1e-14)
    assert abs(result.relative_error) < 1e-3  # brief: 1 %; measured <= 6e-5 (S = 16 hold)


def test_mean_power_error_is_the_sub_step_hold_and_vanishes_as_s_squared():
    errors = [abs(mean_power(SEED, 3.14, substeps=s).relative_error) for s in (4, 16, 64)]
    assert errors[0] > errors[1] > errors[2]
    for coarse, fine in zip(errors, errors[1:]):
        assert 10.0 < coarse / fine < 20.0  # 16 = 4^2 for a second-order error
    assert errors[2] < 2e-4


def test_seed_t_zw_misses_the_mean_power_where_t_fund_does_not():
    """How far the seed's T_zw is from the measured power (DESIGN 3.2 quotes ~2 % / ~20 %).

    Measured: d = 0 it over-predicts by 0.75 % at theta 0.3, 8.8 % at 1, 41 % at 2, 124 % at 3
    (the 1.9 % of DESIGN holds at theta = pi only); d = 1 at the exact criterion's critical
    theta it predicts 40 % more negative power than the loop delivers (not 20 %).
    """
    expected_gaps = {0.3: 0.0075, 1.0: 0.0876, 2.0: 0.411, 3.0: 1.238}
    for theta, gap in expected_gaps.items():
        result = mean_power(SEED, theta)
        measured_gap = (result.seed - result.power) / abs(result.power)
        assert measured_gap == pytest.approx(gap, rel=0.01), theta
    critical = exact_verdict(SEED_D1).critical_theta
    result = mean_power(SEED_D1, critical)
    assert result.power < 0 and result.seed < 0
    assert (result.seed - result.power) / abs(result.power) == pytest.approx(-0.400, abs=0.005)


# --------------------------------------------------------------------------- eq. 23 beyond c ~ 3


def test_large_c_eq23_says_passive_energy_check_says_active():
    """bT/m = 89.9: eq. 23 and the seed's T_zw pass the wall; the loop takes energy out."""
    assert velocity_sampling_slack(BIG_C) > 0  # eq. 23: b = 512 >= KT/2 = 398
    assert seed_verdict(BIG_C).passive
    assert not exact_verdict(BIG_C).passive and exact_verdict(BIG_C).stable
    for theta in (0.01, 0.05, 1.0):
        # the plant settles within a sub-step, so the hold matters more: S = 128 (error ~ S^-2)
        result = mean_power(BIG_C, theta, substeps=128)
        assert result.power < 0 < result.seed
        assert abs(result.relative_error) < 3e-3
    # the number from the issue: -1.447e-7 W at theta = 0.05 with 1 N
    assert mean_power(BIG_C, 0.05, substeps=128).predicted == pytest.approx(-1.447e-7, rel=1e-3)
