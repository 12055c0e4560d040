"""``haptic-bus validate``'s run: the probe through the one runtime's cycle, then the verdict.

:class:`ValidateRun` is the one-axis run kind (:class:`~haptic_bus.app.run_kinds.OneAxisRun`)
with the probe's scene instead of the profile's: :func:`haptic_bus.app.runner.run` reaches and
commissions the drive, runs pre-flight in real time, streams ``record.csv`` and ``run.json`` into
the run's folder and cycles the :class:`~haptic_bus.control.controller.WallController` -- the same
cycle a wall runs in, no second loop.  What differs from a wall's run, and why:

- the scene is the :class:`~haptic_bus.validate.probe.ProbeScene`: the gentle hold (judged by the
  run's gate at its loop) plus the probe;
- the handle is never "inside" it: the hold is centred where the handle rests at the first cycle;
- the passivity layer is off: the probe is a known, bounded active source, and the port's observer
  sees it as energy taken out (about the kinetic and spring energy it stores), which the layer
  would answer by clipping the probe.  The observer still watches: its limit is raised to
  :data:`ENERGY_MARGIN` times the most energy the model says the probe can store at its largest
  peak, so a device storing far more than predicted still ends the run (exit 3);
- no derate: the hold is never scaled down mid-probe; a profile's "derate" on lateness warns
  instead (the jitter shows in the measurement's scatter) and on the observer stops;
- it lasts the plan's cycles exactly (:class:`~haptic_bus.validate.probe.ProbePlan`).

:func:`validate_drive` does all of it and returns the run's end and, when the run completed, the
:class:`~haptic_bus.validate.verdict.Validation` with its pictures in the folder.
"""

from __future__ import annotations

import dataclasses
import json
import math
import pathlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from haptic_bus.analysis.loop import DeviceLoop
from haptic_bus.app.derate_table import DerateTable
from haptic_bus.app.profiles import Profile
from haptic_bus.app.run_folder import VALIDATE_JSON
from haptic_bus.app.run_kinds import OneAxisRun
from haptic_bus.app.run_options import RunOptions, StopRequest
from haptic_bus.app.runner import RunResult, run
from haptic_bus.control.clock import CycleClock
from haptic_bus.control.controller import WallController
from haptic_bus.control.gate import PassivityGate
from haptic_bus.control.passivity_layer import LayerPolicy
from haptic_bus.control.scene import CompiledScene
from haptic_bus.control.supervisor import Action
from haptic_bus.errors import Refusal
from haptic_bus.validate.model import Hold, Prediction, predict
from haptic_bus.validate.probe import AmplitudeRule, Probe, ProbePlan, ProbeScene, gentle_hold, hold_scene
from haptic_bus.validate.verdict import DEFAULT_TOLERANCE, Signals, Validation, validate

ENERGY_MARGIN = 20.0  # times the most energy the probe stores in the model: the observer's limit


