"""The scene a running controller renders, and every change to it, each through the gate.

Uploads through the Python API are judged in the caller's thread and staged; an upload judged
elsewhere (the controller node's, in a worker process: :func:`changed_scene` builds the scene
there) is staged with its decision (:meth:`SceneSwitch.stage`), never judged again.  The control
loop adopts the last accepted one at a cycle boundary, whole, by reference (nothing is ever
cleared, so no upload can be lost between a read and a clear).
Every scene that is ever in effect gets an id; the history keeps its objects and the gate's
decision (what ``run.json`` reports).  A derate (the supervisor's) is adopted at once by the
control thread itself.

With ``beyond_gate`` (a ``bound`` passivity layer that guarantees passivity at run time, opted
into by the profile) a scene the gate refuses is admitted all the same: its decision, refused,
stays in the history and the event says so.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from haptic_bus.control.gate import GateDecision, GateRefusal, PassivityGate
from haptic_bus.control.record import EventLog
from haptic_bus.control.scene import CompiledScene, compile_scene, object_to_dict
from haptic_bus.errors import HapticBusError, ParameterError


class StaleJudgement(HapticBusError):
    """A scene judged elsewhere arrived after the scene or the gate it was judged against changed."""


def changed_scene(base: CompiledScene, changes: dict[str, tuple[float, float]]) -> CompiledScene:
    """``base`` with several objects' ``(K, B)`` (N/m, N s/m) changed; ParameterError for an object
    it does not have, or an invalid value."""
    objects = base.by_name()
    unknown = sorted(set(changes) - set(objects))
    if unknown:
        raise ParameterError("object", unknown[0], f"one of {sorted(objects)}", "scene")
    return compile_scene([obj.with_parameters(*changes[obj.name]) if obj.name in changes else obj
                          for obj in base.objects])


@dataclass(frozen=True)
class SceneEntry:
    """A scene that was in effect (or staged): its id, where it came from, the gate's decision."""

    scene_id: int
    origin: str
    scene: CompiledScene
    decision: GateDecision

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every object (its kind, geometry, K and B), and the gate's margin for each contact wall."""
        return {
            "scene_id": self.scene_id,
            "origin": self.origin,
            "objects": [object_to_dict(o) for o in self.scene.objects],
            "walls": [{"objects": list(w.objects), "K": w.K, "B": w.B, "margin": w.verdict.margin,
                       "critical_theta": w.verdict.critical_theta} for w in self.decision.walls],
            "worst_margin": self.decision.worst_margin,
            "warnings": list(self.decision.warnings),
        }


class SceneSwitch:
    """Switches a running controller's scene, gated, at a cycle boundary: the running scene, the
    last accepted one, and their history (module docstring).  (Not :class:`~haptic_bus.control.scene.Slot`,
    a scene object: a box the handle is held inside.)

    ``now`` gives the run's clock (s) for events; ``events`` receives "upload" and "refused";
    ``beyond_gate``: admit scenes the gate refuses (module docstring).
    """

    def __init__(self, gate: PassivityGate, scene: CompiledScene, events: EventLog, now: Callable[[], float],
                 beyond_gate: bool = False) -> None:
        self.gate = gate
        self.events = events
        self.beyond_gate = beyond_gate
        self._now = now
        self._lock = threading.Lock()
        first = SceneEntry(0, "profile", scene, self._decide(scene))
        self.history: list[SceneEntry] = [first]
        self.running = first
        self._latest = first
        self.applied = 0  # scenes adopted after the first

    @property
    def latest(self) -> SceneEntry:
        """The last accepted scene (running, or staged for the next cycle boundary)."""
        return self._latest

    def upload(self, scene: CompiledScene, origin: str = "upload") -> GateDecision:
        """Gate ``scene`` and stage it for the next cycle boundary; GateRefusal (logged) if refused."""
        with self._lock:
            return self._admit(scene, origin)

    def set_walls(self, changes: dict[str, tuple[float, float]], origin: str = "upload") -> GateDecision:
        """Change several objects' ``(K, B)`` (N/m, N s/m) as one upload: all pass the gate, or none applies."""
        with self._lock:
            return self._admit(changed_scene(self._latest.scene, changes), origin)

    def stage(self, scene: CompiledScene, decision: GateDecision, judged: tuple[PassivityGate, SceneEntry],
              origin: str = "upload") -> GateDecision:
        """Stage ``scene`` with the ``decision`` a judge elsewhere gave (never judged again here), as
        :meth:`upload` would; ``judged``: the gate and the latest entry it was judged against, still
        both current, else :class:`StaleJudgement` (a derate or another upload came in between).
        GateRefusal (logged) if refused."""
        with self._lock:
            gate, base = judged
            if gate is not self.gate or base is not self._latest:
                what = "the gate (a derate)" if gate is not self.gate else f"the scene (now scene {self._latest.scene_id})"
                self.events.add(self._now(), "refused", f"{origin} judged against a scene no longer the latest")
                raise StaleJudgement(f"{what} changed while the {origin} was judged; upload again")
            return self._stage(scene, decision, origin)

    def _decide(self, scene: CompiledScene) -> GateDecision:
        """The gate's decision; GateRefusal for a refused scene unless beyond the gate is allowed."""
        decision = self.gate.judge(scene)
        if not decision.accepted and not self.beyond_gate:
            raise GateRefusal(decision)
        return decision

    def _admit(self, scene: CompiledScene, origin: str) -> GateDecision:
        return self._stage(scene, self.gate.judge(scene), origin)

    def _stage(self, scene: CompiledScene, decision: GateDecision, origin: str) -> GateDecision:
        if not decision.accepted and not self.beyond_gate:
            self.events.add(self._now(), "refused", f"{origin} refused by the gate", reasons=list(decision.reasons))
            raise GateRefusal(decision)
        entry = SceneEntry(len(self.history), origin, scene, decision)
        self.history.append(entry)
        self._latest = entry
        beyond = "" if decision.accepted else " beyond the gate (the bound passivity layer holds it passive)"
        self.events.add(self._now(), "upload", f"{origin} accepted as scene {entry.scene_id}{beyond}",
                        scene_id=entry.scene_id, worst_margin=decision.worst_margin, gate_passed=decision.accepted)
        return decision

    def adopt(self) -> SceneEntry:
        """At a cycle boundary: the last accepted scene becomes the running one (one read, whole)."""
        latest = self._latest
        if latest is not self.running:
            self.running = latest
            self.applied += 1
        return latest

    def replace(self, gate: PassivityGate, scene: CompiledScene, decision: GateDecision, origin: str) -> SceneEntry:
        """From the control thread: ``scene``, judged by ``gate``, runs from now on and stays the
        latest; later uploads are judged by ``gate`` (a derate's: the loop as observed)."""
        with self._lock:
            self.gate = gate
            entry = SceneEntry(len(self.history), origin, scene, decision)
            self.history.append(entry)
            self._latest = self.running = entry
            self.applied += 1
            return entry
