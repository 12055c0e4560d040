"""Velocity models and real delays: the model type, the exact period map, T_fund against the
40-digit definition, and the frequency-domain mean power against the exact time-domain energy.

Tolerances:

* period map (closed forms) vs ``scipy.linalg.expm`` of the same continuous model: both are
  accurate to a few ulps of the entries' magnitudes (O(1) in scaled units); 1e-14 absolute.
* ``Re T_fund`` vs the 80-digit definition: the double evaluation is backward stable, so near a
  closed-loop pole at distance ``delta`` from ``z = e^{j theta}`` it moves by ``~ulps/delta``;
  ``1e-15 |T| + 64 eps/delta`` (measured <= 4e-16 |T| away from poles over 1e-6..pi).
* mean power: the two computations are exact by unrelated routes (``Re T_fund`` in closed form;
  the periodic steady state of the time-domain loop with the work integrated exactly); the brief
  asks for 1 %, measured <= 7e-12 relative; asserted 1 % (plus 1e-9 of the reactive power
  ``|T_fund|/2``, where ``Re T_fund`` itself crosses zero).
"""

from __future__ import annotations

import itertools
import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from haptic_bus.analysis.energy import Sinusoid, periodic_mean_power
from haptic_bus.analysis.frequency import t_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import closed_loop_poles, spectral_radius
from haptic_bus.analysis.sampled_loop import continuous_model, event_times, period_map, pulse_transfer
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.bench.mp_boundary import sampled_map
from haptic_bus.errors import ParameterError
from tests.mp_reference import t_fund_mp

MODELS = ("point", "average", "window:0.0004", "lowpass:0.0005")


# --------------------------------------------------------------------------- the model type


@pytest.mark.parametrize("text,kind,time", [
    ("point", "point", 0.0), ("average", "average", 0.0), ("window:0.0005", "window", 5e-4),
    ("lowpass:0.002", "lowpass", 2e-3), (" Lowpass : 1e-3 ", "lowpass", 1e-3),
])
def test_profile_strings_parse_and_format_back(text: str, kind: str, time: float) -> None:
    model = VelocityModel.parse(text)
    assert (model.kind, model.time) == (kind, time)
    assert VelocityModel.parse(str(model)) == model


@pytest.mark.parametrize("text", ["", "tach", "window", "window:", "window:-1", "window:0", "lowpass:nan",
                                  "lowpass:1e-20", "lowpass:1000", "average:0.001", "point:1", 3])
def test_bad_velocity_models_name_the_parameter_and_the_allowed_forms(text: object) -> None:
    with pytest.raises(ParameterError) as info:
        VelocityModel.parse(text)
    assert info.value.name == "velocity" and "allowed" in str(info.value) and "window:SECONDS" in str(info.value)


def test_a_window_longer_than_the_period_is_refused() -> None:
    WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 0, "window:0.001")  # TW = T is the average itself
    with pytest.raises(ParameterError) as info:
        WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 0, "window:0.0011")
    assert info.value.name == "velocity" and "(0, T]" in str(info.value)


def test_real_delays_and_the_model_travel_with_the_loop() -> None:
    loop = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 1.25, "lowpass:0.0005")
    assert (loop.whole_delay, loop.fractional_delay) == (1, 0.25)
    assert WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 1.0).delay == 1 and isinstance(WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 1.0).delay, int)
    other = loop.with_wall(10.0, 1.0)
    assert (other.delay, other.velocity, other.K, other.B) == (1.25, loop.velocity, 10.0, 1.0)
    assert WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 1000).whole_delay == 1000


# --------------------------------------------------------------------------- the period map


