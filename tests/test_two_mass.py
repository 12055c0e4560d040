"""The gate for a two-mass device (issue 27, item 4): its criterion against the exact time domain, and its rigid limit.

**Agreement** (:func:`test_the_two_mass_verdict_agrees_with_the_time_domain_on_50_designs`): 50 seeded
designs -- handle ``m`` 0.03..2 kg, ``b`` 0.3..30 N s/m, every velocity model, delay 0, 0.5, 1 or
1.5 samples, ``K`` 100..20 000 N/m, ``B`` 0..10 N s/m, a transmission of 3 000..10^7 N/m,
0..20 N s/m and a motor of 0.03..2 times the handle.  The operator pushes at the handle with a
1 N tone at the verdict's critical frequency from rest (the input that takes energy out fastest
for an active loop); the exact energy ``int w v_handle dt`` (two-mass plant exact between samples,
:mod:`haptic_bus.analysis.two_mass_energy`, scipy's ``expm``: nothing from the frequency domain) at
every piece boundary for 1 000 periods, then after ``2^j`` periods up to ``2^30`` by doubling.
The tone's frequency is the one among the verdict's critical ``theta`` and 48 others (1e-3..3.1 rad)
with the least ``Re T_fund``: the most negative mean power per N^2 (W) an active loop offers.
A passive design must never go below minus the round-off bound; an active one must go below it.
**Boundary excluded:** a stable active design whose worst tone drains less than ``5e-10`` W per N^2
(``Re T_fund > -1e-9`` m/(N s)) would be left out.  From rest the switch-on transient puts in energy
that friction keeps (1e-6..1e-4 J here), and only the steady drain takes it back: at that rate it
needs more than the ``2^30`` periods (1.1e6 s) the check runs.  The margin in N s/m is no measure of
it: near the motor's resonance against a held handle ``|Z|`` is huge, and an undamped coupling found in a
wider search had margin -3e9 N s/m with a drain of 4e-15 W per N^2.  None of these 50 is excluded (the
count is asserted; the least ``|margin|`` is 0.31 N s/m); 300 wider designs (coupling up to 1e9 N/m,
delays up to 2.7) agreed too, 2 excluded.

**Mean power** (:func:`test_t_fund_is_the_mean_power_of_the_two_mass_loop`): ``|W|^2 Re T_fund/2``
against the exact periodic steady state, every velocity model, fractional delays, to 1e-9.

**The rigid limit** (derivation in docs/physics/transmission.md): as ``k -> infinity``,
``Z_c Z_load/(Z_c + Z_load) -> Z_load`` and the motor mobility's aliases tend to the rigid handle's
of mass ``m + m_motor``, so ``Re Z -> b + Re Z_wall`` of the rigid loop with mass ``m + m_motor`` and
friction ``b``.  Below Nyquist the corrections are ``O(1/k)``: the margin at a fixed wall and the
largest passive ``K`` close in ten times per decade of ``k``.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter

import numpy as np
import pytest

from haptic_bus.analysis.check import check_loop
from haptic_bus.analysis.coupled_energy import simulate_energies
from haptic_bus.analysis.criterion import Verdict, exact_verdict
from haptic_bus.analysis.energy import RandomSinusoids, Sinusoid
from haptic_bus.analysis.frequency import t_fund
from haptic_bus.analysis.limits import passive_scales
from haptic_bus.analysis.loop import MASS_RANGE, WallLoop
from haptic_bus.analysis.transmission import MOTOR_MASS_RANGE, Transmission
from haptic_bus.analysis.two_mass import TwoMassLoop
from haptic_bus.analysis.two_mass_criterion import (
    largest_passive_stiffness,
    t_fund_two_mass,
    two_mass_passive_scales,
    two_mass_verdict,
)
from haptic_bus.analysis.two_mass_energy import two_mass_machine, two_mass_mean_power
from haptic_bus.errors import ParameterError
from tests.energy_check import DELAYS, MODELS, STEPS, T, bears_out

LEAST_DRAIN = -1e-9  # m/(N s): Re T_fund of the worst tone above this is too slow to show (module docstring)
CANDIDATES = np.geomspace(1e-3, 3.1, 48)  # rad


def random_designs(seed: int = 27, count: int = 50) -> list[TwoMassLoop]:
    """Seeded two-mass wall loops (module docstring)."""
    rng = np.random.default_rng(seed)
    designs = []
    for _ in range(count):
        m, b = float(10 ** rng.uniform(-1.5, 0.3)), float(10 ** rng.uniform(-0.5, 1.5))
        handle = WallLoop(m, b, T, float(10 ** rng.uniform(2, 4.3)), float(rng.uniform(0, 10)), float(rng.choice(DELAYS)),
                          str(rng.choice(MODELS)))
        transmission = Transmission(float(10 ** rng.uniform(3.5, 7)), float(rng.uniform(0, 20)),
                                    m * float(10 ** rng.uniform(-1.5, 0.3)))
        designs.append(TwoMassLoop(handle, transmission))
    return designs


@pytest.fixture(scope="module")
def judged() -> tuple[list[TwoMassLoop], list[Verdict]]:
    """The 50 designs and the two-mass verdict on each."""
    designs = random_designs()
    return designs, [two_mass_verdict(loop) for loop in designs]


def _worst_tone(loop: TwoMassLoop, verdict: Verdict) -> tuple[float, float]:
    """``(theta, Re T_fund)``: of the critical ``theta`` and :data:`CANDIDATES`, the one with the least ``Re T_fund``."""
    thetas = np.append(CANDIDATES, min(max(verdict.critical_theta, 1e-3), 3.1))
    drains = t_fund_two_mass(loop, thetas).real
    k = int(np.argmin(drains))
    return float(thetas[k]), float(drains[k])


def test_the_two_mass_verdict_agrees_with_the_time_domain_on_50_designs(judged) -> None:
    designs, verdicts = judged
    assert Counter(v.outcome for v in verdicts) == {"passive": 30, "not passive": 10, "unstable": 10}
    assert all(v.criterion.startswith("exact, two-mass") for v in verdicts)
    assert min(abs(v.margin) for v in verdicts) == pytest.approx(0.3055, abs=1e-3)
    tones = [_worst_tone(loop, v) for loop, v in zip(designs, verdicts)]
    assert sum(v.stable and not v.passive and drain > LEAST_DRAIN for v, (_, drain) in zip(verdicts, tones)) == 0
    machines = [two_mass_machine(loop, Sinusoid(theta, T)) for loop, (theta, _) in zip(designs, tones)]
    runs = simulate_energies(machines, STEPS)
    agree = [bears_out(machine, float(runs.lowest[k]), float(runs.roundoff[k]), verdict.passive)
             for k, (verdict, machine) in enumerate(zip(verdicts, machines))]
    assert [k for k, ok in enumerate(agree) if not ok] == []


def test_passive_two_mass_designs_stay_passive_for_random_tones(judged) -> None:
    """Beyond the worst tone: each passive design under a random sum of 4 tones below Nyquist, from rest."""
    rng = np.random.default_rng(4)
    loops = [loop for loop, verdict in zip(*judged) if verdict.passive]
    machines = [two_mass_machine(loop, RandomSinusoids(T, int(rng.integers(2**31)), count=4)) for loop in loops]
    runs = simulate_energies(machines, STEPS)
    assert len(machines) == 30 and np.all(runs.lowest >= -runs.roundoff)


@pytest.mark.parametrize("velocity", MODELS)
@pytest.mark.parametrize("delay", [0.0, 0.7, 1.0])
def test_t_fund_is_the_mean_power_of_the_two_mass_loop(velocity: str, delay: float) -> None:
    """``W^2 Re T_fund/2`` is the exact steady-state mean power (W) of ``W sin(omega t)`` at the handle: below the
    resonance, near it and near Nyquist, to 1e-9 relative (the steady state's sum of ``q`` works: ~1e-12 measured)."""
    loop = TwoMassLoop(WallLoop(1.0, 20.0, T, 1500.0, 10.0, delay, velocity), Transmission(3e5, 10.0, 0.3))
    for theta in (0.05, 1.0, 2.9):
        result = two_mass_mean_power(loop, theta)
        assert result.power == pytest.approx(result.predicted, rel=1e-9)


def test_the_margin_closes_on_the_rigid_one_as_1_over_k() -> None:
    """The cia402-handle's wall (K 1500, B 10, D = 1, average) on a 1 kg handle with a 0.3 kg motor and 2 N s/m of
    coupling damping: the margin tends to the rigid loop's with m = 1.3 kg (11.0944 N s/m), the gap shrinking
    about tenfold per decade of k (0.1156, 0.0114, 0.00115, 0.000143 N s/m from 1e8 to 1e11 N/m; 1.1e-5 at 1e12)."""
    handle = WallLoop(1.0, 20.0, T, 1500.0, 10.0, 1, "average")
    rigid = exact_verdict(WallLoop(1.3, 20.0, T, 1500.0, 10.0, 1, "average")).margin
    assert rigid == pytest.approx(11.0944, abs=1e-4)
    gaps = [rigid - two_mass_verdict(TwoMassLoop(handle, Transmission(k, 2.0, 0.3))).margin for k in (1e8, 1e9, 1e10, 1e11)]
    assert gaps[0] == pytest.approx(0.1156, rel=1e-2)
    assert all(7.5 < a / b < 12.5 for a, b in itertools.pairwise(gaps))  # measured 10.1, 9.98, 8.0
    assert abs(gaps[-1]) < 2e-4


def test_the_largest_passive_stiffness_tends_to_the_rigid_one_with_the_motor_mass_added() -> None:
    """At B = 0 on the Omni-class plant (m 0.032 kg, b 3.62 N s/m, D = 1, average) with a 10 g motor and 2 N s/m:
    2425.337 N/m at k = 1e6, 2413.463 at 1e8, 2413.3455 at 1e10, against the rigid 2413.3444 N/m
    (bisection to 1e-7: 2.4e-4 N/m), the gap 100 times smaller per two decades.  Where the limit is
    the flip boundary the mass shows: a 0.5 kg, 5 N s/m handle, point velocity, D = 0, 0.1 kg motor, 20 N s/m:
    rigid 2.400e6 N/m with m + m_motor, 2.000e6 with m alone; the two-mass loop at k = 1e10 N/m passes up to
    2.370e6 (its aliased resonance, damped only by e^{-0.12} a sample, closes the last 1.3 % slowly)."""
    omni = WallLoop(0.032, 3.62, T, 0.0, 0.0, 1, "average")
    rigid = check_loop(WallLoop(0.042, 3.62, T, 0.0, 0.0, 1, "average"), out_of_band=False).max_stiffness
    assert rigid == pytest.approx(2413.3444, abs=1e-3)
    found = [largest_passive_stiffness(TwoMassLoop(omni, Transmission(k, 2.0, 0.01)), relative=1e-7) for k in (1e6, 1e8, 1e10)]
    assert found == pytest.approx([2425.3375, 2413.4627, 2413.3455], abs=5e-4)
    gaps = [f - rigid for f in found]
    assert 80.0 < gaps[0] / gaps[1] < 120.0 and abs(gaps[2]) < 2e-3
    flip = WallLoop(0.5, 5.0, T, 0.0, 0.0, 0, "point")
    heavy = check_loop(WallLoop(0.6, 5.0, T, 0.0, 0.0, 0, "point"), out_of_band=False).max_stiffness
    light = check_loop(flip, out_of_band=False).max_stiffness
    stiff = largest_passive_stiffness(TwoMassLoop(flip, Transmission(1e10, 20.0, 0.1)), relative=1e-6)
    assert (heavy, light) == pytest.approx((2.400e6, 2.000e6), rel=1e-4)
    assert stiff == pytest.approx(2.3698e6, rel=1e-4)


def test_a_transmission_without_damping_needs_the_walls_damper() -> None:
    """With c = 0 the motor's resonance against a held handle is undamped: where the wall lags there (D = 1,
    average, B = 0) every K > 0 is active -- K = 1500 N/m even unstable, at the resonance of the motor against
    the coupling and the wall's spring, sqrt((k + K)/m_motor) T = 0.5817 rad -- while B = 10 N s/m at the motor
    damps it (margin +17.04 N s/m).  Above Nyquist the resonance is out of the operator's band and the rigid
    limit returns (13 369 N/m at k = 1e7 N/m, rigid 13 333)."""
    handle = WallLoop(1.0, 20.0, T, 0.0, 0.0, 1, "average")
    assert largest_passive_stiffness(TwoMassLoop(handle, Transmission(1e5, 0.0, 0.3)), relative=1e-4) == 0.0
    assert largest_passive_stiffness(TwoMassLoop(handle, Transmission(1e7, 0.0, 0.3)), relative=1e-5) == pytest.approx(
        13369.2, rel=1e-4)
    undamped = two_mass_verdict(TwoMassLoop(handle.with_wall(1500.0, 0.0), Transmission(1e5, 0.0, 0.3)))
    assert undamped.outcome == "unstable"
    assert undamped.critical_theta == pytest.approx(math.sqrt((1e5 + 1500.0) / 0.3) * T, rel=1e-2)
    damped = two_mass_verdict(TwoMassLoop(handle.with_wall(1500.0, 10.0), Transmission(1e5, 0.0, 0.3)))
    assert damped.passive and damped.margin == pytest.approx(17.04, abs=0.01)


def test_t_fund_tends_to_the_rigid_one() -> None:
    """At k = 1e11 N/m the two-mass T_fund is the rigid loop's with m + m_motor across (0, pi]: at low frequency to
    about K/k = 2e-8 (the coupling's spring in series with the wall's: 2.1e-8 measured), near pi to 5.7e-6
    (measured), where the aliased resonance (836 rad per sample) weighs most."""
    handle = WallLoop(0.5, 5.0, T, 2000.0, 3.0, 0.5, "window:0.0005")
    loop = TwoMassLoop(handle, Transmission(1e11, 5.0, 0.2))
    theta = np.array([1e-9, 1e-4, 0.1, 1.0, 2.0, math.pi])
    assert t_fund_two_mass(loop, theta) == pytest.approx(t_fund(loop.rigid, theta), rel=1e-5)
    assert t_fund_two_mass(loop, theta[:3]) == pytest.approx(t_fund(loop.rigid, theta[:3]), rel=4e-8)


@pytest.mark.parametrize(("text", "name"), [("20000:2", "transmission"), ("0:2:0.3", "transmission stiffness"),
                                            ("2e4:-1:0.3", "transmission damping"), ("2e4:2:0", "transmission motor_mass"),
                                            ("2e4:2:nan", "transmission motor_mass"), ("a:b:c", "transmission")])
def test_invalid_transmissions_name_their_range(text: str, name: str) -> None:
    with pytest.raises(ParameterError) as caught:
        Transmission.parse(text)
    assert caught.value.name == name
    assert MOTOR_MASS_RANGE == MASS_RANGE  # the motor's mass spans what a handle's may


def test_the_sampled_ramp_scales_find_the_rigid_limits_exact_ones() -> None:
    """K 30 000 N/m, B 10 N s/m (D = 1, average): the rigid handle of 1.3 kg is passive for scales up to
    0.5682308 (exact); the two-mass loop at k = 1e11 N/m, its sampled search, up to 0.5682304 (the 1/k gap
    and the 2^-30 bisection)."""
    rigid = passive_scales(WallLoop(1.3, 20.0, T, 30000.0, 10.0, 1, "average"))
    sampled = two_mass_passive_scales(TwoMassLoop(WallLoop(1.0, 20.0, T, 30000.0, 10.0, 1, "average"),
                                                  Transmission(1e11, 2.0, 0.3)))
    [(low, high)] = sampled.intervals
    assert low == 0.0 and rigid.intervals[0][0] == 0.0
    assert high == pytest.approx(rigid.intervals[0][1], abs=2e-6) and rigid.intervals[0][1] == pytest.approx(0.56823, abs=1e-5)
