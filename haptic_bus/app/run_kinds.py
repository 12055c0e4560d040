"""What a run does differently for a one-axis profile and a multi-axis one, behind one small interface.

The runner (:mod:`~haptic_bus.app.runner`) and the demo (:mod:`~haptic_bus.app.demo`) run either
kind through the same steps; only these differ:

- the scene (a 1-D :class:`~haptic_bus.control.scene.CompiledScene`, or a
  :class:`~haptic_bus.control.space_scene.SpaceScene`) and how pre-flight asks the gate for
  another loop delay (samples);
- where the handle is before enabling (m): one position, or one per joint mapped into space,
  and whether it is inside an object then;
- the controller's arguments (names, force limits in N) and where the supervisor's derate table
  is built (:mod:`~haptic_bus.app.derate_table`: at once for the 1-D gate, in the judge worker for
  the coupled gate, whose judgements of a scaled scene take seconds);
- ``run.json``'s sections that differ (``sections``: the scaling, the scenes --
  :meth:`~haptic_bus.control.scene_switch.SceneEntry.to_dict`, or
  :func:`~haptic_bus.app.space_records.space_scene_dict` -- and for several axes each axis'
  summary; :func:`~haptic_bus.app.run_folder.run_document` writes the rest alike for both) and
  which records are streamed (``record.csv``, or ``record-<axis>.csv`` per axis).

:func:`run_kind` picks the kind for a profile.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

from haptic_bus.app import preflight
from haptic_bus.app.derate_table import COUPLED_SCALE_STEPS, DerateTable, asks_derate
from haptic_bus.app.profile_policies import StartPolicy
from haptic_bus.app.profiles import AxesProfile, Profile
from haptic_bus.app.run_folder import RECORD_CSV, DocumentKind, gate_loop, record_name, scene_dicts
from haptic_bus.app.space_records import space_scene_dict
from haptic_bus.control.clock import CycleClock
from haptic_bus.control.controller import WallController
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.joints import encoder_origin, encoder_origins
from haptic_bus.control.record import RunRecord
from haptic_bus.control.scene import CompiledScene
from haptic_bus.control.scene_switch import SceneEntry
from haptic_bus.control.space_gate import SpaceGate
from haptic_bus.control.space_scene import SpaceScene
from haptic_bus.profile.device import ON_ARRIVAL
from haptic_bus.validation import some_names

Records = list[tuple[str, str, RunRecord]]  # (file name, axis name, record) as the recorder streams them


SceneT = TypeVar("SceneT")
GateT = TypeVar("GateT", contravariant=True)
OriginT = TypeVar("OriginT")


class RunKind(DocumentKind, Protocol[SceneT, GateT, OriginT]):
    """What the runner and the demo ask of a profile's kind (module docstring), ``run.json``'s
    sections among it (:class:`~haptic_bus.app.run_folder.DocumentKind`)."""

    @property
    def period(self) -> float: ...

    @property
    def on_arrival(self) -> bool: ...

    @property
    def zero_targets(self) -> int | list[int]: ...

    @property
    def start(self) -> StartPolicy: ...

    def loop_extra(self) -> dict[str, Any]: ...

    def scene(self, gate: GateT) -> SceneT: ...

    def scaling(self, drives: Sequence[Any]) -> dict[str, Any]: ...

    def describe_gate(self, gate: GateT, extra: dict[str, Any]) -> None: ...

    def assumed_delay(self, gate: GateT) -> float: ...

    def passes_at(self, gate: GateT, scene: SceneT) -> Callable[[float], bool]: ...

    def origin(self, drive: Any, sampled: bool = False) -> OriginT: ...

    def inside(self, scene: SceneT, origin: OriginT) -> str | None: ...

    def start_extra(self, origin: OriginT, ramp_time: float) -> dict[str, Any]: ...

    def derate(self, gate: GateT, scene: SceneT) -> DerateTable | None: ...

    def controller(self, drive: Any, gate: GateT, scene: SceneT, *, clock: CycleClock | None, origin: OriginT,
                   ramp_time: float = 0.0, hold: float | None = None,
                   derate: DerateTable | None = None) -> WallController[Any, Any]: ...

    def passivity_extra(self, controller: WallController[Any, Any], gate: GateT) -> dict[str, Any]: ...

    def records(self, controller: WallController[Any, Any]) -> Records: ...

    def scene_dicts(self, controller: WallController[Any, Any]) -> Callable[[], list[dict[str, Any]]]: ...


@dataclasses.dataclass(frozen=True)
class OneAxisRun:
    """A one-axis profile: the 1-D scene behind the :class:`PassivityGate`, one ``record.csv``."""

    profile: Profile

    @property
    def zero_targets(self) -> int:
        """What pre-flight writes every cycle: 0 per mille."""
        return 0

    @property
    def period(self) -> float:
        """The cycle's period ``T`` (s)."""
        return self.profile.period

    @property
    def on_arrival(self) -> bool:
        """Whether the drive applies a target as it arrives (:data:`~haptic_bus.profile.device.ON_ARRIVAL`)."""
        return self.profile.loop.timing in ON_ARRIVAL

    def loop_extra(self) -> dict[str, Any]:
        """``run.json``'s ``loop`` before the drive is reached."""
        return {"period": self.period, "timing": self.profile.loop.timing}

    def scene(self, gate: PassivityGate) -> CompiledScene:
        """The profile's scene, compiled (the gate judges it when the controller takes it)."""
        return self.profile.compiled_scene()

    def describe_gate(self, gate: PassivityGate, extra: dict[str, Any]) -> None:
        """The loop the gate judges with, in ``run.json`` (its delay in samples, the K-B plane's loop)."""
        extra["loop"]["delay_assumed"] = gate.device.delay
        extra["gate_loop"] = gate_loop(gate.device)

    def assumed_delay(self, gate: PassivityGate) -> float:
        """The loop delay (samples) the gate judged with."""
        return gate.device.delay

    def passes_at(self, gate: PassivityGate, scene: CompiledScene) -> Callable[[float], bool]:
        """The gate's verdict on ``scene`` at another loop delay (samples)."""
        return preflight.passes_at(gate, scene)

    def origin(self, drive: Any, sampled: bool = False) -> float:
        """The handle's position (m, 0x6064) before enabling (``sampled``: :func:`encoder_origin`'s)."""
        return encoder_origin(drive, sampled)

    def inside(self, scene: CompiledScene, origin: float) -> str | None:
        """Where the handle is if inside an object at ``origin`` (m), else None."""
        names, force, stiffness = scene.contact(origin)
        if force == 0.0:
            return None
        depth = abs(force) / stiffness if stiffness > 0 else math.nan
        return f"handle is {depth * 1e3:.1f} mm inside {some_names(names)} (at rest it would feel {abs(force):.3g} N)"

    def start_extra(self, origin: float, ramp_time: float) -> dict[str, Any]:
        """``run.json``'s ``start``: the position (m) and the ramp's time (s)."""
        return {"position_m": origin, "ramp_time_s": ramp_time}

    @property
    def start(self) -> StartPolicy:
        """The profile's ``[start]``."""
        return self.profile.start

    def derate(self, gate: PassivityGate, scene: CompiledScene) -> DerateTable | None:
        """The supervisor's derate table, built now (the 1-D gate's judgements take microseconds),
        when the profile's supervisor may derate; else None."""
        return DerateTable(gate, scene) if asks_derate(self.profile.supervisor) else None

    def controller(self, drive: Any, gate: PassivityGate, scene: CompiledScene, *, clock: CycleClock | None,
                   origin: float, ramp_time: float = 0.0, hold: float | None = None,
                   derate: DerateTable | None = None) -> WallController[Any, Any]:
        """The controller of this profile (``derate``: the supervisor's, :meth:`derate`)."""
        profile = self.profile
        return WallController(drive, gate, scene, force_limit=profile.force_limit, clock=clock, origin=origin,
                              supervisor=profile.supervisor, ramp_time=ramp_time, derate=derate,
                              passivity=profile.passivity, hold=hold, shared_records=True)

    def passivity_extra(self, controller: WallController[Any, Any], gate: PassivityGate) -> dict[str, Any]:
        """``run.json``'s ``passivity``: the layer, its budget per target (s), the port's cap (J), b (N s/m)."""
        return {"layer": self.profile.passivity.layer, "hold_s": controller.hold,
                "budget_cap_j": controller.ports[0].observer.cap, "friction_min": gate.device.b,
                "beyond_gate": self.profile.passivity.beyond_gate}

    def records(self, controller: WallController[Any, Any]) -> Records:
        """The one record, as ``record.csv``."""
        return [(RECORD_CSV, "", controller.record)]

    def scene_dicts(self, controller: WallController[Any, Any]) -> Callable[[], list[dict[str, Any]]]:
        """Every scene in effect so far, JSON-ready, when called."""
        return functools.partial(scene_dicts, controller, SceneEntry.to_dict)

    def scaling(self, drives: Sequence[Any]) -> dict[str, Any]:
        """``run.json``'s ``scaling`` once the drive is reached: its :func:`scaling_section`."""
        return scaling_section(drives[0])

    def sections(self, controller: WallController[Any, Any]) -> dict[str, Any]:
        """``run.json``'s ``scenes``."""
        return {"scenes": self.scene_dicts(controller)()}


