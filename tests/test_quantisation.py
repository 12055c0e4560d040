"""The quantisation condition (:mod:`haptic_bus.analysis.quantisation`) against the exact quantised
simulation with Coulomb friction (:mod:`haptic_bus.analysis.quantised_loop`), and ``haptic-bus check
--position-resolution --coulomb``.

A run is *active* when the operator's energy goes below minus the run's round-off bound (a bound
of ``64 n u sum|work|``, about 1e-20 J here, far below every leak found: >= 7e-12 J).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from haptic_bus.analysis.check import check_passivity
from haptic_bus.analysis.criterion import exact_verdict
from haptic_bus.analysis.energy import Constant, RandomSinusoids, simulate
from haptic_bus.analysis.loop import WallLoop
from haptic_bus.analysis.quantisation import CROSSING, DRIFT, EXACT, quantisation_condition
from haptic_bus.analysis.quantised_loop import Hand, QuantisedRun, Quantiser, simulate_quantised
from haptic_bus.analysis.resolution import Quantisation
from haptic_bus.app.cli import main
from haptic_bus.errors import ParameterError

DONE_WHEN = ["check", "--mass", "0.032", "--friction", "3.62", "--period", "0.001", "--stiffness", "1500",
             "--damping", "0", "--velocity", "average", "--delay", "1", "--position-resolution", "5e-5"]
ISSUE_LOOP = WallLoop(0.032, 3.62, 1e-3, 1500.0, 0.0, 1, "average")
ISSUE_DELTA = 5e-5


def active(run: QuantisedRun) -> bool:
    """The operator's energy went below zero by more than its round-off."""
    return run.least_energy < -run.roundoff_bound()


def parked(loop: WallLoop, delta: float, samples: int, level: float = 0.5, damping: float | None = None) -> Hand:
    """A constant push ``level K Delta`` that parks the handle at an encoder level (started just
    below one, so that the push meets it at once), and a hand damping that takes out whatever
    motion the loop keeps up (default: the handle's own ``b``)."""
    return Hand((level * loop.K * delta,) * samples, 1, loop.b if damping is None else damping)


def search(loop: WallLoop, delta: float, coulomb: float, samples: int) -> list[Hand]:
    """The operator inputs of the passive side: parks at two levels with two hand dampings, a
    parked push with a dither of 2, 4 and 6 samples' period (the chatter across a level that
    the lagging force feeds), and the energy module's random tones around the park."""
    hands = [parked(loop, delta, samples), parked(loop, delta, samples, 1.5, 4.0 * loop.b)]
    swing = 2.0 * max(coulomb, loop.K * delta)
    for period in (2, 4, 6):
        hands.append(Hand(tuple(0.5 * loop.K * delta + swing * math.sin(2 * math.pi * k / period + 0.3)
                                for k in range(samples)), 1, loop.b))
    tones = RandomSinusoids(loop.T, seed=7, amplitude=swing)
    hands.append(Hand(tuple(0.5 * loop.K * delta + tones((np.arange(samples) + 0.5) * loop.T)), 1, loop.b))
    return hands


# --------------------------------------------------------------------------- the simulator itself


@pytest.mark.parametrize("velocity", ["point", "average", "window:0.0004"])
@pytest.mark.parametrize("delay", [0, 1, 0.4, 2.7])
def test_without_quantum_or_friction_the_simulator_is_the_energy_modules_exact_machine(velocity: str,
                                                                                       delay: float) -> None:
    """Closed forms per stretch here, matrix exponentials there (:mod:`haptic_bus.analysis.energy`):
    two exact computations of one loop under a constant 1 N push agree to round-off (1e-18 J
    measured against energies of 1e-3 J; asserted: 1e-12 relative)."""
    loop = WallLoop(0.5, 3.0, 1e-3, 2000.0, 5.0, delay, velocity)
    reference = simulate(loop, Constant(1.0), 300).energy[:-1]
    run = simulate_quantised(loop, Hand((1.0,) * 300), Quantiser(0.0))
    np.testing.assert_allclose(run.energy, reference, rtol=0.0, atol=1e-12 * np.abs(reference).max())


