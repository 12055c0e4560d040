"""The coupled-axes criterion (issue 22): it is today's criterion for one axis and for an
axis-aligned wall, and its matrix ``T_fund`` is the time domain's mean power in any direction.

Tolerances: the 1-D and the matrix evaluation compute the same numbers by different routes
(``L conj U/|U|^2`` against a real block solve; one eigenvalue against one real part), each
exact to a few ulps of the terms it sums: measured <= 6e-14 relative on the margins, 1e-12
asserted.  Poles: eigenvalues of the same matrix entries, measured <= 6e-15.  The time-domain
mean power and ``lambda_min/2`` are two exact computations (Van Loan integrals of the exact
plant against the frequency formula): they agree within the summation's round-off bound that
``steady_mean_power`` returns (``2 q eps sum |w_k|``), plus 1e-12 of ``lambda`` for the
eigenvalue; measured <= 6e-13 relative.
"""

from __future__ import annotations

import numpy as np
import pytest

from haptic_bus.analysis.coupled import coupled_verdict, hermitian_impedance, worst_direction
from haptic_bus.analysis.coupled_energy import CoupledMachine, commensurate, steady_mean_power
from haptic_bus.analysis.coupled_loop import CoupledLoop, components, coupled_poles, plane_wall
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.frequency import z_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.poles import closed_loop_poles
from haptic_bus.analysis.theta_search import theta_grid
from haptic_bus.errors import ParameterError

T = 1e-3
MODELS = ["point", "average", "window:0.0004", "lowpass:0.002"]
DELAYS = [0, 0.3, 1, 2.5]
MIXED = (WallLoop(1.0, 20.0, T, 0, 0, 1, "average"), WallLoop(0.3, 2.0, T, 0, 0, 0.4, "lowpass:0.001"),
         WallLoop(2.0, 5.0, T, 0, 0, 2, "point"))


def _axis(velocity: str, delay: float) -> WallLoop:
    return WallLoop(0.5, 3.0, T, 0.0, 0.0, delay, velocity)


@pytest.mark.parametrize("velocity", MODELS)
@pytest.mark.parametrize("delay", DELAYS)
def test_one_axis_through_the_matrix_path_is_the_1d_criterion(velocity: str, delay: float) -> None:
    axis = _axis(velocity, delay)
    wall = axis.with_wall(2000.0, 5.0)
    one = plane_wall((axis,), [1.0], 2000.0, 5.0)
    reference = exact_verdict(wall)
    matrix = coupled_verdict(one, split=False)
    assert matrix.outcome == reference.outcome
    assert matrix.margin == pytest.approx(reference.margin, rel=1e-12)
    assert matrix.critical_theta == pytest.approx(reference.critical_theta, rel=1e-6)  # the zoom's resolution
    grid = theta_grid(wall, closed_loop_poles(wall))
    part = hermitian_impedance(one, grid)
    exact = z_fund(wall, grid)
    assert np.max(np.abs(part.symmetric[:, 0, 0] - exact.real) / part.scale) < 1e-13
    assert np.all(part.antisymmetric == 0.0)
    assert np.max(np.abs(part.full[:, 0, 0] - exact) / np.abs(exact)) < 1e-12
    assert np.sort_complex(coupled_poles(one)) == pytest.approx(np.sort_complex(closed_loop_poles(wall)), abs=1e-13)
    assert coupled_verdict(one) == coupled_verdict(one)  # deterministic
    assert coupled_verdict(one).margin == reference.margin  # split: the lone axis is the 1-D verdict itself


@pytest.mark.parametrize(("K", "B"), [(1000.0, 0.5), (3000.0, 0.5)], ids=["passive", "unstable"])
def test_an_axis_aligned_wall_is_three_1d_loops(K: float, B: float) -> None:
    loop = plane_wall(MIXED, [0.0, -2.0, 0.0], K, B)
    assert components(loop) == [[0], [1], [2]]
    verdict = coupled_verdict(loop)
    alone = [exact_verdict(loop.axis_loop(i)) for i in range(3)]
    assert verdict.margin == min(v.margin for v in alone)
    assert verdict.passive == all(v.passive for v in alone)
    assert loop.axis_loop(1) == MIXED[1].with_wall(K, B)
    # the whole matrix evaluation gives the same: Herm Z is diagonal with each axis' Re Z
    whole = coupled_verdict(loop, split=False)
    assert whole.outcome == verdict.outcome
    if verdict.stable:  # an unstable loop's margin is scaled by max(m_i)/T over the group judged, not the axis' m/T
        assert whole.margin == pytest.approx(verdict.margin, rel=1e-12)
    theta = np.linspace(0.01, np.pi, 50)
    part = hermitian_impedance(loop, theta)
    assert np.all(part.antisymmetric == 0.0)
    for i in range(3):
        assert part.symmetric[:, i, i] == pytest.approx(z_fund(loop.axis_loop(i), theta).real, rel=1e-12, abs=1e-12)
    assert np.all(part.symmetric[:, 0, 1:] == 0.0)


