"""What a multi-axis run keeps: one record per axis, ``run.json`` with every axis, the trajectory plot.

Written as one axis' run is (:class:`~haptic_bus.app.run_recorder.RunRecorder`: the run's writer
process streams the records and keeps ``run.json`` current, written atomically, from before the
first cycle; a killed run keeps them), its folder created before any bus is touched
(:func:`~haptic_bus.app.run_folder.prepare_run_folder`), it receives:

- ``record-<axis>.csv``, one per axis (``record-x.csv``, ``record-y.csv``, ...), each with the
  one-axis record's columns (:data:`haptic_bus.control.record.COLUMNS`): that axis' joint
  position and velocity, the wall force along it (``force_n``, the joint effort ``J^T u``), its
  target torque, its own port energy ``E_i`` (``energy_j``), the force its layer took off, and
  the cycle's scene id, lateness flag and compute time (the same in every file).  One file per
  axis, not columns per axis: each reads like a one-axis record, and the rows of all files are
  the same cycles (the same ``time_s``);
- ``run.json``: software versions, the profile (file, SHA-256, every axis and object), the link
  (bus, node ids, each axis' safety warnings and mapping notes, the bus load), each axis' scaling,
  the scenes in effect with the coupled gate's margins, the summary (the whole port: ``energy``
  is ``sum E_i``) and per axis (``axes``), the events, and how the run ended;
- ``bus.asc``: every frame of the one bus handle (:mod:`~haptic_bus.app.bus_log`);
- ``trajectory.png`` (:mod:`~haptic_bus.app.axes_plots`, drawn from the files as ``haptic-bus
  plot`` draws it): the trajectory in its plane of motion against the objects, the positions and
  forces over time.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import math
import sys
from typing import Any

from haptic_bus.app.profiles import AxesProfile
from haptic_bus.app.run_folder import RUNNING, software_versions
from haptic_bus.control.controller import WallController
from haptic_bus.control.cycle_loop import RunSummary
from haptic_bus.control.record import RunRecord
from haptic_bus.control.space_gate import SpaceDecision
from haptic_bus.control.space_scene import Box, Plane, SpaceObject, SpaceScene, Sphere


def object_dict(obj: SpaceObject) -> dict[str, Any]:
    """One object of a scene in space, JSON-ready."""
    fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if not f.name.startswith("_")}
    return {"kind": type(obj).__name__.lower(), **fields}


def decision_dict(decision: SpaceDecision) -> dict[str, Any]:
    """The coupled gate's decision: accepted, the least margin, every wall judged."""
    return {"accepted": decision.accepted, "worst_margin": decision.worst_margin,
            "walls": [{"objects": list(w.objects), "margin": w.verdict.margin, "outcome": w.verdict.outcome,
                       "parts": [{"K": K, "B": B, "normal": list(n)} for K, B, n in w.parts]} for w in decision.walls]}


def axes_profile_dict(profile: AxesProfile) -> dict[str, Any]:
    """The multi-axis profile as run: loop, bus, every axis, the objects, the policies."""
    return {
        "name": profile.name, "period": profile.period, "bitrate": profile.bitrate,
        "axes": [{"name": a.name, "node_id": a.node_id, "unit_id": a.unit_id, "timing": a.timing, "delay": a.delay,
                  "mapping": a.mapping, "force_limit": a.force_limit,
                  "device": {**{k: v for k, v in dataclasses.asdict(a.device).items() if k != "velocity"},
                             "velocity": str(a.device.velocity)}} for a in profile.axes],
        "space": {"objects": [object_dict(obj) for obj in profile.space], "operator": dict(profile.operator_model)},
        "gate": dataclasses.asdict(profile.gate_policy), "safety": dataclasses.asdict(profile.safety),
        "passivity": dataclasses.asdict(profile.passivity), "supervisor": dataclasses.asdict(profile.supervisor),
    }


def _json_ready(value: Any) -> Any:
    """JSON without NaN/inf (as strings) and with tuples as lists."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    return value


def axes_run_document(profile: AxesProfile, controller: WallController[SpaceScene, SpaceDecision] | None,
                      summary: RunSummary | None,
                      link: dict[str, Any], extra: dict[str, Any], started: dt.datetime, ended: bool = True
                      ) -> dict[str, Any]:
    """The content of ``run.json`` (module docstring); ``controller``/``summary`` None for a run
    that ended before it cycled (``extra`` then carries the reason).  While the run goes on
    (``ended`` False) ``status`` is "running" and ``ended_utc`` None (a :class:`~haptic_bus.app.run_folder.RunJournal`
    renders it)."""
    path = profile.path
    document: dict[str, Any] = {
        "status": extra.get("exit_reason", "ended") if ended else RUNNING,
        "ended": ended,
        "software": software_versions(),
        "command": sys.argv,
        "started_utc": started.isoformat(),
        "ended_utc": dt.datetime.now(dt.UTC).isoformat() if ended else None,
        "profile": {"name": profile.name, "path": None if path is None else str(path),
                    "sha256": hashlib.sha256(path.read_bytes()).hexdigest() if path is not None and path.is_file() else None},
        "settings": axes_profile_dict(profile),
        "link": link,
        **extra,
    }
    if controller is not None:
        scalings = controller.axes.scalings
        document["scaling"] = {name: dataclasses.asdict(s) for name, s in zip(controller.names, scalings)}
        document["scenes"] = space_scene_dicts(controller)
        document["axes"] = controller.axis_summaries()
        document["events"] = controller.events.to_list()
        document["events_dropped"] = controller.events.dropped
        if controller.supervisor is not None:
            document.setdefault("loop", {})["delay_observed"] = controller.supervisor.observed_delay()
    if summary is not None:
        document["summary"] = dataclasses.asdict(summary)
    return _json_ready(document)


def space_scene_dicts(controller: WallController[SpaceScene, SpaceDecision]) -> list[dict[str, Any]]:
    """Every scene ``controller`` had in effect, JSON-ready (``run.json``'s ``scenes``)."""
    return _json_ready([{"scene_id": entry.scene_id, "origin": entry.origin,
                         "objects": [object_dict(o) for o in entry.scene.objects],
                         "decision": decision_dict(entry.decision)} for entry in list(controller.scenes.history)])


def record_files(controller: WallController[SpaceScene, SpaceDecision]) -> list[tuple[str, str, RunRecord]]:
    """Each axis' record and its file, ``record-<axis>.csv`` (what :class:`~haptic_bus.app.run_recorder.RunRecorder` streams)."""
    return [(record_name(name), name, record) for name, record in zip(controller.names, controller.records)]


def record_name(axis: str) -> str:
    """The file of axis ``axis``' record."""
    return f"record-{axis}.csv"


def space_objects(document: dict[str, Any]) -> list[SpaceObject]:
    """The objects of the last scene ``run.json``'s ``document`` names (for the trajectory's picture)."""
    kinds = {cls.__name__.lower(): cls for cls in (Plane, Box, Sphere)}
    scenes = document.get("scenes") or [{"objects": document["settings"]["space"]["objects"]}]
    objects: list[SpaceObject] = []
    for entry in scenes[-1]["objects"]:
        fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in entry.items() if k != "kind"}
        objects.append(kinds[entry["kind"]](**fields))
    return objects
