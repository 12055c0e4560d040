"""The live view of a running controller, once a second: on a terminal a rich panel, else plain lines.

What it shows: cycles, position, force, the scene in effect (and the start ramp's scale),
the start lateness (p99 of the last second) and overruns, the observer's interface energy,
the last event.  It runs in a thread of its own and only reads the controller, so the
control loop never waits for the screen; ``--quiet`` turns it off.
"""

from __future__ import annotations

import sys
import threading
from typing import TYPE_CHECKING, TextIO

import numpy as np

from haptic_bus.control.controller import WallController

if TYPE_CHECKING:
    from rich.live import Live
    from rich.panel import Panel

REFRESH = 1.0  # s


def status_fields(controller: WallController) -> dict[str, str]:
    """The view's fields, formatted (units in the values)."""
    row = controller.record.latest()
    clock = controller.clock
    recent = clock.lateness(last=max(1, round(REFRESH / controller.period)))
    event = controller.events.last()
    fields = {"cycles": f"{controller.cycles}"}
    if row is not None:
        scale = "" if row["scale"] >= 1.0 else f" (ramp {row['scale']:.0%})"
        fields |= {
            "position": f"{row['position_m'] * 1e3:+.3f} mm",
            "force": f"{row['force_n']:+.3f} N",
            "scene": f"{int(row['scene_id'])}{scale}",
            "observer": f"{row['energy_j'] * 1e3:+.4g} mJ",
        }
    if recent.size:
        fields["lateness p99"] = f"{float(np.percentile(recent, 99)) * 1e6:.0f} us"
    fields["overruns"] = f"{clock.overruns}"
    if event is not None:
        fields["last event"] = f"{event.time_s:.3f} s {event.kind}: {event.message[:80]}"
    return fields


class LiveView:
    """Shows :func:`status_fields` every :data:`REFRESH` s while the run goes on (``with`` block)."""

    def __init__(self, controller: WallController, title: str, stream: TextIO | None = None) -> None:
        self.controller = controller
        self.title = title
        self.stream = stream if stream is not None else sys.stderr
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._live: Live | None = None

    def __enter__(self) -> LiveView:
        if self.stream.isatty():
            from rich.console import Console
            from rich.live import Live

            self._live = Live(get_renderable=self._panel, console=Console(file=self.stream), refresh_per_second=1 / REFRESH,
                              transient=False, redirect_stdout=False, redirect_stderr=False)
            self._live.start()
        else:
            self._thread = threading.Thread(target=self._lines, name="live-view", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._live is not None:
            self._live.stop()
        if self._thread is not None:
            self._thread.join(timeout=2 * REFRESH)

    def _panel(self) -> Panel:
        from rich.panel import Panel
        from rich.table import Table

        table = Table.grid(padding=(0, 2))
        for name, value in status_fields(self.controller).items():
            table.add_row(name, value)
        return Panel(table, title=self.title)

    def _lines(self) -> None:
        while not self._stop.wait(REFRESH):
            fields = status_fields(self.controller)
            print(f"{self.title}: " + "; ".join(f"{k} {v}" for k, v in fields.items()), file=self.stream, flush=True)
