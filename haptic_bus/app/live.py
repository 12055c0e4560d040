"""The live view of a running controller, once a second: on a terminal a rich panel, else plain lines.

It runs in the run's writer process (:mod:`~haptic_bus.app.writer_process`) and reads only what
the cycle already wrote: each axis' record ring (:class:`~haptic_bus.control.record.RunRecord`
in shared memory) and the events the control process handed over.  The control loop never
waits for the screen, and the screen takes no share of the control process' interpreter.
``--quiet`` turns it off (no view, nothing started).

What it shows (:meth:`LiveView.fields`): cycles, the run's elapsed and remaining time (and the
wall clock's), then per axis the position, the wall force and the axis' port energy, the scene
(and the start ramp's scale), the whole port's energy (for several axes ``sum E_i``), the start
lateness (p99 of the last second, wall-paced runs), the cycles the supervisor found late, the
targets the passivity layer lowered, and the whole last event (wrapped on a terminal, never
cut).  On a terminal the panel is left showing the state the run ended in (plain lines add
none: a failed run's stderr stays the one line that says why).  The control process' own log
lines are written to the same terminal by that process and appear above the panel's last
drawing.

``clock`` (s, default ``time.monotonic``) is what the wall-clock time shown is read from, and
:meth:`LiveView.update` draws one view now: tests drive the view with a fake clock, without waiting.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from haptic_bus.control.record import COLUMNS, rows_of
from haptic_bus.control.ring import Ring

if TYPE_CHECKING:
    from rich.live import Live
    from rich.panel import Panel

REFRESH = 1.0  # s
_LATENESS, _LATE, _LAYER = COLUMNS.index("lateness_s"), COLUMNS.index("late"), COLUMNS.index("layer_n")


def _duration(seconds: float) -> str:
    minutes, rest = divmod(max(seconds, 0.0), 60.0)
    return f"{int(minutes)}:{rest:04.1f}" if minutes else f"{rest:.1f} s"


class _Tally:
    """What one axis' rows added up to since the run began: late cycles, lowered targets, the last
    second's lateness (s)."""

    def __init__(self, ring: Ring, recent: int) -> None:
        self.ring = ring
        self.recent = recent
        self.next = 0
        self.late = 0
        self.lowered = 0
        self.lateness = np.zeros(0)

    def read(self) -> dict[str, float] | None:
        """Take the rows written since the last read; the newest row by column name (None before the first)."""
        while True:
            first, chunk = self.ring.read_from(self.next, 10_000)
            rows = rows_of(chunk)
            if not rows.shape[0]:
                break
            self.next = first + rows.shape[0]
            self.late += int(np.count_nonzero(rows[:, _LATE]))
            self.lowered += int(np.count_nonzero(rows[:, _LAYER]))
            self.lateness = np.concatenate((self.lateness, rows[:, _LATENESS]))[-self.recent:]
        last = self.ring.last()
        return None if last is None else dict(zip(COLUMNS, last))


class LiveView:
    """Shows :meth:`fields` (module docstring) for the axes ``records`` (``(name, ring)`` pairs;
    one pair for a one-axis run) every time :meth:`update` is called; ``period`` (s) is the run's
    ``T``, ``duration`` (s) its planned length (None: not shown), ``last_event`` gives the newest
    event as run.json has it (None: none yet).  A ``with`` block opens and leaves the panel on a
    terminal."""

    def __init__(self, records: Sequence[tuple[str, Ring]], title: str, period: float, stream: TextIO | None = None, *,
                 duration: float | None = None, last_event: Callable[[], dict[str, Any] | None] = lambda: None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.names = [name for name, _ in records]
        self._tallies = [_Tally(ring, max(1, round(REFRESH / period))) for _, ring in records]
        self.title = title
        # a terminal on stderr gets the panel; otherwise plain lines on stdout, so that a failed run's
        # stderr stays the one line that says why
        self.stream = stream if stream is not None else sys.stderr if sys.stderr.isatty() else sys.stdout
        self.duration = duration
        self.last_event = last_event
        self.clock = clock
        self._opened = 0.0
        self._live: Live | None = None

    def __enter__(self) -> LiveView:
        self._opened = self.clock()
        if self.stream.isatty():
            from rich.console import Console
            from rich.live import Live

            self._live = Live(self._panel(), console=Console(file=self.stream), auto_refresh=False, transient=False)
            self._live.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._live is not None:
            self._live.update(self._panel(), refresh=True)  # the panel stays with the state the run ended in
            self._live.stop()

    def fields(self) -> dict[str, str]:
        """The view's fields, formatted (units in the values)."""
        rows = [tally.read() for tally in self._tallies]
        first = rows[0]
        fields = {"cycles": f"{self._tallies[0].next}" if first is not None else "0 (not enabled yet: start-up, pre-flight)"}
        if self.duration is not None:
            elapsed = first["time_s"] if first is not None else 0.0
            fields["time"] = f"{_duration(elapsed)} of {_duration(self.duration)} " \
                             f"(wall clock {_duration(self.clock() - self._opened)})"
            fields["remaining"] = _duration(self.duration - elapsed)
        several = len(rows) > 1
        for name, row in zip(self.names, rows):
            if row is None:
                continue
            prefix = f"{name}: " if several else ""
            fields[f"{prefix}position"] = f"{row['position_m'] * 1e3:+.3f} mm"
            fields[f"{prefix}force"] = f"{row['force_n']:+.3f} N"
            if several:
                fields[f"{prefix}energy"] = f"{row['energy_j'] * 1e3:+.4g} mJ"
        if first is not None:
            scale = first["scale"]
            fields["scene"] = f"{int(first['scene_id'])}" + ("" if scale >= 1.0 else f" (ramp {scale:.0%})")
            energy = sum(row["energy_j"] for row in rows if row is not None)
            fields["port energy"] = f"{energy * 1e3:+.4g} mJ" + (" (sum over the axes)" if several else "")
        lateness = self._tallies[0].lateness
        if lateness.size and np.any(lateness > 0.0):
            fields["lateness p99"] = f"{float(np.percentile(lateness, 99)) * 1e6:.0f} us"
        fields["late cycles"] = f"{self._tallies[0].late}"
        fields["passivity layer"] = f"lowered {sum(tally.lowered for tally in self._tallies)} targets"
        event = self.last_event()
        if event is not None:
            fields["last event"] = f"{event['time_s']:.3f} s {event['kind']}: {event['message']}"
        return fields

    def update(self) -> None:
        """Draw the view now (the panel, or one plain line)."""
        if self._live is not None:
            self._live.update(self._panel(), refresh=True)
            return
        print(f"{self.title}: " + "; ".join(f"{k} {v}" for k, v in self.fields().items()), file=self.stream, flush=True)

    def _panel(self) -> Panel:
        from rich.panel import Panel
        from rich.table import Table

        table = Table.grid(padding=(0, 2))
        table.add_column(no_wrap=True, style="bold")
        table.add_column(overflow="fold")  # wrapped, never cut
        for name, value in self.fields().items():
            table.add_row(name, value)
        return Panel(table, title=self.title)
