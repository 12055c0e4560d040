"""The sign of Re Z at extreme parameters: a tolerance relative to the terms that cancel, against 80 digits.

``Re Z T/m = c + Im(L E conj U)/(theta |U|^2)`` is evaluated with the magnitudes of the terms it
is summed from (``scale``); the criterion counts ``Re Z >= -SIGN_TOLERANCE * scale`` as
non-negative.  The proof that this is the right yardstick: over extreme loops (``m/T`` from
``1`` to ``1e18``, ``bT/m`` from 0 to ``1e16``, every velocity model, fractional delays) the
error of ``Re Z`` against the 80-digit definition stays below ``SIGN_TOLERANCE * scale``
(measured: below 4 % of it), so a sign outside the band is the loop's, not round-off's.
(The reference's own error, ~1e-80 of ``|Z|``, is allowed for where ``Re Z`` is exactly 0.)
"""

from __future__ import annotations

import math
import random

import mpmath as mp
import numpy as np
import pytest

from haptic_bus.analysis.check import check_passivity
from haptic_bus.analysis.criterion import SIGN_TOLERANCE, exact_verdict
from haptic_bus.analysis.design import exact_region_floor, passive_region_curves
from haptic_bus.analysis.frequency import loop_terms, scaled_impedance
from haptic_bus.analysis.loop import WallLoop
from tests.mp_reference import re_z_mp

THETAS = (1e-6, 1e-3, 0.5, 2.0, math.pi)


def _extreme_loops(count: int, seed: int = 7) -> list[WallLoop]:
    rng = random.Random(seed)
    loops: list[WallLoop] = []
    while len(loops) < count:
        m, T = 10.0 ** rng.choice([-9, -6, -3, 0, 3, 6, 9]), 10.0 ** rng.choice([-9, -6, -3, -1, 1])
        b = rng.choice([0.0, 1e-6, 1.0, 1e3, 1e6])
        K, B = rng.choice([0.0, 1e-3, 1.0, 1e3, 1e6, 1e12]), rng.choice([0.0, 1e-3, 1.0, 10.0, 1e3, 1e6])
        kind = rng.choice(["point", "average", "window", "lowpass"])
        fractions = [0.1, 0.3, 1.0, 3.0] if kind == "lowpass" else [0.3, 1.0]
        velocity = kind if kind in ("point", "average") else f"{kind}:{T * rng.choice(fractions)!r}"
        try:
            loops.append(WallLoop(m, b, T, K, B, rng.choice([0, 0.5, 1, 2.5]), velocity))
        except ValueError:
            continue
    return loops


@pytest.mark.parametrize("loop", _extreme_loops(60),
                         ids=lambda loop: f"m{loop.m:g}-T{loop.T:g}-b{loop.b:g}-{loop.velocity}-D{loop.delay}")
def test_re_z_errs_by_less_than_the_sign_tolerance_of_the_cancelling_terms(loop: WallLoop) -> None:
    z = scaled_impedance(loop_terms(loop, np.array(THETAS)), loop.kappa, loop.q)
    for theta, re, im, scale in zip(THETAS, z.re, z.im, z.scale):
        ref = float(re_z_mp(loop, mp.pi if theta == math.pi else theta)) * loop.T / loop.m
        assert abs(re - ref) <= SIGN_TOLERANCE * scale + 1e-60 * abs(im), (theta, re, ref, scale)


def test_an_active_damper_on_a_heavy_fast_loop_is_not_passive() -> None:
    """m/T = 1e15: |Z| ~ 3e15 N s/m at Nyquist, Re Z = -7.3 N s/m; a tolerance relative to |Z| hid it."""
    loop = WallLoop(1e6, 1.0, 1e-9, 0.0, 10.0, 1)
    verdict = exact_verdict(loop)
    assert verdict.stable and not verdict.passive
    ref = float(re_z_mp(loop, verdict.critical_theta))
    assert ref < -7.0 and verdict.margin == pytest.approx(ref, rel=1e-9)


def test_a_heavy_free_mass_is_checked_without_error() -> None:
    report = check_passivity(1e9, 0.0, 1e-9, 0.0, 0.0, delay=1)
    assert report.passive and report.lossless and report.margin == 0.0


def test_the_region_accepts_every_mass_check_accepts() -> None:
    curves = passive_region_curves(np.array([1.0, 10.0]), m=1e-9, b=1.0, periods=(1e-3,))
    assert np.all(np.isfinite(curves.velocity))
    assert check_passivity(1e-9, 1.0, 1e-3, 0.0, 0.0).passive
    assert exact_region_floor(1e-9, 1e-9, 1e-9, 0) is not None
