"""The port observer's energy terms and the passivity layer's budget, against brute force.

Each term is a least value over splits of a displacement (``port_energy``'s docstring); the
tests compare it with a dense search over the splits, check the rounding bound on quantised
positions, and check that a target the layer lets through keeps the worst case non-negative.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.optimize

from haptic_bus.control.passivity_layer import PassivityLayer, default_budget_cap
from haptic_bus.control.port_energy import PortObserver, interval_energy, switch_energy

B = 20.0  # N s/m
T = 1e-3  # s


def test_one_piece_is_the_design_notes_term() -> None:
    for dx, force in [(1e-4, 3.0), (-2e-4, 10.0), (0.0, -4.0)]:
        term, slope = interval_energy(B, dx, [force], [T])
        assert term == pytest.approx(B * dx * dx / T - force * dx, rel=1e-12, abs=1e-18)
        assert slope == pytest.approx(2 * B * dx / T - force, rel=1e-12, abs=1e-12)


def test_several_pieces_give_the_least_value_over_every_split() -> None:
    rng = np.random.default_rng(4)
    for _ in range(20):
        forces = list(rng.uniform(-30, 30, 3))
        durations = list(rng.uniform(0.2e-3, 3e-3, 3))
        dx = float(rng.uniform(-3e-3, 3e-3))
        term, _ = interval_energy(B, dx, forces, durations)
        # brute force: every split (y1, y2, dx - y1 - y2) on a grid around the optimum
        y1, y2 = np.meshgrid(np.linspace(-0.02, 0.02, 201), np.linspace(-0.02, 0.02, 201))
        y3 = dx - y1 - y2
        values = sum(B * y * y / tau - f * y for y, f, tau in zip((y1, y2, y3), forces, durations))
        assert term <= float(values.min()) + 1e-12  # never above any split: a lower bound
        def split_value(y: np.ndarray, dx: float = dx, forces: list[float] = forces, durations: list[float] = durations) -> float:
            pieces = (y[0], y[1], dx - y[0] - y[1])
            return float(sum(B * v * v / tau - f * v for v, f, tau in zip(pieces, forces, durations)))

        # and a numerical minimiser reaches it
        split = scipy.optimize.minimize(split_value, x0=[dx / 3, dx / 3], method="BFGS", options={"gtol": 1e-12})
        assert term == pytest.approx(float(split.fun), rel=1e-7, abs=1e-12)


def test_a_change_at_an_unknown_instant_takes_the_worst_instant() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        before, after = rng.uniform(-30, 30, 2)
        dx = float(rng.uniform(-2e-3, 2e-3))
        term, _ = switch_energy(B, dx, float(before), float(after), T)
        splits = [interval_energy(B, dx, [before, after], [s * T, (1 - s) * T])[0] for s in np.linspace(1e-9, 1 - 1e-9, 1001)]
        assert term <= min(splits) + 1e-12
        assert term == pytest.approx(min(splits), abs=1e-6 * max(1.0, abs(term)))


def test_counts_rounding_is_bounded_by_the_summed_slopes() -> None:
    """Quantised positions: the true sum lies within the observer's rounding bound of the measured one."""
    rng = np.random.default_rng(6)
    count = 1e-5  # m: a coarse encoder, so rounding matters
    truth = PortObserver(B, 0.0)
    measured = PortObserver(B, count)
    x = 0.0
    for _ in range(5000):
        force = float(rng.uniform(-20, 20))
        for observer in (truth, measured):
            observer.apply(force, T)
        x += float(rng.normal(0.0, 3e-4))
        truth.sample(x)
        measured.sample(round(x / count) * count)
        assert measured.energy - measured.rounding <= truth.energy + 1e-12
        assert measured.energy + measured.rounding >= truth.energy - 1e-12


def test_the_capped_budget_never_exceeds_the_energy() -> None:
    observer = PortObserver(B, 0.0, cap=1e-3)
    x = 0.0
    for k in range(2000):
        observer.apply(-5.0 if k % 400 < 200 else 5.0, T)
        x += 1e-4 if k % 400 < 200 else -1e-4
        observer.sample(x)
        assert observer.budget <= min(observer.energy, 1e-3) + 1e-15


@pytest.mark.parametrize("committed", [0, 1, 2])
def test_a_target_the_layer_passes_fits_the_budget_with_what_is_in_flight(committed: int) -> None:
    """``(F_new^2 + sum F_sent^2) T / (4 b) <= budget``: every worst case keeps E >= 0 -- or the
    forces already in flight have spent it, and the new target is zero."""
    unit = 0.016  # N per per mille
    rng = np.random.default_rng(7 + committed)
    for _ in range(300):
        layer = PassivityLayer("guard", B, T, committed, unit)
        sent = [layer.limit(int(rng.integers(-2000, 2001)), 10.0) * unit for _ in range(committed)]  # in flight
        budget = float(rng.uniform(0.0, 0.02))
        force = layer.limit(int(rng.integers(-2000, 2001)), budget) * unit
        in_flight = sum(f * f for f in sent) * T / (4 * B)
        if in_flight >= budget:
            assert force == 0.0
        else:
            assert (force * force) * T / (4 * B) + in_flight <= budget * (1 + 1e-12)


def test_the_layer_never_raises_a_target_and_off_passes_everything() -> None:
    guard = PassivityLayer("guard", B, T, 1, 0.016)
    off = PassivityLayer("off", B, T, 1, 0.016)
    for torque in (1500, -1500, 3, 0):
        assert abs(guard.limit(torque, 1e-4)) <= abs(torque)
        assert off.limit(torque, 0.0) == torque
    assert off.interventions == 0 and guard.interventions > 0


def test_the_default_cap_covers_the_force_limit_and_the_softest_spring() -> None:
    cap = default_budget_cap(30.0, B, T, 1, 1500.0)
    assert cap == pytest.approx(2 * 900 * T / (4 * B) + 900 / (2 * 1500.0))
    assert math.isclose(default_budget_cap(30.0, B, T, 1, 0.0), 2 * 900 * T / (4 * B))