@dataclasses.dataclass(frozen=True)
class ValidateRun(OneAxisRun):
    """The probe as a one-axis run kind (module docstring): ``travel`` m either side of the rest
    position bounds the probe; ``hold`` and ``plan`` are decided for the profile's gate before the
    run; the probe's amplitude is designed for the run's own gate (its loop: over Modbus, the poll's
    delay), when the run hands it over (:meth:`scene`)."""

    travel: float
    hold: Hold
    plan: ProbePlan
    stop: StopRequest

    @classmethod
    def prepare(cls, profile: Profile, travel: float, stop: StopRequest) -> ValidateRun:
        """The hold and the plan for the profile's gate (Refusal if no gentle hold passes it); ``stop``
        is asked of when the handle leaves the travel (:class:`~haptic_bus.validate.probe.Probe`)."""
        loop = profile.device_loop()
        hold = gentle_hold(loop, profile.gate())
        return cls(profile, travel, hold, ProbePlan.for_loop(loop, hold), stop)

    @property
    def duration(self) -> float:
        """The run's length, s: every cycle of the plan."""
        return self.plan.cycles * self.plan.period

    def predict(self, gate: PassivityGate) -> Prediction:
        """The model's response to the probe at the loop ``gate`` judges (:func:`~haptic_bus.validate.model.predict`)."""
        return predict(gate.device, self.hold, self.plan.theta)

    def scene(self, gate: PassivityGate) -> ProbeScene:
        """The hold with the probe, its amplitude rule designed for the gate's loop; Refusal if the gate refuses the hold."""
        loop = gate.device
        if not gate.passes(hold_scene(self.hold)):
            raise Refusal(f"the hold (K = {self.hold.stiffness:.3g} N/m, B = {self.hold.damping:.3g} N s/m) does not pass "
                          f"the gate at the loop this link has ({loop.describe()})")
        scaling = self.profile.scaling()
        limit = min(self.profile.force_limit, scaling.max_force)
        rule = AmplitudeRule.design(self.plan, self.predict(gate), scaling.velocity_per_count,
                                    scaling.newton_per_permille, limit, self.travel)
        probe = Probe(self.plan, rule, self.travel, lambda: self.stop.ask(left_travel_said(probe)))  # run.json says why
        return ProbeScene.holding(self.hold, probe)

    def inside(self, scene: CompiledScene, origin: float) -> str | None:
        """Never inside: the hold is centred where the handle rests."""
        return None

    def derate(self, gate: PassivityGate, scene: CompiledScene) -> DerateTable | None:
        """None: the hold is not scaled down mid-probe (module docstring)."""
        return None

    def controller(self, drive: Any, gate: PassivityGate, scene: CompiledScene, *, clock: CycleClock | None,
                   origin: float, ramp_time: float = 0.0, hold: float | None = None,
                   derate: DerateTable | None = None) -> WallController[Any, Any]:
        """The controller rendering the probe: no passivity layer, the observer's limit raised, no
        derate (module docstring)."""
        profile = self.profile
        policy = profile.supervisor
        assert isinstance(scene, ProbeScene)  # what :meth:`scene` gave the run
        energy = _stored_energy(self.predict(gate), self.plan, self.hold, gate.device, scene.probe.rule)
        supervisor = dataclasses.replace(
            policy, observer_limit=max(policy.observer_limit, ENERGY_MARGIN * energy),
            on_late=Action.WARN.value if policy.on_late == Action.DERATE.value else policy.on_late,
            on_observer=Action.STOP.value if policy.on_observer == Action.DERATE.value else policy.on_observer)
        return WallController(drive, gate, scene, force_limit=profile.force_limit, clock=clock, origin=origin,
                              supervisor=supervisor, passivity=LayerPolicy("off"), hold=hold, shared_records=True)

    def passivity_extra(self, controller: WallController[Any, Any], gate: PassivityGate) -> dict[str, Any]:
        """``run.json``'s ``passivity``: the layer off for the probe, the observer's raised limit (J)."""
        return {"layer": "off", "why": "haptic-bus validate: the probe is a known active source",
                "observer_limit_j": controller.supervisor.policy.observer_limit if controller.supervisor else None,
                "friction_min": gate.device.b}


def _stored_energy(prediction: Prediction, plan: ProbePlan, hold: Hold, loop: DeviceLoop, rule: AmplitudeRule) -> float:
    """The most kinetic and hold-spring energy (J) the model says the probe stores at its largest peak."""
    velocity, position = plan.steady(prediction.velocity), plan.steady(prediction.position)
    energy = 0.5 * loop.m * velocity**2 + 0.5 * hold.stiffness * position**2
    return float(np.max(energy)) * rule.ceiling**2


@dataclasses.dataclass
class ValidateOutcome:
    """How the run ended (``result``) and, when it completed, the ``validation`` and the files written;
    ``cannot_tell``: why the run could not measure (the handle left the travel), None otherwise."""

    result: RunResult
    validation: Validation | None
    files: list[pathlib.Path]
    cannot_tell: str | None = None


