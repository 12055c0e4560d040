"""Pre-flight timing: how late this machine runs the loop on this bus, measured before enabling.

A real-time run's verdict depends on timing the gate cannot see.  Before the drive is enabled
the run cycles a few hundred times with SYNC running (CANopen: SYNC, the drive's TPDO, an RPDO
with the held controlword and zero torque; Modbus: the same read and write), paced by the real
clock under the run's own scheduling, and keeps how late each cycle started.  Then it judges:

* **the period** -- a cycle's busy time is its exchange with the drive plus how late it started
  after it could have (its deadline, or the end of the cycle before).  A run may overrun in
  :data:`OVERRUN_SHARE` of its cycles (each makes the next cycles late).  Pre-flight's few hundred
  cycles estimate that share roughly (binomial counts): a machine overrunning in exactly 0.5 % of
  its cycles shows 4 or more of 500 busy longer than ``T`` in 24 % of pre-flights, and a point
  estimate (the busy time's 99.5th percentile) refused it then.  ``T`` is refused only when the
  count measured is more than such a machine shows in :data:`CONFIDENCE` of pre-flights
  (:func:`allowed_overruns`: 5 of 500): the share is then above the target with that confidence.
  The price of 500 cycles: a machine overrunning in 1 % of its cycles is held in 62 % of
  pre-flights; the run's supervisor watches its lateness (``on_late``) from there.  A look
  that would refuse ``T`` looks again: the cycles go on, :data:`LOOK_AGAIN` times as many more, and
  the verdict is on them all, up to :data:`LOOKS` looks (:func:`looks_for`: 500, 2000 with 15
  allowed, 8000 with 51).  The cycles a stall makes late come together, so 500 are few to tell a rare
  stall from a frequent one: one stall of the host, 4 ms in 0.5 s, made 7 cycles start late at
  T = 1 ms and refused 1 of 20 fresh pre-flights here, while 20 s runs on the same machine overran in
  0.05-0.1 % of their cycles; and 2000 are few for the stalls of 10-26 ms this virtual machine meets
  every few seconds, each making 10-30 cycles late (on December 7, 9 of 60 fresh pre-flights were
  refused so after their second look): the third look's 8000 take up to two of them.  A stall
  also makes the cycles after it late while the loop catches up, ``S / (T - x)`` of them for a
  stall ``S`` and exchanges ``x``: few at T = 1 ms and 0.2 ms exchanges, many where the exchange
  nearly fills ``T`` (a Modbus run of three units at T = 2 ms, 1.8 ms polls, passed a pre-flight
  that counted busy cycles alone and overran in 40 of 500 cycles), so the cycles that would start
  more than ``T`` late, the measured cycles replayed through the deadline scheduler
  (:func:`catch_up_overruns`), are held to the same count.  The smallest ``T`` on a
  :data:`PERIOD_GRID` grid that holds both counts (or the profile's own ``T``, off the grid, when
  it holds and is shorter, :func:`held_period`), and none the bus cannot carry (CANopen's load
  ceiling) nor one whose watchdog a stall measured would trip, is the period this machine holds for
  this bus (CANopen's SYNC cycle or the Modbus poll), named in every verdict; ``run.json`` keeps the
  counts.  A median
  exchange longer than ``T`` (the loop would fall further behind every cycle), or a profile's
  ``T`` shorter than the period named, refuses the run (exit 1, nothing enabled): the period
  named and the verdict never disagree;
* **the watchdogs** -- a cycle held up longer than the drive's receive watchdog (the RPDO
  deadline, the heartbeat consumer's slack, the Modbus watchdog) faults the drive.  If the
  longest stall measured, times :data:`STALL_MARGIN`, reaches it, the run is refused, naming the
  smallest period ``T`` whose watchdog (a deadline counted in periods, as the drive keeps it, whole ms)
  would stay above that gap (at a longer ``T``, the stall in it as long and its period longer), or none
  where a watchdog that a longer ``T`` does not lengthen (the heartbeat consumer's slack, the Modbus
  watchdog) binds first; every period named, a held run's too, is one whose watchdog holds the gap
  (:func:`_holding_stall`);
* **the gate at the measured delay** -- the loop delay the gate assumed plus the p99 of the delay
  each cycle adds, in samples (:func:`delay_added`): the larger of its own lateness (how late it
  started after it could have: its deadline, or the end of the cycle before when that ran past
  it) and how much longer than ``T`` after the cycle before's start it began (a cycle held up
  inside its exchange starts the next one late: the drive held that torque longer).  After a
  stall of ``S`` the loop catches up, its next cycles each starting as the one before ends: their
  start lateness falls from ``S`` by ``T`` less one exchange a cycle, but each samples fresh and
  its torque goes out at the next SYNC an exchange later, sooner than ``T``.  Only the stalled
  cycle's torque came late; the start lateness's p99 counted the whole catch-up (the catch-up of
  one stall of the host left a start lateness p99 of 4.47 ms in 500 cycles, judged a loop delay
  of 5.47 samples where the drive's is 1).  A drive that applies its target as it arrives ("ideal"
  or "reception" timing, :data:`~haptic_bus.profile.device.ON_ARRIVAL`) does so an exchange after
  it sampled (SYNC out to RPDO out): the delay the gate assumed is then taken as at least the
  exchange's p99 (breaker14: "ideal" timing, a wall passive only below 0.1 samples and no layer,
  was judged at 0.009 samples and ran, its exchanges 0.3-0.67 ms at T = 1 ms).  Passive there:
  nothing to add.  Not passive: with a passivity layer the run goes on (the layer holds the port
  passive; it may act), without one it is refused.

The run prints what was measured and the verdict in one line, and ``run.json`` records both (``preflight``).
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from drives.os_threads import show_own_name
from haptic_bus.app.realtime import HelperPlacement
from haptic_bus.control.clock import RealClock
from haptic_bus.control.cycle_loop import percentiles
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.scene import CompiledScene
from haptic_bus.errors import DriveTimeout, Refusal

logger = logging.getLogger(__name__)

PREFLIGHT_CYCLES = 500  # cycles measured before enabling: 0.5 s at T = 1 ms
LOOK_AGAIN = 3  # a look that would refuse T measures on for this many times its cycles, judged on all
LOOKS = 3  # at most this many looks: 500, 2000 and 8000 cycles
STALL_MARGIN = 1.5  # the longest stall measured, times this, must stay under the drive's watchdog
OVERRUN_SHARE = 0.005  # issue 26's overrun target: at most this share of a run's cycles busy longer than T
CONFIDENCE = 0.95  # T is refused when its overruns exceed OVERRUN_SHARE with this confidence (module docstring)
PERIOD_GRID = 0.25e-3  # s: the smallest T is proposed on this grid

R = TypeVar("R")


@dataclass(frozen=True)
class PreflightReport:
    """What pre-flight measured and decided.

    ``lateness``: p50/p99/p99.9/max of the cycles' start lateness (s); ``cycle``: the same of one
    cycle's exchange with the drive (s, SYNC out to RPDO out); ``longest_gap``: the longest time
    between two cycle starts (s: what the drive went without a SYNC); ``overruns``: cycles started
    more than ``T`` late; ``delay_added_p99``: the p99 of the delay each cycle adds (s,
    :func:`delay_added`); ``busy_over_period``: cycles busy longer than ``T`` (what the period rule
    counts), of which ``busy_allowed`` pass (:func:`allowed_overruns`); ``observed_delay``: the
    gate's delay (at least the exchange's p99 where targets apply on arrival) plus ``delay_added_p99`` (samples);
    ``passive_at_observed``: the gate's verdict there (None: not judged, the timing alone refuses the
    run; at the delay of a machine far behind, hundreds of samples, the coupled gate takes minutes);
    ``watchdog``: the shortest stall (s) that faults the drive (inf: none); ``holdable``: False
    refuses the run, ``reason`` says why;
    ``smallest_period``: the shortest ``T`` (s) this machine holds (the busy time's, or the
    watchdog's where a stall binds; None where no ``T`` holds the stall measured); ``earlier_looks``: the
    cycles of each look before the last, each of which would have refused ``T`` (:func:`looks_again`)."""

    cycles: int
    period: float
    lateness: dict[str, float]
    cycle: dict[str, float]
    longest_gap: float
    overruns: int
    delay_added_p99: float
    busy_over_period: int
    busy_allowed: int
    observed_delay: float
    passive_at_observed: bool | None
    watchdog: float
    holdable: bool
    reason: str
    smallest_period: float | None
    earlier_looks: tuple[int, ...] = ()

    def line(self) -> str:
        """What the run prints: the measurement and the verdict, one line."""
        late, cycle = self.lateness, self.cycle
        holds = f"; holds T >= {self.smallest_period * 1e3:g} ms" if self.holdable and self.smallest_period else ""
        again = ""
        if self.earlier_looks:
            ends = (*self.earlier_looks, self.cycles)
            more = "".join(f", then {end - start} more" for start, end in itertools.pairwise(ends))
            which = "the first alone" if len(ends) == 2 else "each look before the last"
            again = f" ({ends[0]}{more}: {which} would have refused T)"
        return (f"pre-flight: {self.cycles} cycles{again} at T = {self.period * 1e3:g} ms, no torque: start lateness "
                f"p50 {late['p50'] * 1e6:.0f} us, p99 {late['p99'] * 1e6:.0f} us, max {late['max'] * 1e3:.3g} ms; delay "
                f"added p99 {self.delay_added_p99 * 1e6:.0f} us; "
                f"exchange p99 {cycle['p99'] * 1e6:.0f} us; longest gap {self.longest_gap * 1e3:.3g} ms; "
                f"{self.overruns} started more than T late, {self.busy_over_period} busy longer than T "
                f"({self.busy_allowed} allowed){holds}: {self.reason}")

    def to_dict(self) -> dict[str, Any]:
        """For ``run.json``."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Timing:
    """Pre-flight's raw measurement: each cycle's start lateness, start time and exchange time (s); the
    clock's overruns; ``earlier_looks``: the cycles of each look before the last (:func:`measure`)."""

    period: float
    lateness: np.ndarray
    starts: np.ndarray
    exchange: np.ndarray
    overruns: int
    earlier_looks: tuple[int, ...] = ()


def looks_for(cycles: int) -> tuple[int, ...]:
    """The cycle counts at which pre-flight judges, a first look of ``cycles`` and each next
    :data:`LOOK_AGAIN` times as many more (:data:`LOOKS` in all): 500, 2000, 8000."""
    return tuple(cycles * (1 + LOOK_AGAIN) ** look for look in range(LOOKS))


def measure(exchange: Callable[[], object], period: float, looks: tuple[int, ...] = looks_for(PREFLIGHT_CYCLES),
            spin: float | None = None) -> Timing:
    """Time ``exchange`` -- one cycle of the drive(s) at zero torque, called in their cyclic phase so
    that it takes the run's own path (the bus read by this thread, the heartbeat from the cycle) --
    on a fresh real clock of period ``period`` s, ``looks[0]`` times, and on to each next count of
    ``looks`` (ascending) on the same clock while the cycles so far would refuse ``T`` by the period
    rule and the more could change that (:func:`looks_again`, module docstring).  ``exchange`` is where a stop
    asked meanwhile ends the measurement (the caller's check).  A drive that stops answering after
    answering some cycles is a :class:`DriveTimeout` that says so: from here it looks the same as a
    machine that stalls the drive's process (breaker: a simulated drive silent for 280 ms on a loaded
    host was reported as a plain "no TPDO")."""
    clock = RealClock(period, capacity=looks[-1], spin=spin)
    starts = np.zeros(looks[-1])
    took = np.zeros(looks[-1])
    look = k = 0
    while k < looks[look]:
        clock.wait_next(k)
        started = time.perf_counter()
        try:
            exchange()
        except DriveTimeout as silent:
            if k == 0:
                raise
            raise DriveTimeout(silent.node, f"{silent.message}, after answering {k} of pre-flight's {looks[look]} cycles "
                               "(nothing enabled): a drive that stops answering and a machine that stalls the "
                               "drive's process look the same from here") from silent
        starts[k], took[k] = started, time.perf_counter() - started
        k += 1
        if k == looks[look] and look + 1 < len(looks) and looks_again(
                Timing(period, clock.lateness(), starts[:k], took[:k], clock.overruns), looks[look + 1] - k):
            look += 1  # decided in the slack before the next deadline: 0.1-0.3 ms after 500 cycles, 0.6 ms after 2000
    return Timing(period, clock.lateness(), starts[:k], took[:k], clock.overruns, looks[:look])


def looks_again(look: Timing, again: int) -> bool:
    """Whether ``again`` cycles more can change the verdict on the cycles measured so far, ``look``: the
    period rule (:func:`judge_delay`'s two counts: cycles busy longer than ``T``, and cycles starting more
    than ``T`` late once the catch-ups are counted, :func:`catch_up_overruns`) refuses ``T`` on them, by no
    more than the longer measurement allows (the counts only grow with more cycles: a look already over
    that is refused either way), and the median exchange fits ``T``."""
    cycles = look.exchange.size
    if float(np.median(look.exchange)) > look.period:
        return False
    worst = max(period_counts(look))
    return allowed_overruns(cycles) < worst <= allowed_overruns(cycles + again)


def period_counts(timing: Timing) -> tuple[int, int]:
    """The period rule's two counts of the measured cycles at their own ``T``: those busy (late start plus
    exchange, :func:`own_lateness`) longer than ``T``, and those that would start more than ``T`` late once
    the catch-ups are counted (:func:`catch_up_overruns`)."""
    period = timing.period
    busy = int(np.count_nonzero(timing.exchange + own_lateness(timing) > period))
    return busy, int(catch_up_overruns(timing, np.array([period]))[0])


def while_cycling(exchange: Callable[[], object], period: float, work: Callable[[], R], spin: float | None = None) -> R:
    """``work()`` in a thread of its own (``preflight-judge``) while this thread goes on calling
    ``exchange`` once a period on a real clock, as :func:`measure` did: the drives never see the
    pause that a long judgement (the coupled gate on a sphere at the measured delay: seconds) would
    otherwise put between pre-flight's last RPDO and the enable (their RPDO deadline, 30 periods,
    would expire: a CiA 301 drive may leave OPERATIONAL for it).  ``work``'s result, or its exception."""
    result: list[R] = []
    failure: list[BaseException] = []
    placement = HelperPlacement()  # beside a SCHED_FIFO control thread: SCHED_FIFO too, below it

    def run() -> None:
        show_own_name()
        placement.place()
        try:
            result.append(work())
        except BaseException as exc:  # handed to the control thread, raised there
            failure.append(exc)

    thread = threading.Thread(target=run, name="preflight-judge", daemon=True)
    thread.start()
    clock = RealClock(period, capacity=1, spin=spin)
    k = 1  # the first a period from now: the measurement's last exchange has just been
    try:
        while thread.is_alive():
            clock.wait_next(k)
            exchange()
            k += 1
    except BaseException:  # a stop asked, a drive lost: the judgement runs on, unwaited for, as an ordinary thread
        placement.release(thread)
        raise
    thread.join()
    if failure:
        raise failure[0]
    return result[0]


def judge(timing: Timing, gate: PassivityGate, scene: CompiledScene, layer: str, watchdog: float,
          deadline_periods: int | None) -> PreflightReport:
    """The verdict on the measured timing (module docstring).  ``watchdog`` (s): the shortest stall
    that faults the drive; ``deadline_periods``: the RPDO deadline in periods when it is the
    binding watchdog (then a longer ``T`` lengthens it), else None."""
    return judge_delay(timing, gate.device.delay, passes_at(gate, scene), layer, watchdog, deadline_periods)


def passes_at(gate: PassivityGate, scene: CompiledScene) -> Callable[[float], bool]:
    """The 1-D gate's verdict on ``scene`` at another loop delay (samples), as a function of it."""
    def passes(delay: float) -> bool:
        return PassivityGate(dataclasses.replace(gate.device, delay=delay), gate.policy).passes(scene)

    return passes


def judge_delay(timing: Timing, assumed_delay: float, passes_at: Callable[[float], bool], layer: str, watchdog: float,
                deadline_periods: int | None, bus_floor: float = 0.0, on_arrival: bool = False,
                watchdog_at: Callable[[float], float] | None = None) -> PreflightReport:
    """:func:`judge` for any gate: ``assumed_delay`` (samples) is the delay it judged with,
    ``passes_at(delay)`` its verdict on the scene at another loop delay (samples).  ``bus_floor``
    (s): the shortest ``T`` the bus carries (CANopen's load ceiling, checked before the bus was
    opened, so at most ``T``; 0 for Modbus): the period named is never shorter.  ``on_arrival``: a drive
    applies its target as it arrives (:data:`~haptic_bus.profile.device.ON_ARRIVAL`), so the loop's
    delay is at least the exchange's p99 (module docstring).  ``watchdog_at(T)``: the drive's watchdog (s) at
    another ``T`` (the RPDO deadline in whole ms, and the heartbeat consumer's slack that a longer ``T`` does not
    lengthen); None: ``deadline_periods`` x ``T`` where a deadline binds, else ``watchdog``."""
    period = timing.period
    late, cycle = percentiles(timing.lateness), percentiles(timing.exchange)
    gap = float(np.max(np.diff(timing.starts))) if timing.starts.size > 1 else period
    added = delay_added(timing)
    added_p99 = float(np.percentile(added, 99)) if added.size else 0.0
    base = max(assumed_delay, cycle["p99"] / period) if on_arrival else assumed_delay
    observed = base + added_p99 / period
    busy = np.sort(timing.exchange + own_lateness(timing))[::-1]  # each cycle's busy time, the longest first
    allowed = allowed_overruns(busy.size)
    worst = max(float(busy[allowed]) if busy.size > allowed else period, bus_floor)  # the longest the rule lets pass
    holds = held_period(timing, worst, float(busy[0]) if busy.size else period, allowed)
    overlong, caught = period_counts(timing)
    stalled = STALL_MARGIN * gap >= watchdog  # the longest gap measured would fault the drive at this T
    holding = _holding_stall(holds, gap, period, watchdog, deadline_periods, watchdog_at)  # None: no T holds the gap
    unheld = f"; and a gap of {gap * 1e3:.3g} ms between cycles measured, x{STALL_MARGIN:g}, would fault the drive at " \
        "any T: lengthen the drive's watchdog ([safety])" if holding is None else ""

    def report(holdable: bool, reason: str, smallest: float | None = holding,
               passive: bool | None = None) -> PreflightReport:
        if not holdable and smallest is not None:
            reason += f": this machine holds T >= {smallest * 1e3:g} ms"
        return PreflightReport(timing.lateness.size, period, late, cycle, gap, timing.overruns, added_p99, overlong,
                               allowed, observed, passive, watchdog, holdable, reason, smallest, timing.earlier_looks)

    if cycle["p50"] > period:  # the loop cannot keep its period: it falls further behind every cycle
        return report(False, f"refused: one exchange with the drive takes {cycle['p50'] * 1e3:.3g} ms (median), more "
                             f"than T = {period * 1e3:g} ms{unheld}")
    if holds > period and overlong > allowed:
        return report(False, f"refused: {overlong} of {busy.size} cycles were busy (late start plus exchange) longer "
                             f"than T = {period * 1e3:g} ms, the longest {busy[0] * 1e3:.3g} ms: more than "
                             f"{OVERRUN_SHARE:.1%} of a run's cycles would overrun (at most {allowed} of {busy.size} "
                             f"at {CONFIDENCE:.0%} confidence){unheld}")
    if holds > period:
        return report(False, f"refused: {caught} of {busy.size} cycles would start more than T = {period * 1e3:g} ms "
                             f"late, replayed, catching up after the longest busy cycle ({busy[0] * 1e3:.3g} ms) at "
                             f"{(period - cycle['p50']) * 1e3:.3g} ms a cycle (an exchange takes {cycle['p50'] * 1e3:.3g} "
                             f"ms, median): more than {OVERRUN_SHARE:.1%} of a run's cycles would overrun (at most "
                             f"{allowed} of {busy.size} at {CONFIDENCE:.0%} confidence){unheld}")
    if stalled:
        where = f" (RPDO deadline {deadline_periods} periods)" if holding is not None and deadline_periods else \
            "; lengthen the drive's watchdog ([safety])"
        return report(False, f"refused: a gap of {gap * 1e3:.3g} ms between cycles measured, x{STALL_MARGIN:g}, reaches "
                             f"the drive's watchdog of {watchdog * 1e3:.3g} ms: the drive would fault{where}")
    if passes_at(observed):  # judged only for a timing the machine holds (its cost grows with the delay)
        return report(True, f"the gate passes the scene at the measured loop delay of {observed:.3g} samples",
                      passive=True)
    if layer != "off":
        return report(True, f"the scene is not passive at the measured loop delay of {observed:.3g} samples; the "
                            f"passivity layer ({layer}) holds the port passive and may lower the force", passive=False)
    # a longer T: more delay in seconds, a larger K T
    shorter = ", or a shorter T" if holding is not None and holding < period else ""
    return report(False, f"refused: the scene is not passive at the measured loop delay of {observed:.3g} samples "
                         f'and [passivity] layer = "off"; use layer "guard" or "bound", a softer wall{shorter}',
                  passive=False)


def _holding_stall(holds: float, gap: float, period: float, watchdog: float, deadline_periods: int | None,
                   watchdog_at: Callable[[float], float] | None) -> float | None:
    """The shortest ``T``, at least ``holds`` (on the grid, or ``holds`` itself), at which the longest gap measured,
    ``gap`` s at ``period``, x :data:`STALL_MARGIN`, stays strictly under the drive's watchdog (the rule refuses
    a gap that reaches it), or None where no ``T`` does.  At a longer ``T`` the stall in that gap lasts as
    long and its cycle's period is longer (``gap - period + T``); at a shorter one the gap is taken as measured.
    ``watchdog_at(T)``: the watchdog at ``T`` (None: ``deadline_periods`` x ``T``, or ``watchdog`` at any ``T``
    without one): only a deadline counted in periods grows with ``T``, as the drive keeps it (whole ms), and
    the heartbeat consumer's slack may bind before it holds the gap."""
    def at(candidate: float) -> float:
        if watchdog_at is not None:
            return watchdog_at(candidate)
        return deadline_periods * candidate if deadline_periods else watchdog

    def held(candidate: float) -> bool:
        return STALL_MARGIN * (gap + max(0.0, candidate - period)) < at(candidate)

    last = max(holds, period)  # past T a watchdog that does not grow with T holds the gap no better
    if deadline_periods and deadline_periods > STALL_MARGIN:
        # dT x (deadline_periods - STALL_MARGIN) covers the gap, x STALL_MARGIN, and the 0.5 ms the drive's whole
        # ms may fall short of deadline_periods x T
        last += (STALL_MARGIN * gap + 0.5e-3) / (deadline_periods - STALL_MARGIN) + 2 * PERIOD_GRID
    first = math.floor(holds / PERIOD_GRID + 1e-9) + 1  # the grid above holds
    grid = [step * PERIOD_GRID for step in range(first, math.ceil(last / PERIOD_GRID - 1e-9) + 1)]
    for candidate in sorted([holds, *grid, *([period] if period > holds else [])]):  # a 60 s gap, 30 periods: 13 000
        if held(candidate):
            return candidate
    return None


def held_period(timing: Timing, shortest: float, longest_busy: float, allowed: int) -> float:
    """The shortest period (s) this machine holds for the measured cycles: at least ``shortest`` (the busy
    time the period rule lets pass, or the bus' floor), on the :data:`PERIOD_GRID` grid (or ``timing``'s own
    ``T``, off the grid, where it holds and is shorter), and one at which at most ``allowed`` cycles would
    start more than a period late, catch-ups included (:func:`catch_up_overruns`).  At the longest busy
    cycle ``longest_busy`` none would, so the search ends there."""
    period = timing.period

    def fits(at: float) -> bool:
        return bool(catch_up_overruns(timing, np.array([at]))[0] <= allowed)

    low, high = math.ceil(shortest / PERIOD_GRID - 1e-9), math.ceil(max(longest_busy, shortest) / PERIOD_GRID - 1e-9)
    while low < high:  # binary search on the grid: never fewer fit at a longer period, and ``high`` fits
        middle = (low + high) // 2
        low, high = (low, middle) if fits(middle * PERIOD_GRID) else (middle + 1, high)
    grid = high * PERIOD_GRID
    if shortest <= period < grid and fits(period):
        return period  # T itself, off the grid, where it holds and is shorter
    return grid


def catch_up_overruns(timing: Timing, periods: np.ndarray) -> np.ndarray:
    """For each period of ``periods`` (s), how many of the measured cycles would start more than a period
    late if they ran at it: the deadline scheduler replayed (Lindley's recursion) over each cycle's
    exchange ``x`` and own lateness ``o`` (:func:`own_lateness`), ``L_k = max(0, L_{k-1} + x_{k-1} - T) + o_k``.
    At ``timing``'s own ``T`` it is the overruns measured.  It counts what a stall costs after it: at a
    period the exchange nearly fills, the loop catches up slowly, a stall of ``S`` making about
    ``S / (T - x)`` cycles late (a Modbus run at T = 2 ms with 1.8 ms polls overran in 40 of 500 cycles
    after pre-flight, counting only the cycles busy longer than ``T``, had passed it)."""
    own, took = own_lateness(timing).tolist(), timing.exchange.tolist()
    counts = []
    for period in periods.tolist():  # in floats, a period at a time: 0.1-0.2 ms for 500 cycles, 4-7 ms with arrays
        late, count = own[0] if own else 0.0, 0
        count += late > period
        for previous, mine in zip(took, own[1:]):
            late = late + previous - period
            late = (late if late > 0.0 else 0.0) + mine
            count += late > period
        counts.append(count)
    return np.array(counts, dtype=int)


def allowed_overruns(cycles: int) -> int:
    """The most of ``cycles`` measured cycles that may be busy longer than ``T`` for ``T`` to be held:
    the :data:`CONFIDENCE` quantile of the count a machine overrunning in exactly
    :data:`OVERRUN_SHARE` of its cycles shows (binomial; 5 of 500, 3 of 200).  One more is a share
    above the target at that confidence (module docstring)."""
    share, count, term = OVERRUN_SHARE, 0, (1.0 - OVERRUN_SHARE) ** cycles
    below = term  # P(at most ``count`` overruns)
    while below < CONFIDENCE and count < cycles:
        term *= (cycles - count) / (count + 1) * share / (1.0 - share)
        count += 1
        below += term
    return count


def delay_added(timing: Timing) -> np.ndarray:
    """The delay each cycle adds to the loop's (s): the larger of its :func:`own_lateness` and how much
    longer than ``T`` after the cycle before's start it began (a cycle held up inside its exchange,
    waiting for the drive or stalled there, starts the next one late while that one's own lateness is
    none: the drive held the torque before it that much longer)."""
    stretched = np.diff(timing.starts, prepend=timing.starts[:1]) - timing.period  # the first: -T
    return np.maximum(own_lateness(timing), stretched)


def own_lateness(timing: Timing) -> np.ndarray:
    """Each cycle's own lateness (s): how late it started after it could have, its deadline or the
    end of the cycle before when that ran past it (a loop that fell behind carries its lateness on,
    which says nothing of the period it would hold, nor of the delay its torque came with)."""
    deadlines = timing.starts - timing.lateness
    ends = np.concatenate(([-np.inf], (timing.starts + timing.exchange)[:-1]))
    return np.maximum(timing.starts - np.maximum(deadlines, ends), 0.0)  # >= 0: a clock never starts a cycle early


def without_realtime(report: PreflightReport, realtime: dict[str, Any] | None) -> PreflightReport:
    """``report``, its refusal saying that real-time scheduling was not granted when the control
    thread's session (``run.json``'s ``realtime``) could not get SCHED_FIFO: the likeliest reason
    such a machine holds only a longer period, and one its user can change."""
    missing = (realtime or {}).get("missing", {}).get("SCHED_FIFO")
    if report.holdable or missing is None:
        return report
    return dataclasses.replace(report, reason=f"{report.reason} (without real-time scheduling: {missing})")


def settle(report: PreflightReport, live: bool, extra: dict[str, Any]) -> None:
    """Record ``report`` in ``extra`` (``run.json``'s ``preflight``), log it, print its line unless
    the run is quiet (``live`` False), and refuse the run (:class:`~haptic_bus.errors.Refusal`,
    nothing enabled) if the machine cannot hold it."""
    extra["preflight"] = report.to_dict()
    logger.info("%s", report.line())
    if live:
        print(report.line(), flush=True)
    if not report.holdable:
        raise Refusal(report.reason.removeprefix("refused: "))