@dataclasses.dataclass(frozen=True)
class AxesRun:
    """A multi-axis profile: the scene in space behind the coupled :class:`SpaceGate`, a record per axis."""

    profile: AxesProfile

    @property
    def period(self) -> float:
        """The one SYNC's period ``T`` (s)."""
        return self.profile.period

    @property
    def on_arrival(self) -> bool:
        """Whether any axis' drive applies a target as it arrives (:data:`~haptic_bus.profile.device.ON_ARRIVAL`)."""
        return any(axis.timing in ON_ARRIVAL for axis in self.profile.axes)

    @property
    def zero_targets(self) -> list[int]:
        """What pre-flight writes every cycle: 0 per mille to every axis."""
        return [0] * len(self.profile.axes)

    def loop_extra(self) -> dict[str, Any]:
        """``run.json``'s ``loop`` before the drives are reached: ``T`` and each axis' delay (samples)."""
        return {"period": self.period, "delays": [axis.delay for axis in self.profile.axes]}

    def scene(self, gate: SpaceGate) -> SpaceScene:
        """The profile's scene in space (the gate judges it when the controller takes it)."""
        return self.profile.compiled_scene()

    def describe_gate(self, gate: SpaceGate, extra: dict[str, Any]) -> None:
        """The loop delays (samples) the coupled gate judges with, per axis, in ``run.json``'s ``loop``
        (over Modbus, the poll's: not the profile's)."""
        extra["loop"]["delays"] = [loop.delay for loop in gate.axes]

    def assumed_delay(self, gate: SpaceGate) -> float:
        """The longest loop delay (samples) of the coupled gate's axes."""
        return max(loop.delay for loop in gate.axes)

    def passes_at(self, gate: SpaceGate, scene: SpaceScene) -> Callable[[float], bool]:
        """The coupled gate's verdict on ``scene`` with every axis' delay moved by the same samples."""
        assumed = self.assumed_delay(gate)

        def passes(delay: float) -> bool:
            return gate.later(delay - assumed).passes(scene)

        return passes

    def origin(self, drive: Any, sampled: bool = False) -> Sequence[float]:
        """Every joint's position (m, 0x6064) before enabling (``sampled``: :func:`encoder_origin`'s)."""
        return encoder_origins(drive, sampled)

    def inside(self, scene: SpaceScene, origin: Sequence[float]) -> str | None:
        """Where the handle is in space if inside an object with the joints at ``origin`` (m), else None."""
        x = self.profile.kinematics().position(list(origin))
        inside = scene.contacts(x)
        if not inside:
            return None
        force = float(sum(value * value for value in scene.force(x, [0.0] * len(origin))) ** 0.5)
        return (f"handle is inside {some_names(inside)} at ({', '.join(f'{c * 1e3:.3g}' for c in x)}) mm (at rest "
                f"it would feel {force:.3g} N)")

    def start_extra(self, origin: Sequence[float], ramp_time: float) -> dict[str, Any]:
        """``run.json``'s ``start``: every joint's position (m) and the ramp's time (s)."""
        return {"positions_m": list(origin), "ramp_time_s": ramp_time}

    @property
    def start(self) -> StartPolicy:
        """A multi-axis profile has no ``[start]``: the defaults (refuse; ramp over the default time)."""
        return StartPolicy()

    def derate(self, gate: SpaceGate, scene: SpaceScene) -> DerateTable | None:
        """The supervisor's derate table, built in the judge worker (the coupled gate's judgements of a
        scene with a sphere take seconds), when the profile's supervisor may derate; else None."""
        if not asks_derate(self.profile.supervisor):
            return None
        from haptic_bus.node.verdicts import judge_pool

        return DerateTable(gate, scene, COUPLED_SCALE_STEPS, judge_pool())

    def controller(self, drive: Any, gate: SpaceGate, scene: SpaceScene, *, clock: CycleClock | None,
                   origin: Sequence[float], ramp_time: float = 0.0, hold: float | None = None,
                   derate: DerateTable | None = None) -> WallController[Any, Any]:
        """The controller of every axis (each its name and force limit, N; ``derate``: the supervisor's)."""
        profile = self.profile
        return WallController(drive, gate, scene, names=[axis.name for axis in profile.axes],
                              force_limit=[axis.force_limit for axis in profile.axes], clock=clock,
                              origin=list(origin), supervisor=profile.supervisor, ramp_time=ramp_time,
                              derate=derate, passivity=profile.passivity, hold=hold, shared_records=True)

    def passivity_extra(self, controller: WallController[Any, Any], gate: SpaceGate) -> dict[str, Any]:
        """``run.json``'s ``passivity``: the layer (one per axis) and its budget per target (s)."""
        return {"layer": self.profile.passivity.layer, "hold_s": controller.hold, "per_axis": True}

    def records(self, controller: WallController[Any, Any]) -> Records:
        """Each axis' record, as ``record-<axis>.csv``."""
        return [(record_name(name), name, record) for name, record in zip(controller.names, controller.records)]

    def scene_dicts(self, controller: WallController[Any, Any]) -> Callable[[], list[dict[str, Any]]]:
        """Every scene in effect so far, JSON-ready, when called."""
        return functools.partial(scene_dicts, controller, space_scene_dict)

    def scaling(self, drives: Sequence[Any]) -> dict[str, Any]:
        """``run.json``'s ``scaling`` once the drives are reached (in axis order): each axis'
        :func:`scaling_section`, by the profile's axis name."""
        return {axis.name: scaling_section(drive) for axis, drive in zip(self.profile.axes, drives)}

    def sections(self, controller: WallController[Any, Any]) -> dict[str, Any]:
        """``run.json``'s ``scenes`` and ``axes`` (each axis' summary:
        :meth:`~haptic_bus.control.controller.WallController.axis_summaries`)."""
        return {"scenes": self.scene_dicts(controller)(), "axes": controller.axis_summaries()}


def scaling_section(drive: Any) -> dict[str, Any]:
    """One drive's scaling as ``run.json`` keeps it: its factors (``values``), where each came from
    (``sources``) and its scaling report (:class:`~drives.base.ScalingReport`), where it has them."""
    report = getattr(drive, "scaling_report", None)
    return {"values": dataclasses.asdict(drive.scaling), "sources": getattr(drive, "scaling_sources", {}),
            **(report.to_dict() if report is not None else {})}


def run_kind(profile: Profile | AxesProfile) -> RunKind[Any, Any, Any]:
    """The kind of run ``profile`` makes: one axis, or several (``[[axes]]``)."""
    return AxesRun(profile) if isinstance(profile, AxesProfile) else OneAxisRun(profile)