def test_a_sliding_handle_stops_where_coulomb_and_viscous_friction_say() -> None:
    """No wall: from the speed a push left it at, the handle stops after ``t = m/b ln(1 + b v0/f_c)`` at
    ``(m v0 - f_c t)/b`` further on (closed form; asserted to 1e-12 relative, the closed forms' round-off)."""
    loop, coulomb = WallLoop(0.4, 2.0, 1e-3, 0.0, 0.0, 0, "average"), 0.3
    pushed = simulate_quantised(loop, Hand((1.5,) * 101), Quantiser(0.0), coulomb)
    x0, v0 = pushed.position[100], pushed.velocity[100]  # the state at 100 T, when the push ends
    run = simulate_quantised(loop, Hand((1.5,) * 100 + (0.0,) * 1000), Quantiser(0.0), coulomb)
    stop = loop.m / loop.b * math.log1p(loop.b * v0 / coulomb)
    assert 0.1 < stop < 1.0 and run.velocity[-1] == 0.0
    assert run.position[-1] - x0 == pytest.approx((loop.m * v0 - coulomb * stop) / loop.b, rel=1e-12)


# --------------------------------------------------------------------------- the issue's numbers


def test_the_issue_wall_fails_without_coulomb_friction_and_exits_1_naming_the_condition(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*DONE_WHEN, "--coulomb", "0"]) == 1
    out = capsys.readouterr().out
    assert "verdict: NOT passive (the quantisation condition fails)" in out
    # K Delta/2 = 1500 * 5e-5 / 2 = 0.0375 N; per count of travel 0.0375 N * 5e-5 m = 1.875e-6 J
    assert "required K Delta/2 + B Delta/T = 0.0375 N" in out and "leak 1.875e-06 J per crossing" in out


def test_the_issue_wall_passes_with_a_tenth_of_a_newton(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*DONE_WHEN, "--coulomb", "0.1", "--json"]) == 0
    report = check_passivity(0.032, 3.62, 1e-3, 1500, 0, 1, "average", position_resolution=5e-5, coulomb=0.1)
    assert report.passive and report.quantisation is not None and report.quantisation.holds
    assert report.quantisation.required == pytest.approx(0.0375, rel=1e-15)  # one product and a halving


