"""What a run is asked to do (:class:`RunOptions`), how it is asked to stop (:class:`StopRequest`),
and how its end maps to the command's exit status (:func:`exit_status`) and to its one stderr line
(:func:`ended_line`).  Durations in s."""

from __future__ import annotations

import dataclasses
import os
import pathlib
import signal
import threading
from typing import TYPE_CHECKING

from haptic_bus.app.early_stop import signals_reach_this_thread
from haptic_bus.app.profile_policies import START_POLICIES
from haptic_bus.app.realtime import RealtimeSettings
from haptic_bus.errors import ParameterError
from haptic_bus.validation import real_in_range

if TYPE_CHECKING:
    from haptic_bus.control.cycle_loop import RunSummary

WALL, VIRTUAL = "wall", "virtual"
PACINGS = (WALL, VIRTUAL)  # what paces a run's cycles: the wall clock, or the simulated drive (lock-step)
EXIT_STATUS = {"completed": 0, "stopped": 0, "refused": 1, "drive error": 1, "write error": 1, "assumption broken": 3,
               "interrupted": 130}


class StopRequest:
    """How a run is asked to end: SIGTERM stops it (exit 0), SIGINT interrupts it (exit 130), and a
    part of the run that found a reason to stop it (:meth:`ask`) says why (``run.json``'s ``error``)."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.interrupted = False
        self.why: str | None = None

    def ask(self, why: str) -> None:
        """Stop the run at the next cycle boundary, ``why`` the one line its end records."""
        self.why = self.why or why
        self.event.set()

    def said(self, summary: RunSummary) -> None:
        """A run that ended "stopped" says how: "interrupted (Ctrl-C)" where SIGINT stopped it (the
        command's one line on stderr, exit 130), else why a part of the run asked (:meth:`ask`), if one did."""
        if summary.exit_reason != "stopped":
            return
        if self.interrupted:
            summary.exit_reason, summary.error = "interrupted", "interrupted (Ctrl-C)"
        elif summary.error is None and self.why is not None:
            summary.error = self.why  # what in the run stopped it (validate: the handle left its travel)

    def spent(self) -> None:
        """The run it stopped has ended: the request is cleared, so that the same options run again (a
        second hb.run with them ended "stopped" before its first cycle, nothing said)."""
        self.event.clear()
        self.interrupted = False
        self.why = None

    def install(self) -> None:
        """SIGINT and SIGTERM set the event (the loop ends at the next cycle boundary); nothing in a thread
        other than the main one, where Python delivers no signal
        (:func:`~haptic_bus.app.early_stop.signals_reach_this_thread`)."""
        def on_signal(signum: int, frame: object) -> None:
            self.interrupted = self.interrupted or signum == signal.SIGINT
            self.event.set()

        if not signals_reach_this_thread():  # a program's thread: the program stops the run (ask)
            return
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, on_signal)


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """One run: ``duration`` (s), its ``pacing`` (:data:`PACINGS`: "wall", each cycle at its
    deadline on the wall clock, or "virtual", lock-step with a simulated drive, a cycle as soon
    as the last one ends), the output folder (None: ``runs/...``), the start-in-contact policy
    (None: the profile's), the live view, the stop request, what a wall-paced run asks of the OS
    for its control thread (``scheduling``, :mod:`~haptic_bus.app.realtime`: ``--realtime``),
    whether a drive found in FAULT is reset before commissioning, whether a CANopen run logs
    every frame (``bus.asc``, :mod:`~haptic_bus.app.bus_log`), whether the pictures are drawn
    (seconds of matplotlib and of the region's boundary: ``--no-plots``, the benchmark, which runs
    the session many times, and the pytest plugin's runs leave them out), and how many cycles a
    wall-paced run's pre-flight measures (None: :data:`haptic_bus.app.preflight.PREFLIGHT_CYCLES`;
    the benchmark's smoke size asks fewer)."""

    duration: float
    pacing: str = WALL
    out_dir: pathlib.Path | None = None
    start_in_contact: str | None = None
    live: bool = True
    stop: StopRequest = dataclasses.field(default_factory=StopRequest)
    scheduling: RealtimeSettings = dataclasses.field(default_factory=RealtimeSettings)
    reset_fault: bool = False
    bus_log: bool = True
    plots: bool = True
    preflight_cycles: int | None = None

    def __post_init__(self) -> None:
        real_in_range("duration", self.duration, 0.0, 1e9, low_inclusive=False, unit="s", context="run options")
        if self.preflight_cycles is not None and not (isinstance(self.preflight_cycles, int) and self.preflight_cycles >= 2):
            raise ParameterError("preflight_cycles", self.preflight_cycles, "None or a whole number >= 2", "run options")
        check_pacing(self.pacing)
        if self.start_in_contact not in (None, *START_POLICIES):
            raise ParameterError("start_in_contact", self.start_in_contact,
                                 "None (the profile's) or " + " or ".join(repr(p) for p in START_POLICIES), "run options")
        if not isinstance(self.scheduling, RealtimeSettings):
            raise ParameterError("scheduling", self.scheduling, "a RealtimeSettings", "run options")
        for name in ("live", "reset_fault", "bus_log", "plots"):  # a truthy "no" would reset a drive's fault
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(name, getattr(self, name), "True or False", "run options")
        if self.out_dir is not None and not isinstance(self.out_dir, (str, os.PathLike)):
            raise ParameterError("out_dir", self.out_dir, "None (runs/<UTC>-<profile>) or a folder's path", "run options")
        if not isinstance(self.stop, StopRequest):
            raise ParameterError("stop", self.stop, "a StopRequest", "run options")

    @property
    def wall_paced(self) -> bool:
        """Whether the cycles keep the wall clock (``pacing == "wall"``)."""
        return self.pacing == WALL


def check_pacing(pacing: str) -> None:
    """ParameterError unless ``pacing`` is one of :data:`PACINGS`."""
    if pacing not in PACINGS:
        raise ParameterError("pacing", pacing, " or ".join(repr(p) for p in PACINGS), "run options")


def exit_status(reason: str) -> int:
    """0 completed or stopped, 1 refused, a drive error or a folder that could not be written, 3 an
    assumption broken, 130 interrupted."""
    return EXIT_STATUS[reason]


def stopped_in_preflight(cycles: int | None) -> str:
    """What a command's end line adds for a run a stop ended in pre-flight, ``cycles`` measured by then
    (:attr:`~haptic_bus.app.runner.RunResult.preflight_stopped`; None: it did not end there)."""
    return "" if cycles is None else f" during pre-flight, before enabling ({cycles} cycles measured)"


def ended_line(reason: str, error: str) -> str:
    """What a command prints after its name when a run ended for ``reason`` (``run.json``'s
    ``exit_reason``) with ``error``: ``"reason: error"``, or ``error`` alone when it already says
    the reason (``interrupted (Ctrl-C)``, not ``interrupted: interrupted (Ctrl-C)``)."""
    return error if error.startswith(reason) else f"{reason}: {error}"