def _expm_period_map(loop: WallLoop) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Phi, gamma_now, gamma_before)`` composed from ``scipy.linalg.expm`` of the continuous model."""
    model = continuous_model(loop)
    n = model.c.size
    phi, now, before = np.eye(n), np.zeros(n), np.zeros(n)
    for a, b in itertools.pairwise(event_times(loop)):
        if model.reset is not None and a == model.reset[1]:
            keep = np.ones(n)
            keep[model.reset[0]] = 0.0
            phi, now, before = keep[:, None] * phi, keep * now, keep * before
        aug = np.zeros((n + 1, n + 1))
        aug[:n, :n], aug[:n, n] = model.A, model.b
        e = expm(aug * (b - a))
        phi, now, before = e[:n, :n] @ phi, e[:n, :n] @ now, e[:n, :n] @ before
        if b <= loop.fractional_delay:
            before = before + e[:n, n]
        else:
            now = now + e[:n, n]
    return phi, now, before


@pytest.mark.parametrize("model", [*MODELS, "lowpass:5", "window:1e-7"])
@pytest.mark.parametrize("c_value", [1e-12, 0.2, 5.0, 90.0])
@pytest.mark.parametrize("delay", [0, 0.3, 1.99])
def test_closed_form_period_map_equals_the_matrix_exponential(model: str, c_value: float, delay: float) -> None:
    loop = WallLoop(0.5, c_value * 0.5 / 1e-3, 1e-3, 0.0, 0.0, delay, model)
    pmap = period_map(loop)
    phi, now, before = _expm_period_map(loop)
    n = pmap.c.size
    np.testing.assert_allclose(pmap.phi_minus_identity + np.eye(n), phi, rtol=0, atol=1e-14)
    np.testing.assert_allclose(pmap.gamma_now, now, rtol=0, atol=1e-14)
    np.testing.assert_allclose(pmap.gamma_before, before, rtol=0, atol=1e-14)


@pytest.mark.parametrize("model", ["lowpass:1e-7", "lowpass:1e-12", "lowpass:100", "window:1e-9"])
@pytest.mark.parametrize("delay", [0, 0.5])
def test_stiff_and_slow_measurements_match_the_40_digit_sampled_map(model: str, delay: float) -> None:
    """Where ``expm`` itself loses digits (``T/TAU = 1e4``: scaling and squaring), the 40-digit
    ``mp.expm`` map decides: the pulse transfer function ``G(z)`` (coordinate-free) to 1e-14."""
    loop = WallLoop(0.5, 100.0, 1e-3, 0.0, 0.0, delay, model)
    pmap = period_map(loop)
    z = np.exp(1j * np.array([1e-3, 0.5, 2.0, 3.0]))
    ours = pulse_transfer(pmap, z, z - 1.0)
    with mp.workdps(40):
        phi, now, before, C = sampled_map(loop)
        n = phi.rows
        for zi, value in zip(z, ours):
            zz = mp.mpc(zi)
            ref = complex((C * mp.inverse(zz * mp.eye(n) - phi) * (now + before / zz))[0] * loop.m / loop.T)
            assert abs(value - ref) <= 1e-14 * abs(ref)


def test_phi_minus_identity_keeps_its_digits_for_a_plant_that_barely_moves() -> None:
    loop = WallLoop(1e3, 1e-9, 1e-6, 0.0, 0.0, 0, "lowpass:10")
    shifted = period_map(loop).phi_minus_identity
    assert shifted[0, 0] == pytest.approx(-loop.c, rel=1e-15)  # -1e-18: 1 - e^{-c} in full
    assert shifted[1, 1] == pytest.approx(math.expm1(-1e-7), rel=1e-15)


# --------------------------------------------------------------------------- T_fund against the definition

LOOPS = [
    WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 0.3, "average"),
    WallLoop(0.5, 0.1, 1e-3, 50.0, 0.02, 0.75, "point"),
    WallLoop(0.032, 3.62, 1e-3, 700.0, 2.0, 1.5, "lowpass:0.0005"),
    WallLoop(1.0, 20.0, 1e-3, 5e3, 5.0, 1.25, "window:0.0003"),
    WallLoop(0.0244, 512.0, 4.28e-3, 1.86e5, 0.0, 0.5, "lowpass:0.01"),
    WallLoop(1e3, 1e-9, 1e-3, 1.0, 1.0, 2.9, "average"),
]
THETAS = [1e-6, 1e-4, 1e-2, 0.3, 0.49, 0.51, 1.0, 2.0, 3.0, math.pi]


@pytest.mark.parametrize("loop", LOOPS, ids=lambda loop: f"{loop.velocity}-D{loop.delay}")
def test_t_fund_matches_the_40_digit_definition(loop: WallLoop) -> None:
    ours = t_fund(loop, np.array(THETAS))
    poles = closed_loop_poles(loop)
    for theta, value in zip(THETAS, ours):
        ref = complex(t_fund_mp(loop, mp.pi if theta == math.pi else theta))
        delta = float(np.min(np.abs(np.exp(1j * theta) - poles)))
        tolerance = 1e-15 + 64 * np.finfo(float).eps / max(delta, 1e-300)
        assert abs(value.real - ref.real) <= tolerance * abs(ref), theta
        assert abs(value.imag - ref.imag) <= tolerance * abs(ref), theta


# --------------------------------------------------------------------------- frequency domain = time domain


def _loops(model: str) -> st.SearchStrategy[WallLoop]:
    """Realistic loops, T = 1 ms: m 0.01..10 kg, c = bT/m 1e-5..10, kappa = KT^2/m and q = BT/m up to 1, D 0..3."""

    def build(m: float, c: float, kappa: float, q: float, delay: float) -> WallLoop:
        kind, _, fraction = model.partition(":")
        velocity = model if not fraction else f"{kind}:{float(fraction) * 1e-3!r}"
        return WallLoop(m, c * m / 1e-3, 1e-3, kappa * m / 1e-6, q * m / 1e-3, delay, velocity)

    exponent = lambda lo, hi: st.floats(lo, hi).map(lambda e: 10.0**e)
    return st.builds(build, exponent(-2, 1), exponent(-5, 1), exponent(-6, 0),
                     st.one_of(st.just(0.0), exponent(-6, 0)), st.one_of(st.just(0.0), st.floats(0.0, 3.0)))


def _agree(loop: WallLoop, p: int, q: int) -> None:
    assume(spectral_radius(loop) < 0.99999)
    theta = 2 * math.pi * p / q
    simulated = periodic_mean_power(loop, Sinusoid(theta, loop.T), q)
    response = t_fund(loop, theta)[0]
    predicted = 0.5 * response.real
    assert abs(simulated - predicted) <= 0.01 * abs(predicted) + 1e-9 * 0.5 * abs(response)


# 25 fixed examples per model (hypothesis' default is 100: 6 s of CPU more): the two routes agree to 7e-12 where 1 %
# is asserted, so an error in either route shows at many loops, not at a few: predicting with the delay 0.05 samples
# off, or B 5 % off, misses the 1 % at 9 to 19 of these 25 loops per model (measured), a wrong term more.
_PROPERTY = settings(max_examples=25, deadline=None, derandomize=True, database=None,
                     suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow])
_FREQUENCY = st.integers(3, 256).flatmap(lambda q: st.tuples(st.integers(1, (q - 1) // 2), st.just(q)))


@pytest.mark.parametrize("model", ["point", "average", "window:0.4", "lowpass:0.7"])
@_PROPERTY
@given(data=st.data(), pq=_FREQUENCY)
def test_mean_power_matches_the_frequency_response(model: str, data: st.DataObject, pq: tuple[int, int]) -> None:
    _agree(data.draw(_loops(model), label="loop"), *pq)
