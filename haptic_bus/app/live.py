"""The live view of a running controller, once a second: on a terminal a rich panel, else plain lines.

What it shows (:func:`status_fields`): cycles, the run's elapsed and remaining time (and the
wall clock's), position, force, contact (in or out, and which objects), the ``K`` and ``B`` in
effect there, the scene (and the start ramp's scale), the start lateness (p99 of the last
second) and overruns, the port observer's energy and what the passivity layer did (the
targets it lowered), and the whole last event (wrapped on a
terminal, never cut).  It runs in a thread of its own and only reads the controller, so the
control loop never waits for the screen; ``--quiet`` turns it off.  On a terminal the panel is
left showing the state the run ended in (plain lines add none: a failed run's stderr stays the
one line that says why).

On a terminal the panel is a :class:`rich.live.Live` and every log line goes through it: while
the view is up, the root logger's handlers that write to the terminal are replaced by one that
prints through the live console (above the panel), and ``print`` to stdout or stderr is
redirected the same way, so nothing written meanwhile tears the panel.  Everything is put
back when the view closes.

``clock`` (s, default ``time.monotonic``) is what the wall-clock time shown is read from, and
:meth:`LiveView.update` draws one view now: tests drive the view with a fake clock, without its
thread and without waiting.
"""

from __future__ import annotations

import bisect
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from typing import TYPE_CHECKING, TextIO

import numpy as np

from haptic_bus.control.controller import WallController

if TYPE_CHECKING:
    from rich.console import Console
    from rich.live import Live
    from rich.panel import Panel

REFRESH = 1.0  # s


def _duration(seconds: float) -> str:
    minutes, rest = divmod(max(seconds, 0.0), 60.0)
    return f"{int(minutes)}:{rest:04.1f}" if minutes else f"{rest:.1f} s"


def status_fields(controller: WallController, wall_elapsed: float | None = None,
                  duration: float | None = None) -> dict[str, str]:
    """The view's fields, formatted (units in the values); ``wall_elapsed`` (s) is the wall clock
    since the view opened, ``duration`` (s) the run's planned length (None: not shown)."""
    row = controller.record.latest()
    clock = controller.clock
    recent = clock.lateness(last=max(1, round(REFRESH / controller.period)))
    event = controller.events.last()
    fields = {"cycles": f"{controller.cycles}"}
    elapsed = controller.now()
    if duration is not None:
        wall = "" if wall_elapsed is None else f" (wall clock {_duration(wall_elapsed)})"
        fields["time"] = f"{_duration(elapsed)} of {_duration(duration)}{wall}"
        fields["remaining"] = _duration(duration - elapsed)
    if row is not None:
        x = row["position_m"]
        scale = row["scale"]
        scene = controller.scene
        i = bisect.bisect_right(scene.breaks, x)
        names = scene.contributors[i]
        fields |= {
            "position": f"{x * 1e3:+.3f} mm",
            "force": f"{row['force_n']:+.3f} N",
            "contact": f"in {' + '.join(names)}" if names else "out (free)",
            "K, B": f"{scale * scene.stiffness[i]:g} N/m, {scale * scene.damping[i]:g} N s/m",
            "scene": f"{int(row['scene_id'])}" + ("" if scale >= 1.0 else f" (ramp {scale:.0%})"),
            "port energy": f"{row['energy_j'] * 1e3:+.4g} mJ",
            "passivity layer": f"{controller.layer.mode}, lowered {controller.layer.interventions} targets",
        }
    if recent.size:
        fields["lateness p99"] = f"{float(np.percentile(recent, 99)) * 1e6:.0f} us"
    fields["overruns"] = f"{clock.overruns}"
    if event is not None:
        fields["last event"] = f"{event.time_s:.3f} s {event.kind}: {event.message}"
    return fields


class _ThroughConsole(logging.Handler):
    """Prints each record through a rich console (a live display stays below it), formatted as
    the handler it stands in for formatted it."""

    def __init__(self, console: Console, replaced: logging.Handler) -> None:
        super().__init__(replaced.level)
        self.console = console
        self.setFormatter(replaced.formatter)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.console.print(self.format(record), markup=False, highlight=False, emoji=False)
        except Exception:  # logging's own contract: a handler reports, never raises
            self.handleError(record)


@contextmanager
def _logging_through(console: Console, streams: tuple[object, ...]) -> Iterator[None]:
    """While open: the root logger's handlers writing to one of ``streams`` print through ``console``."""
    root = logging.getLogger()
    replaced = [h for h in root.handlers if isinstance(h, logging.StreamHandler) and h.stream in streams]
    through = [_ThroughConsole(console, h) for h in replaced]
    for old, new in zip(replaced, through):
        root.removeHandler(old)
        root.addHandler(new)
    try:
        yield
    finally:
        for old, new in zip(replaced, through):
            root.removeHandler(new)
            root.addHandler(old)


class LiveView:
    """Shows :func:`status_fields` every ``refresh`` s while the run goes on (``with`` block; a
    panel is drawn once more at its end); ``duration`` (s) is the run's planned length;
    ``refresh`` None: no thread (views only on :meth:`update`)."""

    def __init__(self, controller: WallController, title: str, stream: TextIO | None = None, *,
                 duration: float | None = None, clock: Callable[[], float] = time.monotonic,
                 refresh: float | None = REFRESH) -> None:
        self.controller = controller
        self.title = title
        self.stream = stream if stream is not None else sys.stderr
        self.duration = duration
        self.clock = clock
        self.refresh = refresh
        self._opened = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._live: Live | None = None
        self._routing = ExitStack()

    def __enter__(self) -> LiveView:
        self._opened = self.clock()
        if self.stream.isatty():
            from rich.console import Console
            from rich.live import Live

            console = Console(file=self.stream)
            self._live = Live(self._panel(), console=console, auto_refresh=False, transient=False,
                              redirect_stdout=True, redirect_stderr=True)
            self._routing.enter_context(_logging_through(console, (self.stream, sys.__stderr__, sys.__stdout__)))
            self._live.start()
        if self.refresh is not None:
            self._thread = threading.Thread(target=self._loop, args=(self.refresh,), name="live-view", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2 * (self.refresh or REFRESH))
        if self._live is not None:
            self._live.update(self._panel(), refresh=True)  # the panel stays with the state the run ended in
            self._live.stop()
        self._routing.close()

    def update(self) -> None:
        """Draw the view now (the panel, or one plain line)."""
        if self._live is not None:
            self._live.update(self._panel(), refresh=True)
            return
        fields = status_fields(self.controller, self.clock() - self._opened, self.duration)
        print(f"{self.title}: " + "; ".join(f"{k} {v}" for k, v in fields.items()), file=self.stream, flush=True)

    def _panel(self) -> Panel:
        from rich.panel import Panel
        from rich.table import Table

        table = Table.grid(padding=(0, 2))
        table.add_column(no_wrap=True, style="bold")
        table.add_column(overflow="fold")  # wrapped, never cut
        for name, value in status_fields(self.controller, self.clock() - self._opened, self.duration).items():
            table.add_row(name, value)
        return Panel(table, title=self.title)

    def _loop(self, refresh: float) -> None:
        while not self._stop.wait(refresh):
            self.update()
