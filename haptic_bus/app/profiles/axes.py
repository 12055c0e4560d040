"""The multi-axis kind of profile: ``[[axes]]``, each axis its own drive, a scene in space, the coupled gate.

A profile with an ``[[axes]]`` array describes a Cartesian device (axis ``i`` moves coordinate
``i``, :class:`~haptic_bus.control.kinematics.Cartesian`); a profile without it is the one-axis
kind (:mod:`haptic_bus.app.profiles.one_axis`).  Tables:

* ``[profile]``: ``name``, ``operator``, ``task``, ``description`` (as one-axis profiles);
* ``[loop]``: ``period`` T in s -- one SYNC for every axis;
* ``[bus]`` (optional): ``bitrate`` in bit/s (default 1 000 000) -- the bus-load check of a
  CANopen device runs on load (:mod:`haptic_bus.control.bus_load`: refused above 70 %);
* ``[gate]``: ``safety_margin`` (N s/m) and ``bandwidth`` as one-axis profiles (the bandwidth
  rule is a 1-D rule and is not applied to objects in space);
* ``[safety]`` (optional): as one-axis profiles, for every axis' drive;
* ``[passivity]`` and ``[supervisor]`` (optional): as one-axis profiles, for the port observer
  and the passivity layer of every axis and the run's supervisor (``derate`` scales the scene
  down to what the coupled gate passes at the observed delay: :mod:`haptic_bus.app.derate_table`);
* ``[[axes]]``, one table per axis, in coordinate order: ``name``; ``node_id`` (CANopen, 1..127)
  **or** ``unit_id`` (Modbus, 1..247), one kind for all axes; ``timing`` ("ideal", "cia402",
  "reception") and ``delay`` (samples, real; defaults as ``[loop]`` of a one-axis profile);
  ``mapping`` ("minimal" or "with-position", default "minimal"); ``force_limit`` (N, at most what
  the axis' 0x6072 allows); and ``[axes.device]``, the one-axis ``[device]`` table: ``mass``,
  ``friction`` (effective b), ``friction_source``, the scaling (0x606C, 0x6064, 0x6076,
  transmission, 0x6072) and the ``velocity`` model;
* ``[[space.objects]]``: ``kind`` = plane | box | sphere, ``name``, ``stiffness`` (N/m),
  ``damping`` (N s/m), and ``point`` + ``normal`` (plane), ``center`` + ``half`` (box) or
  ``center`` + ``radius`` (sphere), positions in m with one coordinate per axis;
* ``[space.operator]`` (optional): the simulated hand in space (``sim_drive.space_operator``):
  ``model`` = "none" or "push", with ``force`` (N), ``toward`` (a point, or a list of points, m)
  and ``dwell`` (s per point).

:func:`read_axes` validates everything (unknown keys, types, ranges, names; one-line errors naming
the file, the dotted field, the value and the allowed range) and checks the bus load (``loop.period``
refused with the load and the smallest T); the loader (:func:`haptic_bus.app.profiles.load_profile`)
then puts the scene through the coupled gate (:meth:`AxesProfile.judge`,
:class:`~haptic_bus.control.space_gate.SpaceGate`).
"""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from drives.base import DriveScaling
from drives.safety import SafetySettings
from haptic_bus.analysis.can_timing import BITRATE_RANGE, BusLoad
from haptic_bus.analysis.coupled_loop import MAX_AXES
from haptic_bus.analysis.loop import DAMPING_RANGE, PERIOD_RANGE, STIFFNESS_RANGE, WallLoop
from haptic_bus.app.profile_policies import NAME_PATTERN, read_about, read_gate, read_passivity, read_safety, read_supervisor
from haptic_bus.control.bus_load import PDO_MAPPINGS, axes_bus_load
from haptic_bus.control.gate import GatePolicy
from haptic_bus.control.kinematics import Cartesian
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.space_gate import SpaceDecision, SpaceGate
from haptic_bus.control.space_scene import (
    Box,
    Plane,
    SpaceObject,
    SpaceScene,
    Sphere,
    compile_space_scene,
    space_object_to_dict,
)
from haptic_bus.control.supervisor import SupervisorPolicy
from haptic_bus.errors import ParameterError
from haptic_bus.profile.device import DeviceTable, check_velocity_period, read_device, read_timing
from haptic_bus.profile.link import read_link
from haptic_bus.profile.reader import Reader, profile_error, refuse_duplicates
from haptic_bus.profile.scene import FORCE_RANGE, check_force_limit

