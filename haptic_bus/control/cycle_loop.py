"""The loop every controller runs, and what it reports: cycles until done, stopped, or an error.

A controller (:class:`~haptic_bus.control.controller.WallController`, for one drive or several
on one SYNC) provides one cycle (``step``), the run's clock and event log, how to disable its drive(s), and its
summary; :meth:`CycleLoop.run` runs the cycles and, whatever ends them -- the count, the stop
flag, a drive error, an assumption of the gate broken, Ctrl-C -- leaves torque zero and the
drive(s) disabled, the record kept, and the end in the summary (``exit_reason``).
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drives.base import AxesDriveCycle
from haptic_bus.control.clock import CycleClock, RealClock
from haptic_bus.control.record import EventLog
from haptic_bus.control.supervisor import Supervisor
from haptic_bus.errors import AssumptionBroken, DriveError

logger = logging.getLogger(__name__)

@dataclass
class RunSummary:
    """What a run did: counts, peaks, the port's energy (J: the last, the least, and the counts
    rounding bound under which the truth may lie), the passivity layer and how often it lowered a
    target, compute and lateness percentiles (s), and its end.

    ``exit_reason`` is "completed", "stopped", "interrupted", "drive error" or "assumption broken" (a
    run whose folder could not be written: "write error", set by the runner); ``error`` the message
    that ended it early.
    """

    cycles: int
    saturated_cycles: int
    peak_force: float
    energy: float
    least_energy: float
    rounding_bound: float
    observer_active_cycles: int
    layer: str
    layer_interventions: int
    compute_percentiles: dict[str, float]
    clock: str
    overruns: int
    lateness_percentiles: dict[str, float]
    late_cycles: int
    alarms: int
    exit_reason: str = "completed"
    error: str | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def observer_flagged(self) -> bool:
        """True once the port gave the operator more energy than it held."""
        return self.observer_active_cycles > 0


class CycleLoop:
    """The run loop of a controller (module docstring).  A subclass sets ``clock``, ``events``,
    ``cycles``, ``stopped_on_error``, ``error_cycle_s`` (0.0) and ``_cycle`` (None) and implements :meth:`step`, :meth:`now`,
    :meth:`summary`, :meth:`_disable` and :meth:`_phase` (its drives' cyclic phase:
    held in ``_cycle`` while :meth:`run` runs)."""

    _cycle: AxesDriveCycle | None
    clock: CycleClock
    events: EventLog
    cycles: int
    stopped_on_error: bool
    error_cycle_s: float  # how long (s) the cycle that met a drive error had run by then (0.0: none, or virtual time)
    supervisor: Supervisor | None
    saturated_cycles: int
    peak_force: float

    def step(self, lateness: float = 0.0) -> None:
        """One cycle, ``lateness`` s after its deadline."""
        raise NotImplementedError

    def now(self) -> float:
        """The run's clock, s."""
        raise NotImplementedError

    def summary(self, exit_reason: str = "completed", error: str | None = None) -> RunSummary:
        """The summary of everything run so far."""
        raise NotImplementedError

    def _disable(self) -> None:
        """Disable the drive(s) (torque zero)."""
        raise NotImplementedError

    def _phase(self) -> contextlib.AbstractContextManager[AxesDriveCycle]:
        """The drive(s)' cyclic phase, entered once for the cycles of one :meth:`run`."""
        raise NotImplementedError

    @contextlib.contextmanager
    def _cyclic(self) -> Iterator[None]:
        """The phase the cycles of one :meth:`run` share, held in ``_cycle`` until they end."""
        with self._phase() as cycle:
            self._cycle = cycle
            try:
                yield
            finally:
                self._cycle = None

    def _summary(self, exit_reason: str, error: str | None, *, energy: float, least_energy: float, rounding_bound: float,
                 observer_active_cycles: int, layer: str, layer_interventions: int, compute: np.ndarray,
                 warnings: Sequence[str] = ()) -> RunSummary:
        """A :class:`RunSummary` from the port's figures (J, counts) and the cycles' compute times (s),
        with what the loop, its clock and its supervisor counted."""
        supervisor = self.supervisor
        return RunSummary(
            cycles=self.cycles, saturated_cycles=self.saturated_cycles, peak_force=self.peak_force, energy=energy,
            least_energy=least_energy, rounding_bound=rounding_bound, observer_active_cycles=observer_active_cycles,
            layer=layer, layer_interventions=layer_interventions, compute_percentiles=percentiles(compute),
            clock=self.clock.name, overruns=self.clock.overruns, lateness_percentiles=percentiles(self.clock.lateness()),
            late_cycles=supervisor.late_cycles if supervisor is not None else 0,
            alarms=supervisor.alarms if supervisor is not None else 0,
            exit_reason=exit_reason, error=error, warnings=list(warnings))

    def run(self, cycles: int, stop: threading.Event | None = None,
            on_cycle: Callable[[Any], None] | None = None) -> RunSummary:
        """Run up to ``cycles`` cycles (or until ``stop`` is set); ``on_cycle(controller)`` after
        each.  Whatever ends the run leaves torque zero and the drive(s) disabled, the record
        kept, and the end in the summary."""
        reason, error = "completed", None
        try:
            with self._cyclic():
                for _ in range(cycles):
                    if stop is not None and stop.is_set():
                        reason = "stopped"
                        break
                    self.step(self.clock.wait_next(self.cycles))
                    if on_cycle is not None:
                        on_cycle(self)
        except DriveError as exc:
            reason, error = "drive error", str(exc)
            self.stopped_on_error = True
            self.error_cycle_s = self.clock.since_start() if isinstance(self.clock, RealClock) else 0.0
            self._end(exc, "fault")
        except AssumptionBroken as exc:
            reason, error = "assumption broken", str(exc)
            self._end(exc, "stop")
        except KeyboardInterrupt as exc:
            reason, error = "interrupted", "interrupted (Ctrl-C)"
            self._end(exc, "stop")
        except BaseException as exc:  # a bug: still leave the drive safe, then let it surface
            self._end(exc, "fault")
            raise
        return self.summary(reason, error)

    def _end(self, exc: BaseException, kind: str) -> None:
        logger.info("run stopped: %s", str(exc) or type(exc).__name__)  # the summary and the command report it
        self.events.add(self.now(), kind, str(exc) or type(exc).__name__)
        try:
            self._disable()
        except DriveError as failure:  # the drive may be gone; its own trip already zeroed torque
            logger.info("could not disable the drive: %s", failure)  # a consequence of the error reported


def percentiles(values: np.ndarray) -> dict[str, float]:
    """p50, p99, p99.9 and max of ``values`` (empty dict for none)."""
    if values.size == 0:
        return {}
    p50, p99, p999 = np.percentile(values, [50, 99, 99.9])
    return {"p50": float(p50), "p99": float(p99), "p99.9": float(p999), "max": float(values.max())}