def validate_drive(profile: Profile, bus: Mapping[str, Any] | str, options: RunOptions, *, travel: float,
                   node_id: int | None = None, unit_id: int | None = None, controller_node_id: int = 127,
                   tolerance: float = DEFAULT_TOLERANCE, pictures: bool = True) -> ValidateOutcome:
    """Validate ``profile``'s model on the drive ``bus`` names (as :func:`~haptic_bus.app.runner.run`);
    ``options.duration`` is replaced by the plan's.  Refusal (nothing enabled) if no gentle hold passes the gate."""
    kind = ValidateRun.prepare(profile, travel, options.stop)
    options = dataclasses.replace(options, duration=kind.duration, plots=False)
    result = run(profile, bus, options, node_id=node_id, unit_id=unit_id, controller_node_id=controller_node_id, kind=kind)
    files = list(result.files)
    controller = result.controller
    scene = controller.scenes.history[0].scene if controller is not None else None  # as ValidateRun.scene gave it
    if isinstance(scene, ProbeScene) and scene.probe.left is not None:
        return _left_travel(result, files, scene.probe)
    if result.exit_reason != "completed" or controller is None or controller.cycles != kind.plan.cycles:
        return ValidateOutcome(result, None, files)
    gate = controller.gate  # validate derates nothing: the gate is the run's own
    assert isinstance(scene, ProbeScene) and isinstance(gate, PassivityGate)
    probe = scene.probe
    record = controller.record
    scaling = controller.axes.scalings[0]
    signals = Signals(record.column("velocity_m_per_s"), record.column("position_m"),
                      record.column("torque_permille") * scaling.newton_per_permille, probe.forces(kind.plan.cycles),
                      (scaling.velocity_per_count, scaling.position_per_count, scaling.newton_per_permille))
    validation = validate(gate.device, kind.hold, kind.plan, kind.predict(gate), signals, probe.amplitude,
                          probe.noise, tolerance)
    document = {**validation.to_dict(), "summary": validation.summary(), "folder": str(result.folder)}
    path = result.folder / VALIDATE_JSON
    path.write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    files.append(path)
    if pictures:
        from haptic_bus.app.validate_plots import draw

        margin = gate.judge(profile.compiled_scene()).worst_margin  # the run's gate, at its loop
        files += draw(validation, result.folder, None if margin is None or math.isinf(margin) else margin)
    return ValidateOutcome(result, validation, files)


def left_travel_said(probe: Probe) -> str:
    """What validate says of a ``probe`` that found the handle beyond its travel: how far (mm), when (s after
    the probe began, or in the quiet hold before it: the cycle times the period, less the quiet phase's
    cycles) and what to do.  The run stops at that cycle, its drive disabled where the handle is."""
    cycle, offset = probe.left or (0, 0.0)
    plan = probe.plan
    when = (f"{(cycle - plan.quiet) * plan.period:.3g} s into the probe" if cycle >= plan.quiet else
            f"{cycle * plan.period:.3g} s into the quiet hold, before the probe began")
    return (f"cannot tell: the handle went {offset * 1e3:+.4g} mm from where it rested, {when}, beyond --travel "
            f"{probe.travel * 1e3:.4g} mm either side (the probe moves it at most half that): something else pushes "
            "it (a hand, gravity, a spring); the run stopped there, its drive disabled -- validate needs the handle "
            "free, as identify does")


def _left_travel(result: RunResult, files: list[pathlib.Path], probe: Probe) -> ValidateOutcome:
    """The run that ended because the handle left the travel: ``cannot tell`` in ``validate.json`` and the
    outcome, saying how far, when and what to do (the command's exit 1; :func:`left_travel_said`)."""
    cycle, offset = probe.left or (0, 0.0)
    said = left_travel_said(probe)
    document = {"verdict": "cannot tell", "summary": said, "folder": str(result.folder),
                "left_travel": {"time_s": cycle * probe.plan.period, "offset_m": offset, "travel_m": probe.travel}}
    path = result.folder / VALIDATE_JSON
    path.write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    return ValidateOutcome(result, None, [*files, path], said)
