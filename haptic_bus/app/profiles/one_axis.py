"""The one-axis kind of profile: one handle on one drive, a scene on its line.

A one-axis profile says who uses it for what (``[profile]``), the handle and its drive (``[device]``), the
loop (``[loop]``), the simulated operator of a demo (``[operator_model]``) and what
``haptic-bus identify`` measured (``[identification]``, optional): those tables are read once, by
:mod:`haptic_bus.profile` (the simulated drive reads them through it too; a profile whose
``[device]`` or ``[loop]`` is more optimistic than its measurement is refused there).  The
controller's own tables are read here: the force limit (``[limits]``, N, at most what 0x6072
allows), the virtual objects (``[[scene.objects]]`` with ``kind`` = wall | slot | detent) and the
policies of :mod:`haptic_bus.app.profile_policies` (``[gate]``, ``[safety]``, ``[passivity]``,
``[supervisor]``, ``[start]``).

:func:`read_one_axis` validates the whole document (unknown keys, types, ranges, names); the loader
(:func:`haptic_bus.app.profiles.load_profile`) then puts the compiled scene through the passivity
gate (:meth:`Profile.judge`).  Errors name the file, the dotted field (``scene.objects[2].stiffness``,
0-based index), the value and the allowed range.
"""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from drives.base import DriveScaling
from drives.safety import SafetySettings
from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.analysis.transmission import Transmission
from haptic_bus.analysis.velocity import VelocityModel
from haptic_bus.app.profile_policies import (
    StartPolicy,
    read_about,
    read_gate,
    read_passivity,
    read_safety,
    read_start,
    read_supervisor,
)
from haptic_bus.control.gate import GateDecision, GatePolicy, PassivityGate
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.scene import CompiledScene, Detent, SceneObject, Slot, Wall, compile_scene, object_to_dict
from haptic_bus.control.supervisor import SupervisorPolicy
from haptic_bus.profile.device import DeviceTable, LoopTiming
from haptic_bus.profile.identification import IdentifiedDevice
from haptic_bus.profile.plant import ONE_AXIS_TABLES, read_plant
from haptic_bus.profile.reader import Reader
from haptic_bus.profile.scene import ObjectTable, read_force_limit, read_scene


@dataclass(frozen=True)
class Profile:
    """A validated one-axis profile (SI units): what :func:`~haptic_bus.app.profiles.read_profile` gives for a
    file without ``[[axes]]``; :func:`~haptic_bus.app.profiles.load_profile` also puts it through its gate
    (:func:`~haptic_bus.app.profiles.admit`)."""

    name: str
    operator: str
    task: str
    description: str
    device: DeviceTable
    loop: LoopTiming
    scene: tuple[SceneObject, ...]
    force_limit: float
    gate_policy: GatePolicy
    operator_model: Mapping[str, Any] = field(hash=False, compare=True)
    path: pathlib.Path | None = None
    safety: SafetySettings = field(default_factory=SafetySettings)
    supervisor: SupervisorPolicy = field(default_factory=SupervisorPolicy)
    start: StartPolicy = field(default_factory=StartPolicy)
    identification: IdentifiedDevice | None = None
    passivity: LayerPolicy = field(default_factory=LayerPolicy)

    def device_loop(self) -> DeviceLoop:
        """The loop the gate judges: m kg, effective b N s/m, T s, delay samples, velocity model, and
        the quantisation (encoder resolution, Coulomb friction) when the profile states its Coulomb friction."""
        d = self.device
        return DeviceLoop(d.mass, d.friction, self.loop.period, self.loop.delay, d.velocity, d.quantisation(),
                          transmission=d.transmission)

    @property
    def period(self) -> float:
        """The cycle period ``T`` (s), as a multi-axis profile's ``period``."""
        return self.loop.period

    def scaling(self) -> DriveScaling:
        """The drive-unit conversion of :mod:`drives.base`."""
        return self.device.scaling()

    def scalings(self) -> list[DriveScaling]:
        """Each axis' drive-unit conversion, in axis order (one), as a multi-axis profile's."""
        return [self.scaling()]

    def compiled_scene(self) -> CompiledScene:
        """The scene as the piecewise-affine law the controller evaluates."""
        return compile_scene(self.scene)

    def gate(self, delays: Sequence[float] = ()) -> PassivityGate:
        """A passivity gate for this profile's loop and policy; at the loop delay ``delays[0]`` (samples: a
        measured Modbus poll's, one axis) instead of the profile's own when given."""
        loop = self.device_loop()
        return PassivityGate(dataclasses.replace(loop, delay=delays[0]) if delays else loop, self.gate_policy)

    def judge(self) -> GateDecision:
        """The gate's decision on this profile's scene (accepted or not)."""
        return self.gate().judge(self.compiled_scene())

    def sim_device_parameters(self) -> dict[str, object]:
        """Keyword arguments of ``sim_drive.parameters.DeviceParameters`` for this device and loop
        (with the hidden truth: Coulomb friction, velocity noise and its seed)."""
        return self.device.sim_parameters(self.loop.period, self.loop.timing, self.loop.delay)


