"""Where a run keeps its record: ``runs/<UTC timestamp>-<profile>/`` (or ``--out``), written as it goes.

One folder and one ``run.json`` for one axis or several.  The folder is created and probed for
writing before any bus is touched (an unwritable one is a :class:`~haptic_bus.errors.ParameterError`:
exit 2), and owned by the run for its life (:mod:`~haptic_bus.app.folder_lock`: ``.haptic-bus.lock``;
another run's folder is exit 2).  It receives:

- ``run.json`` (:class:`RunJournal`, :func:`run_document`), at once: ``status`` "running",
  ``"ended": false``; kept current while the run goes on (each event, each scene) and completed at
  the end: software versions, the profile file and its SHA-256, its settings (every axis and object
  for several), device, loop (delay assumed, and observed once it cycled), the loop the gate judged (``gate_loop``,
  one axis), link, scaling and where each factor came from (per axis for several), the safety
  settings the drives were given (``settings.safety``: in virtual time the watchdogs' floor,
  :meth:`~drives.safety.SafetySettings.for_virtual_time`; the profile's own are in its file),
  every scene in effect (each object with its geometry, K and B, the gate's margin per contact
  wall; for several axes the coupled gate's decision, :mod:`~haptic_bus.app.space_records`), the
  summary with its ``exit_reason`` (for several axes the whole port's: ``energy`` is ``sum E_i``)
  and each axis' (``axes``), the events (uploads accepted and refused, alarms, derates, faults),
  each with its time, and the files.  What differs by kind comes from the run's kind
  (:meth:`DocumentKind.sections`).  Written whole each time (a temporary file
  renamed over it), so a killed run leaves the last version, saying it did not end;
- ``record.csv``: one row a cycle (:data:`haptic_bus.control.record.COLUMNS`), streamed by the
  run's writer process (:mod:`~haptic_bus.app.run_writer`, :mod:`~haptic_bus.app.record_stream`);
  for several axes ``record-<axis>.csv`` instead (:func:`record_name`), one per axis, each with
  the same columns: that axis' joint position and velocity, the wall force along it (``force_n``,
  the joint effort ``J^T u``), its target torque, its own port energy ``E_i`` (``energy_j``), the
  force its layer took off, and the cycle's scene id, lateness flag and compute time (the same in
  every file).  One file per axis, not columns per axis: each reads like a one-axis record, and
  the rows of all files are the same cycles (the same ``time_s``);
- ``bus.asc``: every CAN frame the one bus handle sent or received (:mod:`~haptic_bus.app.bus_log`; CANopen
  runs, unless ``--no-bus-log``);
- at the end, the pictures (:mod:`~haptic_bus.app.run_plots`; for several axes
  :mod:`~haptic_bus.app.trajectory_plot`), drawn from the files themselves: ``haptic-bus plot
  RUN_DIR`` draws the same again from :func:`read_run_folder`.
"""

from __future__ import annotations

import datetime as dt
import functools
import hashlib
import importlib.metadata
import json
import logging
import pathlib
import platform
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

from drives.safety import SafetySettings
from haptic_bus._version import __version__
from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.app.bus_log import LOG_NAME
from haptic_bus.app.folder_lock import FolderLock, holder, own_folder
from haptic_bus.app.json_ready import json_ready
from haptic_bus.app.profiles import AxesProfile, Profile, profile_to_dict
from haptic_bus.app.run_json import RUN_JSON, write_json
from haptic_bus.app.run_json_shape import check_drawn_fields
from haptic_bus.control.controller import RunSummary, WallController
from haptic_bus.control.protocols import DecisionT, SceneT
from haptic_bus.control.record import RecordTable, read_record
from haptic_bus.control.scene_switch import SceneEntry
from haptic_bus.errors import ParameterError
from haptic_bus.validation import writable_folder

DEFAULT_ROOT = pathlib.Path("runs")
RECORD_CSV = "record.csv"
TIMELINE, FORCE_POSITION, REGION, TRAJECTORY = "timeline.png", "force_position.png", "region.png", "trajectory.png"
PICTURES = (TIMELINE, FORCE_POSITION, REGION, TRAJECTORY)  # what :mod:`~haptic_bus.app.run_pictures` draws
VALIDATE_JSON, BODE_PNG, RE_Z_PNG = "validate.json", "validate-bode.png", "validate-re-z.png"  # haptic-bus validate's
RUNNING = "running"  # run.json's status until the run ends
DRAWN_COLUMNS = ("time_s", "position_m", "force_n", "energy_j")  # what the pictures read from every record
_DISTRIBUTIONS = ("numpy", "scipy", "python-can", "canopen", "pymodbus", "matplotlib")