DEFAULT_BITRATE = 1_000_000
HAND_MODELS = ("none", "push")
_FIELDS = {"plane": ("point", "normal"), "box": ("center", "half"), "sphere": ("center", "radius")}


@dataclass(frozen=True)
class Axis:
    """One checked ``[[axes]]`` table of a multi-axis profile: its ``name``, ``node_id`` (CANopen) or
    ``unit_id`` (Modbus), ``device`` (the one-axis device table), ``timing`` and loop ``delay`` (samples),
    PDO ``mapping``, ``force_limit`` (N)."""

    name: str
    node_id: int | None
    unit_id: int | None
    device: DeviceTable
    timing: str
    delay: float
    mapping: str
    force_limit: float


@dataclass(frozen=True)
class AxesProfile:
    """A validated multi-axis profile (SI units): what :func:`~haptic_bus.app.profiles.read_profile` gives for a
    file with ``[[axes]]``; :func:`~haptic_bus.app.profiles.load_profile` also puts it through the coupled gate
    (:func:`~haptic_bus.app.profiles.admit`)."""

    name: str
    operator: str
    task: str
    description: str
    period: float
    axes: tuple[Axis, ...]
    space: tuple[SpaceObject, ...]
    gate_policy: GatePolicy
    bitrate: float
    safety: SafetySettings = field(default_factory=SafetySettings)
    path: pathlib.Path | None = None
    passivity: LayerPolicy = field(default_factory=LayerPolicy)
    supervisor: SupervisorPolicy = field(default_factory=SupervisorPolicy)
    operator_model: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({"model": "none"}),
                                              hash=False, compare=True)

    def axis_loops(self) -> tuple[WallLoop, ...]:
        """Every axis' loop as the coupled gate judges it (m, effective b, T, its delay and velocity model)."""
        return tuple(WallLoop(a.device.mass, a.device.friction, self.period, 0.0, 0.0, a.delay, a.device.velocity)
                     for a in self.axes)

    def scalings(self) -> list[DriveScaling]:
        """Each axis' drive-unit conversion (:mod:`drives.base`), in axis order."""
        return [axis.device.scaling() for axis in self.axes]

    def compiled_scene(self) -> SpaceScene:
        """The scene in space, compiled (as a one-axis profile's ``compiled_scene``)."""
        return compile_space_scene(self.space)

    def gate(self, delays: Sequence[float] = ()) -> SpaceGate:
        """The coupled gate for these axes and this policy (what an upload path calls); at the loop delays
        ``delays`` (samples, one per axis: a measured Modbus poll's) instead of the axes' own when given."""
        loops = self.axis_loops()
        if delays:
            loops = tuple(dataclasses.replace(loop, delay=delay) for loop, delay in zip(loops, delays))
        return SpaceGate(loops, self.gate_policy)

    def judge(self) -> SpaceDecision:
        """The coupled gate's decision on this profile's scene (accepted or not)."""
        return self.gate().judge(self.compiled_scene())

    def kinematics(self) -> Cartesian:
        """The device's kinematics: Cartesian, axis i along coordinate i."""
        return Cartesian(len(self.axes))

    def bus_load(self) -> BusLoad | None:
        """The CANopen cycle's load (None for Modbus axes); ParameterError above 70 %."""
        if self.axes[0].node_id is None:
            return None
        return axes_bus_load([a.mapping for a in self.axes], self.bitrate, self.period)