# --------------------------------------------------------------------------- the controller's tables

def _build(obj: ObjectTable) -> SceneObject:
    """The controller's scene object of a checked ``[[scene.objects]]`` table."""
    first, second = obj.where
    if obj.kind == "wall":
        return Wall(obj.name, first, int(second), obj.stiffness, obj.damping)
    kind = Slot if obj.kind == "slot" else Detent
    return kind(obj.name, first, second, obj.stiffness, obj.damping)


def read_one_axis(path: pathlib.Path, document: Mapping[str, Any]) -> Profile:
    """Validate the parsed one-axis profile ``document`` of the file ``path`` without judging it; raise ParameterError."""
    top = Reader(path, "", document)
    top.only(ONE_AXIS_TABLES)  # a misspelt table first, not the required one it hides
    name, operator, task, description = read_about(top)
    plant = read_plant(top)
    device = plant.device
    force_limit = read_force_limit(path, top.raw("limits", "a [limits] table"), device)
    policy = read_gate(path, top.raw("gate", "a [gate] table"))
    scene = tuple(_build(obj) for obj in read_scene(path, top.raw("scene", "a [scene] table with [[scene.objects]]")))
    safety = read_safety(path, top.raw("safety", "a [safety] table", default=None))
    passivity = read_passivity(path, top.raw("passivity", "a [passivity] table", default=None))
    supervisor = read_supervisor(path, top.raw("supervisor", "a [supervisor] table", default=None), passivity)
    start = read_start(path, top.raw("start", "a [start] table", default=None))
    top.done()
    return Profile(name, operator, task, description, device, plant.loop, scene, force_limit, policy,
                   plant.operator_model, path, safety, supervisor, start, plant.identification, passivity)


def _device_value(value: Any) -> Any:
    """One ``[device]`` value, JSON-ready: the velocity model as its TOML text, the transmission as its
    table (``stiffness`` N/m, ``damping`` N s/m, ``motor_mass`` kg), the rest as they are."""
    if isinstance(value, VelocityModel):
        return str(value)
    if isinstance(value, Transmission):
        return dataclasses.asdict(value)
    return value


def one_axis_to_dict(profile: Profile) -> dict[str, Any]:
    """A JSON-ready view of a one-axis profile (SI units, as in the TOML)."""
    d = profile.device
    return {
        "profile": {"name": profile.name, "operator": profile.operator, "task": profile.task,
                    "description": profile.description},
        "path": None if profile.path is None else str(profile.path),
        "device": {k: _device_value(v) for k, v in vars(d).items()} | {"max_force": d.max_force},
        "loop": {"period": profile.loop.period, "timing": profile.loop.timing, "delay": profile.loop.delay},
        "identification": None if profile.identification is None else profile.identification.as_table(),
        "limits": {"force_limit": profile.force_limit},
        "gate": {"safety_margin": profile.gate_policy.safety_margin, "bandwidth": profile.gate_policy.bandwidth},
        "scene": {"objects": [object_to_dict(o) for o in profile.scene]},
        "operator_model": dict(profile.operator_model),
        "safety": {k: getattr(profile.safety, k) for k in profile.safety.__dataclass_fields__ if k != "master_node_id"},
        "supervisor": {k: getattr(profile.supervisor, k) for k in profile.supervisor.__dataclass_fields__},
        "passivity": dataclasses.asdict(profile.passivity),
        "start": {k: getattr(profile.start, k) for k in profile.start.__dataclass_fields__},
    }