def test_the_matrix_t_fund_is_the_time_domain_mean_power_in_the_worst_direction() -> None:
    """Three axes, three velocity models, delays 1, 0.4 and 2: ``W = Z v`` puts in ``lambda/2`` W."""
    for K, B in [(1000.0, 2.0), (3000.0, 0.5), (300.0, 0.0)]:
        loop = plane_wall(MIXED, [1.0, 0.5, -0.7], K, B)
        theta, samples = commensurate(coupled_verdict(loop).critical_theta)
        direction = worst_direction(loop, theta)
        part = hermitian_impedance(loop, np.array([theta]))
        least = np.linalg.eigvalsh(part.matrix[0])[0]
        machine = CoupledMachine(loop, theta, part.full[0] @ direction)
        power = steady_mean_power(machine, samples)
        assert abs(power.mean - least / 2) <= power.roundoff + 1e-12 * abs(least)


def test_coupled_poles_of_a_diagonal_wall_are_the_axes_poles() -> None:
    loop = CoupledLoop(MIXED, np.diag([1000.0, 0.0, 300.0]), np.diag([1.0, 2.0, 0.0]))
    together = np.sort_complex(coupled_poles(loop))
    apart = np.sort_complex(np.concatenate([closed_loop_poles(loop.axis_loop(i)) for i in range(3)]))
    # the held-force registers give repeated poles near z = 0, which round-off moves by O(sqrt(eps)):
    # measured 1.6e-12 there, every other pole within 1e-15
    assert together == pytest.approx(apart, abs=1e-8)
    assert np.abs(together[np.abs(together) > 0.1]) == pytest.approx(np.abs(apart[np.abs(apart) > 0.1]), abs=1e-13)


@pytest.mark.parametrize(("K", "message"), [
    (np.array([[1.0, 2.0], [0.0, 1.0]]), "symmetric"),
    (np.array([[1.0, 0.0], [0.0, -1.0]]), "positive semidefinite"),
    (np.ones((3, 3)), "2 x 2"),
    (np.array([[np.nan, 0.0], [0.0, 1.0]]), "finite"),
])
def test_wall_matrices_are_checked(K: np.ndarray, message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        CoupledLoop(MIXED[:2], K, np.zeros((2, 2)))


def test_a_loop_needs_one_period_and_bare_axes() -> None:
    with pytest.raises(ParameterError, match="one period"):
        plane_wall((MIXED[0], WallLoop(1.0, 1.0, 2e-3, 0, 0)), [1, 1], 100.0, 0.0)
    with pytest.raises(ParameterError, match="K = B = 0"):
        plane_wall((MIXED[0], MIXED[1].with_wall(1.0, 0.0)), [1, 1], 100.0, 0.0)
    with pytest.raises(ParameterError, match="normal"):
        plane_wall(MIXED, [0.0, 0.0, 0.0], 100.0, 0.0)


def test_frictionless_axes_with_a_free_direction_are_refused() -> None:
    """Two frictionless axes under one plane: the direction along the plane is a z = 1 mode."""
    free = (WallLoop(1.0, 0.0, T, 0, 0, 1), WallLoop(0.5, 0.0, T, 0, 0, 1), MIXED[2])
    with pytest.raises(ParameterError, match="free frictionless direction"):
        coupled_verdict(plane_wall(free, [1.0, 1.0, 1.0], 100.0, 1.0))
    # one frictionless axis under an oblique wall has no such direction: judged
    assert coupled_verdict(plane_wall((free[0], MIXED[2]), [1.0, 1.0], 100.0, 1.0)).stable
    # a lone frictionless axis without a wall is the 1-D lossless loop
    lossless = coupled_verdict(plane_wall((free[0], MIXED[2]), [0.0, 1.0], 100.0, 1.0))
    assert lossless.groups == ((0,), (1,))