def _read_axis(path: pathlib.Path, index: int, table: object, period: float) -> Axis:
    r = Reader(path, f"axes[{index}]", table)
    name = r.text("name", pattern=NAME_PATTERN)
    node, unit = read_link(r)
    timing, delay = read_timing(r)
    mapping = r.text("mapping", choices=tuple(PDO_MAPPINGS), default="minimal")
    device = read_device(path, r.raw("device", "an [axes.device] table: the one-axis [device] fields"), r.field("device"))
    if device.transmission is not None:  # the coupled gate judges rigid axes only
        raise profile_error(path, r.field("device.transmission"), device.transmission.to_dict(),
                            "none: the coupled gate judges rigid axes (a two-mass device only in a one-axis profile)")
    force_limit = r.real("force_limit", *FORCE_RANGE, "N", low_inclusive=False)
    r.done()
    check_force_limit(r.field("force_limit"), force_limit, device, f"profile {path}")
    check_velocity_period(path, r.field("device.velocity"), device, period)
    return Axis(name, node, unit, device, timing, delay, mapping, force_limit)


def _coordinates(r: Reader, key: str, size: int) -> tuple[Any, ...]:
    """An array of ``size`` entries (the object checks each is a position in range)."""
    value = r.raw(key, f"an array of {size} numbers (one per axis, m)")
    if not isinstance(value, list) or len(value) != size:
        raise profile_error(r.path, r.field(key), value, f"an array of {size} numbers, one per axis")
    return tuple(value)


def _read_object(path: pathlib.Path, index: int, table: object, size: int) -> SpaceObject:
    r = Reader(path, f"space.objects[{index}]", table)
    kind = r.text("kind", choices=tuple(_FIELDS))
    name = r.text("name", pattern=NAME_PATTERN)
    stiffness = r.real("stiffness", *STIFFNESS_RANGE, "N/m")
    damping = r.real("damping", *DAMPING_RANGE, "N s/m")
    where, extent = _FIELDS[kind]
    position = _coordinates(r, where, size)
    shape: Any = r.real("radius", 0.0, 1e6, "m", low_inclusive=False) if kind == "sphere" else _coordinates(r, extent, size)
    r.done()
    try:
        if kind == "plane":
            return Plane(name, position, shape, stiffness, damping)
        return Box(name, position, shape, stiffness, damping) if kind == "box" else Sphere(name, position, shape, stiffness,
                                                                                            damping)
    except ParameterError as error:
        raise profile_error(path, f"space.objects[{index}].{error.name}", error.value, error.allowed) from None


def _read_hand(path: pathlib.Path, table: object, size: int) -> Mapping[str, Any]:
    """``[space.operator]``: the simulated hand in space (module docstring), checked here, built by the simulator."""
    if table is None:
        return MappingProxyType({"model": "none"})
    r = Reader(path, "space.operator", table)
    model = r.text("model", choices=HAND_MODELS)
    out: dict[str, Any] = {"model": model}
    if model == "push":
        out["force"] = r.real("force", 0.0, 1e6, "N")
        toward = r.raw("toward", f"a point of {size} coordinates (m), or a list of them")
        points: list[Any] = toward if isinstance(toward, list) and toward and isinstance(toward[0], list) else [toward]
        if not all(isinstance(p, list) and len(p) == size and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                                                   and abs(c) <= 1e6 for c in p) for p in points):
            raise profile_error(path, r.field("toward"), toward, f"a point of {size} coordinates (m), or a list of them")
        out["toward"] = [[float(c) for c in p] for p in points]
        if "dwell" in r.table:
            out["dwell"] = r.real("dwell", 0.0, 1e9, "s", low_inclusive=False)
    r.done()
    return MappingProxyType(out)


