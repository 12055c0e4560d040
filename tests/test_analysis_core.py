"""The passivity analysis core: the seed's numbers, the exact criterion, limits, numerics, input checks."""

from __future__ import annotations

import json
import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from haptic_bus.analysis.closed_form import velocity_sampling_slack
from haptic_bus.analysis.criterion import exact_verdict, seed_verdict
from haptic_bus.analysis.frequency import seed_t_zw, seed_z_zw, t_fund, z_fund
from haptic_bus.analysis.limits import RELATIVE_TOLERANCE, max_damping, max_stiffness
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import ExactPlant, phi1, phi2, zoh_coefficients
from haptic_bus.analysis.poles import closed_loop_poles, is_stable
from haptic_bus.app.cli import main
from haptic_bus.errors import ParameterError
from tests.mp_reference import t_fund_mp, t_zw_mp

SEED = WallLoop(m=0.5, b=0.1, T=1e-3, K=200.0, B=100.0)


def log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(math.log10(low), math.log10(high)).map(lambda e: 10.0**e)


def wall_values() -> st.SearchStrategy[float]:
    return st.one_of(st.just(0.0), log_uniform(1e-6, 1e9))


loops = st.builds(
    WallLoop,
    m=log_uniform(1e-3, 1e3),
    b=log_uniform(1e-9, 1e4),
    T=log_uniform(1e-6, 0.1),
    K=wall_values(),
    B=wall_values(),
    delay=st.integers(0, 2),
)


# --- the seed's numbers ---------------------------------------------------------------------


def test_seed_closed_loop_poles_to_the_printed_digits() -> None:
    poles = np.sort(closed_loop_poles(SEED).real)[::-1]
    assert np.all(closed_loop_poles(SEED).imag == 0)
    assert round(poles[0], 3) == 0.998
    assert round(poles[1], 4) == 0.8014


def test_seed_design_is_passive_by_every_zero_delay_criterion() -> None:
    assert velocity_sampling_slack(SEED) > 0
    assert SEED.alpha == pytest.approx(500.0) and SEED.alpha > 6
    exact, seed = exact_verdict(SEED), seed_verdict(SEED)
    assert exact.passive and exact.stable and seed.passive
    # the seed's T_zw margin at theta = pi is exactly eq. 23's slack (b - tanh(c/2)(KT/2 + B))
    assert seed.critical_theta == pytest.approx(math.pi)
    assert seed.margin == pytest.approx(velocity_sampling_slack(SEED), rel=1e-9)


def test_one_sample_of_delay_makes_the_seed_design_active() -> None:
    delayed = exact_verdict(WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, delay=1))
    assert delayed.stable and not delayed.passive
    assert delayed.margin < -50.0  # -84.09 N s/m at theta = 1.974
    assert 1.9 < delayed.critical_theta < 2.05


# --- the plant -------------------------------------------------------------------------------


@pytest.mark.parametrize("c", [0.0, 1e-300, 1e-12, 0.0999999, 0.1, 0.1000001, 1.0, 50.0, 1e6])
def test_phi_functions_match_mpmath(c: float) -> None:
    mc = mp.mpf(c)
    ref1 = 1 if c == 0 else -mp.expm1(-mc) / mc
    with mp.workdps(700):  # (c - 1 + e^-c) cancels about -2 log10(c) digits
        ref2 = mp.mpf(1) / 2 if c == 0 else (mc - 1 + mp.exp(-mc)) / mc**2
    assert phi1(c) == pytest.approx(float(ref1), rel=4e-16)
    assert phi2(c) == pytest.approx(float(ref2), rel=4e-15)


def test_exact_plant_matches_the_first_order_response() -> None:
    m, b, T, force = 0.5, 0.1, 1e-3, 2.0
    plant = ExactPlant(m, b, T)
    for _ in range(1000):
        plant.advance(force)
    t = 1.0
    assert plant.velocity == pytest.approx(force / b * -math.expm1(-b * t / m), rel=1e-12)
    expected_x = force / b * (t - m / b * -math.expm1(-b * t / m))
    assert plant.position == pytest.approx(expected_x, rel=1e-11)


def test_zoh_limit_without_friction_is_the_pure_mass() -> None:
    co = zoh_coefficients(2.0, 0.0, 1e-3)
    assert (co.a, co.k1, co.p_v, co.p_f) == (1.0, 5e-4, 1e-3, pytest.approx(0.25e-6, rel=1e-15))


