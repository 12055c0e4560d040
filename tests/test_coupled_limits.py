"""Limits along a direction (issue 22): the passive K and B of a plane wall on coupled axes.

Each end is located to ~1e-12 relative (an envelope minimum by the zoom); the coupled gate,
asked 1e-9 inside and outside an end, must say passive and not passive: the limits are the
gate's own boundary.  The scalar plane condition ``F`` and the least eigenvalue of ``Herm Z``
are two forms of one test: same sign at every grid point, both well away from round-off.
"""

from __future__ import annotations

import numpy as np
import pytest

from haptic_bus.analysis.coupled import coupled_verdict, least_eigenvalue
from haptic_bus.analysis.coupled_limits import PlaneWall, passive_along, plane_quadratic
from haptic_bus.analysis.coupled_loop import plane_wall, unit_normal
from haptic_bus.analysis.limits import passive_set
from haptic_bus.analysis.loop import STIFFNESS_RANGE, WallLoop
from haptic_bus.errors import ParameterError

T = 1e-3
MIXED = (WallLoop(1.0, 20.0, T, 0, 0, 1, "average"), WallLoop(0.3, 2.0, T, 0, 0, 0.4, "lowpass:0.001"),
         WallLoop(2.0, 5.0, T, 0, 0, 2, "point"))
NORMAL = [1.0, 0.5, -0.7]


def _gate_passive(which: str, value: float, K: float, B: float) -> bool:
    K, B = (value, B) if which == "K" else (K, value)
    return coupled_verdict(plane_wall(MIXED, NORMAL, K, B)).passive


@pytest.mark.parametrize(("which", "K", "B", "expected"), [
    ("K", 0.0, 0.0, ((0.0, 3873.4464625),)),
    ("K", 0.0, 2.0, ((0.0, 5077.7327005),)),
    ("B", 1000.0, 0.0, ((0.0, 8.8501985858),)),
    ("B", 4000.0, 0.0, ((0.2097617426, 6.4425117526),)),  # too little damping is active as well as too much
    ("B", 6000.0, 0.0, ()),
])
def test_every_end_is_where_the_coupled_gate_turns(which: str, K: float, B: float, expected: tuple) -> None:
    found = passive_along(MIXED, NORMAL, K, B, which)
    assert found.parameter == which
    assert len(found.intervals) == len(expected)
    for (lo, hi), (want_lo, want_hi) in zip(found.intervals, expected):
        assert (lo, hi) == pytest.approx((want_lo, want_hi), rel=1e-9)
        for end, inward in ((lo, 1.0), (hi, -1.0)):
            if end == 0.0:
                assert _gate_passive(which, 0.0, K, B)
                continue
            assert _gate_passive(which, end * (1 + inward * 1e-9), K, B)
            assert not _gate_passive(which, end * (1 - inward * 1e-9), K, B)


def test_an_axis_aligned_normal_gives_the_axis_own_limits() -> None:
    for i, axis in enumerate(MIXED):
        normal = np.zeros(3)
        normal[i] = -3.0
        assert passive_along(MIXED, normal, 0.0, 1.0, "K") == passive_set(axis.with_wall(0.0, 1.0), "K")
        assert passive_along(MIXED, normal, 800.0, 0.0, "B") == passive_set(axis.with_wall(800.0, 0.0), "B")


def test_axes_the_normal_does_not_touch_take_no_part() -> None:
    two = passive_along(MIXED[:2], NORMAL[:2], 0.0, 1.0, "K")
    three = passive_along(MIXED, [*NORMAL[:2], 0.0], 0.0, 1.0, "K")
    assert np.array(three.intervals) == pytest.approx(np.array(two.intervals), rel=1e-12)


@pytest.mark.parametrize(("K", "B"), [(1000.0, 2.0), (3000.0, 0.5), (300.0, 0.0), (20000.0, 3.0)])
def test_the_plane_condition_has_the_sign_of_the_least_eigenvalue(K: float, B: float) -> None:
    theta = np.geomspace(1e-6, np.pi, 300)
    wall = PlaneWall(MIXED, unit_normal(NORMAL, 3), K, B)
    least, tolerance = least_eigenvalue(plane_wall(MIXED, NORMAL, K, B), theta)
    for which, x in (("K", K), ("B", B)):
        q, magnitudes = plane_quadratic(wall, which, theta)
        value = q[0] * x * x + q[1] * x + q[2]
        size = magnitudes[0] * x * x + magnitudes[1] * x + magnitudes[2]
        clear = (np.abs(least) > 1e3 * tolerance) & (np.abs(value) > 1e-10 * size)
        assert clear.sum() > 280
        assert np.array_equal(np.sign(value[clear]), np.sign(least[clear]))


def test_unbounded_and_refused() -> None:
    stiff_axes = (WallLoop(1.0, 20.0, T, 0, 0, 0, "point"), WallLoop(2.0, 30.0, T, 0, 0, 0, "point"))
    ideal = passive_along(stiff_axes, [1.0, 1.0], 0.0, 0.0, "B")  # no delay, no wall spring: any B up to its flip
    assert ideal.lowest == 0.0 and 0.0 < ideal.largest < STIFFNESS_RANGE[1]
    with pytest.raises(ParameterError, match="'K', 'B' or 'scale'"):
        passive_along(MIXED, NORMAL, 0.0, 0.0, "T")
    frictionless = (WallLoop(1.0, 0.0, T, 0, 0, 1), MIXED[0])
    with pytest.raises(ParameterError, match="b > 0"):
        passive_along(frictionless, [1.0, 1.0], 0.0, 0.0, "K")
