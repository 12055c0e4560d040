"""Closed-loop poles from the state matrix's eigenvalues: long delays, the integrator, the lossless mass.

The independent checks use the characteristic function written out, never expanded:
``f(z) = (z - a)(z - 1) + k1 (K T z + B (z - 1)) z^{-d}`` (point velocity, whole delay ``d``;
the poles are its zeros and ``d`` more at ``z = 0``): a Newton step in 30 digits from each
computed pole, and the argument principle on circles just inside and just outside the
spectral radius (the winding number of ``f`` is the number of poles inside minus ``d``).
"""

from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest

from haptic_bus.analysis.check import check_passivity
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.design import exact_region_boundary, exact_region_floor
from haptic_bus.analysis.limits import max_stiffness
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.plant import phi1
from haptic_bus.analysis.poles import closed_loop_poles, is_stable, spectral_radius

ISSUE_40 = WallLoop(0.5, 1.0, 1e-3, 1.0, 0.01, 40)


def _char(loop: WallLoop, z: complex | np.ndarray) -> complex | np.ndarray:
    a = math.exp(-loop.c)
    k1 = loop.T / loop.m * phi1(loop.c)
    return (z - a) * (z - 1) + k1 * (loop.K * loop.T * z + loop.B * (z - 1)) * z ** (-int(loop.delay))


def _winding(loop: WallLoop, radius: float, near: np.ndarray) -> int:
    """Winding number of ``f`` round ``|z| = radius``: 64 samples per turn of ``z^-d``, and 4001
    more within 1e-7 rad of each angle in ``near`` (a zero 1e-9 off the circle turns the phase there)."""
    local = (near[:, None] + np.linspace(-1e-7, 1e-7, 4001)[None, :]).ravel() % (2 * np.pi)
    phi = np.sort(np.concatenate([np.linspace(0.0, 2 * np.pi, 64 * (int(loop.delay) + 4) + 1), local]))
    values = _char(loop, radius * np.exp(1j * phi))
    return round(float(np.sum(np.diff(np.unwrap(np.angle(values))))) / (2 * np.pi))


def _newton_mp(loop: WallLoop, z0: complex) -> mp.mpc:
    with mp.workdps(30):
        m, b, T, K, B = (mp.mpf(x) for x in (loop.m, loop.b, loop.T, loop.K, loop.B))
        a = mp.exp(-b * T / m)
        k1 = -mp.expm1(-b * T / m) / b
        d = int(loop.delay)
        return mp.findroot(lambda z: (z - a) * (z - 1) + k1 * (K * T * z + B * (z - 1)) * z ** (-d), mp.mpc(z0))


def test_the_issue_delay_40_loop_is_stable_and_passive() -> None:
    """The roots of the expanded polynomial said UNSTABLE, 1.2975; the loop is passive."""
    assert spectral_radius(ISSUE_40) == pytest.approx(0.99903, abs=5e-6)
    verdict = exact_verdict(ISSUE_40)
    assert verdict.stable and verdict.passive and verdict.margin > 0
    top = closed_loop_poles(ISSUE_40)[0]
    assert abs(top - complex(_newton_mp(ISSUE_40, top))) < 1e-13  # the eigenvalue is the root to 1e-13


@pytest.mark.parametrize("delay", [40, 200, 1000])
def test_long_delays_agree_with_the_argument_principle(delay: int) -> None:
    """Every pole inside ``rho (1 + 1e-9)``, one pair (or one real pole) on ``rho``: the count of
    zeros of the unexpanded characteristic function changes by exactly that across it."""
    loop = ISSUE_40.with_delay(delay)
    poles = closed_loop_poles(loop)
    assert poles.size == delay + 2
    rho = spectral_radius(loop)
    top = poles[np.abs(np.abs(poles) - rho) < 1e-12]
    angles = np.angle(top) % (2 * np.pi)
    assert _winding(loop, rho * (1 + 1e-9), angles) == 2
    assert _winding(loop, rho * (1 - 1e-9), angles) == 2 - top.size
    refined = complex(_newton_mp(loop, poles[0]))
    assert abs(abs(refined) - rho) < 1e-12
    assert is_stable(loop) == (rho < 1)


def test_delay_1000_is_judged_and_its_limits_found() -> None:
    """A spring lagging ``D T`` acts as a damping ``-K D T`` at low frequency (DESIGN 3.5): the
    largest passive ``K`` at ``B = 0`` is close to ``b / (D T)`` = 1 N/m here."""
    loop = WallLoop(0.5, 1.0, 1e-3, 0.5, 0.0, 1000)
    assert exact_verdict(loop).passive
    k_max = max_stiffness(loop)
    assert k_max is not None and k_max == pytest.approx(1.0 / (1000 * 1e-3), rel=0.01)
    assert exact_verdict(loop.with_wall(k_max * (1 - 1e-6), 0.0)).passive
    assert not exact_verdict(loop.with_wall(k_max * (1 + 1e-6), 0.0)).passive


def test_region_at_delay_64_finds_the_passive_walls() -> None:
    """The expanded polynomial's roots drew 'no passive wall' here; the device has them."""
    floor = exact_region_floor(0.5, 1.0, 1e-3, 64)
    assert floor is not None
    alpha = exact_region_boundary(0.5, 1.0, 1e-3, 64, floor * np.array([1.5, 4.0, 30.0]))
    assert np.all(np.isfinite(alpha) & (alpha > 0))


def test_without_a_spring_the_integrator_is_no_pole() -> None:
    damper = WallLoop(0.5, 0.1, 1e-3, 0.0, 100.0)
    assert closed_loop_poles(damper).size == 1  # z = a - k1 B only
    assert closed_loop_poles(damper)[0] == pytest.approx(math.exp(-damper.c) - damper.T / damper.m * phi1(damper.c) * 100.0)
    assert closed_loop_poles(damper.with_wall(200.0, 100.0)).size == 2


def test_the_free_frictionless_mass_is_lossless_not_unstable() -> None:
    for m, T in ((0.5, 1e-3), (1e9, 1e-9), (1e-9, 10.0)):
        loop = WallLoop(m, 0.0, T, 0.0, 0.0)
        verdict = exact_verdict(loop)
        assert verdict.lossless and verdict.passive and verdict.outcome == "lossless" and verdict.margin == 0.0
        report = check_passivity(m, 0.0, T, 0.0, 0.0)
        assert report.lossless and report.to_dict()["outcome"] == "lossless"
        assert report.stiffness_set.intervals[0] == (0.0, 0.0)  # any spring on it rings forever
    # a spring on the frictionless mass: poles on the unit circle, not lossless, not passive
    ringing = exact_verdict(WallLoop(0.5, 0.0, 1e-3, 100.0, 0.0))
    assert not ringing.lossless and not ringing.passive
