"""Numerical stress: any float in, a typed error or a finite answer out; long-run sums."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.frequency import t_fund, z_fund
from haptic_bus.analysis.limits import max_damping, max_stiffness
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.control.port_energy import PortObserver
from haptic_bus.errors import ParameterError

any_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True),
    st.floats(width=32, allow_nan=True, allow_infinity=True).map(np.float32),
    st.sampled_from([5e-324, 1e-310, -0.0, 1e308, 3.4e38, 1e-45]),
)


@settings(deadline=None)
@given(m=any_float, b=any_float, T=any_float, K=any_float, B=any_float)
@example(m=1.0, b=0.0, T=0.5, K=5e-324, B=0.0)  # no friction, the wall below the smallest normal double: w = 0 a double
# zero whose terms are all 0 (0/0 in the pole search's residual and error bound), found by Hypothesis in a run of the suite
def test_any_float_gives_a_typed_error_or_a_finite_verdict(m, b, T, K, B) -> None:
    try:
        loop = WallLoop(m, b, T, K, B)
    except ParameterError as error:
        assert error.name in {"m", "b", "T", "K", "B"} and "allowed" in str(error)
        return
    verdict = exact_verdict(loop)
    assert math.isfinite(verdict.margin) and (verdict.margin >= 0) == verdict.passive
    for limit in (max_stiffness(loop), max_damping(loop)):
        assert limit is None or (math.isfinite(limit) and limit >= 0)


def test_float32_theta_and_parameters_give_the_double_answer() -> None:
    loop32 = WallLoop(np.float32(0.5), np.float32(0.1), np.float32(1e-3), np.float32(200), np.float32(100))
    theta32 = np.linspace(1e-3, np.pi, 50, dtype=np.float32)
    values = t_fund(loop32, theta32)
    assert values.dtype == np.complex128 and np.all(np.isfinite(values))
    assert exact_verdict(loop32).passive


def test_extreme_but_valid_corners_stay_finite() -> None:
    corners = [WallLoop(1e-9, 0.0, 1e-9, 0.0, 0.0), WallLoop(1e9, 1e12, 10.0, 1e15, 1e15),
               WallLoop(1e-9, 1e12, 10.0, 1e15, 0.0), WallLoop(1e9, 0.0, 1e-9, 1e15, 1e15, delay=3)]
    theta = np.array([1e-12, 1e-6, 1.0, np.pi - 1e-12, np.pi])
    for loop in corners:
        assert np.all(np.isfinite(t_fund(loop, theta))) and np.all(np.isfinite(z_fund(loop, theta[1:])))
        assert math.isfinite(exact_verdict(loop).margin)


def test_port_observer_sum_over_a_million_cycles_stays_within_its_rounding_bound() -> None:
    """The port observer adds one term a cycle; after N cycles plain summation is within
    N eps sum|terms| of the exact sum (here far inside it).  Reference: math.fsum of the same
    terms (``b dx^2 / T - F dx``), correctly rounded."""
    n = 1_000_000
    k = np.arange(n + 1)
    position = 1e-3 * np.sin(2 * np.pi * k / 997.0)
    force = 3.0 + 2.0 * np.cos(2 * np.pi * k / 997.0 + 0.3)
    T, b = 1e-3, 20.0
    observer = PortObserver(b, 0.0)
    apply, sample = observer.apply, observer.sample
    sample(float(position[0]))
    for x, f in zip(position[1:].tolist(), force[:-1].tolist()):
        apply(f, T)
        sample(x)
    dx = np.diff(position)
    terms = b * dx * dx / T - force[:-1] * dx
    exact = math.fsum(terms.tolist())
    bound = n * np.finfo(float).eps * float(np.sum(np.abs(terms)))
    assert abs(observer.energy - exact) <= bound
    assert abs(observer.energy - exact) <= 1e-9 * float(np.sum(np.abs(terms)))  # what it really is
