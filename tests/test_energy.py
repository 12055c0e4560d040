"""The time-domain energy check (DESIGN 3.4) and its agreement with the frequency criteria.

Tolerances:

* round-off: :meth:`EnergyRecord.roundoff_bound`, ``(n + 64/(1 - rho)) 2^-53 sum|work|`` (recursive
  summation of n terms errs by at most ``(n - 1) u sum|x_i|``; the state recursion amplifies
  its own round-off by at most ``1/(1 - rho)``).
* the operator's work is integrated exactly over every piece (Van Loan's exponential, no held
  force), so the exact steady-state mean power and ``|W|^2 Re T_fund / 2`` are two exact
  computations of one number by unrelated routes: they agree to round-off, measured <= 5e-12
  relative (both have ~1e-13 of their own); 1e-9 leaves the margin of the cancellation in a
  mean that is 1e-3 of the reactive power.
* the independent ODE reference (``scipy.integrate.solve_ivp``, DOP853, rtol 1e-12) errs by
  ~1e-11 relative per piece; 1e-8 of the run's total ``|work|`` bounds it.
"""

from __future__ import annotations

import itertools
import math

import mpmath
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from haptic_bus.analysis.closed_form import velocity_sampling_slack
from haptic_bus.analysis.criterion import exact_verdict, seed_verdict
from haptic_bus.analysis.energy import (
    Constant,
    RandomSinusoids,
    Sinusoid,
    Tones,
    commensurate_theta,
    mean_power,
    periodic_mean_power,
    simulate,
)
from haptic_bus.analysis.frequency import t_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.errors import ParameterError

SEED = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 0)
SEED_D1 = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 1)
BIG_C = WallLoop(0.02442, 512.26, 0.0042836, 185830.0, 0.0, 0)  # bT/m = 89.9: settles within a sample
README_C90 = WallLoop(0.0244, 512.0, 4.28e-3, 1.86e5, 0.0, 0)  # the README's low-frequency example
N = 20_000


# --------------------------------------------------------------------------- an independent reference


def _ode_reference(loop: WallLoop, tones: Tones, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """(E at the sample instants in J, u_{k-d} in N) from ``solve_ivp`` on the physical ODE.

    States ``[v, x, nu, E]``: ``m v' = w - f - b v``, ``x' = v``, ``TAU nu' = v - nu``,
    ``E' = w v``; the controller runs at the samples, the velocity read as the model says
    (``x(kT) - x(kT - TW)`` from the position stored at the window's start).
    """
    m, b, T = loop.m, loop.b, loop.T
    kind = loop.velocity.kind
    tau = loop.velocity.time if kind == "lowpass" else 1.0
    window = loop.velocity.window(T)
    d, delta = loop.whole_delay, loop.fractional_delay

    def rhs(t: float, s: np.ndarray, f: float) -> list[float]:
        w = float(tones(t))
        v = s[0]
        return [(w - f - b * v) / m, v, (v - s[2]) / tau, w * v]

    state = np.zeros(4)
    x_at_window_start = 0.0
    integ, forces, energy, applied = 0.0, [], [0.0], []
    for k in range(n_samples):
        t0 = k * T
        if kind == "point":
            y = state[0]
        elif kind == "lowpass":
            y = state[2]
        else:
            y = (state[1] - x_at_window_start) / window if k else 0.0
        integ += T * y
        forces.append(loop.K * integ + loop.B * y)
        now = forces[k - d] if k >= d else 0.0
        before = forces[k - d - 1] if k >= d + 1 else 0.0
        applied.append(now)
        events = sorted({0.0, delta, 1.0} | ({1.0 - window / T} if window else set()))
        for a, c in itertools.pairwise(events):
            if window and a == 1.0 - window / T:
                x_at_window_start = state[1]
            f = before if c <= delta else now
            sol = solve_ivp(rhs, (t0 + a * T, t0 + c * T), state, args=(f,), method="DOP853", rtol=1e-12, atol=1e-20)
            state = sol.y[:, -1]
        energy.append(state[3])
    return np.array(energy), np.array(applied)


@pytest.mark.parametrize(
    "loop",
    [SEED, SEED_D1, SEED.with_wall(0.0, 100.0), WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 2.3, "average"),
     WallLoop(0.04, 0.0, 1e-3, 1000.0, 2.0, 0.6, "lowpass:0.0007"), WallLoop(0.5, 3.0, 1e-3, 400.0, 1.0, 1.25, "window:0.0004")],
    ids=["seed", "seed-d1", "damper-only", "average-d2.3", "b=0-lowpass-d0.6", "window-d1.25"],
)
def test_exact_simulation_equals_an_ode_solver(loop: WallLoop) -> None:
    force = Tones((700.0, 2600.0, 9000.0), (0.6, 0.3, 0.1), (0.2, 1.0, 2.0))  # 9 kHz: above Nyquist too
    # 60 samples (60 ms; the ODE reference costs about 8 ms of CPU a sample): every tone turns 42 times
    # or more, the whole delays (up to 2) and the window start are passed within 3 samples, and the
    # seed's fast pole 0.8014 is down to 2e-6 of its start, so the loop's own motion is compared too
    record = simulate(loop, force, 60, 1)
    energy, applied = _ode_reference(loop, force, 60)
    np.testing.assert_allclose(record.energy, energy, rtol=0, atol=1e-8 * record.work_scale)
    np.testing.assert_allclose(record.wall_force, applied, rtol=0, atol=1e-8 * max(np.max(np.abs(applied)), 1e-300))


