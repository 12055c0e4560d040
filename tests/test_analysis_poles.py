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
from haptic_bus.analysis.poles import closed_loop_poles, is_stable, shifted_poles, spectral_radius, stability
from haptic_bus.analysis.velocity import VelocityModel

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


# --- issue 19: loops whose stability double precision cannot judge --------------------------------

CORNER = WallLoop(81111842.28316566, 0.09841793101174633, 2.086875209114912e-09, 23970.471528040052,
                  0.027791958297842794, 0.5, "window:2.501302623119371e-10")


def _mp_excess(loop: WallLoop) -> float:
    """``max |z| - 1`` from the eigenvalues of the closed-loop matrix built in 80 digits from matrix
    exponentials (:mod:`haptic_bus.bench.mp_boundary`): nothing shared with the analysis."""
    from haptic_bus.bench.mp_boundary import closed_loop_matrix

    with mp.workdps(80):
        matrix = closed_loop_matrix(loop, mp.mpf(loop.K), mp.mpf(loop.B))
        return float(max(abs(e) for e in mp.eig(matrix, left=False, right=False)) - 1)


def test_the_issue_corner_loop_is_stable_and_passive() -> None:
    """bT/m = 2.5e-18: the poles sit 1.6e-18 inside the circle (80 digits); the dense eigenvalues said
    outside (UNSTABLE, margin -0.0444).  The margin is Re Z at its minimum, to the 80-digit value's digits."""
    from tests.mp_reference import re_z_mp

    judged = stability(CORNER)
    assert judged.stable and judged.excess == pytest.approx(_mp_excess(CORNER), rel=1e-6)
    verdict = exact_verdict(CORNER)
    assert verdict.stable and verdict.passive and verdict.margin == pytest.approx(0.07916, abs=1e-5)
    assert verdict.margin == pytest.approx(float(re_z_mp(CORNER, verdict.critical_theta)), rel=1e-12)


def _corner_loops(count: int, seed: int = 19) -> list[WallLoop]:
    """The issue's corner: m 1e6..1e9 kg, T 1e-9..1e-7 s, bT/m 1e-22..1e-17, every velocity model, delays."""
    rng = np.random.default_rng(seed)
    loops: list[WallLoop] = []
    while len(loops) < count:
        m, T, c = 10 ** rng.uniform(6, 9), 10 ** rng.uniform(-9, -7), 10 ** rng.uniform(-22, -17)
        kind = ["point", "average", f"window:{T * rng.uniform(0.05, 1.0)!r}", f"lowpass:{T * rng.uniform(0.1, 3.0)!r}"][
            len(loops) % 4]
        loops.append(WallLoop(m, c * m / T, T, 10 ** rng.uniform(0, 6), 10 ** rng.uniform(-3, 1),
                              float(rng.choice([0, 0.5, 1, 1.5, 3])), kind))
    return loops


@pytest.mark.parametrize("loop", _corner_loops(24), ids=lambda loop: f"{loop.velocity.kind}-D{loop.delay}")
def test_corner_stability_agrees_with_80_digits(loop: WallLoop) -> None:
    reference = _mp_excess(loop)
    judged = stability(loop)
    assert judged.stable == (reference < 0)
    assert judged.excess == pytest.approx(reference, rel=1e-6, abs=1e-30)


@pytest.mark.parametrize("loop", [WallLoop(0.5, 1.0, 1e-3, 1.0, 0.01, 200), WallLoop(0.5, 0.1, 1e-3, 0.0, 1.0, 150.5, "average"),
                                  WallLoop(0.032, 3.62, 1e-3, 700.0, 0.0, 120.3, "window:0.0004"),
                                  WallLoop(0.5, 0.1, 1e-3, 20.0, 0.05, 97.25, "lowpass:0.0005")],
                         ids=lambda loop: f"{loop.velocity.kind}-D{loop.delay}")
def test_the_long_delay_solver_finds_every_dense_eigenvalue(loop: WallLoop) -> None:
    """Above the dense limit the poles come from ring starts, Newton and Aberth on ``f``: each is
    matched one to one with an eigenvalue of the closed-loop matrix (LAPACK) to 1e-9."""
    from haptic_bus.analysis.sampled_loop import loop_matrix

    ours = shifted_poles(loop)
    dense = np.linalg.eigvals(loop_matrix(loop))
    assert ours.size == dense.size
    remaining = list(dense)
    for w in ours:
        k = int(np.argmin(np.abs(np.array(remaining) - w)))
        assert abs(remaining.pop(k) - w) < 1e-9


def test_schur_cohn_decides_long_delays_as_the_poles_do() -> None:
    """The recursion on the expanded polynomial decides a long delay's stability in O(L) per step;
    where it answers (its margin beyond 1e-8) it agrees with the poles on every loop drawn."""
    from haptic_bus.analysis.characteristic import SCHUR_COHN_TRUST, characteristic, schur_cohn

    rng = np.random.default_rng(5)
    answered = 0
    for _ in range(40):
        m, b = 10 ** rng.uniform(-2, 1), float(rng.choice([0.0, 10 ** rng.uniform(-3, 2)]))
        K, B = float(rng.choice([0.0, 10 ** rng.uniform(-3, 4)])), float(rng.choice([0.0, 10 ** rng.uniform(-4, 2)]))
        delay = float(rng.choice([97, 120.5, 300, 999.25, 1000]))
        velocity = VelocityModel.parse(str(rng.choice(["point", "average", "lowpass:0.0005", "window:0.0004"])))
        loop = WallLoop(m, b, 1e-3, K, B, delay, velocity)
        char = characteristic(loop)
        wall = char.wall(loop.kappa, loop.q, loop.K > 0)
        if not np.any(wall):
            continue
        margin = schur_cohn(char, wall, loop.K > 0)
        if abs(margin) > SCHUR_COHN_TRUST:
            answered += 1
            assert (margin > 0) == stability(loop).stable, loop
    assert answered >= 25


def test_delay_1000_limit_agrees_with_40_digits() -> None:
    """At D = 1000 the largest passive K at B = 0 is the low-frequency root Re Z(K, theta -> 0) = 0:
    solved in 80 digits from matrix exponentials (tests.mp_reference), it agrees to 1e-12; the
    Schur-Cohn recursion in 40 digits on the characteristic polynomial says stable just inside."""
    from haptic_bus.bench.mp_boundary import THETA_LOW, schur_cohn_stable
    from tests.mp_reference import re_z_mp

    loop = WallLoop(0.5, 1.0, 1e-3, 0.5, 0.0, 1000)
    k_max = max_stiffness(loop)
    assert k_max is not None
    with mp.workdps(40):
        root = mp.findroot(lambda K: re_z_mp(loop, THETA_LOW, K, 0), (k_max * (1 - 1e-6), k_max * (1 + 1e-6)),
                           solver="anderson")
        assert abs(k_max - float(root)) <= 1e-12 * float(root)
        assert schur_cohn_stable(loop, root * (1 - mp.mpf("1e-9")), mp.mpf(0))
    assert float(re_z_mp(loop, THETA_LOW, k_max * (1 + 1e-9), 0)) < 0
