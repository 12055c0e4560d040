"""Passive intervals of K and B (per-theta quadratic), against the 40-digit reference and the verdict.

Tolerance against :func:`haptic_bus.bench.mp_boundary.reference_boundary` (40 digits): the brief
asks 1e-9; asserted 1e-12 relative (``RELATIVE_TOLERANCE``; measured: upper ends <= 7.4e-16,
lower ends <= 2.4e-13), plus ``1e-15`` of the parameter's natural scale (``b`` for ``B``,
``b/T`` for ``K``) for a lower end near 0: a lower end is where the wall's negative damping
``~K tau`` just balances ``b``, so its value is a small difference of larger terms, which the
quadratic's coefficients resolve to a few ulps of those terms (measured 8e-18 of ``b``).

The references are the stored table of :mod:`tests.mp_boundaries` (constants of the loops below,
12 s of CPU to compute); one entry of each kind is recomputed here.
"""

from __future__ import annotations

import pytest

from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.limits import RELATIVE_TOLERANCE, max_damping, max_stiffness, passive_limits, passive_set
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.bench.mp_boundary import reference_boundary
from tests.mp_boundaries import D1, D2, REFERENCED, Boundary, read_table, stored

TABLE = read_table()


def _check_against_reference(loop: WallLoop, which: str, value: float, lower: bool, interval: int = 0) -> None:
    ref = stored(TABLE, loop, which, interval, lower)
    natural = loop.b if which == "B" else loop.b / loop.T
    assert abs(value - ref.value) <= RELATIVE_TOLERANCE * abs(ref.value) + 1e-15 * natural, (which, lower, value, ref)


def _one_of_each_kind() -> list[Boundary]:
    first: dict[str, Boundary] = {}
    for boundary in TABLE.values():
        first.setdefault(boundary.kind, boundary)
    return list(first.values())


@pytest.mark.parametrize("boundary", _one_of_each_kind(), ids=lambda boundary: boundary.kind.split()[0])
def test_the_stored_table_is_what_the_40_digit_reference_finds(boundary: Boundary) -> None:
    """Searched from the same estimate, the reference finds the stored value to 2 ulps (its root is
    resolved at 40 digits, far below a double's step; 2 ulps leave mpmath room to round its last
    digits differently), at the same place, as verified as stored."""
    ref = reference_boundary(boundary.loop, boundary.parameter, boundary.estimate, lower=boundary.lower)
    assert ref.value == pytest.approx(boundary.value, rel=4.5e-16, abs=0)
    assert (ref.kind, ref.verified) == (boundary.kind, boundary.verified)
    assert ref.theta == pytest.approx(boundary.theta, rel=1e-12)


def test_the_passive_damping_of_a_delayed_loop_starts_above_zero() -> None:
    damping = passive_set(D1, "B")
    assert len(damping.intervals) == 1
    low, high = damping.intervals[0]
    assert max_damping(D1) == high and damping.lowest == low
    assert 3.3e-6 < low < 3.4e-6 and 0.0565 < high < 0.0566
    _check_against_reference(D1, "B", low, lower=True)
    _check_against_reference(D1, "B", high, lower=False)
    assert not exact_verdict(D1.with_wall(D1.K, 0.0)).passive  # no damper: active
    assert exact_verdict(D1).passive


def test_seed_device_at_two_samples_has_passive_damping_only_in_a_band() -> None:
    low, high = passive_set(D2, "B").intervals[0]
    assert low == pytest.approx(0.012462, rel=1e-4) and high == pytest.approx(0.063372, rel=1e-4)
    _check_against_reference(D2, "B", low, lower=True)
    _check_against_reference(D2, "B", high, lower=False)
    for value, expected in ((low * 0.999, False), (low * 1.001, True), (high * 0.999, True), (high * 1.001, False)):
        assert exact_verdict(D2.with_wall(D2.K, value)).passive is expected


@pytest.mark.parametrize("loop", REFERENCED, ids=lambda loop: f"{loop.velocity}-D{loop.delay}")
def test_limits_match_the_40_digit_reference(loop: WallLoop) -> None:
    stiffness, damping = passive_limits(loop)
    for passive in (stiffness, damping):
        for interval, (low, high) in enumerate(passive.intervals):
            _check_against_reference(loop, passive.parameter, high, lower=False, interval=interval)
            if low > 0:
                _check_against_reference(loop, passive.parameter, low, lower=True, interval=interval)


@pytest.mark.parametrize("loop", [D1, D2, WallLoop(0.032, 3.62, 1e-3, 700.0, 2.0, 1.5, "lowpass:0.0005"),
                                  WallLoop(0.5, 0.1, 1e-3, 0.0, 0.0, 0.0, "average")],
                         ids=["d1", "d2", "lowpass-d1.5", "average"])
def test_limits_bracket_the_verdict(loop: WallLoop) -> None:
    """Just inside each end passive, just outside not (1e-6 relative: far beyond both round-offs)."""
    for passive in passive_limits(loop):
        make = (lambda x: loop.with_wall(x, loop.B)) if passive.parameter == "K" else (lambda x: loop.with_wall(loop.K, x))
        for low, high in passive.intervals:
            assert exact_verdict(make(high * (1 - 1e-6))).passive
            assert not exact_verdict(make(high * (1 + 1e-6))).passive
            if low > 0:
                assert exact_verdict(make(low * (1 + 1e-6))).passive
                assert not exact_verdict(make(low * (1 - 1e-6))).passive


def test_none_only_when_nothing_is_passive() -> None:
    seed_d1 = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 1)
    assert max_stiffness(seed_d1) is None and max_damping(seed_d1) is None
    assert passive_set(seed_d1, "K").intervals == () and passive_set(seed_d1, "K").lowest is None
    assert max_damping(D1) is not None  # the null where a passive B exists


def test_eq23_without_delay_is_the_limit_to_the_last_digit() -> None:
    """Point velocity, no delay: the flip boundary b / tanh(c/2) = KT/2 + B (eq. 23) is the limit."""
    seed = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0)
    assert max_stiffness(seed) == pytest.approx(1800000.0066666666, rel=1e-14)
    assert max_damping(seed) == pytest.approx(999.9000033333333, rel=1e-14)