def _bare_position(force: float, t: np.ndarray, m: float = 0.5, b: float = 0.1) -> np.ndarray:
    """``x(t) = (W/b)(t - (m/b)(1 - e^{-bt/m}))`` at 40 digits (the float formula cancels)."""
    mpmath.mp.dps = 40
    f, m_, b_ = mpmath.mpf(force), mpmath.mpf(m), mpmath.mpf(b)
    return np.array([float(f / b_ * (mpmath.mpf(s) - m_ / b_ * (1 - mpmath.exp(-b_ * mpmath.mpf(s) / m_)))) for s in t])


def test_energy_is_exact_for_a_constant_push_on_the_bare_handle() -> None:
    """No wall: E(t) = W x(t); 8000 pieces summed, each exact to ~1e-16: 1e-12 relative."""
    loop = WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0)
    record = simulate(loop, Constant(2.0), 500, 16)
    np.testing.assert_allclose(record.energy, 2.0 * _bare_position(2.0, record.t), rtol=1e-12, atol=1e-300)


def test_energy_at_arbitrary_times_is_exact_between_sub_steps() -> None:
    record = simulate(SEED, Sinusoid(1.0, SEED.T), 200, 4)
    np.testing.assert_allclose(record.energy_at(record.t[:-1]), record.energy[:-1], rtol=0, atol=1e-18)
    bare = simulate(WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0), Constant(1.0), 2, 1)
    when = np.array([0.25e-3, 0.5e-3, 1.5e-3])
    np.testing.assert_allclose(bare.energy_at(when), _bare_position(1.0, when), rtol=1e-12)


def test_inputs_refuse_frequencies_at_or_above_nyquist() -> None:
    for bad in (0.0, math.pi, 4.0, -1.0, float("nan")):
        with pytest.raises(ParameterError):
            Sinusoid(bad, 1e-3)
    with pytest.raises(ParameterError):
        RandomSinusoids(1e-3, seed=0, theta_max=3.2)
    with pytest.raises(ParameterError):
        Tones((-1.0,), (1.0,), (0.0,))
    assert np.max(RandomSinusoids(1e-3, seed=4, theta_max=3.0).thetas) < 3.0


def test_commensurate_theta() -> None:
    p, q = commensurate_theta(1.0)
    assert q <= 4096 and abs(2 * math.pi * p / q - 1.0) < 1e-6


# --------------------------------------------------------------------------- passive: E >= 0


def _inputs(T: float):
    yield from (Sinusoid(theta, T) for theta in (0.01, 0.3, 1.0, 2.0, 3.0, 3.1, math.pi - 1e-3))
    yield Sinusoid(2.5, T, phase=1.0)
    yield Constant(1.0)
    yield from (RandomSinusoids(T, seed=s, count=8, theta_max=0.999 * math.pi) for s in range(5))


def test_seed_design_without_delay_never_gives_energy_back() -> None:
    assert exact_verdict(SEED).passive
    for force in _inputs(SEED.T):
        record = simulate(SEED, force, N)
        bound = record.roundoff_bound()
        assert bound < 1e-11  # J; the energies are 1e-6 .. 1e-1 J
        assert np.min(record.energy) >= -bound, force


# --------------------------------------------------------------------------- active: E < 0


def test_one_sample_delay_at_the_critical_frequency_drives_energy_negative() -> None:
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
def test_mean_power_matches_t_fund(loop: WallLoop, theta: float) -> None:
    result = mean_power(loop, theta, amplitude=2.0)
    assert abs(result.theta - theta) < 1e-5
    assert result.predicted == pytest.approx(2.0 * t_fund(loop, result.theta)[0].real, rel=1e-14)
    assert abs(result.relative_error) < 1e-9  # exact both ways; measured <= 5e-12


def test_the_readme_low_frequency_example_is_exact() -> None:
    """The README's c = 90 example: -1.450e-7 W for 1 N at theta = 0.05, simulated and predicted.

    (A force held on 16 sub-steps per period made it 5.6 % low; the exact intersample
    integral has no such error.)
    """
    result = mean_power(README_C90, 0.05)
    assert README_C90.c > 89
    assert result.power == pytest.approx(-1.4504e-7, rel=1e-4)
    assert abs(result.relative_error) < 1e-9


def test_periodic_mean_power_needs_whole_turns_and_a_stable_loop() -> None:
    with pytest.raises(ParameterError):
        periodic_mean_power(SEED, Sinusoid(1.0, SEED.T), 100)  # 1 rad per sample: never repeats
    with pytest.raises(ParameterError):
        periodic_mean_power(SEED.with_wall(1e7, 0.0), Sinusoid(2 * math.pi / 8, SEED.T), 8)


def test_seed_t_zw_misses_the_mean_power_where_t_fund_does_not() -> None:
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


def test_large_c_eq23_says_passive_energy_check_says_active() -> None:
    """bT/m = 89.9: eq. 23 and the seed's T_zw pass the wall; the loop takes energy out."""
    assert velocity_sampling_slack(BIG_C) > 0  # eq. 23: b = 512 >= KT/2 = 398
    assert seed_verdict(BIG_C).passive
    assert not exact_verdict(BIG_C).passive and exact_verdict(BIG_C).stable
    for theta in (0.01, 0.05, 1.0):
        result = mean_power(BIG_C, theta)
        assert result.power < 0 < result.seed
        assert abs(result.relative_error) < 1e-9
    # the number from the issue: -1.447e-7 W at theta = 0.05 with 1 N
    assert mean_power(BIG_C, 0.05).predicted == pytest.approx(-1.447e-7, rel=1e-3)
