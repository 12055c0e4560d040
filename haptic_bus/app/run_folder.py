"""Where a run keeps its record: ``runs/<UTC timestamp>-<profile>/`` (or ``--out``), written as it goes.

The folder is created and probed for writing before any bus is touched (an unwritable one is
a :class:`~haptic_bus.errors.ParameterError`: exit 2).  It receives:

- ``run.json`` (:class:`RunJournal`), at once: ``status`` "running", ``"ended": false``; kept
  current while the run goes on (each event, each scene) and completed at the end: software
  versions, the profile file and its SHA-256, device, loop (delay assumed and observed), the
  loop the gate judged (``gate_loop``), link, scaling and where each factor came from, safety
  settings, every scene in effect (each object with its geometry, K and B, the gate's margin per
  contact wall), the summary with its ``exit_reason``, the events (uploads accepted and refused,
  alarms, derates, faults), each with its time, and the files.  Written whole each time (a
  temporary file renamed over it), so a killed run leaves the last version, saying it did not end;
- ``record.csv``: one row a cycle (:data:`haptic_bus.control.record.COLUMNS`), streamed by the
  run's writer process (:mod:`~haptic_bus.app.run_writer`, :mod:`~haptic_bus.app.record_stream`);
- ``bus.asc``: every CAN frame (:mod:`~haptic_bus.app.bus_log`; CANopen runs, unless ``--no-bus-log``);
- at the end, the pictures (:mod:`~haptic_bus.app.run_plots`), drawn from the files themselves:
  ``haptic-bus plot RUN_DIR`` draws the same again from :func:`read_run_folder`.
"""

from __future__ import annotations

import datetime as dt
import functools
import hashlib
import importlib.metadata
import json
import math
import os
import pathlib
import platform
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Generic, TypeVar

from haptic_bus._version import __version__
from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.app.profiles import Profile, profile_to_dict
from haptic_bus.control.controller import RunSummary, WallController
from haptic_bus.control.record import RecordTable, read_record
from haptic_bus.errors import ParameterError
from haptic_bus.validation import writable_folder

DEFAULT_ROOT = pathlib.Path("runs")
RUN_JSON, RECORD_CSV = "run.json", "record.csv"
RUNNING = "running"  # run.json's status until the run ends
_DISTRIBUTIONS = ("numpy", "scipy", "python-can", "canopen", "pymodbus", "matplotlib")


def _utc_now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def prepare_run_folder(out: str | pathlib.Path | None, profile_name: str, root: pathlib.Path = DEFAULT_ROOT) -> pathlib.Path:
    """The run's folder, created and shown writable now: ``out``, or ``root/<UTC>-<profile>``
    (``-2``, ``-3``... if that exists).  ParameterError naming the folder otherwise, and for an
    ``out`` holding a run that has not ended (:func:`refuse_unended`)."""
    if out is not None:
        folder = writable_folder("--out", out, context="run")  # as given: an empty one is refused, not '.'
        refuse_unended(folder)
        return folder
    else:
        stamp = _utc_now().strftime("%Y%m%dT%H%M%SZ")
        path = root / f"{stamp}-{profile_name}"
        n = 2
        while path.exists():
            path = root / f"{stamp}-{profile_name}-{n}"
            n += 1
    return writable_folder("--out", path, context="run")


def refuse_unended(folder: pathlib.Path) -> None:
    """ParameterError if ``folder``'s ``run.json`` says its run has not ended: another run is writing
    there now (a second run would replace its ``run.json`` and its records), or one was killed and
    the folder keeps its last cycles.  A folder without a readable ``run.json`` passes."""
    try:
        document = json.loads((folder / RUN_JSON).read_text())
    except (OSError, ValueError):
        return
    if isinstance(document, dict) and document.get("ended") is False:
        raise ParameterError("--out", str(folder), "a folder without a run that has not ended (its run.json says "
                             f"{document.get('status', RUNNING)!r}: a run writing there now, or one killed whose "
                             "record it keeps); choose another folder", "run")