# --- frequency responses against mpmath --------------------------------------------------------


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(loop=loops, theta=st.sampled_from([1e-12, 1e-7, 1e-3, 0.7, 2.0, math.pi - 1e-12, math.pi]))
def test_responses_match_mpmath_and_never_flip_sign(loop: WallLoop, theta: float) -> None:
    # A backward-stable evaluation is exact for parameters a few ulps away; near a closed-loop
    # pole p at distance delta from z = e^{j theta} that moves T by about ulps / delta.
    delta = float(np.min(np.abs(np.exp(1j * theta) - closed_loop_poles(loop))))
    tolerance = 1e-13 + 64 * np.finfo(float).eps / max(delta, 1e-300)
    for ours, reference in ((t_fund(loop, theta)[0], t_fund_mp(loop, theta)), (seed_t_zw(loop, theta)[0], t_zw_mp(loop, theta))):
        ref = complex(reference)
        assert np.isfinite(ours)
        # Re is accurate to the tolerance times |T|; below that the sign is not a property of the loop
        assert abs(ours.real - ref.real) <= tolerance * abs(ref)
        if abs(ref.real) > tolerance * abs(ref):
            assert math.copysign(1, ours.real) == math.copysign(1, ref.real)


@settings(deadline=None)
@given(loop=loops)
@example(loop=WallLoop(0.001, 1.0, 0.1, 0.0, 1.0, 0))  # a pole on the unit circle to double precision
def test_everything_is_finite_over_the_whole_range(loop: WallLoop) -> None:
    theta = np.array([1e-12, 1e-6, 0.5, 3.0, math.pi - 1e-12, math.pi])
    assert np.all(np.isfinite(t_fund(loop, theta)))
    impedance = seed_z_zw(loop, theta)
    assert np.all(np.isfinite(impedance))
    # T_zw is finite except where its impedance is exactly zero: a closed-loop pole on the unit
    # circle to double precision (e.g. m 1e-3, b 1, T 0.1, B 1: the pole -1 + 4e-44 at theta = pi)
    assert np.all(np.isfinite(seed_t_zw(loop, theta)) | (impedance == 0))
    verdict = exact_verdict(loop)
    assert math.isfinite(verdict.margin) and 0 < verdict.critical_theta <= math.pi
    assert (verdict.margin >= 0) == verdict.passive


# --- the exact criterion against eq. 23 -------------------------------------------------------

# Distance from the boundary below which the two verdicts may differ by round-off: eq. 23's
# slack and the Jury/impedance forms are evaluated differently, each to ~1e-15 relative.
BOUNDARY_BAND = 1e-9


@settings(deadline=None)
@given(loop=loops.map(lambda loop: WallLoop(loop.m, loop.b, loop.T, loop.K, loop.B, 0)))
def test_exact_criterion_agrees_with_eq23_without_delay(loop: WallLoop) -> None:
    slack = velocity_sampling_slack(loop)
    scale = loop.b + 0.5 * loop.K * loop.T + loop.B
    assume(abs(slack) > BOUNDARY_BAND * scale)
    verdict = exact_verdict(loop)
    if loop.c <= 3.0:
        assert verdict.passive == (slack >= 0)
    else:  # a plant that settles within a sample: eq. 23 is necessary (flip), not sufficient
        assert not verdict.passive or slack >= 0
    assert is_stable(loop) == (slack > 0)  # eq. 23 is the flip boundary, K = 0 included


def test_eq23_misses_low_frequency_activity_when_the_plant_settles_within_a_sample() -> None:
    loop = WallLoop(m=0.024419910768078666, b=512.2589430129525, T=0.00428364115454665, K=185830.03326090527, B=0.0)
    assert loop.c > 80 and velocity_sampling_slack(loop) > 0
    verdict = exact_verdict(loop)
    assert verdict.stable and not verdict.passive
    assert float(mp.re(1 / t_fund_mp(loop, 0.05))) < -1000  # N s/m, from the definition itself


@settings(deadline=None)
@given(loop=loops)
def test_more_physical_damping_never_makes_a_passive_loop_active(loop: WallLoop) -> None:
    assume(exact_verdict(loop).passive and loop.c <= 3.0)
    damper = WallLoop(loop.m, loop.b * 2.0, loop.T, loop.K, loop.B, loop.delay)
    assume(damper.c <= 3.0)
    assert exact_verdict(damper).passive


def test_delay_verdict_matches_a_brute_force_minimum() -> None:
    loop = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, delay=1)
    theta = np.linspace(1e-6, math.pi, 400_001)
    brute = z_fund(loop, theta).real.min()
    assert exact_verdict(loop).margin == pytest.approx(brute, rel=1e-9)


# --- limits against mpmath ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "loop",
    [SEED, WallLoop(0.032, 3.62, 1e-3, 400.0, 1.0), WallLoop(1e3, 1e-9, 1e-3, 1.0, 1.0), WallLoop(1e-3, 1.0, 1e-3, 10.0, 0.5)],
    ids=["seed", "desktop", "heavy-frictionless", "light"],
)
def test_zero_delay_limits_match_mpmath(loop: WallLoop) -> None:
    m, b, T = (mp.mpf(x) for x in (loop.m, loop.b, loop.T))
    budget = b / mp.tanh(b * T / (2 * m))
    assert max_stiffness(loop) == pytest.approx(float(2 * (budget - loop.B) / T), rel=1e-12)
    assert max_damping(loop) == pytest.approx(float(budget - loop.K * T / 2), rel=1e-12)


