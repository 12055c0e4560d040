"""Out-of-band exposure: harmonic (lifted) analysis of alias pairs, its convergence, the exact simulation.

Tolerances: the harmonic analysis and the periodic steady state of the exact time-domain loop
(Van Loan work integrals) compute one number by unrelated routes, both to round-off; measured
agreement <= 3e-11 relative, asserted 1e-8.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from haptic_bus.analysis.frequency import t_fund
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.out_of_band import confirm_by_simulation, exposure_at, exposure_convergence, worst_force

SEED = WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0)


def test_the_seed_design_gives_energy_to_a_near_dc_plus_1_khz_pair() -> None:
    """The independent check's "about 7e-5 W per N^2": the worst pair takes 7.957e-5 W out per N^2
    of force (0.707 N in each tone), in the limit of a near-DC tone below ~2 mHz (theta < 1e-5);
    at 16 mHz (theta = 1e-4) it is 7.36e-5, at 0.16 Hz 6.3e-6."""
    pair = worst_force(SEED, pair=True)
    assert pair.power == pytest.approx(-7.957e-5, rel=1e-3)
    assert pair.frequencies[0] < 0.01 and abs(pair.frequencies[1] - 1000.0) < 0.01
    assert pair.amplitudes == pytest.approx((0.7071, 0.7071), abs=1e-3)
    assert exposure_at(SEED, 1e-4, pair=True).power == pytest.approx(-7.36e-5, rel=1e-2)
    assert exposure_at(SEED, 1e-3, pair=True).power == pytest.approx(-6.29e-6, rel=1e-2)


def test_the_lifted_analysis_converges_in_the_number_of_harmonics() -> None:
    """More harmonics, more freedom: nonincreasing; the steps halve with N (an O(1/N) tail:
    the held force's harmonics fall as 1/n).  N = 0 is the band-limited min Re T_fund / 2."""
    series = exposure_convergence(SEED, (0, 1, 2, 4, 8, 16, 32))
    powers = np.array([e.power for e in series])
    assert np.all(np.diff(powers) <= 1e-15)
    steps = -np.diff(powers[2:])  # N = 2 -> 4 -> 8 -> 16 -> 32
    assert np.all((steps[:-1] / steps[1:] > 1.6) & (steps[:-1] / steps[1:] < 2.6))
    limit = powers[-1] - steps[-1]  # Richardson for an O(1/N) tail: -1.443e-4
    assert limit == pytest.approx(-1.443e-4, rel=5e-3)
    band = 0.5 * float(np.min(t_fund(SEED, np.geomspace(1e-6, math.pi, 4000)).real))
    assert powers[0] == pytest.approx(band, rel=1e-3) and powers[0] > 0  # passive below Nyquist


@pytest.mark.parametrize("loop", [
    SEED, WallLoop(0.5, 0.1, 1e-3, 200.0, 100.0, 1),
    WallLoop(0.5, 0.1, 1e-3, 20.0, 0.05, 0.3, "lowpass:0.0005"),
    WallLoop(0.5, 0.1, 1e-3, 20.0, 0.5, 1, "average"),
    WallLoop(0.032, 3.62, 1e-3, 700.0, 2.0, 1.25, "window:0.0004"),
], ids=lambda loop: f"{loop.velocity}-D{loop.delay}")
@pytest.mark.parametrize("q,harmonics,pair", [(4096, 8, True), (512, 3, False), (7, 2, False)])
def test_the_harmonic_analysis_is_confirmed_by_the_exact_simulation(loop: WallLoop, q: int, harmonics: int,
                                                                      pair: bool) -> None:
    exposure = exposure_at(loop, 2 * math.pi / q, harmonics, pair)
    simulated = confirm_by_simulation(loop, exposure, q)
    assert simulated == pytest.approx(exposure.power, rel=1e-8)
    assert sum(a * a for a in exposure.amplitudes) == pytest.approx(1.0, rel=1e-12)