@functools.cache
def software_versions() -> dict[str, str]:
    """haptic_bus, Python and the libraries a run depends on."""
    versions = {"haptic_bus": __version__, "python": platform.python_version()}
    for name in _DISTRIBUTIONS:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def profile_identity(profile: Profile) -> dict[str, Any]:
    """The profile's name, file and the SHA-256 of its bytes (None for a profile built in code)."""
    path = profile.path
    digest = hashlib.sha256(path.read_bytes()).hexdigest() if path is not None and path.is_file() else None
    return {"name": profile.name, "path": None if path is None else str(path), "sha256": digest}


def _finite(value: Any) -> Any:
    """JSON without NaN/inf: non-finite floats as strings."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def run_document(profile: Profile, controller: WallController | None, summary: RunSummary | None,
                 link: dict[str, Any], extra: dict[str, Any], started: dt.datetime, ended: bool = True) -> dict[str, Any]:
    """The content of ``run.json`` (see the module docstring); ``controller`` and ``summary`` may
    be None for a run that ended before it cycled (then ``extra`` carries the reason).  While the
    run goes on (``ended`` False) ``status`` is "running" and ``ended_utc`` None."""
    document: dict[str, Any] = {
        "status": extra.get("exit_reason", "ended") if ended else RUNNING,
        "ended": ended,
        "software": dict(software_versions()),
        "command": sys.argv,
        "started_utc": started.isoformat(),
        "ended_utc": _utc_now().isoformat() if ended else None,
        "profile": profile_identity(profile),
        "settings": profile_to_dict(profile),
        "link": link,
        **extra,
    }
    if controller is not None:
        drive = controller.axes.drives[0]
        report = getattr(drive, "scaling_report", None)
        document["scaling"] = {"values": asdict(drive.scaling), "sources": getattr(drive, "scaling_sources", {}),
                               **(report.to_dict() if report is not None else {})}
        document["scenes"] = scene_dicts(controller)
        document["events"] = controller.events.to_list()
        document["events_dropped"] = controller.events.dropped
        supervisor = controller.supervisor
        if supervisor is not None:
            document.setdefault("loop", {})["delay_observed"] = supervisor.observed_delay()
    if summary is not None:
        document["summary"] = asdict(summary)
    return _finite(document)


def scene_dicts(controller: WallController) -> list[dict[str, Any]]:
    """Every scene ``controller`` had in effect, JSON-ready (``run.json``'s ``scenes``)."""
    return [entry.to_dict() for entry in list(controller.scenes.history)]


def gate_loop(device: DeviceLoop) -> dict[str, Any]:
    """The loop the gate judged the run's scenes with (``run.json``'s ``gate_loop``): ``m`` kg,
    ``b`` N s/m, ``T`` s, ``delay`` samples, ``velocity`` model; what the K-B plane is drawn for."""
    return {"m": device.m, "b": device.b, "T": device.T, "delay": device.delay, "velocity": str(device.velocity)}


def write_json(path: pathlib.Path, document: dict[str, Any]) -> pathlib.Path:
    """Write ``document`` to ``path`` whole or not at all (a temporary file renamed over it), so a
    process killed meanwhile leaves the previous version, never half of one."""
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_text(json.dumps(document, indent=1) + "\n")
    os.replace(temporary, path)
    return path


P = TypeVar("P")  # the profile: one axis' or several axes'
C = TypeVar("C")  # the controller
Render = Callable[[P, "C | None", "RunSummary | None", dict[str, Any], dict[str, Any], dt.datetime, bool], dict[str, Any]]
"""``run.json``'s content from (profile, controller, summary, link, extra, started, ended): :func:`run_document`,
or :func:`~haptic_bus.app.axes_records.axes_run_document` for several axes."""


class RunJournal(Generic[P, C]):
    """``run.json`` over a run's life: written before anything is touched (``status`` "running",
    ``ended`` false), rewritten whenever the events or the scenes change (by the run's writer
    process, :mod:`~haptic_bus.app.run_writer`, from :meth:`document` and the events), and
    completed at the end (:meth:`finish`).  A run killed at any moment
    leaves it saying ``"ended": false``: :func:`read_run_folder` reports it as not ended cleanly."""

    def __init__(self, folder: pathlib.Path, profile: P, link: dict[str, Any], extra: dict[str, Any],
                 render: Render[P, C]) -> None:
        self.folder = folder
        self.path = folder / RUN_JSON
        self.profile = profile
        self.link = link
        self.extra = extra
        self.started = _utc_now()
        self.controller: C | None = None
        self._render = render

    def document(self, summary: RunSummary | None = None, ended: bool = False) -> dict[str, Any]:
        """``run.json``'s content as the run stands now."""
        return self._render(self.profile, self.controller, summary, self.link, self.extra, self.started, ended)

    def write(self, summary: RunSummary | None = None, ended: bool = False) -> pathlib.Path:
        """Write ``run.json`` as the run stands now."""
        return write_json(self.path, self.document(summary, ended))

    def finish(self, summary: RunSummary | None, written: list[pathlib.Path]) -> list[pathlib.Path]:
        """The run has ended: ``run.json`` completed, naming the files ``written`` and itself
        (called again when more files come); the paths, ``run.json`` last."""
        self.extra["files"] = [str(p) for p in written] + [str(self.path)]
        self.write(summary, ended=True)
        return [*written, self.path]


@dataclass(frozen=True)
class RunFolder:
    """A run folder read back: ``run.json``'s document, ``record.csv`` (None if the run never
    cycled, or for several axes), each axis' record for several axes (``axes``: axis name ->
    ``record-<axis>.csv``, empty for one axis), and whether the run ended cleanly."""

    path: pathlib.Path
    document: dict[str, Any]
    record: RecordTable | None
    axes: dict[str, RecordTable] = field(default_factory=dict)

    @property
    def ended_cleanly(self) -> bool:
        """True when ``run.json`` was completed (``"ended": true``)."""
        return self.document.get("ended", True) is True

    @property
    def records(self) -> dict[str, RecordTable]:
        """Every record read, by file name."""
        one = {RECORD_CSV: self.record} if self.record is not None else {}
        return one | {f"record-{axis}.csv": table for axis, table in self.axes.items()}

    @property
    def drawable(self) -> bool:
        """Whether there is anything to draw: a record with cycles (every axis' for several), or
        the loop the gate judged (the K-B plane of a run that never cycled)."""
        if self.axes:
            named = len(self.document.get("settings", {}).get("axes", []))
            return len(self.axes) == named and all(table.cycles for table in self.axes.values())
        return (self.record is not None and self.record.cycles > 0) or "gate_loop" in self.document

    def notes(self) -> list[str]:
        """What a reader should know before trusting the pictures (one line each)."""
        notes = []
        if not self.ended_cleanly:
            held = "; ".join(f"{name} holds {table.cycles} cycles" for name, table in self.records.items()) or \
                "no record"
            notes.append(f"{self.path}: the run did not end cleanly (run.json still says {self.document.get('status')!r}: "
                         f"the process was killed or crashed); {held}")
        for name, table in self.records.items():
            if table.torn_line:
                notes.append(f"{self.path / name}: its last line was torn (written when the process died) and is left out")
        return notes


def read_run_folder(folder: str | pathlib.Path) -> RunFolder:
    """Read a run folder (``run.json`` and ``record.csv``); ParameterError naming what is missing or unreadable."""
    path = pathlib.Path(folder)
    if not (path / RUN_JSON).is_file():
        raise ParameterError("RUN_DIR", str(path), "a run folder: one with run.json (written by haptic-bus run or demo)",
                             "plot")
    try:
        document = json.loads((path / RUN_JSON).read_text())
        if not isinstance(document, dict):
            raise ValueError("run.json is not a JSON object")
        record = read_record(path / RECORD_CSV) if (path / RECORD_CSV).is_file() else None
        names = [axis["name"] for axis in document.get("settings", {}).get("axes", [])]
        axes = {name: read_record(path / f"record-{name}.csv") for name in names if (path / f"record-{name}.csv").is_file()}
    except (OSError, ValueError, TypeError, KeyError) as exc:
        raise ParameterError("RUN_DIR", str(path), f"a readable run folder ({exc})", "plot") from None
    return RunFolder(path, document, record, axes)
