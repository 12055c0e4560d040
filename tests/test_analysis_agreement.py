"""The printed passive intervals and the verdict agree (issue 19): a property over random loops.

For every loop drawn (no friction among them, real delays, every velocity model): the loop is
passive iff its own ``K`` lies in the passive ``K`` set at its ``B`` and iff its own ``B`` lies in
the passive ``B`` set at its ``K``; and a point drawn inside any printed interval checks passive.
Points within 1e-9 (relative) of an end are not asked about: the ends are exact to 1e-12, the
verdict's sign to round-off, and in between either answer is right.  Example counts come from
the active hypothesis profile (nothing is pinned here).
"""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.limits import PassiveSet, passive_limits
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.velocity import VelocityModel

_NEAR = 1e-9
T = 1e-3


@st.composite
def loops(draw: st.DrawFn) -> WallLoop:
    m = 10 ** draw(st.floats(-1.7, 0.3))
    c = draw(st.one_of(st.just(0.0), st.floats(-5.0, 0.0).map(lambda e: 10**e)))  # b T/m
    delay = draw(st.sampled_from([0, 0.3, 1, 2.5]))
    velocity = draw(st.sampled_from(["point", "average", f"window:{0.4 * T!r}", f"lowpass:{0.5 * T!r}"]))
    K = draw(st.one_of(st.just(0.0), st.floats(-7.0, 0.6).map(lambda e: 10**e * m / T**2)))
    B = draw(st.one_of(st.just(0.0), st.floats(-7.0, 0.3).map(lambda e: 10**e * m / T)))
    return WallLoop(m, c * m / T, T, K, B, delay, VelocityModel.parse(velocity))


def _near_an_end(passive: PassiveSet, value: float) -> bool:
    return any(abs(value - end) <= _NEAR * max(abs(end), 1e-300) for interval in passive.intervals for end in interval)


def _inside(low: float, high: float, u: float) -> float:
    """A point of (low, high) at fraction ``u``: geometric across many decades, else linear."""
    if low > 0 and high / low > 1e3:
        return math.exp(math.log(low) + u * (math.log(high) - math.log(low)))
    return low + u * (high - low)


@settings(deadline=None)
@given(loop=loops(), u=st.floats(0.01, 0.99))
def test_the_verdict_and_both_printed_intervals_agree(loop: WallLoop, u: float) -> None:
    stiffness, damping = passive_limits(loop)
    passive = exact_verdict(loop).passive
    if not _near_an_end(stiffness, loop.K):
        assert stiffness.contains(loop.K) == passive, (stiffness, passive)
    if not _near_an_end(damping, loop.B):
        assert damping.contains(loop.B) == passive, (damping, passive)
    for passive_set, make in ((stiffness, lambda x: loop.with_wall(x, loop.B)),
                              (damping, lambda x: loop.with_wall(loop.K, x))):
        for low, high in passive_set.intervals:
            point = low if low == high else _inside(low, high, u)
            if low == high or not _near_an_end(passive_set, point):
                assert exact_verdict(make(point)).passive, (passive_set, point)