def read_axes(path: pathlib.Path, document: Mapping[str, Any]) -> AxesProfile:
    """Validate the parsed multi-axis profile ``document`` of the file ``path`` and check its bus load, without
    judging its scene; raise ParameterError (the bus load above 70 %: ``loop.period`` with the load and the smallest T)."""
    top = Reader(path, "", document)
    name, operator, task, description = read_about(top)
    loop = Reader(path, "loop", top.raw("loop", "a [loop] table with the period"))
    period = loop.real("period", *PERIOD_RANGE, "s")
    loop.done()
    bus = Reader(path, "bus", top.raw("bus", "a [bus] table", default={}))
    bitrate = bus.real("bitrate", *BITRATE_RANGE, "bit/s", default=float(DEFAULT_BITRATE))
    bus.done()
    tables = top.raw("axes", f"an array of 1 to {MAX_AXES} tables [[axes]]")
    if not isinstance(tables, list) or not 1 <= len(tables) <= MAX_AXES:
        raise profile_error(path, "axes", tables, f"an array of 1 to {MAX_AXES} tables [[axes]], one per axis")
    axes = tuple(_read_axis(path, i, table, period) for i, table in enumerate(tables))
    refuse_duplicates(path, "axes", "name", [a.name for a in axes])
    refuse_duplicates(path, "axes", "node_id", [a.node_id for a in axes])
    refuse_duplicates(path, "axes", "unit_id", [a.unit_id for a in axes])
    if len({a.node_id is None for a in axes}) > 1:
        raise profile_error(path, "axes", [a.node_id or a.unit_id for a in axes],
                            "one kind of bus for every axis: all node_id (CANopen) or all unit_id (Modbus)")
    policy = read_gate(path, top.raw("gate", "a [gate] table"))
    safety = read_safety(path, top.raw("safety", "a [safety] table", default=None))
    passivity = read_passivity(path, top.raw("passivity", "a [passivity] table", default=None))
    supervisor = read_supervisor(path, top.raw("supervisor", "a [supervisor] table", default=None), passivity)
    space = Reader(path, "space", top.raw("space", "a [space] table with [[space.objects]]"))
    objects = space.raw("objects", "an array of tables [[space.objects]] (may be empty)", default=[])
    if not isinstance(objects, list):
        raise profile_error(path, "space.objects", objects, "an array of tables [[space.objects]]")
    hand = _read_hand(path, space.raw("operator", "a [space.operator] table", default=None), len(axes))
    space.done()
    top.done()
    scene = tuple(_read_object(path, i, table, len(axes)) for i, table in enumerate(objects))
    refuse_duplicates(path, "space.objects", "name", [obj.name for obj in scene])
    profile = AxesProfile(name, operator, task, description, period, axes, scene, policy, bitrate, safety, path,
                          passivity, supervisor, hand)
    try:
        profile.bus_load()
    except ParameterError as error:
        raise profile_error(path, "loop.period", period, error.allowed) from None
    return profile


def axes_to_dict(profile: AxesProfile) -> dict[str, Any]:
    """A JSON-ready view of a multi-axis profile as run (SI units): who and what (as a one-axis profile's
    ``profile`` and ``path``), loop, bus, every axis, the objects, the policies."""
    return {
        "profile": {"name": profile.name, "operator": profile.operator, "task": profile.task,
                    "description": profile.description},
        "path": None if profile.path is None else str(profile.path),
        "loop": {"period": profile.period}, "bus": {"bitrate": profile.bitrate},
        "axes": [{"name": a.name, "node_id": a.node_id, "unit_id": a.unit_id, "timing": a.timing, "delay": a.delay,
                  "mapping": a.mapping, "force_limit": a.force_limit,
                  "device": {**{k: v for k, v in dataclasses.asdict(a.device).items() if k != "velocity"},
                             "velocity": str(a.device.velocity)}} for a in profile.axes],
        "space": {"objects": [space_object_to_dict(obj) for obj in profile.space], "operator": dict(profile.operator_model)},
        "gate": dataclasses.asdict(profile.gate_policy), "safety": dataclasses.asdict(profile.safety),
        "passivity": dataclasses.asdict(profile.passivity), "supervisor": dataclasses.asdict(profile.supervisor),
    }
