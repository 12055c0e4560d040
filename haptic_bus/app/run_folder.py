"""Where a run keeps its record: ``runs/<UTC timestamp>-<profile>/`` (or ``--out``), always written.

The folder is created and probed for writing before any bus is touched (an unwritable one is
a :class:`~drives.errors.ParameterError`: exit 2).  Whatever ends the run, it receives:

- ``record.csv``: one row a cycle (:data:`haptic_bus.control.record.COLUMNS`);
- ``run.json``: software versions, the profile file and its SHA-256, device, loop (delay
  assumed and observed), link, scaling and where each factor came from, safety settings,
  every scene in effect (each object's K and B, the gate's margin per contact wall), the
  summary with its ``exit_reason``, and the events (uploads accepted and refused, alarms,
  derates, faults), each with its time;
- ``position_force.png`` and ``region.png``: the plots the demo draws.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import importlib.metadata
import json
import math
import pathlib
import platform
import sys
from dataclasses import asdict
from typing import Any

from haptic_bus._version import __version__
from haptic_bus.app.profiles import Profile, profile_to_dict
from haptic_bus.control.controller import RunSummary, WallController
from haptic_bus.validation import writable_folder

DEFAULT_ROOT = pathlib.Path("runs")
_DISTRIBUTIONS = ("numpy", "scipy", "python-can", "canopen", "pymodbus", "matplotlib")


def _utc_now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def prepare_run_folder(out: str | pathlib.Path | None, profile_name: str, root: pathlib.Path = DEFAULT_ROOT) -> pathlib.Path:
    """The run's folder, created and shown writable now: ``out``, or ``root/<UTC>-<profile>``
    (``-2``, ``-3``... if that exists).  ParameterError naming the folder otherwise."""
    if out is not None:
        path = pathlib.Path(out)
    else:
        stamp = _utc_now().strftime("%Y%m%dT%H%M%SZ")
        path = root / f"{stamp}-{profile_name}"
        n = 2
        while path.exists():
            path = root / f"{stamp}-{profile_name}-{n}"
            n += 1
    return writable_folder("--out", path, context="run")


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
                 link: dict[str, Any], extra: dict[str, Any], started: dt.datetime) -> dict[str, Any]:
    """The content of ``run.json`` (see the module docstring); ``controller`` and ``summary`` may
    be None for a run that ended before it cycled (then ``extra`` carries the reason)."""
    document: dict[str, Any] = {
        "software": software_versions(),
        "command": sys.argv,
        "started_utc": started.isoformat(),
        "ended_utc": _utc_now().isoformat(),
        "profile": profile_identity(profile),
        "settings": profile_to_dict(profile),
        "link": link,
        **extra,
    }
    if controller is not None:
        drive = controller.drive
        report = getattr(drive, "scaling_report", None)
        document["scaling"] = {"values": asdict(drive.scaling), "sources": getattr(drive, "scaling_sources", {}),
                               **(report.to_dict() if report is not None else {})}
        document["scenes"] = [entry.to_dict() for entry in controller.scenes.history]
        document["events"] = controller.events.to_list()
        document["events_dropped"] = controller.events.dropped
        supervisor = controller.supervisor
        if supervisor is not None:
            document.setdefault("loop", {})["delay_observed"] = supervisor.observed_delay()
    if summary is not None:
        document["summary"] = asdict(summary)
    return _finite(document)


def write_run(folder: pathlib.Path, profile: Profile, controller: WallController | None,
              document: dict[str, Any], plots: bool = True) -> list[pathlib.Path]:
    """Write ``record.csv``, the plots (unless not ``plots``) and ``run.json`` into ``folder``; the paths written."""
    written: list[pathlib.Path] = []
    if controller is not None and controller.record.total:
        written.append(controller.record.write_csv(folder / "record.csv"))
        if plots:
            written += write_plots(folder, profile, controller)
    path = folder / "run.json"
    document["files"] = [str(p) for p in written] + [str(path)]
    path.write_text(json.dumps(document, indent=1) + "\n")
    return [*written, path]


def write_plots(folder: pathlib.Path, profile: Profile, controller: WallController) -> list[pathlib.Path]:
    """``position_force.png`` (position, force, observer energy over time) and ``region.png``
    (the seed's Fig. 4 for the device, with the running wall marked)."""
    from haptic_bus.app.plots import plot_region
    from haptic_bus.app.run_plots import plot_run

    surfaces = [obj.position for obj in profile.scene if hasattr(obj, "position")]
    loop = controller.gate.device
    title = f"{profile.name}: {profile.loop.timing} timing, T = {loop.T * 1e3:g} ms"
    run_png = plot_run(folder / "position_force.png", controller.record, title, surfaces)
    main_wall = max(controller.decision.walls, key=lambda w: w.K, default=None)
    point = None if main_wall is None or main_wall.K == 0 or main_wall.B == 0 else (
        main_wall.B / (main_wall.K * loop.T), loop.b / main_wall.B)
    region_png = plot_region(folder / "region.png", loop.m, loop.b, loop.T, delay=loop.delay, point=point)
    return [run_png, region_png]