def test_the_limits_check_reports_are_the_quantisation_conditions_too(capsys: pytest.CaptureFixture[str]) -> None:
    # the exact criterion alone admits K up to 2413 N/m and B up to 3.47 N s/m on the issue's loop;
    # with f_c = 0.1 N and Delta = 5e-5 m, f_c >= K Delta/2 + B Delta/T caps K at 2 f_c/Delta = 4000 N/m
    # (the exact limit binds) and B at (f_c - K Delta/2) T/Delta = (0.1 - 0.0375)/0.05 = 1.25 N s/m
    report = check_passivity(0.032, 3.62, 1e-3, 1500, 0, 1, "average", position_resolution=5e-5, coulomb=0.1)
    unquantised = check_passivity(0.032, 3.62, 1e-3, 1500, 0, 1, "average")
    assert report.max_stiffness == unquantised.max_stiffness and report.max_damping == pytest.approx(1.25, rel=1e-12)
    assert report.damping_set.ends() == ((True, True),)  # f_c = required passes: the cap is in the set
    # f_c = 0.01 N: K up to 2 f_c/Delta = 400 N/m; no B at K = 1500 (the spring alone needs 0.0375 N)
    assert main([*DONE_WHEN, "--coulomb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert "passive K at this B: [0, 400] N/m; passive B at this K: none" in out
    # a spring that drifts (window velocity): only K = 0; B up to f_c TW/Delta = 0.1 * 5e-4 / 5e-5 = 1 N s/m
    window = check_passivity(0.032, 3.62, 1e-3, 0, 0, 1, "window:0.0005", position_resolution=5e-5, coulomb=0.1)
    assert window.stiffness_set.intervals == ((0.0, 0.0),) and window.max_damping == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize(("flag", "value", "allowed"), [
    ("--position-resolution", "nan", "[0, 1e+06] m"), ("--position-resolution", "-1e-5", "[0, 1e+06] m"),
    ("--coulomb", "-0.1", "[0, 1e+06] N"), ("--coulomb", "inf", "[0, 1e+06] N")])
def test_invalid_resolution_or_coulomb_is_one_line_and_exit_2(flag: str, value: str, allowed: str,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    argv = [a for a in DONE_WHEN if a not in ("--position-resolution", "5e-5")]
    assert main([*argv, f"{flag}={value}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{flag} = {value} is invalid; allowed: a finite real in {allowed}" in err


def test_without_coulomb_friction_the_issue_wall_keeps_a_limit_cycle_and_the_hand_takes_energy_out() -> None:
    hand = parked(ISSUE_LOOP, ISSUE_DELTA, 1500)
    run = simulate_quantised(ISSUE_LOOP, hand, Quantiser(ISSUE_DELTA), 0.0, start=0.999 * ISSUE_DELTA)
    assert active(run)
    tail = run.position[-500:]
    # the handle never sticks: it chatters across the level at Delta = 5e-5 m for ever
    assert tail.min() < ISSUE_DELTA < tail.max() and np.ptp(tail) > 0.1 * ISSUE_DELTA
    still = simulate_quantised(ISSUE_LOOP, hand, Quantiser(ISSUE_DELTA), 0.1, start=0.999 * ISSUE_DELTA)
    assert np.ptp(still.position[-500:]) == 0.0 and not active(still)  # parked: it sticks and stays


def test_with_a_tenth_of_a_newton_no_input_of_the_search_takes_energy_out() -> None:
    for hand in search(ISSUE_LOOP, ISSUE_DELTA, 0.1, 800):
        assert not active(simulate_quantised(ISSUE_LOOP, hand, Quantiser(ISSUE_DELTA), 0.1, start=0.999 * ISSUE_DELTA))


@pytest.mark.parametrize(("delay", "swing", "period"), [(0, 0.2, 2), (1, 0.06, 6)])
def test_with_a_damper_the_bound_is_nearly_needed(delay: int, swing: float, period: int) -> None:
    """B = 2 N s/m on the issue's wall needs K Delta/2 + B Delta/T = 0.0375 + 0.1 = 0.1375 N; at 0.13 N
    (95 % of it) a park at K Delta with a dither, found by a search over 324 such inputs, still takes
    energy out (the manual's quantisation page); at the bound it takes nothing."""
    loop = WallLoop(0.032, 3.62, 1e-3, 1500.0, 2.0, delay, "average")
    assert quantisation_condition(loop, Quantisation(ISSUE_DELTA, 0.13)).required == pytest.approx(0.1375)
    pushes = tuple(loop.K * ISSUE_DELTA + swing * math.sin(2 * math.pi * k / period + 0.3) for k in range(1200))
    hand, start = Hand(pushes, 1, 16.0), 0.999 * ISSUE_DELTA
    assert active(simulate_quantised(loop, hand, Quantiser(ISSUE_DELTA), 0.13, start=start))
    assert not active(simulate_quantised(loop, hand, Quantiser(ISSUE_DELTA), 0.1375, start=start))  # at the bound


# --------------------------------------------------------------------------- 50 random designs


def _design(rng: np.random.Generator) -> WallLoop:
    """A linear-passive ``average`` wall (margin > 5 % of b), half of them without a damper."""
    while True:
        m = math.exp(rng.uniform(math.log(0.03), math.log(1.0)))
        b = math.exp(rng.uniform(math.log(0.5), math.log(20.0)))
        T = float(rng.choice([5e-4, 1e-3, 2e-3]))
        delay = float(rng.choice([0.0, 1.0, 2.0, rng.uniform(0.0, 2.0)]))
        K = rng.uniform(0.1, 0.8) * b / ((delay + 0.5) * T)  # inside K <= b/tau_eff (DESIGN 3.5), checked below
        B = 0.0 if rng.random() < 0.5 else rng.uniform(0.0, 0.5) * b
        loop = WallLoop(m, b, T, K, B, delay, "average")
        if exact_verdict(loop).margin > 0.05 * b:
            return loop


def test_the_condition_agrees_with_the_exact_simulation_on_50_random_quantised_designs() -> None:
    """Active draws take ``f_c`` in [0, 0.7] K Delta/2 and must be found active by a parked push;
    passive draws take ``f_c`` in [1, 3] times the condition's requirement and no input of the search
    may take energy out.  Excluded: (0.7, 1) K Delta/2, where the relay's net force K Delta/2 - f_c
    -> 0 and the energy the hand takes per second falls with it (at 0.93 K Delta/2 on the issue's
    wall, 1e-7 W: more than 10 s to beat the energy a park stores, where 1500 samples are run;
    the passive side runs 500 samples for each of its inputs);
    and with a damper, (K Delta/2, K Delta/2 + B Delta/T), where the condition is sufficient, not
    shown necessary (the manual's quantisation page gives the numbers)."""
    rng = np.random.default_rng(27)
    outcomes = []
    for _ in range(50):
        loop = _design(rng)
        delta = math.exp(rng.uniform(math.log(1e-6), math.log(1e-4)))
        needed = quantisation_condition(loop, Quantisation(delta, 0.0)).required
        expect_active = rng.random() < 0.5
        coulomb = rng.uniform(0.0, 0.7) * loop.K * delta / 2 if expect_active else rng.uniform(1.0, 3.0) * needed
        holds = quantisation_condition(loop, Quantisation(delta, coulomb)).holds
        assert holds is not expect_active
        hands = [parked(loop, delta, 1500)] if expect_active else search(loop, delta, coulomb, 500)
        found = any(active(simulate_quantised(loop, hand, Quantiser(delta), coulomb, start=0.999 * delta))
                    for hand in hands)
        assert found is expect_active, (loop, delta, coulomb)
        outcomes.append(expect_active)
    assert 15 <= sum(outcomes) <= 35  # both sides well represented


# --------------------------------------------------------------------------- the other velocity models


def test_a_point_velocity_quantum_makes_the_wall_drift_and_a_creep_cycle_leaks() -> None:
    """Push in by A, then creep out slower than vq/2: 0x606C reads 0, and the wall keeps pushing with
    its full K A all the way out.  The push stores about K A^2/2 + f_c A (plus the handle's own
    viscous loss); the creep hands back (K A - f_c) A: at K = 1500 N/m, f_c = 0.1 N, A = 1 mm the
    operator ends near 0.99e-3 - 1.45e-3 = -0.46e-3 J: Coulomb friction only sets the depth A > 4 f_c/K that leaks."""
    loop, vq, coulomb = WallLoop(0.032, 3.62, 1e-3, 1500.0, 0.0, 0, "point"), 1e-3, 0.1
    condition = quantisation_condition(loop, Quantisation(0.0, coulomb, vq))
    assert condition.kind == DRIFT and not condition.holds and math.isinf(condition.required)
    creep, hand_damping = 0.3 * vq, 50.0  # m/s; N s/m: the hand holds the creep speed against the wall
    push = (1.6,) * 300
    pushed = simulate_quantised(loop, Hand(push, 1, hand_damping), Quantiser(0.0, vq), coulomb)
    depth, wall = pushed.position[-1], pushed.wall_force[-1]
    # at rest near (1.6 - f_c)/K = 1 mm: the wall's K x_k balances the push, and x_k already drifted from
    # the true depth on the way in (a few hundred samples rounded to 1e-3 m/s: 6 % here)
    assert depth == pytest.approx(1e-3, rel=0.1)
    creep_push = wall - coulomb - (loop.b + hand_damping) * creep  # a steady creep out at -0.3 vq
    samples = int(depth / (creep * loop.T))
    run = simulate_quantised(loop, Hand(push + (creep_push,) * samples, 1, hand_damping), Quantiser(0.0, vq), coulomb)
    assert run.wall_force[-1] == wall  # the wall never saw the creep
    travel = depth - run.position[-1]
    assert travel == pytest.approx(depth, rel=0.01)  # 1 % of the creep's time is its start-up transient
    # the handle's own viscous loss b v travel is 1.2e-6 J (the hand's c v^2 is its own): 0.1 % of what the wall hands back
    assert run.energy[-1] - pushed.energy[-1] == pytest.approx(-(wall - coulomb) * travel, rel=0.02)
    assert run.energy[-1] < -4e-4


def test_the_drift_repeats_with_the_wall_back_where_it_was() -> None:
    """A point velocity rounded to vq = 5 mm/s; each cycle, with a hand damping of 50 N s/m holding
    the speeds: creep in by A = 0.6 mm at 0.3 vq (unseen), push in by A at 4 vq (seen), creep out
    unseen, pull out seen.  The wall's force and the handle come back where they were, and the
    operator's energy falls each time by K A^2 - 4 f_c A - 2 b A (v_seen + v_creep)
    = 5.4e-4 - 2.4e-4 - 0.87e-4 - 0.07e-4 = 2.07e-4 J (measured 1.8e-4 and 1.95e-4: the open-loop
    pushes start and stop each move a little short of A; asserted within 20 %)."""
    loop, vq, coulomb, hand_damping = WallLoop(0.032, 3.62, 1e-3, 1500.0, 0.0, 0, "point"), 5e-3, 0.1, 50.0
    depth, creep, seen = 0.6e-3, 0.3 * vq, 4 * vq  # m, m/s, m/s
    drag = loop.b + hand_damping  # N s/m: the push that holds a speed, beside the wall and Coulomb

    def now(pushes: list[float]) -> tuple[float, float, float]:
        """(x, u, E) after ``pushes``, one push per period."""
        run = simulate_quantised(loop, Hand((*pushes, pushes[-1]), 1, hand_damping), Quantiser(0.0, vq), coulomb)
        n = len(pushes)
        return run.position[n], run.wall_force[n], run.energy[n]

    pushes = [1.0] * 200  # at rest near (1 - f_c)/K = 0.6 mm
    marks = [now(pushes)]
    for _ in range(2):
        for direction in (1, -1):
            u = now(pushes)[1]
            pushes += [u + direction * (coulomb + drag * creep)] * round(depth / (creep * loop.T))  # unseen
            u = now(pushes)[1]
            pushes += [u + direction * (loop.K * seen * loop.T * k + coulomb + drag * seen)
                       for k in range(round(depth / (seen * loop.T)))]  # seen
        marks.append(now(pushes))
    predicted = loop.K * depth**2 - 4 * coulomb * depth - 2 * loop.b * depth * (seen + creep)
    assert marks[0][1] == marks[1][1] == marks[2][1]  # the wall's force back to the same count every time
    assert marks[2][0] == pytest.approx(marks[1][0], rel=1e-3)  # the second cycle ends where the first did
    for (_, _, before), (_, _, after) in itertools.pairwise(marks):
        assert before - after == pytest.approx(predicted, rel=0.2)


def test_a_window_velocity_misses_counts_outside_its_window_and_a_steady_creep_leaks() -> None:
    """``window:0.000125`` at T = 1 ms sees a count change only in the last eighth of a period.  Push
    in to about 0.95 mm, stop, then creep out with a constant push at one count (5 um) every 4 periods,
    timed so that every crossing falls 0.4 T into a period: a force far below Nyquist, and the wall
    never sees one of the ~190 counts.  It holds 1.2 N all the way out: the operator's energy falls
    from +5.0e-4 J to -5.3e-4 J (the creep hands back (1.2 - f_c) N over 0.94 mm)."""
    loop = WallLoop(0.032, 3.62, 1e-3, 1500.0, 0.0, 1, "window:0.000125")
    delta, coulomb, hand_damping, steps = 5e-6, 0.1, 2000.0, 16  # m, N, N s/m, pushes per period
    assert quantisation_condition(loop, Quantisation(delta, coulomb)).kind == DRIFT
    push_in = (10.0,) * (200 * steps)
    wall = simulate_quantised(loop, Hand(push_in + (10.0,) * steps, steps, hand_damping),
                              Quantiser(delta), coulomb).wall_force[200]
    hold = (wall,) * (2 * steps)  # the push equals the wall force: the handle stops and sticks
    held = simulate_quantised(loop, Hand(push_in + hold + (wall,) * steps, steps, hand_damping), Quantiser(delta),
                              coulomb)
    x = held.position[202]
    speed = delta / (4 * loop.T)  # m/s: one count every 4 periods
    first_crossing = (x - delta * math.floor(x / delta)) / speed  # s after the creep starts
    wait = round(((0.4 * loop.T - first_crossing) % loop.T) / (loop.T / steps))  # pushes of T/16 held still
    samples = 4 * round(x / delta)  # periods to creep back to about 0
    creep = wall - coulomb - (loop.b + hand_damping) * speed  # a steady slide out at `speed`
    pushes = push_in + hold + (wall,) * wait + (creep,) * (samples * steps - wait)
    run = simulate_quantised(loop, Hand(pushes, steps, hand_damping), Quantiser(delta), coulomb)
    assert np.all(run.wall_force[202:] == wall)  # not one count seen
    travel = x - run.position[-1]
    assert travel == pytest.approx(x, rel=0.02)  # back to within one count of the start
    # the handle's own viscous loss b v travel is 4.3e-6 J (the hand's c v^2 is its own): 0.4 % of what the wall hands back
    assert run.energy[-1] - held.energy[202] == pytest.approx(-(wall - coulomb) * travel, rel=0.01)
    assert run.energy[-1] < -4e-4


def test_which_quantum_enters_each_velocity_model() -> None:
    q = Quantisation(2e-5, 0.05, 1e-4)
    average = quantisation_condition(WallLoop(1, 20, 1e-3, 1000, 4, 1, "average"), q)
    assert average.kind == CROSSING and average.required == pytest.approx(1000 * 2e-5 / 2 + 4 * 2e-5 / 1e-3)
    window = quantisation_condition(WallLoop(1, 20, 1e-3, 1000, 4, 1, "window:0.0005"), q)
    assert window.kind == DRIFT
    damper = quantisation_condition(WallLoop(1, 20, 1e-3, 0, 4, 1, "window:0.0005"), q)
    assert damper.kind == CROSSING and damper.required == pytest.approx(4 * 2e-5 / 5e-4)  # B Delta/TW
    lowpass = quantisation_condition(WallLoop(1, 20, 1e-3, 0, 4, 1, "lowpass:0.002"), q)
    assert lowpass.required == pytest.approx(4 * 1e-4 / 2)  # B vq/2
    rounded = quantisation_condition(WallLoop(1, 20, 3e-4, 1000, 4, 1, "average"), q)  # 2e-5/(3e-4 1e-4) = 666.7
    assert rounded.kind == DRIFT and "not whole" in rounded.describe()
    unquantised = quantisation_condition(WallLoop(1, 20, 1e-3, 1000, 4, 1, "point"), Quantisation(2e-5, 0.0))
    assert unquantised.kind == EXACT and unquantised.holds  # the encoder does not enter a point velocity's wall


def test_quantiser_and_hand_refuse_values_out_of_range() -> None:
    with pytest.raises(ParameterError, match="position_resolution"):
        Quantiser(float("nan"))
    with pytest.raises(ParameterError, match="coulomb"):
        Quantisation(1e-5, -0.1)
    with pytest.raises(ParameterError, match="pushes"):
        Hand((1.0, 2.0, 3.0), substeps=2)