def _mp_boundary(loop: WallLoop, stiffness: float, theta: float) -> float:
    """The K where min_theta Re(1/T_fund) touches 0 (tangency), solved in 60 digits."""

    def equations(k, th):  # Re Z = 0 and d/dtheta Re Z = 0 together: the tangency
        f = lambda t: mp.re(1 / _t_fund_any_k(loop, k, t))
        return [f(th), mp.diff(f, th)]

    k, _ = mp.findroot(equations, (mp.mpf(stiffness), mp.mpf(theta)))
    return float(k)


def _t_fund_any_k(loop: WallLoop, k, theta):
    m, b, T, B = (mp.mpf(x) for x in (loop.m, loop.b, loop.T, loop.B))
    omega = theta / T
    z = mp.exp(1j * theta)
    g11 = 1 / (m * 1j * omega + b)
    a = mp.exp(-b * T / m)
    g11d = (1 - a) / b / (z - a)
    wall = (k * T * z / (z - 1) + B) * z ** (-loop.delay)
    hold = (1 - mp.exp(-1j * theta)) / (1j * omega) / T
    return g11 * (1 - hold * wall * g11 / (1 + g11d * wall))


def test_delayed_stiffness_limit_matches_mpmath() -> None:
    loop = WallLoop(0.032, 3.62, 1e-3, 400.0, 1.0, delay=1)
    ours = max_stiffness(loop)
    theta = exact_verdict(loop.with_wall(ours, loop.B)).critical_theta
    assert 0.01 < theta < math.pi  # an interior tangency, so the 2x2 system applies
    assert ours == pytest.approx(_mp_boundary(loop, ours, theta), rel=10 * RELATIVE_TOLERANCE)


def test_delayed_limits_bracket_the_verdict() -> None:
    loop = WallLoop(0.032, 3.62, 1e-3, 400.0, 1.0, delay=1)
    k, b = max_stiffness(loop), max_damping(loop)
    assert exact_verdict(loop.with_wall(k * (1 - 1e-8), loop.B)).passive
    assert not exact_verdict(loop.with_wall(k * (1 + 1e-8), loop.B)).passive
    assert exact_verdict(loop.with_wall(loop.K, b * (1 - 1e-8))).passive
    assert not exact_verdict(loop.with_wall(loop.K, b * (1 + 1e-8))).passive


def test_no_passive_stiffness_reports_none() -> None:
    assert max_stiffness(WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, delay=1)) is None


# --- input checks --------------------------------------------------------------------------------

BAD_INPUTS = [
    ("m", float("nan")), ("m", 0.0), ("m", -1.0), ("m", float("inf")),
    ("T", 0.0), ("T", -1e-3), ("T", float("nan")),
    ("b", -0.1), ("K", -1.0), ("B", -5.0), ("K", float("inf")),
    ("delay", -1), ("delay", 1000.5), ("delay", float("inf")), ("delay", float("nan")), ("m", "heavy"), ("B", True),
]


@pytest.mark.parametrize("name,value", BAD_INPUTS)
def test_bad_input_is_a_typed_error_naming_parameter_value_and_range(name: str, value: object) -> None:
    params = {"m": 0.5, "b": 0.1, "T": 1e-3, "K": 200.0, "B": 100.0, "delay": 0}
    params[name] = value
    with pytest.raises(ParameterError) as info:
        WallLoop(**params)
    assert info.value.name == name
    message = str(info.value)
    assert message.startswith(f"{name} = ") and repr(value) in message and "allowed:" in message


def test_float32_and_numpy_inputs_are_accepted() -> None:
    loop = WallLoop(np.float32(0.5), np.float64(0.1), np.float32(1e-3), np.int64(200), 100, np.int32(1))
    assert isinstance(loop.m, float) and loop.delay == 1


def test_check_cli_json_fields_and_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    seed_args = ["check", "--mass", "0.5", "--friction", "0.1", "--period", "0.001", "--stiffness", "200", "--damping", "100"]
    assert main([*seed_args, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["passive"] is True and report["margin"] >= 0
    assert report["max_stiffness"] == pytest.approx(1.8e6, rel=1e-6)
    assert report["max_damping"] == pytest.approx(999.9, rel=1e-6)
    assert report["critical_theta"] == pytest.approx(math.pi)
    assert main([*seed_args, "--delay", "1", "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["passive"] is False and report["margin"] < 0 and report["max_stiffness"] is None


@pytest.mark.parametrize("flag,value", [("--mass", "nan"), ("--period", "0"), ("--friction", "-1"), ("--delay", "2000")])
def test_check_cli_bad_input_exits_2_with_one_line(flag: str, value: str, capsys: pytest.CaptureFixture[str]) -> None:
    args = {"--mass": "0.5", "--friction": "0.1", "--period": "0.001", "--delay": "0"}
    args[flag] = value
    argv = ["check", "--stiffness", "200", "--damping", "100"] + [x for kv in args.items() for x in kv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "allowed" in err
