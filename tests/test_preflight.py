"""Pre-flight's verdict on measured timing: held, held by the layer, or refused with the T that holds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from haptic_bus.app.preflight import (
    LOOK_AGAIN,
    PERIOD_GRID,
    PREFLIGHT_CYCLES,
    STALL_MARGIN,
    Timing,
    allowed_overruns,
    catch_up_overruns,
    judge,
    judge_delay,
    looks_again,
    looks_for,
    measure,
    without_realtime,
)
from haptic_bus.app.profiles import load_profile
from haptic_bus.errors import DriveTimeout

T = 1e-3


def timing(lateness: np.ndarray, exchange: float = 100e-6, gap_at: int | None = None, gap: float = 0.0) -> Timing:
    """Cycles due every T with the given lateness; one extra gap of ``gap`` s before cycle ``gap_at``."""
    starts = np.arange(lateness.size) * T + lateness
    if gap_at is not None:
        starts[gap_at:] += gap
        lateness = lateness.copy()
        lateness[gap_at] += gap
    return Timing(T, lateness, starts, np.full(lateness.size, exchange), int(np.sum(lateness > T)))


def test_a_quiet_machine_is_judged_at_its_measured_delay() -> None:
    profile = load_profile("cia402-handle")
    late = np.full(500, 20e-6)
    late[::50] = 300e-6  # 2 % of the cycles: p99 = 300 us
    report = judge(timing(late), profile.gate(), profile.compiled_scene(), "guard", 0.020, 20)
    assert report.holdable and report.passive_at_observed
    assert report.observed_delay == pytest.approx(1.0 + 0.3, rel=1e-9)
    assert report.lateness["p99"] == pytest.approx(300e-6)
    assert "passes the scene" in report.reason


def test_a_stall_that_would_trip_the_rpdo_deadline_refuses_naming_the_period_that_holds_it() -> None:
    """A 4 ms stall: its catch-up (0.1 ms exchanges) makes 4 cycles start more than T late, within the 5 of 500
    allowed, but the gap it leaves between two cycles (5 ms), x1.5, reaches an RPDO deadline of 5 periods (5 ms):
    refused, naming the T whose deadline holds it: 1.5 x 5 ms / 5 = 1.5 ms reaches it too (5 periods of 1.5 ms,
    7.5 ms: refused, judged again at it), so the next on the 0.25 ms grid, 1.75 ms."""
    profile = load_profile("cia402-handle")
    report = judge(timing(np.zeros(500), gap_at=250, gap=4e-3), profile.gate(), profile.compiled_scene(), "guard", 0.005, 5)
    assert not report.holdable and report.overruns == 1 and report.busy_over_period == 1
    assert report.longest_gap == pytest.approx(5e-3)
    expected = np.floor(STALL_MARGIN * 5e-3 / 5 / PERIOD_GRID + 1) * PERIOD_GRID  # strictly above 1.5 ms
    assert report.smallest_period == pytest.approx(expected) and expected == pytest.approx(1.75e-3)
    assert "this machine holds T >= 1.75 ms" in report.reason and "a gap of 5 ms" in report.reason


def test_a_machine_slower_than_the_period_refuses() -> None:
    profile = load_profile("cia402-handle")
    k = np.arange(500)
    behind = Timing(T, k * 1e-3, k * 2e-3, np.full(500, 2e-3), 499)  # each cycle starts when the last one ends
    report = judge(behind, profile.gate(), profile.compiled_scene(), "guard", 0.020, 20)
    assert not report.holdable and report.smallest_period == pytest.approx(2e-3)  # its 2 ms busy, not the growing lateness
    assert "more than T = 1 ms" in report.reason


def test_lateness_the_gate_cannot_cover_is_held_by_the_layer_and_refused_without_it() -> None:
    profile = load_profile("stiff-wall")  # passive at D = 1 with a small margin, not at D = 1.2
    late = np.full(500, 550e-6)  # busy 0.65 ms a cycle with the 0.1 ms exchange: x1.5 within T
    covered = judge(timing(late), profile.gate(), profile.compiled_scene(), "guard", 0.050, 50)
    assert covered.holdable and not covered.passive_at_observed and "layer (guard) holds" in covered.reason
    bare = judge(timing(late), profile.gate(), profile.compiled_scene(), "off", 0.050, 50)
    assert not bare.holdable and 'layer = "off"' in bare.reason


def test_a_period_shorter_than_the_one_named_is_refused_naming_it() -> None:
    """6 of 500 cycles (1.2 %) are busy 1.2 ms (1.1 ms late + 0.1 ms exchange): one more than the 5 a
    machine overrunning in 0.5 % of its cycles shows at 95 %, so the period named is the sixth
    longest busy time, 1.2 ms, up to the 0.25 ms grid = 1.25 ms, and T = 1 ms is refused: the
    period named and the verdict agree."""
    profile = load_profile("cia402-handle")
    late = np.full(500, 20e-6)
    late[::84] = 1.1e-3  # cycles 0, 84, ..., 420: six
    report = judge(timing(late), profile.gate(), profile.compiled_scene(), "guard", 0.050, 50)
    assert report.overruns == 6 and not report.holdable
    assert report.smallest_period == pytest.approx(1.25e-3)
    assert report.reason.startswith("refused: 6 of 500 cycles were busy (late start plus exchange) longer than "
                                    "T = 1 ms, the longest 1.2 ms: more than 0.5% of a run's cycles would overrun "
                                    "(at most 5 of 500 at 95% confidence)")
    assert report.reason.endswith("this machine holds T >= 1.25 ms")


@pytest.mark.parametrize(("overlong", "named"), [(2, 0.5e-3), (5, 0.75e-3)])
def test_late_cycles_a_machine_at_the_overrun_target_shows_are_held_at_the_period_the_rest_name(overlong: int,
                                                                                             named: float) -> None:
    """2 or 5 of 500 cycles (0.4 %, 1 %) a period late are what a machine overrunning in 0.5 % of its
    cycles shows in 95 % of pre-flights (up to 5), so T = 1 ms is held: the supervisor and the passivity
    layer cover stalls that rare at run time.  (The 99.5th percentile refused 5: a machine at the target,
    one pre-flight in four.)  The period named is the shortest at which these stalls' catch-ups keep within
    the 5 allowed: each 1.1 ms stall (0.1 ms exchanges, 20 us late otherwise) makes 7 cycles late at
    0.25 ms (the rest's busy 120 us alone named it), 2 at 0.5 ms, 1 at 0.75 ms."""
    profile = load_profile("cia402-handle")
    late = np.full(500, 20e-6)
    late[: 100 * overlong : 100] = 1.1e-3
    report = judge(timing(late), profile.gate(), profile.compiled_scene(), "guard", 0.050, 50)
    assert report.overruns == overlong and report.holdable
    assert report.smallest_period == pytest.approx(named)


@pytest.mark.parametrize("cycles", [1, 50, 200, 500, 2000])
def test_the_overruns_allowed_are_the_95_percent_quantile_of_a_machine_at_the_target(cycles: int) -> None:
    """The count allowed is scipy's binomial quantile (exact integers: no tolerance)."""
    from scipy.stats import binom

    allowed = allowed_overruns(cycles)
    assert allowed == int(binom.ppf(0.95, cycles, 0.005))
    assert binom.sf(allowed, cycles, 0.005) <= 0.05  # more than allowed: 5 % of such pre-flights at most
    assert allowed == 0 or binom.sf(allowed - 1, cycles, 0.005) > 0.05  # and the smallest such count


def test_a_refusal_says_when_real_time_scheduling_was_not_granted() -> None:
    """A machine refused at pre-flight whose control thread could not get SCHED_FIFO (an ordinary
    user: no CAP_SYS_NICE, no RLIMIT_RTPRIO) is told so in the refusal's one line; a held run, or one
    that had it, is left as it was."""
    profile = load_profile("cia402-handle")
    late = np.full(500, 20e-6)
    late[::84] = 1.1e-3
    refused = judge(timing(late), profile.gate(), profile.compiled_scene(), "guard", 0.050, 50)
    why = "[Errno 1] Operation not permitted (needs CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least 80)"
    said = without_realtime(refused, {"got": {}, "missing": {"SCHED_FIFO": why}})
    assert said.reason == f"{refused.reason} (without real-time scheduling: {why})" and "\n" not in said.reason
    assert without_realtime(refused, {"got": {"SCHED_FIFO": "priority 80"}, "missing": {}}) == refused
    held = judge(timing(np.full(500, 20e-6)), profile.gate(), profile.compiled_scene(), "guard", 0.050, 50)
    assert without_realtime(held, {"missing": {"SCHED_FIFO": why}}) == held


def test_a_drive_that_stops_answering_during_pre_flight_is_said_to_have_answered_first() -> None:
    # the exchange pre-flight times: five cycles answered, then the drive's silence (the master's own
    # DriveTimeout); from the control process a stalled drive process looks the same, and it says so
    answered = []

    def exchange() -> None:
        if len(answered) == 5:
            raise DriveTimeout("CANopen node 5", "no TPDO (COB-ID 0x185) for 3 consecutive cycles (timeout 50 ms each)")
        answered.append(True)

    with pytest.raises(DriveTimeout) as silent:
        measure(exchange, T, (20,))
    assert str(silent.value) == ("CANopen node 5: no TPDO (COB-ID 0x185) for 3 consecutive cycles (timeout 50 ms each), "
                                 "after answering 5 of pre-flight's 20 cycles (nothing enabled): a drive that stops "
                                 "answering and a machine that stalls the drive's process look the same from here")


def test_a_drive_that_never_answers_in_pre_flight_keeps_its_own_words() -> None:
    def exchange() -> None:
        raise DriveTimeout("CANopen node 5", "no TPDO (COB-ID 0x185) for 3 consecutive cycles (timeout 50 ms each)")

    with pytest.raises(DriveTimeout, match=r"^CANopen node 5: no TPDO \(COB-ID 0x185\) for 3 consecutive cycles "
                                           r"\(timeout 50 ms each\)$"):
        measure(exchange, T, (20,))


def test_a_stall_adds_one_late_cycle_to_the_delay_and_its_catch_up_to_the_overruns() -> None:
    """One 8 ms stall in 500 cycles, then the loop catching up (each cycle starting as the one before
    ends, 0.4 ms exchanges, as this machine's udp_multicast has them at p99): the start lateness
    falls by 0.6 ms a cycle, 8, 7.4, ... ms, fourteen cycles of it, so its p99 is over 4 ms; but only
    the stalled cycle started late of its own accord (the bench's section 11 judged such a run at
    5.5 samples).  Judged at the delay each cycle adds, 20 us (the stall alone is 1 of 500, above
    the p99): 1.02 samples.  The overruns count the catch-up: 12 cycles started more than T late, more
    than the 5 of 500 a machine at the target shows (one cycle busy longer than T did not say so), so T =
    1 ms is refused, naming 1.75 ms, where the same stall makes 5 late (at 1.5 ms, 6)."""
    profile = load_profile("cia402-handle")
    exchange = 400e-6
    late = np.full(500, 20e-6)
    catch_up, k = 8e-3, 200
    while catch_up > 20e-6:  # cycle k starts when cycle k - 1 ends, until it is on time again
        late[k] = catch_up
        catch_up -= T - exchange
        k += 1
    report = judge(timing(late, exchange), profile.gate(), profile.compiled_scene(), "guard", 0.050, 50)
    assert k - 200 == 14 and report.lateness["p99"] > 4e-3
    assert report.delay_added_p99 == pytest.approx(20e-6, abs=1e-12)
    assert report.observed_delay == pytest.approx(1.02, abs=1e-9)
    assert report.busy_over_period == 1 and report.overruns == 12 and not report.holdable
    assert report.reason.startswith("refused: 12 of 500 cycles would start more than T = 1 ms late, replayed, catching "
                                    "up after the "
                                    "longest busy cycle (8.4 ms) at 0.6 ms a cycle (an exchange takes 0.4 ms, median)")
    assert report.smallest_period == pytest.approx(1.75e-3) and report.reason.endswith("this machine holds T >= 1.75 ms")


def test_a_cycle_held_up_inside_its_exchange_adds_the_delay_to_the_next() -> None:
    """Six exchanges of 8 ms (waiting for the drive, or stalled there) in 500 cycles: each next cycle
    starts when it ends, its own lateness none, but 7 ms more than T after the cycle before began:
    the drive held that torque 8 ms.  The delay each cycle adds counts it (p99 7 ms: 8 samples);
    the busy cycles refuse T anyway (six of 500, five allowed), and the delay is recorded."""
    profile = load_profile("cia402-handle")
    exchange = np.full(500, 100e-6)
    exchange[50::80] = 8e-3  # cycles 50, 130, ..., 450: six
    starts = np.zeros(500)
    for k in range(1, 500):  # each cycle at its deadline, or when the one before ends
        starts[k] = max(k * T, starts[k - 1] + exchange[k - 1])
    lateness = starts - np.arange(500) * T
    report = judge(Timing(T, lateness, starts, exchange, int(np.sum(lateness > T))), profile.gate(),
                   profile.compiled_scene(), "guard", 0.050, 50)
    assert report.delay_added_p99 == pytest.approx(7e-3, rel=1e-9)
    assert report.observed_delay == pytest.approx(8.0, rel=1e-9)
    assert not report.holdable and report.busy_over_period == 6


def test_a_target_applied_on_arrival_is_judged_at_least_an_exchange_late() -> None:
    """desktop-touch's "ideal" timing: the drive applies a target as its RPDO arrives, an exchange
    (here 0.6 ms, SYNC out to RPDO out) after it sampled, so the gate's 0 samples become at least
    0.6 (breaker14: an "ideal" wall passive only below 0.1 samples, without a layer, ran at a judged
    0.009 samples while its exchanges took 0.3-0.67 ms).  A "cia402" drive applies it at the next
    SYNC whatever the exchange: its delay stays the gate's."""
    asked: list[float] = []

    def passes_at(delay: float) -> bool:
        asked.append(delay)
        return True

    late = np.full(500, 20e-6)
    on_arrival = judge_delay(timing(late, exchange=600e-6), 0.0, passes_at, "guard", 0.050, 50, on_arrival=True)
    assert on_arrival.observed_delay == pytest.approx(0.6 + 0.02, abs=1e-9) and asked == [on_arrival.observed_delay]
    at_sync = judge_delay(timing(late, exchange=600e-6), 1.0, passes_at, "guard", 0.050, 50)
    assert at_sync.observed_delay == pytest.approx(1.02, abs=1e-9)
    assert load_profile("desktop-touch").loop.timing == "ideal"  # the shipped profile such a run would load


def _stall_of(stall: float, cycles: int) -> Timing:
    """``cycles`` cycles due every T, 20 us late, 0.6 ms exchanges; cycle 250 held up ``stall`` s in its
    exchange, the ones after it starting as the one before ends until the loop has caught up."""
    exchange = np.full(cycles, 600e-6)
    exchange[250] = stall
    return _looped(exchange)


def test_one_stall_in_the_first_look_is_judged_again_over_four_times_the_cycles() -> None:
    """One stall of 4 ms: in 500 cycles its catch-up (0.4 ms a cycle) starts 6 of them more than T late, over
    the 5 allowed (so the first look alone refused T: 1 of 20 fresh pre-flights here); in the 2000 of the second
    look the same 6 are under the 15 allowed, and T is held.  Four such stalls in 2000 (24 late) are not; three
    in the first 500 (18 late) are over the 2000's allowance already: no second look."""
    first = _stall_of(4e-3, PREFLIGHT_CYCLES)
    assert catch_up_overruns(first, np.array([T]))[0] == 6
    assert not judge_delay(first, 1.0, lambda delay: True, "guard", 0.030, 30).holdable
    assert allowed_overruns(PREFLIGHT_CYCLES) == 5 and allowed_overruns((1 + LOOK_AGAIN) * PREFLIGHT_CYCLES) == 15
    assert looks_again(first, LOOK_AGAIN * PREFLIGHT_CYCLES)
    second = _stall_of(4e-3, (1 + LOOK_AGAIN) * PREFLIGHT_CYCLES)
    report = judge_delay(dataclasses.replace(second, earlier_looks=(PREFLIGHT_CYCLES,)), 1.0, lambda delay: True,
                         "guard", 0.030, 30)
    assert report.holdable and report.cycles == 2000 and report.smallest_period == T
    assert report.earlier_looks == (500,)
    assert report.line().startswith("pre-flight: 2000 cycles (500, then 1500 more: the first alone would have refused "
                                    "T) at T = 1 ms, no torque: ")
    stalls = second.exchange.copy()
    stalls[[250, 750, 1250, 1750]] = 4e-3
    assert not judge_delay(_looped(stalls), 1.0, lambda delay: True, "guard", 0.030, 30).holdable
    three = first.exchange.copy()
    three[[100, 250, 400]] = 4e-3
    assert catch_up_overruns(_looped(three), np.array([T]))[0] == 18 and not looks_again(_looped(three), 1500)


def test_one_stall_of_10_ms_is_held_on_the_third_look_over_8000_cycles() -> None:
    """A stall of 10 ms (this virtual machine's stalls of 10-26 ms refused 9 of 60 fresh pre-flights after their
    second look on December 7, docs/process.md): its catch-up (0.4 ms a cycle) starts 21 cycles more than T late,
    over the 15 allowed in 2000 and within the 51 of 8000, where T is held; the line names each look. Three such
    stalls in 8000 (63 late) are not held."""
    assert looks_for(PREFLIGHT_CYCLES) == (500, 2000, 8000) and allowed_overruns(8000) == 51
    second = _stall_of(10e-3, 2000)
    assert catch_up_overruns(second, np.array([T]))[0] == 21 and looks_again(second, 6000)
    third = _stall_of(10e-3, 8000)
    report = judge_delay(dataclasses.replace(third, earlier_looks=(500, 2000)), 1.0, lambda delay: True, "guard",
                         0.030, 30)
    assert report.holdable and report.cycles == 8000 and report.smallest_period == T
    assert report.line().startswith("pre-flight: 8000 cycles (500, then 1500 more, then 6000 more: each look before "
                                    "the last would have refused T) at T = 1 ms, no torque: ")
    stalls = third.exchange.copy()
    stalls[[2250, 4250]] = 10e-3
    assert catch_up_overruns(_looped(stalls), np.array([T]))[0] == 63
    assert not judge_delay(_looped(stalls), 1.0, lambda delay: True, "guard", 0.030, 30).holdable


def _looped(exchange: np.ndarray) -> Timing:
    """Cycles due every T with the exchanges ``exchange`` (s), each starting 20 us late or as the one before
    ends, whichever is later (the loop catching up)."""
    starts, late, end = np.zeros(exchange.size), np.zeros(exchange.size), -np.inf
    for k in range(exchange.size):
        starts[k] = max(k * T + 20e-6, end)
        late[k] = starts[k] - k * T
        end = starts[k] + exchange[k]
    return Timing(T, late, starts, exchange, int(np.sum(late > T)))


@pytest.mark.parametrize(("refusing", "measured", "asked"), [(0, 20, [(20, 60)]), (1, 80, [(20, 60), (80, 240)]),
                                                           (2, 320, [(20, 60), (80, 240)])])
def test_the_cycles_go_on_only_while_the_looks_so_far_would_refuse(monkeypatch: pytest.MonkeyPatch, refusing: int,
                                                                   measured: int, asked: list[tuple[int, int]]) -> None:
    """The decision is the period rule's on the cycles so far (``looks_again``, here as given: the first
    ``refusing`` looks would refuse); each next look's cycles go on from there, three looks at most, one timing of
    them all, which says where each earlier look ended."""
    import haptic_bus.app.preflight as preflight

    looked: list[tuple[int, int]] = []

    def rule(timing: Timing, again: int) -> bool:
        looked.append((timing.exchange.size, again))
        return len(looked) <= refusing

    monkeypatch.setattr(preflight, "looks_again", rule)
    calls: list[None] = []
    timing = measure(lambda: calls.append(None), T, looks_for(20))
    assert looks_for(20) == (20, 80, 320) and looked == asked and len(calls) == measured
    assert timing.lateness.size == timing.starts.size == timing.exchange.size == measured
    assert timing.earlier_looks == looks_for(20)[:refusing]
