"""The run supervisor: every cycle it measures what the gate assumed, and a policy acts on it.

The gate's verdict holds for the loop it judged: the period ``T`` and the loop delay it
assumed, the configured ``m`` and ``b``.  At run time two things can break that, and this
module watches both (DESIGN 4.1):

- **lateness**: a cycle that starts later than ``late_tolerance * T`` after its deadline held
  the previous torque that much longer, a loop delay beyond the assumed one.  So does a cycle
  whose torque was computed from an older input than its own (on CANopen: this cycle's TPDO
  missed, the last one's velocity used again): its input is ``input_age`` whole samples older
  than the gate assumed.  A cycle is late when its start lateness plus ``input_age * T``
  exceeds the tolerance; more than ``late_limit`` late cycles among the last ``late_window``
  is an alarm;
- **the observer**: the port's energy (:mod:`~haptic_bus.control.port_energy`, which starts
  from the energy stored in the walls the run begins in contact with) more than
  ``observer_limit`` J below zero is an alarm.  It sees energy the gate's linear,
  time-invariant model does not: lateness, a scene changed while the handle is inside it (a
  stiffer wall releases ``(K2 - K1) x^2 / 2`` it never stored), the unilateral contact.  With
  a passivity layer on, the layer keeps it from going below zero in the first place
  (:mod:`~haptic_bus.control.passivity_layer`); the alarm is for what the layer cannot cover.
  It cannot see a handle whose true ``b`` is smaller than configured: its sum credits the
  configured ``b`` with its dissipation, and the operator's force is not measured, so no
  run-time sum can tell a weaker handle from a pushing operator.  ``m`` and ``b`` are measured
  at commissioning (``haptic-bus identify``, a profile's ``[identification]``).

What an alarm does is the policy's (``[supervisor]`` in a profile): ``warn`` (an event, the run
goes on: the default for lateness, which the passivity layer holds passive), ``derate`` (the
scene scaled down to what the gate proves passive at the observed delay; a stop if none is),
``stop`` (torque zero, drive disabled, summary, exit 3: an assumption of the gate broken at run
time). Every alarm is an event of the run's record.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from haptic_bus.errors import AssumptionBroken, ParameterError


class Action(enum.Enum):
    """What an alarm does."""

    WARN = "warn"
    DERATE = "derate"
    STOP = "stop"


@dataclass(frozen=True)
class SupervisorPolicy:
    """``on_late``/``on_observer``: "warn", "derate" or "stop"; ``late_tolerance`` (fraction of
    ``T``), ``late_window`` (cycles), ``late_limit`` (late cycles tolerated in a window),
    ``observer_limit`` (J below zero)."""

    on_late: str = Action.WARN.value  # the passivity layer holds a late cycle passive (a profile without one: stop)
    late_tolerance: float = 0.5
    late_window: int = 1000
    late_limit: int = 10
    on_observer: str = Action.STOP.value
    observer_limit: float = 1e-3

    def __post_init__(self) -> None:
        actions = tuple(a.value for a in Action)
        for name in ("on_late", "on_observer"):
            if getattr(self, name) not in actions:
                raise ParameterError(name, getattr(self, name), " or ".join(map(repr, actions)), "supervisor")
        checks = (
            ("late_tolerance", isinstance(self.late_tolerance, (int, float)) and 0 < self.late_tolerance <= 100,
             "a fraction of the period in (0, 100]"),
            ("late_window", isinstance(self.late_window, int) and 1 <= self.late_window <= 1_000_000, "1..1000000 cycles"),
            ("late_limit", isinstance(self.late_limit, int) and 0 <= self.late_limit < self.late_window,
             f"0..{self.late_window - 1} late cycles (fewer than the window)"),
            ("observer_limit", isinstance(self.observer_limit, (int, float)) and 0 <= self.observer_limit < float("inf"),
             "a finite energy >= 0 J"),
        )
        for name, ok, allowed in checks:
            if not ok or isinstance(getattr(self, name), bool):
                raise ParameterError(name, getattr(self, name), allowed, "supervisor")


@dataclass(frozen=True)
class Alarm:
    """One alarm: ``kind`` ("late" or "observer"), what the policy says to do, a one-line
    ``message``, and for lateness the loop delay observed (samples, a high quantile of the window)."""

    kind: str
    action: Action
    message: str
    observed_delay: float | None = None

    def broken(self, assumed_delay: float, no_derate: str | None = None) -> AssumptionBroken:
        """The exit-3 error this alarm stands for (``no_derate``: why a derate could not answer it)."""
        if self.kind == "late":
            observed = self.message if no_derate is None else f"{self.message}; no derated scene: {no_derate}"
            return AssumptionBroken("the loop delay", observed, f"a loop delay of {assumed_delay:g} sample(s)")
        return AssumptionBroken("the passivity observer", self.message,
                                "a port that never gives back more energy than it held")


class Supervisor:
    """Counts late cycles in a sliding window and watches the observer's energy (module docstring).

    ``period`` (s) and ``assumed_delay`` (samples) are what the gate judged.  :meth:`cycle` runs
    every cycle and costs a few comparisons; it returns whether the cycle was late and at most
    one alarm (each kind alarms once per window, so a warning does not flood the record).
    """

    def __init__(self, policy: SupervisorPolicy, period: float, assumed_delay: float,
                 sources: tuple[str, ...] = ("the drive",)) -> None:
        self.policy = policy
        self.sources = sources  # who renews the inputs, in axis order: named when one did not in time
        self.period = period
        self.assumed_delay = assumed_delay
        self.late_cycles = 0
        self.alarms = 0
        self._tolerance = policy.late_tolerance * period
        # the window, as lists: a cycle stores three Python values where NumPy made a scalar of each (arrays are
        # made of them only for an alarm's message)
        self._lateness = [0.0] * policy.late_window  # s beyond the assumed delay: start lateness + input age
        self._late = [False] * policy.late_window
        self._stale = [0] * policy.late_window  # 1 + the source of an input older than the cycle, else 0
        self._late_in_window = 0
        self._slot = 0
        self._quiet_until = {"late": 0, "observer": 0}
        self._cycle = 0

    def cycle(self, lateness: float, energy: float, input_age: int = 0, source: int = 0) -> tuple[bool, Alarm | None]:
        """Account one cycle: its start ``lateness`` (s), the observer's ``energy`` (J), and how many
        samples older than the cycle's own its oldest input was (``input_age``, 0: fresh), from which of
        :attr:`sources` (``source``, an index)."""
        policy = self.policy
        slot = self._slot
        beyond = lateness + input_age * self.period
        late = beyond > self._tolerance
        self._late_in_window += late - self._late[slot]
        self._late[slot] = late
        self._stale[slot] = source + 1 if input_age > 0 else 0
        self._lateness[slot] = beyond
        self._slot = slot + 1 if slot + 1 < policy.late_window else 0
        self._cycle += 1
        if late:
            self.late_cycles += 1
            if self._late_in_window > policy.late_limit and self._cycle >= self._quiet_until["late"]:
                return late, self._raise("late", Action(policy.on_late), self._late_message())
        if energy < -policy.observer_limit and self._cycle >= self._quiet_until["observer"]:
            message = (f"the port's energy is {energy * 1e3:.4g} mJ, below the -{policy.observer_limit * 1e3:.4g} mJ "
                       f"allowed: the port gave the operator more energy than it held")
            return late, self._raise("observer", Action(policy.on_observer), message)
        return late, None

    @property
    def cycles(self) -> int:
        """The cycles accounted so far (:meth:`cycle`; 0: none, the window shows no delay)."""
        return self._cycle

    def observed_delay(self) -> float:
        """The loop delay (samples) the window shows: the assumed one plus the lateness that more
        than ``late_limit`` of its cycles reached (its ``late_limit + 1``-th largest), the same
        count the alarm is raised on -- so an alarm's delay is always beyond the tolerance."""
        rank = min(self.policy.late_limit + 1, len(self._lateness))
        return self.assumed_delay + float(np.partition(self._lateness, -rank)[-rank]) / self.period

    def _late_message(self) -> str:
        worst = max(self._lateness)
        stale = int(np.count_nonzero(self._stale))
        late = ", ".join(self.sources[index - 1] for index in np.unique(self._stale) if index)
        verb, why = ("started", "") if not stale else ("acted", f"{stale} on an input {late} did not renew in time; ")
        return (f"{self._late_in_window} of the last {self.policy.late_window} cycles {verb} more than "
                f"{self.policy.late_tolerance:g} T late ({why}worst {worst * 1e3:.3g} ms at T = {self.period * 1e3:g} ms): "
                f"a loop delay of about {self.observed_delay():.3g} samples")

    def _raise(self, kind: str, action: Action, message: str) -> Alarm:
        self.alarms += 1
        self._quiet_until[kind] = self._cycle + self.policy.late_window
        return Alarm(kind, action, message, self.observed_delay() if kind == "late" else None)