logger = logging.getLogger(__name__)


def record_name(axis: str) -> str:
    """The file of axis ``axis``' record in a multi-axis run's folder (one axis' is :data:`RECORD_CSV`)."""
    return f"record-{axis}.csv"


def _utc_now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def prepare_run_folder(out: str | pathlib.Path | None, profile_name: str, root: pathlib.Path = DEFAULT_ROOT) -> pathlib.Path:
    """The run's folder, created and shown writable now: ``out``, or ``root/<UTC>-<profile>``
    (``-2``, ``-3``... if that exists).  ParameterError naming the folder otherwise."""
    if out is not None:
        return writable_folder("out_dir", out, context="run")  # as given: an empty one is refused, not '.'
    else:
        path = _claim_new_folder(root, f"{_utc_now().strftime('%Y%m%dT%H%M%SZ')}-{profile_name}")
    return writable_folder("out_dir", path, context="run")


CLAIM_ATTEMPTS = 10_000  # names tried after ``<UTC>-<profile>``: ``-2`` .. (a second's runs never come near it)


def _claim_new_folder(root: pathlib.Path, base: str) -> pathlib.Path:
    """``root/base`` (``-2``, ``-3``... if taken), created here, so that no other run takes the same name: two
    runs started in the same second (two threads calling hb.run, two commands in one folder) both found the
    name free and the second was refused ("a folder no other run is writing") with no --out given.  Where
    ``root`` cannot be made, the name without creating it (the caller's check names the folder and why)."""
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError:
        return root / base
    for n in range(1, CLAIM_ATTEMPTS + 1):
        path = root / (base if n == 1 else f"{base}-{n}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
        except OSError:
            return path
    return root / f"{base}-{CLAIM_ATTEMPTS + 1}"


def own_run_folder(out: str | pathlib.Path | None, profile_name: str) -> tuple[pathlib.Path, FolderLock]:
    """The run's folder (:func:`prepare_run_folder`), owned by this process (:func:`~haptic_bus.app.folder_lock.own_folder`:
    another run's folder is refused) and cleared of what an earlier run left there that a run writes
    (``run.json``, the records, ``bus.asc``, the pictures, validate's files), so that a folder given
    again never holds two runs (one warning line names what was replaced); ParameterError naming the
    folder otherwise."""
    folder = prepare_run_folder(out, profile_name)
    lock = own_folder(folder)
    earlier = [RUN_JSON, RECORD_CSV, LOG_NAME, *PICTURES, VALIDATE_JSON, BODE_PNG, RE_Z_PNG, *_axis_records(folder)]
    found = [path for path in (folder / name for name in earlier) if path.exists()]
    try:
        _remove_all_or_none(found)
    except OSError as exc:
        lock.release()
        raise ParameterError("out_dir", str(folder), f"a folder whose earlier run this run can replace (nothing removed; "
                             f"{exc.filename}: {exc.strerror})", "run") from None
    if found:
        logger.warning("run folder %s: this run replaces the earlier run's %s", folder, ", ".join(p.name for p in found))
    return folder, lock


def _axis_records(folder: pathlib.Path) -> list[str]:
    """The per-axis records (``record-<axis>.csv``) of the axes the earlier run's ``run.json`` in
    ``folder`` names: none where it names none or cannot be read (a user's own ``record-*.csv`` stays)."""
    try:
        axes = json.loads((folder / RUN_JSON).read_text())["settings"]["axes"]
        return [record_name(str(axis["name"])) for axis in axes]
    except (OSError, ValueError, TypeError, KeyError):
        return []


def _remove_all_or_none(paths: list[pathlib.Path]) -> None:
    """Remove every file of ``paths`` (in one folder), or, where one cannot go (OSError), none of them:
    each is first renamed aside (``.<name>.replaced``) and the renamed ones are put back if one fails,
    so that a refused run leaves the earlier run whole (a run.json gone beside its records is no run)."""
    aside: list[tuple[pathlib.Path, pathlib.Path]] = []
    try:
        for path in paths:
            hidden = path.with_name(f".{path.name}.replaced")
            path.rename(hidden)
            aside.append((path, hidden))
    except OSError:
        for path, hidden in reversed(aside):
            hidden.rename(path)
        raise
    for _, hidden in aside:
        hidden.unlink()


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


def profile_identity(profile: Profile | AxesProfile) -> dict[str, Any]:
    """The profile's name, file and the SHA-256 of its bytes (None for a profile built in code)."""
    path = profile.path
    digest = hashlib.sha256(path.read_bytes()).hexdigest() if path is not None and path.is_file() else None
    return {"name": profile.name, "path": None if path is None else str(path), "sha256": digest}


class DocumentKind(Protocol):
    """What ``run.json`` asks of a run's kind, one axis or several (a :class:`~haptic_bus.app.run_kinds.RunKind`)."""

    @property
    def profile(self) -> Profile | AxesProfile: ...

    def sections(self, controller: WallController[Any, Any]) -> dict[str, Any]:
        """``run.json``'s sections that differ by kind and need the controller: ``scenes`` and, for
        several axes, ``axes`` (``scaling`` is written once the drives are reached: :meth:`RunKind.scaling
        <haptic_bus.app.run_kinds.RunKind.scaling>`)."""
        ...


def run_document(kind: DocumentKind, controller: WallController[Any, Any] | None, summary: RunSummary | None,
                 link: dict[str, Any], extra: dict[str, Any], started: dt.datetime, ended: bool = True) -> dict[str, Any]:
    """The content of ``run.json`` (see the module docstring) of a run of ``kind`` (one axis or several:
    what differs, the scaling, the scenes and the per-axis summaries, comes from
    :meth:`DocumentKind.sections`); ``controller`` and ``summary`` may be None for
    a run that ended before it cycled (then ``extra`` carries the reason).  While the run goes on
    (``ended`` False) ``status`` is "running" and ``ended_utc`` None."""
    document: dict[str, Any] = {
        "status": extra.get("exit_reason", "ended") if ended else RUNNING,
        "ended": ended,
        "software": dict(software_versions()),
        "command": sys.argv,
        "started_utc": started.isoformat(),
        "ended_utc": _utc_now().isoformat() if ended else None,
        "profile": profile_identity(kind.profile),
        "settings": profile_to_dict(kind.profile),
        "link": link,
        **extra,
    }
    if controller is not None:
        document |= kind.sections(controller)
        document["events"] = controller.events.to_list()
        document["events_dropped"] = controller.events.dropped
        supervisor = controller.supervisor
        if supervisor is not None and supervisor.cycles:  # refused before its first cycle: nothing observed
            document.setdefault("loop", {})["delay_observed"] = supervisor.observed_delay()
    if summary is not None:
        document["summary"] = asdict(summary)
    return json_ready(document)


def scene_dicts(controller: WallController[SceneT, DecisionT],
                entry_dict: Callable[[SceneEntry[SceneT, DecisionT]], dict[str, Any]]) -> list[dict[str, Any]]:
    """Every scene ``controller`` had in effect, each as ``entry_dict`` gives it, JSON-ready (``run.json``'s ``scenes``)."""
    return json_ready([entry_dict(entry) for entry in list(controller.scenes.history)])


def gate_loop(device: DeviceLoop) -> dict[str, Any]:
    """The loop the gate judged the run's scenes with (``run.json``'s ``gate_loop``): ``m`` kg,
    ``b`` N s/m, ``T`` s, ``delay`` samples, ``velocity`` model; what the K-B plane is drawn for."""
    return {"m": device.m, "b": device.b, "T": device.T, "delay": device.delay, "velocity": str(device.velocity)}


class RunJournal:
    """``run.json`` over a run's life: written before anything is touched (``status`` "running",
    ``ended`` false), rewritten whenever the events or the scenes change (by the run's writer
    process, :mod:`~haptic_bus.app.run_writer`, from :meth:`document` and the events), and
    completed at the end (:meth:`finish`).  A run killed at any moment
    leaves it saying ``"ended": false``: :func:`read_run_folder` reports it as not ended cleanly.
    ``kind``: the run's kind, one axis or several (:func:`~haptic_bus.app.run_kinds.run_kind`)."""

    def __init__(self, folder: pathlib.Path, kind: DocumentKind, link: dict[str, Any], extra: dict[str, Any],
                 safety: SafetySettings | None = None) -> None:
        self.folder = folder
        self.safety = safety  # what the drives were given, shown as settings.safety (None: the profile's)
        self.path = folder / RUN_JSON
        self.kind = kind
        self.link = link
        self.extra = extra
        self.started = _utc_now()
        self.controller: WallController[Any, Any] | None = None

    def document(self, summary: RunSummary | None = None, ended: bool = False) -> dict[str, Any]:
        """``run.json``'s content as the run stands now; ``settings.safety`` what the drives were given."""
        document = run_document(self.kind, self.controller, summary, self.link, self.extra, self.started, ended)
        if self.safety is not None:
            shown = document["settings"]["safety"]
            document["settings"]["safety"] = {key: getattr(self.safety, key) for key in shown}
        return document

    def begin(self) -> None:
        """``run.json`` "running", before any bus is touched; ParameterError (exit 2) naming the
        folder if it cannot be written (a full disk)."""
        try:
            self.write()
        except OSError as exc:
            raise ParameterError("out_dir", str(self.folder), f"a folder this run can write ({exc.strerror} writing "
                                 f"{RUN_JSON})", "run") from None

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
    def writer(self) -> str | None:
        """The process id of the run still writing this folder (its lock held), or None: it ended, or its
        process is gone (:func:`~haptic_bus.app.folder_lock.holder`)."""
        return None if self.ended_cleanly else holder(self.path)

    @property
    def records(self) -> dict[str, RecordTable]:
        """Every record read, by file name."""
        one = {RECORD_CSV: self.record} if self.record is not None else {}
        return one | {record_name(axis): table for axis, table in self.axes.items()}

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
            writer = self.writer
            notes.append(f"{self.path}: the run of process {writer} is still writing it; so far {held}" if writer else
                         f"{self.path}: the run did not end cleanly (run.json still says {self.document.get('status')!r}: "
                         f"the process was killed or crashed); {held}")
        for name, table in self.records.items():
            if table.torn_line:
                notes.append(f"{self.path / name}: its last line was torn (written when the process died) and is left out")
        for name, written in self._rows_written().items():
            kept = self.records[name].cycles if name in self.records else 0
            if kept < written:
                notes.append(f"{self.path / name}: holds {kept} of the {written} cycles run.json says the run wrote "
                             "(cut short or removed since): the pictures show only what it holds")
        return notes

    def _rows_written(self) -> dict[str, int]:
        """The rows ``run.json`` of an ended run says each record file received, by file name (none
        where it says nothing: a run killed before it could)."""
        one, several = self.document.get("record"), self.document.get("records")
        counts = {RECORD_CSV: one} if isinstance(one, dict) else several if isinstance(several, dict) else {}
        return {name: count["rows_written"] for name, count in counts.items()
                if isinstance(count, dict) and isinstance(count.get("rows_written"), int)}


def read_run_folder(folder: str | pathlib.Path) -> RunFolder:
    """Read a run folder (``run.json`` and ``record.csv``); ParameterError naming what is missing or unreadable."""
    path = pathlib.Path(folder)
    if not (path / RUN_JSON).is_file():
        raise ParameterError("RUN_DIR", str(path), "a run folder: one with run.json (written by haptic-bus run or demo)",
                             "plot")
    document: Any = {}
    try:
        document = json.loads((path / RUN_JSON).read_text())
        if not isinstance(document, dict):
            raise ValueError("run.json is not a JSON object")
        check_drawn_fields(document)
        record = read_record(path / RECORD_CSV) if (path / RECORD_CSV).is_file() else None
        names = [axis["name"] for axis in document.get("settings", {}).get("axes", [])]
        axes = {name: read_record(path / record_name(name)) for name in names if (path / record_name(name)).is_file()}
        tables = [(RECORD_CSV, record)] if record is not None else []
        for name, table in tables + [(record_name(axis), table) for axis, table in axes.items()]:
            lacking = [column for column in DRAWN_COLUMNS if column not in table.columns]
            if table.columns and lacking:
                raise ValueError(f"{path / name} has no column {', '.join(lacking)}; the pictures draw "
                                 f"{', '.join(DRAWN_COLUMNS)}")
    except (OSError, ValueError, TypeError, KeyError) as exc:
        software = document.get("software") if isinstance(document, dict) else None
        written = software.get("haptic_bus") if isinstance(software, dict) else None
        other = f"; run.json written by haptic_bus {written}, this is {__version__}" if written not in (None, __version__) else ""
        raise ParameterError("RUN_DIR", str(path), f"a readable run folder ({exc}{other})", "plot") from None
    return RunFolder(path, document, record, axes)
